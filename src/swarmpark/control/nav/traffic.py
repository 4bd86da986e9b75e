"""Traffic control at bottlenecks: doors and narrow corridors as resources with queues.

Skids that meet in a door jam it: each is held up by the others, the collision monitor stops
them all, and they turn in place for the rest of the run (found on generated sites: 4 skids
through a 2.6 m door took 6.8 times the lower bound). As Open-RMF's traffic schedule treats
doors and lanes as resources that robots negotiate for before they enter (Open-RMF,
"Traffic Management", https://osrf.github.io/ros2multirobotbook/traffic-editor.html; the same
idea as prioritized planning with reservations, Silver 2005), each bottleneck of the map
(:func:`swarmpark.plan.bottlenecks.find_bottlenecks`) is a zone that a skid may enter only
with a grant:

- a skid whose path enters a zone within ``lookahead_m`` asks for it, from the region it comes
  from (standing in the zone: the one its path leads away from); the askers are queued
  by their path distance to the zone (first come, first served; ties by index); a path
  that only cuts the zone's padding, leaving it into the region it came from, does not go
  through and asks for nothing;
- a grant goes to the head of the queue when the zone is empty, or when every skid holding
  a grant came from the same side (a convoy) and the last one was granted ``convoy_gap_s``
  ago (counted from its grant: counted from when it entered, a 10-skid door site took 134 s
  against 116 s, the zone reaching 2.7 m round the door); a skid that the fill order holds
  back gets no grant (it would wait in the door);
- a skid refused because skids coming the other way hold the zone does not stop the
  convoy: the next skids from the convoy's side are still granted behind it, until it has
  waited ``convoy_max_s``; from then on only its side goes next (through a corridor each
  turn of the way costs a whole crossing; strictly first come, first served, two groups
  changing rooms through one crossed one skid each way at a time);
- a skid without a grant stops ``gap_m`` short of the zone (moving away stays allowed);
- a grant ends when the skid leaves the zone, parks, or its path no longer crosses it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from swarmpark.control.base import ControlView
from swarmpark.control.nav.follower import PathFollower, PathState
from swarmpark.control.nav.hold import stop_short
from swarmpark.control.nav.params import TrafficParams
from swarmpark.plan.bottlenecks import Bottlenecks, find_bottlenecks

__all__ = ["TrafficControl", "TrafficState", "zones_for"]


def _along(st: PathState, cum: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Points ``(K, 2)`` of path ``st`` at arc lengths ``s`` (``cum``: its arc lengths)."""
    return np.column_stack([np.interp(s, cum, st.path[:, 0]), np.interp(s, cum, st.path[:, 1])])


def zones_for(grid, footprints, p: TrafficParams) -> Bottlenecks:
    """The zones of ``grid`` for a fleet of ``footprints``: passages wide enough for the
    widest skid but narrower than two side by side plus ``p.lane_clearance_m``, grown by half
    the longest skid plus ``p.pad_m``."""
    width = max(f.width_m for f in footprints)
    length = max(f.length_m for f in footprints)
    return find_bottlenecks(
        grid,
        min_width_m=width,
        lane_width_m=2.0 * width + p.lane_clearance_m,
        pad_m=0.5 * length + p.pad_m,
        resolution_m=max(p.resolution_m, grid.resolution_m),
    )


@dataclass
class TrafficState:
    """One skid's standing with the zones: the zone it holds a grant for (0: none), the
    region it came from and when the grant was given; the zone it waits for (0: none)."""

    zone: int = 0
    side: int = 0
    since: float = 0.0
    waiting: int = 0
    #: when it began to wait at the head of its zone's queue for skids coming the other way
    refused_since: float | None = None


class TrafficControl:
    """Grants for the bottleneck zones (see the module docstring)."""

    def __init__(self, params: TrafficParams) -> None:
        self.params = params
        self._grid = None
        self._fps = None
        self.zones: Bottlenecks | None = None
        # Derived from the zones, on demand (only skids standing in a zone need them).
        self._joins: list[tuple[int, ...]] | None = None
        self._distance: dict[int, np.ndarray] = {}
        self._zone_m: np.ndarray | None = None
        self._zone_on_edge = False

    def prepare(self, view: ControlView) -> None:
        """Find the map's bottlenecks now (before the first tick)."""
        self.bottlenecks(view)

    def bottlenecks(self, view: ControlView) -> Bottlenecks:
        """The map's bottlenecks for this fleet (recomputed when the map or fleet changes)."""
        fps = tuple(view.footprints)
        if self.zones is None or self._grid is not view.grid or self._fps != fps:
            self.zones = zones_for(view.grid, fps, self.params)
            self._grid, self._fps = view.grid, fps
            self._joins, self._distance, self._zone_m = None, {}, None
        return self.zones

    def _far_from_zones(self, z: Bottlenecks, xy: np.ndarray) -> np.ndarray:
        """``(K,)`` bool: points ``xy`` from which no point within ``lookahead_m`` lies in a
        zone cell (the distance from the point's cell centre to the nearest zone cell centre
        exceeds the lookahead by two cells), so :meth:`_ahead` finds no zone along a path
        from there. Points off the grid count on its edge cells, so with a zone on the edge
        the disc must lie on the grid too. Only saves work: it never changes what
        :meth:`_ahead` returns."""
        if self._zone_m is None:
            self._zone_m = ndimage.distance_transform_edt(z.zone == 0) * z.resolution_m
            edge = np.concatenate([z.zone[0], z.zone[-1], z.zone[:, 0], z.zone[:, -1]])
            self._zone_on_edge = bool(edge.any())
        res, reach = z.resolution_m, self.params.lookahead_m + 2.0 * z.resolution_m
        r, c = z.cells(xy)
        far = self._zone_m[r, c] > reach
        if self._zone_on_edge:
            h, w = z.zone.shape
            lo = z.origin + reach
            hi = z.origin + np.array([w, h]) * res - reach
            far &= np.all((xy >= lo) & (xy <= hi), axis=1)
        return far

    def step(
        self,
        view: ControlView,
        idx: np.ndarray,
        cmd: np.ndarray,
        paths: list[PathState],
        follower: PathFollower,
        states: list[TrafficState],
        parked: np.ndarray,
    ) -> np.ndarray:
        """Update the grants and stop (in place on ``cmd``, rows of all skids) the skids that
        must wait; returns which of ``idx`` wait."""
        z = self.bottlenecks(view)
        waiting = np.zeros(len(idx), dtype=bool)
        if z.count == 0:
            return waiting
        p = self.params
        here = z.zone_at(view.poses[:, :2])
        asks: dict[int, list[tuple[float, int, int]]] = {}
        # Where each skid stands on its path, for the whole fleet at once.
        pk = follower.packed
        pk.update(paths)
        s_here = np.full(len(view.poses), np.nan)
        rows = idx[(pk.nseg[idx] > 0) & pk.is_for(idx, view.goals[idx])]
        far = np.zeros(len(view.poses), dtype=bool)
        if len(rows):
            s_here[rows] = pk.project(rows, view.poses[rows, :2])[1]
            far[rows] = self._far_from_zones(z, pk.point_at(rows, s_here[rows])[0])
        for i in idx.tolist():
            st = states[i]
            st.waiting = 0
            ahead = (0, 0.0, 0) if far[i] else self._ahead(view, i, paths[i], s_here[i], z)
            if st.zone and (parked[i] or (here[i] != st.zone and ahead[0] != st.zone)):
                st.zone = 0  # left the zone (or parked, or no longer going through it)
            if st.zone or ahead[0] == 0 or parked[i]:
                continue
            asks.setdefault(ahead[0], []).append((ahead[1], i, ahead[2]))
        held = np.zeros(len(view.poses), dtype=bool) if view.hold is None else view.hold
        heads: set[int] = set()
        for zone, queue in asks.items():
            self._serve(view, zone, sorted(queue), states, held, heads)
        for i in idx.tolist():
            if i not in heads:
                states[i].refused_since = None
        for k, i in enumerate(idx.tolist()):
            zone = states[i].waiting
            if zone and stop_short(view, i, cmd, z.polygons[zone - 1], p.gap_m, p.check_s):
                waiting[k] = True
        return waiting

    def _serve(self, view: ControlView, zone: int, queue, states, held, heads: set) -> None:
        """Grant ``zone`` to the skids of its ``queue`` (sorted by path distance) that may
        enter now; mark the others waiting. ``heads`` collects the skids refused for skids
        coming the other way."""
        p = self.params
        refused = None  # the side of a skid refused for a convoy coming the other way
        # A side refused for convoy_max_s: from now on only it goes next, however near the
        # zone the convoy's next skid stands.
        overdue = {
            side
            for _, i, side in queue
            if states[i].refused_since is not None
            and view.t - states[i].refused_since >= p.convoy_max_s
        }
        for _dist, i, side in queue:
            st = states[i]
            if held[i] or (overdue and side not in overdue):
                # Held back by the fill order: no grant (it would wait in the door), and
                # the skids behind it, maybe the one it waits for, go ahead of it. Or it
                # would lengthen a convoy that an overdue side waits for.
                st.waiting = zone
                continue
            if refused is not None:
                # Behind a refused skid only the oncoming convoy's next skids go.
                if side != refused and self._grant(view, zone, side, states, p):
                    st.zone, st.side, st.since = zone, side, view.t
                else:
                    st.waiting = zone
                continue
            if self._grant(view, zone, side, states, p):
                st.zone, st.side, st.since = zone, side, view.t
                continue
            if self._oncoming(zone, side, states):
                # The zone is busy the other way: the convoy coming that way goes on while
                # this skid has waited less than convoy_max_s (through a long corridor the
                # way turning round costs a whole crossing).
                heads.add(i)
                if st.refused_since is None:
                    st.refused_since = view.t
                if view.t - st.refused_since < p.convoy_max_s:
                    refused, st.waiting = side, zone
                    continue
            # Not granted: this one and every one behind it wait (first come, first served).
            for _, j, _ in queue:
                if states[j].zone == 0:
                    states[j].waiting = zone
            return

    @staticmethod
    def _oncoming(zone: int, side: int, states) -> bool:
        """Skids coming the other way hold ``zone``."""
        return any(st.zone == zone and st.side != side for st in states)

    @staticmethod
    def _grant(view: ControlView, zone: int, side: int, states, p: TrafficParams) -> bool:
        holders = [st for st in states if st.zone == zone]
        if not holders:
            return True
        if any(st.side != side for st in holders):
            return False
        return view.t - max(st.since for st in holders) >= p.convoy_gap_s

    def _ahead(
        self, view: ControlView, i: int, st: PathState, s_here: float, z: Bottlenecks
    ) -> tuple[int, float, int]:
        """The first zone on skid ``i``'s path within ``lookahead_m`` of arc length
        ``s_here`` (0: none; NaN: no path), the path distance to it and the region the skid
        comes from (its side)."""
        if not np.isfinite(s_here):
            return 0, 0.0, 0
        cum = st.geometry().cum
        s = np.arange(s_here, min(s_here + self.params.lookahead_m, cum[-1]), z.resolution_m)
        if not len(s):
            return 0, 0.0, 0
        pts = _along(st, cum, s)
        zones = z.zone_at(pts)
        hit = np.flatnonzero(zones)
        if not len(hit):
            return 0, 0.0, 0
        regions = z.region_at(pts)
        first = hit[0]
        while True:
            zone = int(zones[first])
            before = regions[: first + 1]
            if not np.any(before > 0):
                return zone, float(s[first] - s_here), self._side_inside(st, zone, z)
            side = int(before[before > 0][-1])
            if not self._comes_back(st, cum, s[first], zone, side, z):
                return zone, float(s[first] - s_here), side
            # Into the zone's edge and out again on the side it came from: not through it.
            after = np.flatnonzero((np.arange(len(s)) > first) & (zones != zone))
            later = hit[hit >= (after[0] if len(after) else len(s))]
            if not len(later):
                return 0, 0.0, 0
            first = later[0]

    @staticmethod
    def _comes_back(
        st: PathState, cum: np.ndarray, s0: float, zone: int, side: int, z: Bottlenecks
    ) -> bool:
        """Whether a path entering ``zone`` at arc length ``s0`` from region ``side`` leaves
        it back into ``side`` (not into another region, and it does not end in the zone).
        Such a path does not go through the bottleneck: it only cuts the zone's padding (a
        skid in a bay beside a door backing out of a row to go round it; queued for the
        door, it stood in the way of the skid holding the door's grant, which waited for it,
        for the rest of a generated door run)."""
        s = np.arange(s0, cum[-1] + z.resolution_m, z.resolution_m)
        s[-1] = min(s[-1], cum[-1])
        pts = _along(st, cum, s)
        out = np.flatnonzero(z.zone_at(pts) != zone)
        if not len(out):
            return False
        region = z.region_at(pts[out[0] :])
        region = region[region > 0]
        return bool(len(region)) and int(region[0]) == side

    def _side_inside(self, st: PathState, zone: int, z: Bottlenecks) -> int:
        """The side a skid standing inside ``zone`` comes from: of the two regions the zone
        joins, the one its path leads away from (the start nearer to it than the end is; 0 if
        the zone does not join two). Counted as side 0, skids that started in a corridor's
        mouth refused a convoy from the side they were going with, headed its queue and held
        it for good (a generated corridor: none of 10 skids went through in 190 s)."""
        if self._joins is None:
            grown = ndimage.grey_dilation(z.zone, size=(3, 3))
            self._joins = []
            for k in range(1, z.count + 1):
                near = z.region[(grown == k) & (z.zone == 0)]
                self._joins.append(tuple(np.unique(near[near > 0]).tolist()))
        joined = self._joins[zone - 1]
        if len(joined) != 2:
            return 0
        ends = z.cells(st.path[[0, -1]])
        away = [float(d[ends][0] - d[ends][1]) for d in map(self._region_distance, joined)]
        return joined[int(np.argmin(away))]

    def _region_distance(self, region: int) -> np.ndarray:
        """Distance (cells) from every cell of the zones' grid to ``region``, once per region."""
        if region not in self._distance:
            self._distance[region] = ndimage.distance_transform_edt(self.zones.region != region)
        return self._distance[region]
