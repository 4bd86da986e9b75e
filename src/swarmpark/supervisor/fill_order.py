"""Fill order of a parking group: which goal must stay free until which others are filled.

A skid that parks at the mouth of a dead end before the skids bound deeper would wall them
in (2018 paper, Fig. 6: deepest goals first). :class:`Reach` says which goals can be
reached with a set of goals taken; :func:`blockers` works out from it, once per park
command, for every goal the goals it would cut off in the layout's fill order; :func:`held`
decides every tick which skids must wait outside their boundary because of that, or because
their goal would cut one off together with the goals filled now.

Both are functions of their inputs (a grid, goals, footprints; the group's robots and their
pose estimates), testable without a simulator.
"""

from __future__ import annotations

import numpy as np
import shapely
from scipy import ndimage
from shapely.geometry import Polygon

from swarmpark.core.geometry import footprint_polygon
from swarmpark.core.gridmap import OccupancyGrid
from swarmpark.metrics import HEADING_TOL_RAD, POSITION_TOL_M, goal_errors

__all__ = [
    "Reach",
    "blockers",
    "held",
    "holds",
    "hand_over",
    "reach",
    "BLOCKING_RESOLUTION_M",
    "BLOCKING_MAX_GOALS",
    "BLOCKING_CROP_M",
]

#: Fill-order blocking is judged on a grid this coarse, cropped this far around the boundary.
BLOCKING_RESOLUTION_M = 0.1
BLOCKING_MAX_GOALS = 40
BLOCKING_CROP_M = 3.0


class Reach:
    """Which goals of one parking group a disc one skid wide can reach from outside the
    boundary, with a given set of the group's goals occupied: connectivity of the free space
    of the map on a coarse grid cropped around the boundary (scipy.ndimage.label), seeded
    outside the boundary. Results are cached by the set occupied (a park fills a few dozen
    goals, so a tick looks them up). Parameters as :func:`blockers`.
    """

    def __init__(self, goals: np.ndarray, fps, boundary: Polygon, grid: OccupancyGrid) -> None:
        half = max(f.width_m for f in fps) / 2
        res = max(grid.resolution_m, BLOCKING_RESOLUTION_M)
        xmin, ymin, xmax, ymax = boundary.buffer(BLOCKING_CROP_M).bounds
        gx0, gy0, gx1, gy1 = grid.bounds
        xmin, ymin = max(xmin, gx0), max(ymin, gy0)
        xmax, ymax = min(xmax, gx1), min(ymax, gy1)
        xs = np.arange(xmin + res / 2, xmax, res)
        ys = np.arange(ymin + res / 2, ymax, res)
        X, Y = np.meshgrid(xs, ys)
        pts = np.column_stack([X.ravel(), Y.ravel()])
        occ = grid.is_occupied(pts).reshape(X.shape)
        self.free = ndimage.distance_transform_edt(~occ) * res > half
        polys = [footprint_polygon(g, f) for g, f in zip(goals, fps, strict=True)]
        self.masks = [shapely.contains_xy(poly.buffer(half - 1e-6), X, Y) for poly in polys]
        self.seeds = ~shapely.contains_xy(boundary.buffer(res), X, Y) & self.free
        centers = np.array([list(p.centroid.coords)[0] for p in polys])
        self.cj = np.clip(((centers[:, 1] - ymin) / res).astype(int), 0, len(ys) - 1)
        self.ci = np.clip(((centers[:, 0] - xmin) / res).astype(int), 0, len(xs) - 1)
        self._reached: dict[frozenset, np.ndarray] = {}

    def reached(self, occupied: frozenset) -> np.ndarray:
        """``(G,)``: which goals can be reached with the goals ``occupied`` taken (an occupied
        goal counts as not reached)."""
        out = self._reached.get(occupied)
        if out is None:
            space = self.free.copy()
            for k in occupied:
                space &= ~self.masks[k]
            labels, _ = ndimage.label(space, structure=np.ones((3, 3)))
            outside = np.unique(labels[self.seeds & space])
            lab = labels[self.cj, self.ci]
            out = (lab > 0) & np.isin(lab, outside)
            self._reached[occupied] = out
        return out

    def cut_off(self, filled: frozenset, k: int) -> np.ndarray:
        """``(G,)``: the goals, reached with ``filled`` taken, that taking goal ``k`` as
        well would cut off."""
        before = self.reached(filled)
        after = self.reached(filled | {k})
        cut = before & ~after
        cut[k] = False
        return cut


def reach(goals: np.ndarray, fps, boundary: Polygon, grid: OccupancyGrid) -> Reach | None:
    """The :class:`Reach` of a group, or None for groups of one goal or of more than
    :data:`BLOCKING_MAX_GOALS` (the fill order's tests are quadratic): those get no holds."""
    n = len(goals)
    if n < 2 or n > BLOCKING_MAX_GOALS:
        return None
    return Reach(goals, fps, boundary, grid)


def blockers(
    goals: np.ndarray,
    fps,
    boundary: Polygon,
    fill_order,
    grid: OccupancyGrid,
    r: Reach | None = None,
) -> tuple[tuple[int, ...], ...]:
    """For each goal k, the goals j filled before k (in the layout's fill order) that can be
    reached from outside the boundary with the goals before j occupied, but not once k is
    occupied as well: k must stay free until those are filled (:class:`Reach`; ``r`` if
    given, else made here). Groups of one goal, or of more than :data:`BLOCKING_MAX_GOALS`,
    get no holds.

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
    n = len(goals)
    r = r if r is not None else reach(goals, fps, boundary, grid)
    if r is None:
        return tuple(() for _ in goals)
    rank = {g: i for i, g in enumerate(fill_order)}
    order = sorted(range(n), key=lambda g: rank.get(g, n))
    blocks: list[set[int]] = [set() for _ in range(n)]
    for pos, j in enumerate(order):
        before = frozenset(order[:pos])
        if not r.reached(before)[j]:
            continue
        for k in order[pos + 1 :]:
            if not r.reached(before | {k})[j]:
                blocks[k].add(j)
    return tuple(tuple(sorted(b)) for b in blocks)


def held(groups, poses: np.ndarray) -> np.ndarray:
    """Robots that must wait outside their boundary: their goal would cut off a goal that is
    not filled yet and whose skid is not ahead of them (deepest goals first, 2018 Fig. 6). A
    skid may follow the one bound deeper; it must not overtake it.

    A goal cuts off another when the layout's fill order says so (``blocks``), or when taking
    it as well as the goals filled now would (``reach``, :meth:`Reach.cut_off`): skids do
    not park in the fill order, and two spots side by side can shut a door that neither
    shuts alone.

    Parameters
    ----------
    groups
        Parking groups, each with ``robots`` (indices), ``goals`` ``(G, 3)``, ``goal_of``
        (goal index per robot), ``blocks`` (from :func:`blockers`) and ``reach`` (a
        :class:`Reach` or None).
    poses
        ``(N, 3)`` the poses the fleet decides from (estimates with onboard localization).
    """
    return holds(groups, poses)[0]


def holds(groups, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(outside, short)``, each ``(N,)`` bool: the robots :func:`held` outside their
    boundary, and those that follow a skid bound deeper (not held) that is still turning
    towards its goal (off the goal's axis or heading). A follower may come near, but keeps
    off its own spot until the skid ahead is on its straight run in: that skid may still
    need the room to turn, and a follower parked beside it early would shut it out. A
    convoy into a dead end, each skid on its axis, closes up as before."""
    outside = np.zeros(len(poses), dtype=bool)
    short = np.zeros(len(poses), dtype=bool)
    for g in groups:
        for row, waits, ahead in _waits(g, poses):
            outside[g.robots[row]] = bool(waits)
            short[g.robots[row]] = not waits and bool(ahead)
    return outside, short


def hand_over(g, poses: np.ndarray, fits=None) -> tuple[int, int] | None:
    """A swap of goals that ends a wait: rows ``(a, b)`` of group ``g`` (as :func:`held`),
    or None.

    Skid a waits outside because its goal k would cut off goal j, whose skid b is farther
    from j than a is from k. When a is nearer to j than b is, a stands between b and j (the
    usual case: a came first and waits at the mouth b must pass through), so a takes j and b
    takes k. The skids of a group are interchangeable, so the swap costs nothing but the
    difference in distance, and a follows nobody: this is the target swap of TSWAP (Okumura
    and Defago, "Solving simultaneously target assignment and path planning efficiently with
    time-independent execution", AIJ 2023), where an agent blocked by one waiting on its way
    takes over that agent's target. The nearest such j is handed over first; one swap per
    call. ``fits(a, j)``: whether row a's skid fits goal j (all do if None).
    """
    xy = poses[g.robots, :2]
    row_of = {int(k): r for r, k in enumerate(g.goal_of)}
    best = None
    for a, waits, _ in _waits(g, poses):
        for j in waits:
            b = row_of.get(int(j))
            if b is None:
                continue
            k = int(g.goal_of[a])
            d_aj = float(np.hypot(*(xy[a] - g.goals[j, :2])))
            d_bj = float(np.hypot(*(xy[b] - g.goals[j, :2])))
            if d_aj >= d_bj:
                continue
            if fits is not None and not (fits(a, int(j)) and fits(b, k)):
                continue
            if best is None or d_aj < best[0]:
                best = (d_aj, a, b)
    return None if best is None else (best[1], best[2])


def _waits(g, poses: np.ndarray):
    """For each row of group ``g`` (:func:`held`), the goals it waits for: not filled, cut
    off by its goal, their skid no nearer to them than it is to its own; and those it
    follows: not filled, cut off by its goal, their skid nearer but still turning (off its
    goal's axis or heading). Yields ``(row, waits, follows)``; nothing for a group without
    holds."""
    r = g.reach
    if r is None and (not g.blocks or not any(g.blocks)):
        return
    pos_err, head_err = goal_errors(poses[g.robots], g.goals[g.goal_of])
    parked = (pos_err <= POSITION_TOL_M) & (head_err <= HEADING_TOL_RAD)
    filled = np.zeros(len(g.goals), dtype=bool)
    filled[g.goal_of[parked]] = True
    to_go = np.full(len(g.goals), np.inf)  # distance of each goal's skid to it
    to_go[g.goal_of] = pos_err
    # A skid on its goal's axis, facing along it, has only its straight run in to go: it
    # needs no room to turn (within the parking tolerances).
    goal = g.goals[g.goal_of]
    rel = poses[g.robots, :2] - goal[:, :2]
    lateral = np.abs(rel[:, 1] * np.cos(goal[:, 2]) - rel[:, 0] * np.sin(goal[:, 2]))
    turning = np.zeros(len(g.goals), dtype=bool)
    along = np.abs(rel[:, 0] * np.cos(goal[:, 2]) + rel[:, 1] * np.sin(goal[:, 2]))
    # On the run in, its spot lies within the heading tolerance of straight ahead (or behind).
    off_line = lateral > np.maximum(POSITION_TOL_M, along * np.tan(HEADING_TOL_RAD))
    turning[g.goal_of] = off_line | (head_err > HEADING_TOL_RAD)
    taken = frozenset(np.flatnonzero(filled).tolist())
    for row, (k, d) in enumerate(zip(g.goal_of, pos_err, strict=True)):
        first = [j for j in (g.blocks[k] if g.blocks else ()) if not filled[j]]
        if r is not None:
            first += np.flatnonzero(r.cut_off(taken, int(k))).tolist()
        first = sorted({int(j) for j in first})
        waits = [j for j in first if to_go[j] >= d]
        yield row, waits, [j for j in first if to_go[j] < d and turning[j]]
