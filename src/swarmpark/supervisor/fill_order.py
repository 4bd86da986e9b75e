"""Fill order of a parking group: which goal must stay free until which others are filled.

A skid that parks at the mouth of a dead end before the skids bound deeper would wall them
in (2018 paper, Fig. 6: deepest goals first). :func:`blockers` works out, once per park
command, for every goal the goals it would cut off; :func:`held` decides every tick which
skids must wait outside their boundary because of that.

Both are functions of their inputs (a grid, goals, footprints; the group's robots and their
pose estimates), testable without a simulator.
"""

from __future__ import annotations

import numpy as np
import shapely
from shapely.geometry import Polygon

from swarmpark.core.gridmap import OccupancyGrid
from swarmpark.metrics import HEADING_TOL_RAD, POSITION_TOL_M, goal_errors

__all__ = ["blockers", "held", "BLOCKING_RESOLUTION_M", "BLOCKING_MAX_GOALS", "BLOCKING_CROP_M"]

#: Fill-order blocking is judged on a grid this coarse, cropped this far around the boundary.
BLOCKING_RESOLUTION_M = 0.1
BLOCKING_MAX_GOALS = 40
BLOCKING_CROP_M = 3.0


def blockers(
    goals: np.ndarray, fps, boundary: Polygon, fill_order, grid: OccupancyGrid
) -> tuple[tuple[int, ...], ...]:
    """For each goal k, the goals j filled before k (in the layout's fill order) that can be
    reached from outside the boundary with the goals before j occupied, but not once k is
    occupied as well: k must stay free until those are filled.

    Reachability is connectivity of the free space of ``grid`` for a disc one skid wide, on a
    coarse grid cropped around the boundary (scipy.ndimage.label), seeded outside the
    boundary. Groups of one goal, or of more than :data:`BLOCKING_MAX_GOALS` (the test is
    quadratic), get no holds.

    Parameters
    ----------
    goals
        ``(G, 3)`` goal poses.
    fps
        The footprint laid out at each goal.
    boundary
        The parking boundary.
    fill_order
        Goal indices in the order they should be filled (the layout's).
    grid
        The map the skids plan in.
    """
    from scipy import ndimage

    from swarmpark.core.geometry import footprint_polygon

    n = len(goals)
    if n < 2 or n > BLOCKING_MAX_GOALS:
        return tuple(() for _ in goals)
    half = max(f.width_m for f in fps) / 2
    res = max(grid.resolution_m, BLOCKING_RESOLUTION_M)
    xmin, ymin, xmax, ymax = boundary.buffer(BLOCKING_CROP_M).bounds
    gx0, gy0, gx1, gy1 = grid.bounds
    xmin, ymin, xmax, ymax = max(xmin, gx0), max(ymin, gy0), min(xmax, gx1), min(ymax, gy1)
    xs = np.arange(xmin + res / 2, xmax, res)
    ys = np.arange(ymin + res / 2, ymax, res)
    X, Y = np.meshgrid(xs, ys)
    pts = np.column_stack([X.ravel(), Y.ravel()])
    occ = grid.is_occupied(pts).reshape(X.shape)
    free = ndimage.distance_transform_edt(~occ) * res > half
    polys = [footprint_polygon(g, f) for g, f in zip(goals, fps, strict=True)]
    masks = [shapely.contains_xy(poly.buffer(half - 1e-6), X, Y) for poly in polys]
    seeds = ~shapely.contains_xy(boundary.buffer(res), X, Y) & free
    centers = np.array([list(p.centroid.coords)[0] for p in polys])
    cj = np.clip(((centers[:, 1] - ymin) / res).astype(int), 0, len(ys) - 1)
    ci = np.clip(((centers[:, 0] - xmin) / res).astype(int), 0, len(xs) - 1)
    rank = {g: r for r, g in enumerate(fill_order)}
    order = sorted(range(n), key=lambda g: rank.get(g, n))

    def reachable(space: np.ndarray, j: int) -> bool:
        labels, _ = ndimage.label(space, structure=np.ones((3, 3)))
        lab = labels[cj[j], ci[j]]
        return bool(lab) and bool(np.any(labels[seeds & space] == lab))

    blocks: list[set[int]] = [set() for _ in range(n)]
    occupied = np.zeros(X.shape, dtype=bool)
    for pos, j in enumerate(order):
        base = free & ~occupied
        if reachable(base, j):
            for k in order[pos + 1 :]:
                if not reachable(base & ~masks[k], j):
                    blocks[k].add(j)
        occupied |= masks[j]
    return tuple(tuple(sorted(b)) for b in blocks)


def held(groups, poses: np.ndarray) -> np.ndarray:
    """Robots that must wait outside their boundary: their goal would block a deeper goal
    that is not filled yet and whose skid is not ahead of them (deepest goals first, 2018
    Fig. 6). A skid may follow the one bound deeper; it must not overtake it.

    Parameters
    ----------
    groups
        Parking groups, each with ``robots`` (indices), ``goals`` ``(G, 3)``, ``goal_of``
        (goal index per robot) and ``blocks`` (from :func:`blockers`).
    poses
        ``(N, 3)`` the poses the fleet decides from (estimates with onboard localization).
    """
    hold = np.zeros(len(poses), dtype=bool)
    for g in groups:
        if not g.blocks or not any(g.blocks):
            continue
        pos_err, head_err = goal_errors(poses[g.robots], g.goals[g.goal_of])
        parked = (pos_err <= POSITION_TOL_M) & (head_err <= HEADING_TOL_RAD)
        filled = np.zeros(len(g.goals), dtype=bool)
        filled[g.goal_of[parked]] = True
        to_go = np.full(len(g.goals), np.inf)  # distance of each goal's skid to it
        to_go[g.goal_of] = pos_err
        for r, k, d in zip(g.robots, g.goal_of, pos_err, strict=True):
            hold[r] = any(not filled[j] and to_go[j] >= d for j in g.blocks[k])
    return hold
