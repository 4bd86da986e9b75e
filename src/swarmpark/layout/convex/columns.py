"""Column arrangements of the skids of one convex piece (the ``square`` and ``diamond``
schemes, after the paper's Fig. 2), each a constraint graph (:func:`.graph.from_columns`),
solved as the program of eqs. 5-11; and the walls across a piece's cuts.

``square`` columns are of equal size (a rows x columns grid); ``diamond`` column sizes
follow the height of the piece at each column, so the narrow ends of a diamond, triangle
or trapezoid get fewer skids. Several column counts of both are solved and the best kept.

Walls across cuts. A piece keeps ``R_j / 2`` from a cut between pieces, which is enough
against a skid across the cut (it keeps the other half) but not against a wall across it:
a wall leaving the cut's end at a reflex vertex, or the far side of a thin neighbour. Such
a skid sat closer than the margin to the wall, failed validation, and the whole layout
fell back to stacking. Now every solution is checked against the free region's edges and
a skid closer than ``R_j`` to one gets a separating plane (through the closest point of the
wall, normal along the closest-points direction: the wall lies beyond it, so ``R_j`` from
the plane is ``R_j`` from the wall), and the program is solved again (cutting planes).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import shapely

from swarmpark.layout.convex.graph import from_columns
from swarmpark.layout.convex.pieces import ConvexPiece
from swarmpark.layout.convex.program import (
    ACTIVE_TOL_M,
    MAX_STRUCTURED_ITERATIONS,
    Program,
    graph_program,
    solve_lp,
)
from swarmpark.layout.convex.program import structured as run_structured

__all__ = ["SCHEMES", "PieceSolution", "solve_piece", "wall_cuts", "MAX_CUT_ROUNDS"]

SCHEMES = ("square", "diamond")
#: Rounds of adding separating planes against walls across cuts before giving up.
MAX_CUT_ROUNDS = 8
#: A skid this much (metres) closer to a wall than ``R_j`` gets a cutting plane.
CUT_TOL_M = 1e-7


@dataclass
class PieceSolution:
    """Result for one piece: centres, the first max-min objective, details."""

    centres: np.ndarray
    objective: float
    scheme: str
    columns: list[int]
    iterations: int
    held: int = 0
    notes: list[str] = field(default_factory=list)


def wall_cuts(prog: Program, z: np.ndarray, walls: np.ndarray):
    """Separating planes ``(A, b)`` for skids closer than ``R_j`` to a wall segment
    (``walls``: ``(W, 2, 2)``), or ``None`` if there are none."""
    n = prog.n
    if n == 0 or len(walls) == 0:
        return None
    c = prog.centres(z)
    r = z[2 * n : 3 * n]
    lo, hi = c - prog.half, c + prog.half
    boxes = shapely.box(lo[:, 0], lo[:, 1], hi[:, 0], hi[:, 1])
    segs = shapely.linestrings(walls)
    d = shapely.distance(boxes[:, None], segs[None, :])
    i, k = np.nonzero(d < r[:, None] - CUT_TOL_M)
    if len(i) == 0:
        return None
    lines = shapely.shortest_line(boxes[i], segs[k])
    ends = shapely.get_coordinates(lines).reshape(-1, 2, 2)
    q, w = ends[:, 0], ends[:, 1]  # on the box, on the wall
    u = w - q
    norm = np.hypot(u[:, 0], u[:, 1])
    touching = norm < 1e-12
    u[touching] = w[touching] - c[i[touching]]
    u /= np.maximum(np.hypot(u[:, 0], u[:, 1]), 1e-12)[:, None]
    support = np.einsum("kd,kd->k", np.abs(u), prog.half[i])
    m = len(i)
    rows = np.repeat(np.arange(m), 3)
    cols = np.column_stack([i, n + i, 2 * n + i]).ravel()
    vals = np.column_stack([u[:, 0], u[:, 1], np.ones(m)]).ravel()
    a = sp.csr_matrix((vals, (rows, cols)), shape=(m, prog.nvar))
    return a, np.einsum("kd,kd->k", u, w) - support


def _solver_with_cuts(walls: np.ndarray):
    """:func:`solve_lp` that adds wall cuts until the solution keeps every wall."""

    def solve(prog: Program, margin: float, held=None, values=None):
        for _ in range(MAX_CUT_ROUNDS):
            sol = solve_lp(prog, margin, held, values)
            if sol is None:
                return None
            cuts = wall_cuts(prog, sol[0], walls)
            if cuts is None:
                return sol
            prog.add_rows(*cuts)
        return None

    return solve


def _column_plans(piece: ConvexPiece, half: np.ndarray, margin: float):
    """Candidate column arrangements ``(scheme, counts)`` for the skids of a piece."""
    n = len(half)
    x0, y0, x1, y1 = piece.polygon.bounds
    px = float(2 * half[:, 0].max() + margin)
    py = float(2 * half[:, 1].max() + margin)
    ratio = max((x1 - x0) / px, 1e-9) / max((y1 - y0) / py, 1e-9)
    c0 = float(np.sqrt(n * ratio))
    cands = sorted(
        {
            int(np.clip(c, 1, n))
            for c in (np.floor(c0) - 1, np.floor(c0), np.ceil(c0), np.ceil(c0) + 1, np.ceil(c0) + 2)
        }
    )
    plans: list[tuple[str, tuple[int, ...]]] = []
    for ncol in cands:
        base, extra = divmod(n, ncol)
        square = tuple(base + (1 if c < extra else 0) for c in range(ncol))
        plans.append(("square", square))
        # Diamond: column sizes follow the piece's height at each column's centre line.
        xs = x0 + (np.arange(ncol) + 0.5) * (x1 - x0) / ncol
        lines = shapely.linestrings(
            np.stack(
                [
                    np.column_stack([xs, np.full(ncol, y0 - 1)]),
                    np.column_stack([xs, np.full(ncol, y1 + 1)]),
                ],
                axis=1,
            )
        )
        heights = shapely.length(shapely.intersection(piece.polygon, lines))
        if n >= ncol and heights.sum() > 0:
            share = heights / heights.sum() * (n - ncol)
            counts = 1 + np.floor(share).astype(int)
            rest = n - counts.sum()
            order = np.argsort(-(share - np.floor(share)), kind="stable")
            counts[order[:rest]] += 1
            diamond = tuple(int(c) for c in counts)
            if diamond != square:
                plans.append(("diamond", diamond))
    return plans


def _columns_from_counts(order: np.ndarray, counts: tuple[int, ...]) -> list[list[int]]:
    out, k = [], 0
    for c in counts:
        out.append([int(i) for i in order[k : k + c]])
        k += c
    return out


def piece_cells(piece: ConvexPiece, n: int) -> tuple[np.ndarray, ...]:
    """Eq. 9 rows of every skid in a piece: ``(skid, normals, offsets, weights)``."""
    e = len(piece.offsets)
    return (
        np.repeat(np.arange(n), e),
        np.tile(piece.normals, (n, 1)),
        np.tile(piece.offsets, n),
        np.tile(piece.weights, n),
    )


def solve_piece(
    piece: ConvexPiece,
    half: np.ndarray,
    margin: float,
    *,
    structured: bool = True,
    max_iterations: int = MAX_STRUCTURED_ITERATIONS,
    plan: tuple[str, tuple[int, ...]] | None = None,
    walls: np.ndarray | None = None,
) -> PieceSolution | None:
    """Lay out skids with half sizes ``half`` in one convex piece; ``None`` if infeasible.

    Every candidate column arrangement is solved once; the best max-min objective wins
    (ties: the first, square before diamond, fewer columns first) and is then refined by
    structured optimization. ``plan`` = ``(scheme, column counts)`` skips the search.
    ``walls`` (``(W, 2, 2)`` segments of the free region's edge) are kept at ``R_j`` by
    cutting planes; without them only the piece's own edges are.
    """
    n = len(half)
    if n == 0:
        return PieceSolution(np.zeros((0, 2)), np.inf, "none", [], 0)
    walls = np.zeros((0, 2, 2)) if walls is None else walls
    solve = _solver_with_cuts(walls)
    # Larger skids first, so each column starts with the biggest.
    order = np.argsort(-(half[:, 0] * half[:, 1]), kind="stable")
    cells = piece_cells(piece, n)
    best = None
    plans = [plan] if plan is not None else _column_plans(piece, half, margin)
    for scheme, counts in plans:
        graph = from_columns(_columns_from_counts(order, counts), scheme)
        prog = graph_program(graph, half, cells)
        sol = solve(prog, margin)
        if sol is not None and (best is None or sol[1] > best[2] + ACTIVE_TOL_M):
            best = (scheme, counts, sol[1], prog, sol)
    if best is None:
        return None
    scheme, counts, objective, prog, sol = best
    done = run_structured(prog, margin, sol, max_iterations if structured else 1, solve)
    return PieceSolution(
        prog.centres(done.z), objective, scheme, list(counts), done.iterations, done.held
    )
