"""Whole-region programs of the convex layout: the stacking-seeded constraint graph, and the
distance constraints with their linear approximation (Hing et al. 2015, eqs. 3-4).

Cells. A non-convex free region is no ``A z <= b``; around a valid arrangement each skid
gets a convex *cell* instead: for every edge of the free region, a half-plane that keeps
the skid on its side. The edge's own line is used when the skid keeps the margin from it
(for a convex region every edge: the cell is the region, eq. 9 exactly); otherwise (a
reflex corner) the plane through the edge's closest point, normal along the closest-points
direction. Each edge lies beyond its plane, so a skid ``R_j`` inside its cell is ``R_j``
from every wall, and the arrangement itself satisfies every row with ``R_j >= margin``.

Seeding (:func:`seeded`). The constraint graph of the stacking layout
(:func:`.graph.from_arrangement`) with the cells of that layout: stacking is feasible for
it, so the program finds a layout of the same skids with a max-min spacing at least the
margin wherever stacking fits them.

Distance constraints (:func:`refine`). Eq. 3 asks ``||p_i - p_j|| >= D_ij`` (non-convex);
eq. 4 replaces it by ``a_ij . (p_i - p_j) >= D_ij`` with ``a_ij`` the direction between
``i`` and ``j`` in a solution ``p^`` of the program without them (the paper's heuristic).
For rectangles the direction is taken between the footprints' closest points (for point
robots that is the paper's centre direction), and ``D_ij`` is the centre distance along
``a_ij`` at which the footprints keep the margin,
``D_ij = |a_x| (l_i + l_j) / 2 + |a_y| (w_i + w_j) / 2 + margin``: the plane normal to
``a_ij`` then separates the footprints by the margin, and ``||p_i - p_j|| >= D_ij`` follows.
Neighbouring pairs (closer than the smallest skid side plus twice the margin) get one,
with the gap beyond ``D_ij - margin`` a spacing item of the max-min objective; the H and V
edges are the cases ``a = (1, 0)`` and ``(0, 1)``, and a diagonal ``a_ij`` lets
neighbouring columns interleave. Eq. 4 is written for every pair; the far pairs (apart by
at least sqrt(2) times the margin, so by the margin on x or on y) keep that axis order
through the transitively reduced H and V graphs of ``p^`` instead, which keeps the program
O(N) rows per round rather than O(N^2) (100 skids: 1.6 s -> see docs/layout.md). ``p^`` satisfies
every row (its gap along ``a_ij`` is its true gap), so each round of re-linearizing at the
new solution keeps the max-min spacing from falling. Structured optimization follows.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely

from swarmpark.layout.convex.graph import (
    ConstraintGraph,
    axis_relations,
    from_arrangement,
    from_relations,
)
from swarmpark.layout.convex.program import (
    MAX_STRUCTURED_ITERATIONS,
    Program,
    ProgramBuilder,
    graph_program,
    solve_lp,
    structured,
)

__all__ = [
    "DistanceConstraints",
    "free_segments",
    "cells_around",
    "distance_constraints",
    "seeded",
    "refine",
    "MAX_LINEARIZATION_ROUNDS",
    "LINEARIZATION_GAIN_M",
]

#: Rounds of re-linearizing the distance constraints (eq. 4) at the last solution.
MAX_LINEARIZATION_ROUNDS = 8
#: Stop re-linearizing when the max-min spacing grew by less than this (metres).
LINEARIZATION_GAIN_M = 1e-4
#: Slack (metres) when testing that a skid keeps the margin from an edge's line.
_LINE_TOL_M = 1e-9


@dataclass(frozen=True)
class DistanceConstraints:
    """The linearized distance constraints (eq. 4) of a layout.

    Attributes
    ----------
    i, j
        ``(P,)`` skid pairs, ``i < j``.
    a
        ``(P, 2)`` unit directions ``a_ij`` (from ``i`` towards ``j``).
    d
        ``(P,)`` ``D_ij``: ``a_ij . (c_j - c_i) >= D_ij`` is required.
    """

    i: np.ndarray
    j: np.ndarray
    a: np.ndarray
    d: np.ndarray

    def residual(self, centres: np.ndarray) -> np.ndarray:
        """``a_ij . (c_j - c_i) - D_ij`` (>= 0 where the constraint holds)."""
        diff = centres[self.j] - centres[self.i]
        return np.einsum("kd,kd->k", self.a, diff) - self.d


def free_segments(free) -> np.ndarray:
    """Every edge of the free region's rings, ``(W, 2, 2)``."""
    rings = shapely.get_parts(shapely.get_rings(shapely.get_parts(free)))
    segs = []
    for ring in rings:
        pts = np.asarray(ring.coords)
        segs.append(np.stack([pts[:-1], pts[1:]], axis=1))
    out = np.concatenate(segs) if segs else np.zeros((0, 2, 2))
    d = out[:, 1] - out[:, 0]
    return out[np.hypot(d[:, 0], d[:, 1]) > 1e-12]


def cells_around(segs: np.ndarray, centres: np.ndarray, half: np.ndarray, margin: float):
    """Cell rows ``(skid, normals, offsets, weights)`` of every skid around an arrangement."""
    n, w = len(centres), len(segs)
    p0, p1 = segs[:, 0], segs[:, 1]
    d = p1 - p0
    nl = np.column_stack([d[:, 1], -d[:, 0]]) / np.hypot(d[:, 0], d[:, 1])[:, None]
    side = np.einsum("wd,nwd->nw", nl, centres[:, None, :] - p0[None])
    normal = -np.where(side[..., None] >= 0, 1.0, -1.0) * nl[None]  # towards the line
    support = np.einsum("nwd,nd->nw", np.abs(normal), half)
    offset = np.einsum("nwd,wd->nw", normal, p0)
    slack = offset - np.einsum("nwd,nd->nw", normal, centres) - support
    bad = slack < margin - _LINE_TOL_M
    if bad.any():
        ii, kk = np.nonzero(bad)
        lo, hi = centres[ii] - half[ii], centres[ii] + half[ii]
        boxes = shapely.box(lo[:, 0], lo[:, 1], hi[:, 0], hi[:, 1])
        ends = shapely.get_coordinates(
            shapely.shortest_line(boxes, shapely.linestrings(segs[kk]))
        ).reshape(-1, 2, 2)
        u = ends[:, 1] - ends[:, 0]
        u /= np.maximum(np.hypot(u[:, 0], u[:, 1]), 1e-12)[:, None]
        normal[ii, kk] = u
        offset[ii, kk] = np.einsum("kd,kd->k", u, ends[:, 1])
    skid = np.repeat(np.arange(n), w)
    return skid, normal.reshape(-1, 2), offset.reshape(-1), np.ones(n * w)


def distance_constraints(centres: np.ndarray, half: np.ndarray, margin: float, pairs=None):
    """Eq. 4 for the pairs ``(i, j)`` (default: every ``i < j``), linearized at ``centres``
    (see the module doc)."""
    n = len(centres)
    i, j = np.triu_indices(n, 1) if pairs is None else pairs
    diff = centres[j] - centres[i]
    reach = half[i] + half[j]
    gap = np.abs(diff) - reach  # per-axis gaps between the footprints
    a = np.sign(diff) * np.maximum(gap, 0.0)
    # Footprints apart on neither axis overlap: use the axis closest to apart.
    none = ~(gap > 0).any(axis=1)
    if none.any():
        axis = np.argmax(gap[none], axis=1)
        a[none] = 0.0
        a[np.flatnonzero(none), axis] = np.where(diff[none, axis] >= 0, 1.0, -1.0)
    a /= np.hypot(a[:, 0], a[:, 1])[:, None]
    d = np.einsum("kd,kd->k", np.abs(a), reach) + margin
    return DistanceConstraints(i, j, a, d)


def neighbours(centres: np.ndarray, half: np.ndarray, margin: float):
    """``(pairs, graph)``: the pairs ``i < j`` closer than :func:`neighbour_gap` (they get
    distance constraints) and the H and V graphs of the other pairs (each apart on x or y
    by at least the margin, since their Euclidean gap is at least sqrt(2) times it)."""
    diff = np.abs(centres[None, :, :] - centres[:, None, :])
    gaps = np.maximum(diff - (half[None, :, :] + half[:, None, :]), 0.0)
    gap = np.hypot(gaps[..., 0], gaps[..., 1])
    far = gap >= neighbour_gap(half, margin)
    left, below = axis_relations(centres, half, margin)
    graph = from_relations(left & far, below & far, "far pairs")
    i, j = np.nonzero(np.triu(~far, 1))
    return (i, j), graph


def neighbour_gap(half: np.ndarray, margin: float) -> float:
    """Gap (metres) below which two skids are neighbours: the smallest skid side plus twice
    the margin, so a pair with a skid between them is never one (and the far pairs' graph
    implies nothing about neighbours)."""
    return float(2.0 * half.min() + 2.0 * margin)


def _program(segs, centres, half, margin) -> tuple[Program, DistanceConstraints, object]:
    b = ProgramBuilder(half)
    b.cell_rows(*cells_around(segs, centres, half, margin))
    pairs, graph = neighbours(centres, half, margin)
    dc = distance_constraints(centres, half, margin, pairs)
    b.gap_items(dc.i, dc.j, dc.a, "distance")
    # Far pairs keep their axis order (eqs. 5-6); not items: their gap on that axis can be
    # small while the pair is far apart.
    b.gap_rows(graph.h[:, 0], graph.h[:, 1], np.tile([1.0, 0.0], (len(graph.h), 1)), margin)
    b.gap_rows(graph.v[:, 0], graph.v[:, 1], np.tile([0.0, 1.0], (len(graph.v), 1)), margin)
    b.r_items()
    return b.build(), dc, graph


def seeded(segs: np.ndarray, seed: np.ndarray, half: np.ndarray, margin: float):
    """The program of the seed's constraint graph (eqs. 5, 6, 9, 11) with the seed's cells.

    Returns ``(centres, objective, graph)``, or ``None`` if the solver fails (the seed
    itself is feasible, so only numerically).
    """
    graph: ConstraintGraph = from_arrangement(seed, half, margin, "stacking")
    prog = graph_program(graph, half, cells_around(segs, seed, half, margin))
    sol = solve_lp(prog, margin)
    if sol is None:
        return None
    return prog.centres(sol[0]), sol[1], graph


def refine(
    segs: np.ndarray,
    centres: np.ndarray,
    half: np.ndarray,
    margin: float,
    *,
    rounds: int = MAX_LINEARIZATION_ROUNDS,
    max_iterations: int = MAX_STRUCTURED_ITERATIONS,
):
    """Linearized distance constraints from a valid layout, re-linearized for ``rounds``
    rounds, then structured optimization. Returns ``(centres, info, constraints)`` or
    ``None`` if the first program fails numerically."""
    cur = np.asarray(centres, dtype=float)
    best = None
    used = 0
    for _ in range(max(rounds, 1)):
        prog, dc, graph = _program(segs, cur, half, margin)
        sol = solve_lp(prog, margin)
        if sol is None:
            break
        used += 1
        gain = np.inf if best is None else sol[1] - best[1][1]
        best = (prog, sol, dc, graph)
        cur = prog.centres(sol[0])
        if gain < LINEARIZATION_GAIN_M:
            break
    if best is None:
        return None
    prog, sol, dc, graph = best
    done = structured(prog, margin, sol, max_iterations)
    info = {
        "objective_m": done.objective,
        "linearization_rounds": used,
        "distance_constraints": len(dc.i),
        "far_pair_edges": len(graph.h) + len(graph.v),
        "iterations": done.iterations,
        "held": done.held,
    }
    return prog.centres(done.z), info, dc, graph
