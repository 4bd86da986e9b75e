"""Potential-field layout (Hing et al. 2018, Sect. 3.2.2, eqs. 1-4).

Starting from the stacking goals, each goal is a floating point repelled by every other goal
(``1/d``, eq. 3) and by the discretized boundary points within a distance threshold
(``1/d``, eq. 2); the goals follow the force ``-grad U`` (eq. 4) until the total energy
(eq. 1) changes by less than a tolerance or an iteration cap is hit.

Three variants: the paper's two of Fig. 5, and one with the distances measured between
footprints:

- ``"centroid"``: distances between goal centroids, and centroid to boundary points.
- ``"vertex"``: distances between the rectangles' vertices (and vertex to boundary point);
  the forces on a rectangle's vertices add up to the force on its centroid.
- ``"footprint"`` (the default, ``"auto"``): ``dist`` in eqs. 2-3 is the distance between
  the two goals' footprint rectangles (and from a footprint to a boundary point), i.e. the
  gap the skids will actually have, instead of the distance between their centres. The
  equations are otherwise as written (``1/d`` energies, ``-grad U`` forces).

Why the default is not the paper's centroid field (issue 21): it is isotropic while a skid is
half again as long as it is wide, so it spaces centres, not skids. For 9 skids of 1.2 x 0.8
m in an 8 x 6 m box its lowest minimum found is a 4-2-3 arrangement with four skids end to
end along the long side (closest pair 0.54 m; eq. 1 is 12.2 there against 12.8 for the 3 x 3
grid, so no better search would fix it). The paper's vertex field sees the shape and settles
in the 3 x 3 grid (0.86 m) but costs 16 times the pairs (10 s for 100 skids against 2 s,
measured under load). The footprint field also settles in the 3 x 3 grid (0.82 m; convex
max-min: 0.90 m) and handles mixed sizes; with the boundary points looked up in a KD-tree it
takes 0.4-0.8 s for 50-100 skids (``swarmpark bench --only layout``). Near capacity (24 skids in the L-bay of
docs/layout.md: footprint 0.43 m, centroid and vertex 0.30 m; 9 in an 8 x 8 m diamond: all
0.30 m) the closest pair can stay at the margin: eq. 1 lowers the sum of ``1/d``, not the
smallest gap, and a pair pressed together by the walls is a constrained minimum of it. Every
goal keeps the operator's heading in all variants, so the "appearance of disorder" the paper
saw with vertices (rotated goals, Fig. 5) does not arise.

Departures from the paper, for a layout that is always valid and a loop that terminates:

- The boundary term is shifted, ``1/d - 1/threshold``, so the energy is continuous at the
  threshold (the force, ``1/d^2``, is the paper's). The paper does not weight the boundary
  against the goals; here each boundary point weighs ``spacing / pitch`` of a goal, so a
  wall pushes like a row of goals at the skids' pitch whatever the discretization.
- Each goal moves along its force by its own adaptive step (a plain common gradient step
  stalls: the goal with the largest force, pressed against a wall, sets the scale for all).
  A move is kept only if it lowers that goal's energy, keeps its footprint in the free
  region with the margin and keeps the margin to the other goals; otherwise the goal stays
  (rejected) and its step is halved. An iteration that raises the total energy is undone.
  So every iterate is a valid layout and the energy never rises.
"""

from __future__ import annotations

import itertools

import numpy as np
import shapely
from scipy.spatial import cKDTree

from swarmpark.layout.region import Region, Skids, rect_gaps

__all__ = ["VARIANTS", "spread", "boundary_points", "local_terms", "total_energy"]

VARIANTS = ("centroid", "vertex", "footprint")
#: The variant ``"auto"`` picks: distances between footprints (module docstring).
DEFAULT_VARIANT = "footprint"
#: Footprint variant: distances below this (overlapping rectangles, a boundary point inside
#: a footprint: only ever proposed, never kept) count as this, so the energy stays finite.
_MIN_GAP_M = 1e-3
#: Iteration cap (the paper's "set number of iterations").
MAX_ITERATIONS = 300
#: Stop when the total energy has changed by less than this fraction of it in each of
#: ``ENERGY_PATIENCE`` consecutive iterations (single small steps happen while the goals'
#: step lengths adapt, so one small change is not yet a minimum).
ENERGY_RTOL = 1e-5
ENERGY_PATIENCE = 10
#: Relocation stops when this many of the most crowded skids in a row gain nothing by it.
MAX_FAILED_RELOCATIONS = 3
#: Boundary discretization: points per skid width (and at most this spacing, metres).
BOUNDARY_POINTS_PER_WIDTH = 4
MAX_BOUNDARY_SPACING_M = 0.25
#: First and smallest step of each goal (fractions of the narrowest skid width), and the
#: growth after a kept move (a rejected move halves the step; the largest is one width).
INITIAL_STEP_FRACTION = 0.25
MIN_STEP_FRACTION = 1e-3
STEP_GROWTH = 1.25
#: A pair closer than the margin by more than this is a conflict (round-off allowance).
_GAP_TOL_M = 1e-9
#: Parts of a move tried in turn: the whole move, then its x part, then its y part.
_MOVE_PARTS = (np.array([1.0, 1.0]), np.array([1.0, 0.0]), np.array([0.0, 1.0]))
#: Rectangle corners as multiples of the half size (vertex variant), counter-clockwise.
_CORNER_SIGNS = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])


def boundary_points(region: Region, spacing_m: float) -> np.ndarray:
    """Points ``(M, 2)`` along the free region's edge (boundary, walls, obstacles)."""
    edge = shapely.segmentize(region.free.boundary, spacing_m)
    pts = shapely.get_coordinates(edge)
    return np.unique(pts, axis=0)


def _points(centres: np.ndarray, half: np.ndarray, variant: str) -> np.ndarray:
    """Repelling points of each skid ``(N, K, 2)``: its centroid, or its four vertices."""
    if variant == "centroid":
        return centres[:, None, :]
    return centres[:, None, :] + _CORNER_SIGNS[None] * half[:, None, :]


def local_terms(
    moving: np.ndarray,
    others: np.ndarray,
    half: np.ndarray,
    bpts: np.ndarray,
    *,
    variant: str,
    threshold_m: float,
    boundary_weight: float,
    rows: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Energy and force of skid ``i`` at ``moving[i]`` against all others at ``others``.

    Returns ``(pair, boundary, force)``: the skid's goal-goal energy (eq. 3) summed over the
    others, its boundary energy (eq. 2), both ``(R,)``, and the force ``-grad U`` on it
    ``(R, 2)`` (eq. 4). ``rows`` (indices, default all) selects the skids evaluated;
    ``moving`` then holds only those rows. In the vertex variant, pair terms are averaged
    over the 16 vertex pairs and boundary terms over the 4 vertices, so the variants are on
    one scale.
    """
    n = len(others)
    rows = np.arange(n) if rows is None else np.asarray(rows)
    if variant == "footprint":
        return _footprint_terms(moving, others, half, bpts, rows, threshold_m, boundary_weight)
    p = _points(moving, half[rows], variant)  # (R, K, 2)
    q = _points(others, half, variant)  # (N, K, 2)
    r, k = p.shape[:2]
    px, py = p[..., 0].reshape(-1, 1), p[..., 1].reshape(-1, 1)  # (R*K, 1)
    dx = px - q[..., 0].reshape(1, -1)  # (R*K, N*K)
    dy = py - q[..., 1].reshape(1, -1)
    dist = np.sqrt(dx * dx + dy * dy)
    # A skid does not repel itself: infinite distance, zero energy and force.
    self_cols = np.repeat(rows, k)[:, None] * k + np.arange(k)[None, :]  # (R*K, K)
    dist[np.repeat(np.arange(r * k), k), self_cols.ravel()] = np.inf
    inv = 1.0 / dist
    pair_scale = 1.0 / (k * k)
    inv3 = inv * inv * inv
    pair = pair_scale * inv.sum(axis=1).reshape(r, k).sum(axis=1)
    fx = (inv3 * dx).sum(axis=1)
    fy = (inv3 * dy).sum(axis=1)
    force = pair_scale * np.column_stack([fx, fy]).reshape(r, k, 2).sum(axis=1)

    boundary = np.zeros(r)
    if len(bpts):
        bx = px - bpts[None, :, 0]  # (R*K, M)
        by = py - bpts[None, :, 1]
        bdist = np.sqrt(bx * bx + by * by)
        far = bdist >= threshold_m
        bdist[far] = np.inf
        binv = 1.0 / bdist
        b_scale = boundary_weight / k
        shifted = binv - np.where(far, 0.0, 1.0 / threshold_m)
        boundary = b_scale * shifted.sum(axis=1).reshape(r, k).sum(axis=1)
        binv3 = binv * binv * binv
        bf = np.column_stack([(binv3 * bx).sum(axis=1), (binv3 * by).sum(axis=1)])
        force = force + b_scale * bf.reshape(r, k, 2).sum(axis=1)
    return pair, boundary, force


def _rect_gap(dc: np.ndarray, reach: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance between axis-aligned rectangles whose centres differ by ``dc`` (``(..., 2)``)
    and whose half sizes add up to ``reach`` (broadcast), and its gradient with respect to the
    first centre (``(..., 2)``)."""
    ax = np.maximum(np.abs(dc) - reach, 0.0)  # per-axis gaps (0 if overlapping)
    dist = np.maximum(np.hypot(ax[..., 0], ax[..., 1]), _MIN_GAP_M)
    return dist, np.sign(dc) * ax / dist[..., None]


def _footprint_terms(moving, others, half, bpts, rows, threshold_m, boundary_weight):
    """:func:`local_terms` of the footprint variant: eqs. 2-3 on footprint distances."""
    dc = moving[:, None, :] - others[None, :, :]
    dist, grad = _rect_gap(dc, half[rows][:, None, :] + half[None, :, :])
    dist[np.arange(len(rows)), rows] = np.inf  # a skid does not repel itself
    inv = 1.0 / dist
    pair = inv.sum(axis=1)
    # -grad (1/d) = grad(d) / d^2.
    force = ((inv * inv)[..., None] * grad).sum(axis=1)
    boundary = np.zeros(len(rows))
    if len(bpts):
        # Only boundary points within the threshold of a footprint act: those within the
        # threshold plus the half diagonal of its centre (a KD-tree finds them; the dense
        # skids x points arrays were most of the layout's time).
        reach = threshold_m + float(np.hypot(*half[rows].max(axis=0)))
        hits = cKDTree(bpts).query_ball_point(moving, reach)
        lens = np.fromiter((len(h) for h in hits), int, len(hits))
        if lens.sum():
            row = np.repeat(np.arange(len(rows)), lens)
            pts = bpts[np.fromiter(itertools.chain.from_iterable(hits), int, lens.sum())]
            # A boundary point is a rectangle of no size.
            bdist, bgrad = _rect_gap(moving[row] - pts, half[rows][row])
            near = bdist < threshold_m
            binv = np.where(near, 1.0 / bdist, 0.0)
            energy = boundary_weight * np.where(near, binv - 1.0 / threshold_m, 0.0)
            boundary = np.bincount(row, energy, len(rows))
            f = boundary_weight * (binv * binv)[:, None] * bgrad
            force = force + np.column_stack(
                [np.bincount(row, f[:, 0], len(rows)), np.bincount(row, f[:, 1], len(rows))]
            )
    return pair, boundary, force


def total_energy(pair: np.ndarray, boundary: np.ndarray) -> float:
    """Eq. 1 from the per-skid terms of :func:`local_terms` (each pair counted once)."""
    return float(0.5 * pair.sum() + boundary.sum())


def _resolve(region: Region, half: np.ndarray, old: np.ndarray, prop: np.ndarray, moved):
    """Positions after rejecting moves that leave the region or come within the margin.

    Returns the positions and the mask of moves kept.
    """
    moved = moved.copy()
    idx = np.flatnonzero(moved)
    moved[idx] = region.inside(prop[idx], half[idx])
    limit = region.margin - _GAP_TOL_M
    while True:
        cur = np.where(moved[:, None], prop, old)
        idx = np.flatnonzero(moved)
        if len(idx) == 0:
            return cur, moved
        # Gaps of the moved footprints to all others (axis-aligned rectangles).
        revert = (rect_gaps(cur, half, idx) < limit).any(axis=1)
        if not revert.any():
            return cur, moved
        moved[idx[revert]] = False


def _descend(
    region: Region,
    half: np.ndarray,
    bpts: np.ndarray,
    c: np.ndarray,
    params,
    *,
    max_iterations: int,
    energy_rtol: float,
) -> tuple[np.ndarray, float, int, bool]:
    """Gradient descent with per-goal adaptive steps (see the module docstring) from the
    valid centres ``c``; returns the centres, the energy, the iterations and whether the
    energy settled before the cap."""
    n = len(half)
    width = 2.0 * float(half.min())
    pair, bnd, force = local_terms(c, c, half, bpts, **params)
    energy = total_energy(pair, bnd)
    steps = np.full(n, INITIAL_STEP_FRACTION * width)
    min_step = MIN_STEP_FRACTION * width
    quiet = 0  # consecutive iterations with a small energy change
    it = 0
    while it < max_iterations:
        it += 1
        norm = np.linalg.norm(force, axis=1)
        active = norm > 0
        if not active.any():
            return c, energy, it, True
        direction = force / np.where(norm > 0, norm, 1.0)[:, None]
        new, kept = c, np.zeros(n, dtype=bool)
        # The full move first; where it is blocked, its x or y part alone (footprints are
        # axis-aligned here, so this projects the move onto the wall or neighbour it hit).
        for axes in _MOVE_PARTS:
            todo = active & ~kept
            if not todo.any():
                break
            rows = np.flatnonzero(todo)
            prop = new.copy()
            prop[rows] += steps[rows, None] * direction[rows] * axes
            p_pair, p_bnd, _ = local_terms(prop[rows], c, half, bpts, rows=rows, **params)
            downhill = np.zeros(n, dtype=bool)
            downhill[rows] = p_pair + p_bnd < pair[rows] + bnd[rows]
            new, moved = _resolve(region, half, new, prop, downhill)
            kept |= moved
        # A blocked goal keeps trying with a short step: as the others move away, its force
        # may turn to a direction it can move in.
        steps = np.where(kept, np.minimum(steps * STEP_GROWTH, width), steps * 0.5)
        steps = np.maximum(steps, min_step)
        drop = 0.0
        if kept.any():
            n_pair, n_bnd, n_force = local_terms(new, new, half, bpts, **params)
            e_new = total_energy(n_pair, n_bnd)
            if e_new < energy:
                drop = energy - e_new
                c, pair, bnd, force, energy = new, n_pair, n_bnd, n_force, e_new
            else:
                # Simultaneous moves can interfere: undo, and retry with shorter steps.
                steps = np.where(kept, steps * 0.25, steps)
        quiet = quiet + 1 if drop < energy_rtol * abs(energy) else 0
        if quiet >= ENERGY_PATIENCE:
            return c, energy, it, True
    return c, energy, it, False


def _largest_hole(region: Region, half: np.ndarray, c: np.ndarray, i: int) -> np.ndarray | None:
    """The centre, on a grid of half the narrowest skid width, where skid ``i`` fits (in
    the free region with the margin, the margin from every other skid) farthest from the
    other skids' rectangles; ``None`` if it fits nowhere but where it is."""
    step = float(half.min())
    xmin, ymin, xmax, ymax = region.inner.bounds
    xs = np.arange(xmin + half[i, 0], xmax - half[i, 0] + 1e-9, step)
    ys = np.arange(ymin + half[i, 1], ymax - half[i, 1] + 1e-9, step)
    if not len(xs) or not len(ys):
        return None
    cand = np.stack(np.meshgrid(xs, ys), -1).reshape(-1, 2)
    others = np.delete(np.arange(len(c)), i)
    d = np.abs(cand[:, None, :] - c[None, others, :]) - (half[i] + half[others])[None]
    gap = np.where(
        np.maximum(d[..., 0], d[..., 1]) < 0,
        -np.inf,
        np.hypot(np.maximum(d[..., 0], 0), np.maximum(d[..., 1], 0)),
    ).min(axis=1, initial=np.inf)
    ok = gap >= region.margin - _GAP_TOL_M
    ok[ok] = region.inside(cand[ok], np.broadcast_to(half[i], (int(ok.sum()), 2)))
    if not ok.any():
        return None
    return cand[np.flatnonzero(ok)[np.argmax(gap[ok])]]


def spread(
    region: Region,
    skids: Skids,
    centres: np.ndarray,
    *,
    variant: str = "auto",
    max_iterations: int = MAX_ITERATIONS,
    energy_rtol: float = ENERGY_RTOL,
    threshold_m: float | None = None,
    relocations: int | None = None,
) -> tuple[np.ndarray, dict]:
    """Spread a valid layout by the potential field.

    Each iteration, every goal proposes a move of its own step length along its force; a
    move is kept if it lowers that goal's energy (others held where they were), keeps the
    footprint in the free region with the margin and keeps the margin to the other goals
    (after their moves). Kept moves lengthen that goal's step, rejected ones halve it.

    The descent stops in the nearest minimum of eq. 1, and from the stacking layout that is
    a packed one: stacking fills columns from one side, and a skid in a full column is held
    by its neighbours' equal and opposite pushes. So, after the descent, the goal with the
    highest energy is moved to the largest free hole (the grid point where it fits farthest
    from the others) and the descent runs again; the move is kept if the total energy
    drops (a basin-hopping step, Wales and Doye 1997), and this repeats up to
    ``relocations`` times or until a move does not help. Every kept layout is valid, and
    the energy never rises.

    Parameters
    ----------
    region, skids
        Layout-frame region and the footprints.
    centres
        ``(N, 2)`` valid starting centres (the stacking layout).
    variant
        ``"centroid"``, ``"vertex"``, ``"footprint"``, or ``"auto"`` (footprint: see the
        module docstring for why it is the default).
    max_iterations
        Iteration cap of each descent.
    energy_rtol
        Stop when the total energy changes by less than this fraction in an iteration.
    threshold_m
        Boundary points farther than this do not act (eq. 2). Default: the largest skid
        pitch (length + margin).
    relocations
        Largest number of relocation moves (default: the number of skids; 0 gives the
        plain descent of eqs. 1-4).

    Returns
    -------
    centres, info
        Final centres and a dict with ``variant``, ``iterations``, ``relocations``,
        ``energy_initial``, ``energy_final``, ``converged``, ``notices``.
    """
    if variant == "auto":
        variant = DEFAULT_VARIANT
    if variant not in VARIANTS:
        raise ValueError(f"potential variant must be one of {VARIANTS} or 'auto' (got {variant!r})")
    half = skids.half
    n = len(half)
    c = np.asarray(centres, dtype=float).copy()
    width = 2.0 * float(half.min())
    pitch = float(
        np.sqrt(np.mean((2 * half[:, 0] + region.margin) * (2 * half[:, 1] + region.margin)))
    )
    spacing = min(width / BOUNDARY_POINTS_PER_WIDTH, MAX_BOUNDARY_SPACING_M)
    bpts = boundary_points(region, spacing)
    thr = float(threshold_m) if threshold_m is not None else float(2 * half.max() + region.margin)
    params = dict(variant=variant, threshold_m=thr, boundary_weight=spacing / pitch)
    opts = dict(max_iterations=max_iterations, energy_rtol=energy_rtol)

    e0 = total_energy(*local_terms(c, c, half, bpts, **params)[:2])
    c, energy, iterations, converged = _descend(region, half, bpts, c, params, **opts)
    moves = 0
    budget = n if relocations is None else int(relocations)
    tried: set[int] = set()
    while moves < budget and n > 1:
        pair, bnd, _ = local_terms(c, c, half, bpts, **params)
        order = [int(k) for k in np.argsort(-(pair + bnd), kind="stable") if int(k) not in tried]
        if not order:
            break
        i = order[0]
        hole = _largest_hole(region, half, c, i)
        tried.add(i)
        if hole is None:
            continue
        trial = c.copy()
        trial[i] = hole
        t_c, t_e, t_it, t_conv = _descend(region, half, bpts, trial, params, **opts)
        iterations += t_it
        if t_e < energy * (1.0 - energy_rtol):
            c, energy, converged = t_c, t_e, t_conv
            moves += 1
            tried.clear()
        elif len(tried) >= min(n, MAX_FAILED_RELOCATIONS):
            break  # the most crowded skids gain nothing by moving: a settled layout
    info = {
        "variant": variant,
        "iterations": iterations,
        "relocations": moves,
        "energy_initial": e0,
        "energy_final": energy,
        "converged": converged,
        "boundary_points": len(bpts),
        "threshold_m": thr,
        "notices": [] if converged else [f"potential: iteration cap {max_iterations} reached"],
    }
    return c, info
