"""Fill order of a parking group: which skids must wait so that no spot is walled in.

A skid that parks at the mouth of a dead end before the skids bound deeper would wall them
in (2018 paper, Fig. 6: deepest goals first). The layout gives a deepest-first fill order,
but the skids do not arrive in it, and a spot can be walled in by two neighbours together
that neither walls in alone (a spot in the middle of a block, its last two open sides
filled at once). So the holds are decided from the state of the park, not once:
:func:`reach_grid` prepares, once per park command, the free space around the boundary and
every spot's cells on a coarse grid; :func:`held` then plays the filling forward from the
spots already filled, skid by skid in the order they will get there (nearest first), and
holds a skid whose spot would cut off a spot whose skid is not ahead of it.

Both are functions of their inputs (a grid, goals, footprints; the group's robots and their
pose estimates), testable without a simulator.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely
from shapely.geometry import Polygon

from swarmpark.core.gridmap import OccupancyGrid
from swarmpark.metrics import HEADING_TOL_RAD, POSITION_TOL_M, goal_errors

__all__ = [
    "Reach",
    "reach_grid",
    "held",
    "held_goals",
    "BLOCKING_RESOLUTION_M",
    "BLOCKING_MAX_GOALS",
    "BLOCKING_CROP_M",
]

#: Fill-order blocking is judged on a grid this coarse, cropped this far around the boundary.
BLOCKING_RESOLUTION_M = 0.1
BLOCKING_MAX_GOALS = 40
BLOCKING_CROP_M = 3.0


@dataclass(frozen=True)
class Reach:
    """The coarse grid a group's holds are judged on (see :func:`reach_grid`)."""

    #: ``(H, W)`` cells a disc one skid wide can stand on (walls and obstacles eroded).
    free: np.ndarray
    #: ``(G, H, W)`` the cells each goal's skid takes from that disc (footprint grown by it).
    masks: np.ndarray
    #: ``(H, W)`` free cells outside the boundary, where the skids come from.
    seeds: np.ndarray
    #: ``(G, 2)`` (row, column) of each goal's centre.
    centres: np.ndarray

    def reachable(self, space: np.ndarray, goals) -> np.ndarray:
        """Whether each of ``goals`` is connected to the outside in ``space``."""
        from scipy import ndimage

        labels, _ = ndimage.label(space, structure=np.ones((3, 3)))
        outside = np.unique(labels[self.seeds & space])
        lab = labels[self.centres[goals, 0], self.centres[goals, 1]]
        return (lab > 0) & np.isin(lab, outside)


def reach_grid(goals: np.ndarray, fps, boundary: Polygon, grid: OccupancyGrid) -> Reach | None:
    """The free space around ``boundary`` for a disc one skid wide, and each goal's cells, on
    a coarse grid (:data:`BLOCKING_RESOLUTION_M`) cropped :data:`BLOCKING_CROP_M` around the
    boundary. Groups of one goal, or of more than :data:`BLOCKING_MAX_GOALS` (each hold test
    labels the grid once per goal), get none: nobody is held.

    Parameters
    ----------
    goals
        ``(G, 3)`` goal poses.
    fps
        The footprint laid out at each goal.
    boundary
        The parking boundary.
    grid
        The map the skids plan in.
    """
    from scipy import ndimage

    from swarmpark.core.geometry import footprint_polygon

    n = len(goals)
    if n < 2 or n > BLOCKING_MAX_GOALS:
        return None
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
    masks = np.stack([shapely.contains_xy(poly.buffer(half - 1e-6), X, Y) for poly in polys])
    seeds = ~shapely.contains_xy(boundary.buffer(res), X, Y) & free
    centres = np.array([list(p.centroid.coords)[0] for p in polys])
    rows = np.clip(((centres[:, 1] - ymin) / res).astype(int), 0, len(ys) - 1)
    cols = np.clip(((centres[:, 0] - xmin) / res).astype(int), 0, len(xs) - 1)
    return Reach(free, masks, seeds, np.column_stack([rows, cols]))


def held_goals(reach: Reach, filled: np.ndarray, to_go: np.ndarray) -> np.ndarray:
    """The goals whose skids must wait: play the filling forward and hold each spot that would
    cut a spot still to be filled off the outside, unless that spot's skid is ahead.

    The spots already ``filled`` are taken. The others are taken one by one in the order
    their skids will get there (``to_go``, nearest first, then by index): a spot is taken if
    taking it leaves every spot not yet taken whose skid comes after its own connected
    to the outside (as it was before), else it is held and left free. A skid may follow the
    one bound deeper; it must not overtake it, and two skids must not close a spot between
    them together.

    Parameters
    ----------
    reach
        The group's grid (:func:`reach_grid`).
    filled
        ``(G,)`` goals with their skid parked on them.
    to_go
        ``(G,)`` distance of each goal's skid to it (``inf`` for a goal no skid is bound for).

    Returns
    -------
    ``(G,)`` bool: goals whose skid is held.
    """
    n = len(filled)
    hold = np.zeros(n, dtype=bool)
    taken = filled.copy()
    space = reach.free & ~np.any(reach.masks[taken], axis=0)
    order = np.lexsort((np.arange(n), to_go))
    bound = np.isfinite(to_go)
    for pos, k in enumerate(order):
        if taken[k] or not bound[k]:
            continue
        # The spots still to be reached, by the skids after k's in that order.
        rest = np.array([j for j in order[pos + 1 :] if bound[j] and not taken[j]], dtype=int)
        trial = space & ~reach.masks[k]
        if len(rest):
            before = reach.reachable(space, rest)
            after = reach.reachable(trial, rest[before]) if before.any() else before[:0]
            if not after.all():
                hold[k] = True
                continue
        taken[k] = True
        space = trial
    return hold


def held(groups, poses: np.ndarray) -> np.ndarray:
    """Robots that must wait outside their boundary (:func:`held_goals` of each group).

    Parameters
    ----------
    groups
        Parking groups, each with ``robots`` (indices), ``goals`` ``(G, 3)``, ``goal_of``
        (goal index per robot), ``reach`` (from :func:`reach_grid`, or ``None``) and
        ``hold_memo`` (the last holds worked out, kept here).
    poses
        ``(N, 3)`` the poses the fleet decides from (estimates with onboard localization).
    """
    hold = np.zeros(len(poses), dtype=bool)
    for g in groups:
        if g.reach is None or len(g.robots) < 2:
            continue
        pos_err, head_err = goal_errors(poses[g.robots], g.goals[g.goal_of])
        parked = (pos_err <= POSITION_TOL_M) & (head_err <= HEADING_TOL_RAD)
        filled = np.zeros(len(g.goals), dtype=bool)
        filled[g.goal_of[parked]] = True
        to_go = np.full(len(g.goals), np.inf)
        to_go[g.goal_of] = pos_err
        # The holds depend on the filled spots and the skids' order only: worked out again
        # when either changes, not every tick.
        key = (filled.tobytes(), np.lexsort((np.arange(len(to_go)), to_go)).tobytes())
        if g.hold_memo is None or g.hold_memo[0] != key:
            g.hold_memo = (key, held_goals(g.reach, filled, to_go))
        hold[g.robots] = g.hold_memo[1][g.goal_of]
    return hold
