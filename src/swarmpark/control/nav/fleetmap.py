"""The rest of the fleet on one skid's planning map, and when a plan must be repaired.

The static costmap (:mod:`swarmpark.plan.grid`) knows walls only. A path planned on it alone
runs through the gap between two goal spots that will be filled, or through skids that are
already parked there, and the skid then meets a wall of parked skids that its plan does not
know (found on generated sites: a skid circling in front of a 0.4 m gap between two parked
neighbours for the rest of the run). As in Navigation2's layered costmap, where the obstacle
layer adds what the sensors see to the static layer, each plan here is made on the static
costmap plus two fleet layers:

- **parked skids** (settled on their goal, stopped, or without orders) are lethal, grown by the
  planning skid's inscribed radius, with a cost band around them. A skid of higher priority
  is not stopped by them: the block makes room for it (2018 paper, Sect. 3.4.1, and the
  pass-through of the 2015 paper's Fig. 6);
- **the goal spots of skids still on their way** cost extra per metre, so a path goes around
  spots that will be filled while there is a way around, and crosses them (to reach a deep
  spot through the front row) only when there is none;
- **people standing** (in a stuck skid's repair only) are lethal discs as wide as the stand-off
  the people yield keeps from them (:mod:`.people`), grown by the planning skid's inscribed
  radius: a skid that the yield holds in front of a person standing in its lane plans round
  them, where before it drove up to the person again after every repair (found on a
  generated people site: a skid 5 m from its spot for the last 150 s of the run).

The first plan for a goal is made on the static map alone (by the time the skid gets there
the fleet has moved); the fleet layers are used when a plan is *repaired*: when a skid parks
on the rest of another skid's path, and when a skid has made no progress along its path for
:attr:`FleetMapParams.stuck_s`, when the skids standing still around it count as parked too
(the repair a prioritized planner makes when its reservation fails: Silver, "Cooperative
Pathfinding", AIIDE 2005, replans a blocked agent against the others' current positions).
Planning every first path on the fleet layers was measured on the scenario suite and made
most parks slower (the paths went round the whole bay to avoid spots that were still empty
when the skid passed: hangar-bay-12 no longer parked, l-shape-obstacle took 136 s, not 54 s).
"""

from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass, replace

import numpy as np

from swarmpark.control.base import ControlView
from swarmpark.control.nav.params import FleetMapParams
from swarmpark.core.geometry import Footprint
from swarmpark.plan.grid import Costmap

__all__ = [
    "FleetState",
    "blocking",
    "disc_cells",
    "fleet_costmap",
    "fleet_layers",
    "points_in_rects",
    "rect_cells",
    "run_extra",
]


@dataclass(frozen=True)
class FleetState:
    """What the planner needs to know of the fleet this tick (each ``(N,)`` bool).

    ``parked``: fixed obstacles (settled on their goal, stopped, or without orders);
    ``bound``: on their way to a goal; ``still``: on their way but held still for a while;
    ``waiting``: waiting on purpose (held back by the fill order, queued at a bottleneck),
    which is not being stuck.
    """

    parked: np.ndarray
    bound: np.ndarray
    still: np.ndarray
    waiting: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.waiting is None:
            object.__setattr__(self, "waiting", np.zeros(len(self.parked), dtype=bool))


def _window(cm: Costmap, centre, reach: float):
    """The cells of ``cm`` within ``reach`` of ``centre`` along each axis (a square window,
    clipped to the map): their rows, columns and centres ``(K, 2)``, flattened."""
    grid = cm.grid
    res = grid.resolution_m
    h, w = cm.cost.shape
    ox, oy = grid.origin
    c0 = max(int(np.floor((centre[0] - reach - ox) / res)), 0)
    c1 = min(int(np.ceil((centre[0] + reach - ox) / res)) + 1, w)
    r0 = max(int(np.floor((centre[1] - reach - oy) / res)), 0)
    r1 = min(int(np.ceil((centre[1] + reach - oy) / res)) + 1, h)
    if r0 >= r1 or c0 >= c1:
        return np.zeros(0, int), np.zeros(0, int), np.zeros((0, 2))
    rr, cc = np.mgrid[r0:r1, c0:c1]
    rr, cc = rr.ravel(), cc.ravel()
    return rr, cc, np.column_stack([ox + (cc + 0.5) * res, oy + (rr + 0.5) * res])


def rect_cells(cm: Costmap, pose: np.ndarray, fp: Footprint, grow_m: float):
    """Cells ``(rows, cols)`` whose centres lie in footprint ``fp`` at ``pose`` grown by
    ``grow_m`` on every side (a conservative stand-in for the Minkowski sum with a disc)."""
    centre = pose[:2] + fp.center_offset_m * np.array([np.cos(pose[2]), np.sin(pose[2])])
    reach = float(np.hypot(fp.length_m / 2 + grow_m, fp.width_m / 2 + grow_m))
    rr, cc, xy = _window(cm, centre, reach)
    inside = points_in_rects(xy, pose[None], [fp], grow_m)
    return rr[inside], cc[inside]


def disc_cells(cm: Costmap, centres: np.ndarray, radii: np.ndarray):
    """Cells ``(rows, cols)`` whose centres lie in any of the discs (``(K, 2)``, ``(K,)``)."""
    rows_l, cols_l = [np.zeros(0, int)], [np.zeros(0, int)]
    for c, r in zip(centres, radii, strict=True):
        rr, cc, xy = _window(cm, c, float(r))
        inside = np.hypot(*(xy - c).T) <= r
        rows_l.append(rr[inside])
        cols_l.append(cc[inside])
    return np.concatenate(rows_l), np.concatenate(cols_l)


def points_in_rects(
    xy: np.ndarray, poses: np.ndarray, fps: list[Footprint], grow_m: float
) -> np.ndarray:
    """Whether each point ``(K, 2)`` lies in any of the footprints at ``poses`` grown by
    ``grow_m`` (``(K,)`` bool)."""
    hit = np.zeros(len(xy), dtype=bool)
    if len(poses) > 8 and len(xy):
        # Only footprints within reach of the points can hold one: the others are left out
        # (the same answer; a repair on a 1000-skid fleet tested every footprint).
        centre = xy.mean(axis=0)
        rad = np.hypot(*(xy - centre).T).max()
        reach = np.array(
            [
                np.hypot(f.length_m / 2 + grow_m, f.width_m / 2 + grow_m) + abs(f.center_offset_m)
                for f in fps
            ]
        )
        near = np.flatnonzero(np.hypot(*(poses[:, :2] - centre).T) <= rad + reach + 1e-6)
        poses, fps = poses[near], [fps[k] for k in near]
    for pose, fp in zip(poses, fps, strict=True):
        c, s = np.cos(pose[2]), np.sin(pose[2])
        d = xy - (pose[:2] + fp.center_offset_m * np.array([c, s]))
        along, across = d[:, 0] * c + d[:, 1] * s, -d[:, 0] * s + d[:, 1] * c
        hit |= (np.abs(along) <= fp.length_m / 2 + grow_m) & (
            np.abs(across) <= fp.width_m / 2 + grow_m
        )
    return hit


def blocking(view: ControlView, i: int, parked: np.ndarray) -> np.ndarray:
    """The parked skids that block skid ``i``'s plans: all but itself and those of lower
    priority (they make room for it)."""
    out = parked.copy()
    out[i] = False
    return out & (view.priority >= view.priority[i])


def _layer_changes(
    cm: Costmap, view: ControlView, i, parked, bound, p: FleetMapParams, people=None
):
    """The fleet layers as changes to ``cm``'s cells, in order: ``(rows, cols, add)``, with
    ``add=None`` for lethal (``people``: discs ``(centres, radii)`` to keep off, or None)."""
    out = []
    r_in = cm.inscribed_m
    if people is not None and len(people[0]):
        out.append((*disc_cells(cm, people[0], people[1] + r_in), None))
    if p.spot_cost:  # adding 0 changes nothing (the default): skip the skids' spots
        for j in np.flatnonzero(bound & ~parked):
            if j == i:
                continue
            # Grown by the inscribed radius: where the planning skid's body would overlap it.
            rows, cols = rect_cells(cm, view.goals[j], view.footprints[j], r_in)
            out.append((rows, cols, p.spot_cost))
    for j in np.flatnonzero(blocking(view, i, parked)):
        fp = view.footprints[j]
        rows, cols = rect_cells(cm, view.poses[j], fp, r_in + p.band_m)
        out.append((rows, cols, p.band_cost))
        rows, cols = rect_cells(cm, view.poses[j], fp, r_in)
        out.append((rows, cols, None))
    return out


def _apply(cost: np.ndarray, changes) -> None:
    for rows, cols, add in changes:
        if add is None:
            cost[rows, cols] = np.inf
        else:
            cost[rows, cols] += add


def fleet_costmap(
    cm: Costmap,
    view: ControlView,
    i: int,
    parked: np.ndarray,
    bound: np.ndarray,
    p: FleetMapParams,
    people=None,
) -> Costmap:
    """Skid ``i``'s costmap ``cm`` with the fleet layers (see the module docstring), a copy.

    Parameters
    ----------
    parked
        ``(N,)`` skids to treat as fixed obstacles (before the priority rule).
    bound
        ``(N,)`` skids still on their way to a goal: their goal spots cost extra.
    """
    cost = cm.cost.copy()
    _apply(cost, _layer_changes(cm, view, i, parked, bound, p, people))
    return replace(cm, cost=cost)


@contextmanager
def fleet_layers(
    cm: Costmap,
    view: ControlView,
    i: int,
    parked: np.ndarray,
    bound: np.ndarray,
    p: FleetMapParams,
    people=None,
):
    """:func:`fleet_costmap` in place: ``cm`` itself with the fleet layers for the block, its
    cells restored after it (a copy of a large map per repair would cost more than the plan)."""
    changes = _layer_changes(cm, view, i, parked, bound, p, people)
    if not changes:
        yield cm
        return
    w = cm.cost.shape[1]
    flat = np.unique(np.concatenate([rows * w + cols for rows, cols, _ in changes]))
    saved = cm.cost.flat[flat]
    try:
        _apply(cm.cost, changes)
        yield cm
    finally:
        cm.cost.flat[flat] = saved


def run_extra(
    view: ControlView,
    i: int,
    parked: np.ndarray,
    bound: np.ndarray,
    p: FleetMapParams,
):
    """The fleet layers along skid ``i``'s straight docking run, as a function of the run's
    points ``(K, 2)``: the extra cost per metre (the mean over the points), ``inf`` if a
    parked skid that blocks ``i`` is on it (measured on the footprints, not the raster, so a
    run that ends beside a parked neighbour is not refused)."""
    block = np.flatnonzero(blocking(view, i, parked))
    others = np.flatnonzero(bound & ~parked)
    others = others[others != i]
    r_in = view.footprints[i].width_m / 2
    fps = view.footprints

    def extra(pts: np.ndarray) -> float:
        if (
            len(block)
            and points_in_rects(pts, view.poses[block], [fps[j] for j in block], r_in - 1e-3).any()
        ):
            return np.inf
        if not len(others) or p.spot_cost == 0:  # (no spots: 0 times any share is 0)
            return 0.0
        inside = points_in_rects(pts, view.goals[others], [fps[j] for j in others], r_in)
        return float(p.spot_cost * inside.mean())

    return extra
