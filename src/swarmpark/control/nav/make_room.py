"""Making room: a parked skid standing in another's way moves aside along its own axis.

With RVO every parked skid makes room for every skid on the move and every walking person. In
the monitor mode (the default) a parked skid makes room for skids of higher priority (2015
paper Fig. 6: a skid with priority passes through a parked formation) and for walking people,
who outrank every skid (issue 15: people have the right of way; skids on the move give way to
them by :mod:`.people`); skids of equal priority keep their spots. A skid walled in by
parked skids (no manoeuvre to its spot round them, one without them) ranks above all others
until it docks (the navigator's priority inheritance), so its parked neighbours make room.
Skids waiting on purpose (held back by the fill order, queued at a bottleneck) make room in
monitor mode too, for any skid on the move (:meth:`MakeRoom.step_waiting`).

The corridors are the paths (rear to ``lookahead_m`` ahead) of the skids on the move and the
walks of people, widened by the mover's half-width plus ``clearance_m``. A settled skid inside
one drives along its axis to the nearer side that is clear of every corridor and of static
solids, keeping the side it chose while it stays in the way, and waits there while its own
spot is still in the way.

A skid pushed off its spot along its axis drives back along it; when another skid has parked
in between since (a mover that pushed it past its own goal, found on the suite's room swap
with perturbed starts: the two then shoved each other along the row for the rest of the run),
it is *cut off* (:func:`cut_off`) and plans its way back round as a skid on the move.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np
import shapely

from swarmpark.control.base import ControlView
from swarmpark.control.nav.follower import PackedPaths, PathState, paths_ahead
from swarmpark.control.nav.params import MakeRoomParams
from swarmpark.control.nav.scene import Scene
from swarmpark.core.geometry import footprint_corners

__all__ = ["MakeRoom", "RoomResult", "RoomState", "cut_off"]

#: People slower than this stand still: they have no walk ahead to keep clear.
_WALKING_MPS = 1e-6
#: A walk crosses a skid's axis when it meets it at more than this angle (see
#: ``MakeRoom._aside``).
_CROSSING_RAD = np.radians(45.0)
#: Segments per quarter circle of a buffer's round corners (a shapely geometry's own
#: ``buffer`` default; the vectorised ``shapely.buffer`` has 8).
_QUAD_SEGS = 16


@dataclass
class RoomState:
    """Side (+1 along the heading, -1 against it) this skid last made room to, or 0."""

    side: int = 0


@dataclass(frozen=True)
class RoomResult:
    """Per skid ``(N,)``: signed speed along its axis, whether it stands aside (making room or
    waiting aside), and whether it moves off its spot (it must dock again afterwards)."""

    speed: np.ndarray
    aside: np.ndarray
    undock: np.ndarray


class _Ways:
    """Ways (shapely geometries) in an STR tree: which shapes meet any of them. The same as
    intersecting the shapes with the ways' union, without building the union (the union of a
    fleet's ways was a fifth of a 22-skid door site's run time)."""

    def __init__(self, geoms) -> None:
        self.tree = shapely.STRtree(list(geoms))
        self.extra = None  # one more way, tested on its own (see plus)

    def plus(self, geom) -> _Ways:
        """These ways and ``geom`` (sharing the tree)."""
        out = copy.copy(self)
        out.extra = geom
        return out

    def hits(self, shapes: np.ndarray) -> np.ndarray:
        """``(len(shapes),)`` bool: the shapes that meet a way."""
        out = np.zeros(len(shapes), dtype=bool)
        rows, _ = self.tree.query(shapes, predicate="intersects")
        out[rows] = True
        if self.extra is not None:
            out |= shapely.intersects(self.extra, shapes)
        return out


class MakeRoom:
    """See the module docstring.

    Parameters
    ----------
    params
        :class:`~swarmpark.control.nav.params.MakeRoomParams`.
    """

    def __init__(self, params: MakeRoomParams) -> None:
        self.params = params
        n = int(round(params.shift_max_m / params.shift_step_m))
        steps = np.arange(1, n + 1) * params.shift_step_m
        self.shifts = np.concatenate([steps, -steps])  # candidate moves along the axis, m
        self._packed = PackedPaths()  # the paths, for projecting every mover at once

    def corridors(
        self,
        view: ControlView,
        settled,
        paths: list[PathState],
        scene: Scene,
        *,
        above: float | None = None,
        people: bool = True,
    ):
        """The ways the movers (skids not settled, walking people unless ``people`` is false)
        will take, as ``(shapely geometry, walk direction)``: the direction ``(2,)`` of a
        person's walk, ``None`` for a skid's way. With ``above``, only the ways of skids with a
        priority above it (and of all walking people)."""
        p = self.params
        out: list[tuple[shapely.Geometry, np.ndarray | None]] = []
        movers = view.active & ~settled
        if above is not None:
            movers &= view.priority > above
        rows = np.flatnonzero(movers)
        if len(rows):
            lines = paths_ahead(view, rows, paths, self._packed, p.lookahead_m)
            half = np.array([view.footprints[j].width_m / 2 for j in rows.tolist()])
            ways = shapely.buffer(
                shapely.linestrings(
                    np.concatenate(lines),
                    indices=np.repeat(np.arange(len(lines)), list(map(len, lines))),
                ),
                half + p.clearance_m,
                quad_segs=_QUAD_SEGS,
                cap_style="flat",
            )
            # The skids themselves as they stand (they may be turning on the spot).
            feet = shapely.buffer(
                shapely.polygons(footprint_corners(view.poses[rows], scene.skids.plain[rows])),
                p.clearance_m,
                quad_segs=_QUAD_SEGS,
            )
            for way, foot in zip(ways.tolist(), feet.tolist(), strict=True):
                out += [(way, None), (foot, None)]
        for k in np.flatnonzero(_walking(view)) if people else ():
            u = view.people_vel[k] / np.linalg.norm(view.people_vel[k])
            ahead = view.people_xy[k] + u * p.lookahead_m
            half = view.people_radius[k] + p.clearance_m
            out.append((shapely.LineString([view.people_xy[k], ahead]).buffer(half), u))
        return out

    def step(
        self,
        view: ControlView,
        settled: np.ndarray,
        paths: list[PathState],
        rooms: list[RoomState],
        scene: Scene,
        *,
        by_priority: bool = False,
        people: bool = True,
    ) -> RoomResult:
        """Speeds along the axis of the settled skids (``settled``) that stand in a way; with
        ``by_priority``, only in the ways of skids of higher priority than their own and of
        walking people (``people``: people's ways count at all)."""
        n = len(view.poses)
        res = RoomResult(np.zeros(n), np.zeros(n, dtype=bool), np.zeros(n, dtype=bool))
        free = settled & ~view.stopped if view.stopped is not None else settled
        cand = np.flatnonzero(free)
        if not len(cand):
            return res  # no settled skid to move aside: the corridors are not needed
        if not by_priority:
            ways = self.corridors(view, settled, paths, scene, people=people)
            self._aside(view, cand, ways, rooms, scene, res)
            return res
        outranked = np.any(view.active & ~settled & (view.priority > view.priority[cand].min()))
        if not outranked and not (people and np.any(_walking(view))):
            for i in cand:
                rooms[i].side = 0
            return res  # nobody outranks a parked skid: nobody makes room (the usual park)
        for level in np.unique(view.priority[cand]):
            rows = cand[view.priority[cand] == level]
            ways = self.corridors(view, settled, paths, scene, above=float(level), people=people)
            self._aside(view, rows, ways, rooms, scene, res)
        return res

    def step_waiting(
        self,
        view: ControlView,
        waiting: np.ndarray,
        settled: np.ndarray,
        paths: list[PathState],
        rooms: list[RoomState],
        scene: Scene,
        hold_gap_m: float = 0.0,
    ) -> RoomResult:
        """Monitor mode: skids waiting on purpose (``waiting`` ``(N,)``: held back by the fill
        order or queued at a bottleneck) that stand in the way of a skid on the move (neither
        settled nor waiting) drive along their axis out of it, as a parked skid makes room,
        and stay there while they wait. A skid the fill order holds outside its boundary
        (``view.hold``, ``view.hold_zones``) does not move into it grown by ``hold_gap_m``.

        A held skid stops 1 m outside its boundary, which at a bay's door is where the skids
        it waits for have to pass (found on a generated 4-skid elevator: the skid waiting for
        the deeper one stood in the door's approach, and the deeper one, unable to pass it,
        circled behind it for the rest of the run)."""
        n = len(view.poses)
        res = RoomResult(np.zeros(n), np.zeros(n, dtype=bool), np.zeros(n, dtype=bool))
        stopped = np.zeros(n, dtype=bool) if view.stopped is None else view.stopped
        free = view.active & ~settled & ~waiting
        for i in np.flatnonzero(free):
            rooms[i].side = 0  # on the move again: it stood aside for the last time
        cand = np.flatnonzero(view.active & waiting & ~settled & ~stopped)
        if not len(cand) or not (free & ~stopped).any():
            return res
        # The ways of the skids on the move: neither settled nor waiting (nor stopped).
        ways = self.corridors(view, settled | waiting | stopped, paths, scene, people=False)
        way = _Ways(g for g, _ in ways)
        feet = shapely.polygons(footprint_corners(view.poses[cand], scene.skids.plain[cand]))
        inside = way.hits(feet)
        for i, hit in zip(cand.tolist(), inside.tolist(), strict=True):
            st = rooms[i]
            if not hit:
                res.aside[i] = bool(st.side)  # waits where it stood aside
                continue
            res.aside[i] = True
            zone = None
            if view.hold is not None and view.hold[i] and i < len(view.hold_zones):
                zone = view.hold_zones[i]
                zone = None if zone is None else zone.buffer(hold_gap_m)
            best = self._nearest_free_shift(
                view, i, way if zone is None else way.plus(zone), st.side, scene
            )
            if best is None:
                continue
            st.side = int(np.sign(best))
            res.speed[i] = self._shift_speed(view, i, best)
        return res

    def _shift_speed(self, view: ControlView, i: int, shift: float) -> float:
        """Skid ``i``'s speed along its axis towards a shift of ``shift`` metres."""
        p = self.params
        return float(
            np.clip(
                p.gain_per_s * (shift + np.sign(shift) * p.overshoot_m),
                -view.max_speed[i],
                view.max_speed[i],
            )
        )

    def _aside(self, view, cand, corridors, rooms, scene, res: RoomResult) -> None:
        """Fills ``res`` for the settled skids ``cand`` against the ways ``corridors`` (from
        :meth:`corridors`). A person's walk counts for a skid only if it crosses the skid's
        axis at more than :data:`_CROSSING_RAD`: stepping along its axis takes a skid out of
        such a walk, while from a walk along its axis it would only drive ahead of the person
        (an aisle between parked columns is passed side by side, the field and
        :mod:`.people` keeping the skids' distance)."""
        walks = [(g, u) for g, u in corridors if u is not None]
        if not walks:
            self._aside_of(view, cand, [g for g, _ in corridors], rooms, scene, res)
            return
        heading = view.poses[cand, 2]
        axis = np.column_stack([np.cos(heading), np.sin(heading)])
        crosses = np.abs(axis @ np.stack([u for _, u in walks]).T) < np.cos(_CROSSING_RAD)
        ways = [g for g, u in corridors if u is None]
        groups: dict[bytes, list[int]] = {}
        for row, flags in enumerate(crosses):
            groups.setdefault(flags.tobytes(), []).append(row)
        for rows in groups.values():
            mine = ways + [g for (g, _), c in zip(walks, crosses[rows[0]], strict=True) if c]
            self._aside_of(view, cand[rows], mine, rooms, scene, res)

    def _aside_of(self, view, cand, corridors, rooms, scene, res: RoomResult) -> None:
        """:meth:`_aside` for skids ``cand`` against one list of ways (shapely)."""
        if not corridors:
            for i in cand:
                rooms[i].side = 0
            return
        way = _Ways(corridors)
        plain = scene.skids.plain
        inside = way.hits(shapely.polygons(footprint_corners(view.poses[cand], plain[cand])))
        # Skids that stood aside wait there while their own spot is still in the way.
        spot_taken = way.hits(shapely.polygons(footprint_corners(view.goals[cand], plain[cand])))
        for i, hit, taken in zip(cand, inside, spot_taken, strict=True):
            st = rooms[i]
            if not hit:
                if st.side and taken:
                    res.aside[i] = True
                else:
                    st.side = 0
                continue
            res.aside[i] = True
            best = self._nearest_free_shift(view, i, way, st.side, scene)
            if best is None:
                continue
            st.side = int(np.sign(best))
            res.undock[i] = True  # dock again precisely once the way is clear
            res.speed[i] = self._shift_speed(view, i, best)

    def _nearest_free_shift(self, view, i, way: _Ways, side: int, scene: Scene) -> float | None:
        """The smallest shift along skid ``i``'s axis clear of ``way`` and static solids, on
        its previous ``side`` if it has one and that side is free, else on the nearer side."""
        shifts = self.shifts
        head = np.array([np.cos(view.poses[i, 2]), np.sin(view.poses[i, 2])])
        poses = np.repeat(view.poses[i][None], len(shifts), axis=0)
        poses[:, :2] += shifts[:, None] * head
        moved = shapely.polygons(footprint_corners(poses, scene.skids.plain[[i] * len(shifts)]))
        free = ~way.hits(moved)
        blocked, _ = scene.static.tree.query(moved, predicate="intersects")
        free[blocked] = False
        best = None
        for s in ([side] if side else []) + [1, -1]:
            ok = np.flatnonzero(free & (np.sign(shifts) == s))
            if len(ok):
                t = shifts[ok[np.argmin(np.abs(shifts[ok]))]]
                if best is None or (s == side) or abs(t) < abs(best):
                    best = t
                if s == side:
                    break
        return best


def _walking(view: ControlView) -> np.ndarray:
    """``(P,)`` bool: the people that walk (faster than :data:`_WALKING_MPS`)."""
    if not len(view.people_xy):
        return np.zeros(0, dtype=bool)
    return np.linalg.norm(view.people_vel, axis=1) > _WALKING_MPS


def cut_off(
    view: ControlView, settled: np.ndarray, plain: np.ndarray, on_goal_m: float
) -> np.ndarray:
    """Settled skids ``(N,)`` bool that are off their spot by more than ``on_goal_m`` with
    another settled skid, standing within ``on_goal_m`` of its own goal, in the lane between
    (the hull of its footprints where it stands and on its spot): the way back along its axis
    is shut for good. ``plain``: body-frame footprint corners ``(N, 4, 2)``."""
    n = len(view.poses)
    out = np.zeros(n, dtype=bool)
    off = np.hypot(*(view.poses[:, :2] - view.goals[:, :2]).T)
    cand = np.flatnonzero(settled & (off > on_goal_m))
    home = np.flatnonzero(settled & (off <= on_goal_m))
    if not len(cand) or not len(home):
        return out
    now = footprint_corners(view.poses[cand], plain[cand])
    spot = footprint_corners(view.goals[cand], plain[cand])
    lanes = shapely.convex_hull(shapely.multipoints(np.concatenate([now, spot], axis=1)))
    # Shrunk a little: a neighbour in the next row touching the lane's side does not shut it.
    lanes = shapely.buffer(lanes, -0.02, join_style="mitre")
    feet = shapely.polygons(footprint_corners(view.poses[home], plain[home]))
    # A tree over the skids on their spots: a large fleet has hundreds (cand x home pairs
    # tested one by one would cost a 1000-skid tick milliseconds).
    lane_k, _ = shapely.STRtree(feet).query(lanes, predicate="intersects")
    out[cand[lane_k]] = True  # cand and home are disjoint: a skid never shuts its own lane
    return out
