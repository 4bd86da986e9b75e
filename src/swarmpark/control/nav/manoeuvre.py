"""Manoeuvres out of a dead end: when a skid has made no progress towards its goal for a
while, plan a manoeuvre for its rectangle (turns on the spot, forward and reverse runs:
:func:`swarmpark.plan.lattice.plan_manoeuvre`) around the walls and the other skids where they
stand, and drive it segment by segment.

The potential field follows a path planned for a disc; into a spot that can only be entered
at one heading (a pillar on one side, a parked neighbour on the other) or through a door
lengthwise it can circle for ever (found on generated sites: a skid 1.5 m and 70 deg off its
goal for 80 s). The manoeuvre takes over only then, so the skids that park without it are
driven exactly as before. Its commands still go through the collision monitor; a manoeuvre
held up by the monitor for ``blocked_s`` is dropped and planned again later.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from swarmpark.control.base import ControlView
from swarmpark.control.nav.follower import PathState, point_at, station
from swarmpark.control.nav.params import ManoeuvreParams
from swarmpark.core.geometry import wrap_angle
from swarmpark.core.gridmap import refine_occupancy
from swarmpark.core.progress import NAV_HEADING_LEVER_M, remaining_m
from swarmpark.plan.lattice import footprint_clear, free_masks, plan_manoeuvre, stamp_footprint

__all__ = ["ManoeuvrePlanner", "ManoeuvreState", "turn_clear"]

#: A skid slower than these stands still (for :meth:`ManoeuvrePlanner.cramped`).
STILL_MPS = 0.02
STILL_RADPS = 0.05
#: The step of :func:`turn_clear`.
TURN_STEP_RAD = float(np.deg2rad(5.0))


def segment_time(segment, speed_mps: float, yaw_rate_radps: float) -> float:
    """How long a manoeuvre's segment ``(kind, start, end)`` takes at this speed and yaw rate
    (s): a turn its angle, a run its length."""
    kind, a, b = segment
    if kind == "turn":
        return abs(float(wrap_angle(b[2] - a[2]))) / yaw_rate_radps
    return float(np.hypot(b[0] - a[0], b[1] - a[1])) / speed_mps


def turn_clear(occ, origin, res: float, fp, pose: np.ndarray, want: float, grow_m: float) -> bool:
    """Whether footprint ``fp`` turns on the spot at ``pose`` to heading ``want``, the short
    way round, clear of the window ``occ`` (checked every 5 degrees, grown by ``grow_m``)."""
    err = float(wrap_angle(want - pose[2]))
    for a in np.append(np.arange(TURN_STEP_RAD, abs(err), TURN_STEP_RAD), abs(err)).tolist():
        q = np.array([pose[0], pose[1], pose[2] + np.sign(err) * a])
        if not footprint_clear(occ, origin, res, fp, q, grow_m):
            return False
    return True


@dataclass
class ManoeuvreState:
    """One skid's manoeuvre: its segments and the current one, the progress watch that
    starts it, and when it may be tried again."""

    segments: list | None = None
    seg: int = 0
    #: When the current segment must be done by (a watchdog: dropped after that).
    seg_deadline: float = np.inf
    best_left_m: float = np.inf
    best_t: float = 0.0
    #: Where the skid stood when the progress watch last restarted.
    anchor: np.ndarray | None = field(default=None, repr=False)
    retry_t: float = -np.inf
    blocked_s: float = 0.0
    goal: np.ndarray | None = field(default=None, repr=False)
    #: The last manoeuvre was held up by the monitor or overran: plan the next one roomy.
    roomy: bool = False
    #: How many manoeuvres were planned and how many found no way (for the run report).
    planned: int = 0
    failed: int = 0
    #: A search for its goal found no way round the skids standing but one with the settled
    #: skids left out: walled in by them until it docks or its goal changes (the navigator
    #: ranks it above the others meanwhile, so they make room).
    walled: bool = False
    #: The goal for which it first waited for skids on the move rather than go the long way
    #: round them, and since when (:meth:`ManoeuvrePlanner._detour`).
    detour_goal: np.ndarray | None = field(default=None, repr=False)
    detour_t: float = 0.0

    def running(self) -> bool:
        return self.segments is not None

    def stop(self, t: float, retry_s: float) -> None:
        self.segments, self.seg, self.blocked_s = None, 0, 0.0
        self.seg_deadline = np.inf
        self.retry_t = t + retry_s
        self.best_left_m, self.best_t = np.inf, t


class ManoeuvrePlanner:
    """Starts, drives and ends manoeuvres (see the module docstring).

    Parameters
    ----------
    params
        :class:`~swarmpark.control.nav.params.ManoeuvreParams`.
    """

    def __init__(self, params: ManoeuvreParams) -> None:
        self.params = params

    def step(
        self,
        view: ControlView,
        idx: np.ndarray,
        raw: np.ndarray,
        states: list[ManoeuvreState],
        eligible: np.ndarray,
        settled: np.ndarray | None = None,
        paths: list[PathState] | None = None,
        cramped: np.ndarray | None = None,
        want: np.ndarray | None = None,
    ) -> np.ndarray:
        """Replace the commands ``raw`` (rows of ``idx``) of the skids in a manoeuvre; start
        one for an ``eligible`` skid that made no progress for ``stuck_s`` (``near_stuck_s``
        within ``near_goal_m`` of its goal). Returns which rows are manoeuvring. ``settled``
        ``(N,)``: the skids that could make room; a skid for which no manoeuvre is found but
        one is without them is marked walled in. ``paths`` (per skid): the planned paths, for
        a skid whose goal is too far for one window (:meth:`_via`). ``cramped`` (rows): the
        skids that cannot turn on the spot to their path heading ``want`` (rows;
        :meth:`cramped`), which wait only ``cramped_s`` and first try to get out straight
        (:meth:`_unwedge`)."""
        p = self.params
        out = np.zeros(len(idx), dtype=bool)
        pose, goal = view.poses[idx], view.goals[idx]
        dist = np.linalg.norm(goal[:, :2] - pose[:, :2], axis=1)
        # Parking (near the goal) a skid waits near_stuck_s, on its way stuck_s.
        wait_s = np.where(dist <= p.near_goal_m, p.near_stuck_s, p.stuck_s)
        if cramped is not None and p.cramped:
            wait_s = np.where(cramped, np.minimum(wait_s, p.cramped_s), wait_s)
        wait_s = wait_s.tolist()
        left = remaining_m(
            dist,
            np.abs(wrap_angle(goal[:, 2] - pose[:, 2])),
            NAV_HEADING_LEVER_M,
        )
        roamed = self._roamed(pose, [states[i] for i in idx.tolist()])
        t = view.t
        for k, (i, ok) in enumerate(zip(idx.tolist(), np.asarray(eligible).tolist(), strict=True)):
            st = states[i]
            if st.segments is not None and (  # running
                not ok or st.goal is None or np.any(st.goal != view.goals[i])
            ):
                st.stop(t, 0.0)
            if not ok:
                st.best_left_m, st.best_t = np.inf, t
                continue
            # Progress, or travel: a skid driving round an obstacle away from its goal is
            # not stuck, one loitering within roam_m of where it last got closer is.
            if left[k] < st.best_left_m - p.progress_m or roamed[k] or st.anchor is None:
                st.best_left_m, st.best_t = left[k], view.t
                st.anchor = pose[k, :2].copy()
            if not st.running():
                if view.t - st.best_t < wait_s[k] or view.t < st.retry_t:
                    continue
                turn_to = want[k] if cramped is not None and cramped[k] else None
                self._start(view, i, st, settled, None if paths is None else paths[i], turn_to)
                if not st.running():
                    continue
            cmd = self._drive(view, i, st)
            if cmd is None:
                continue
            raw[k] = cmd
            out[k] = True
        return out

    def cramped(self, view: ControlView, idx: np.ndarray, want: np.ndarray, near) -> np.ndarray:
        """Which of skids ``idx`` cannot turn on the spot to heading ``want`` (rows): standing
        still, more than ``cramped_rad`` off it, a solid of the map within reach of the pivot
        (``near``: a k-d tree of the map's outline points, or None) and the footprint, swept
        the short way round in steps of 5 degrees, not clear of the map."""
        p = self.params
        out = np.zeros(len(idx), dtype=bool)
        if not p.cramped or near is None or not len(idx):
            return out
        pose = view.poses[idx]
        err = wrap_angle(want - pose[:, 2])
        still = (np.abs(view.vel[idx, 0]) < STILL_MPS) & (np.abs(view.vel[idx, 1]) < STILL_RADPS)
        cand = np.flatnonzero(still & (np.abs(err) > p.cramped_rad))
        if not len(cand):
            return out
        reach = np.array([view.footprints[i].reach_m for i in idx[cand].tolist()])
        gap, _ = near.query(pose[cand, :2], distance_upper_bound=float(reach.max()))
        grid = view.grid
        for k in cand[gap < reach].tolist():
            fp = view.footprints[idx[k]]
            out[k] = not turn_clear(
                grid.occupied, grid.origin, grid.resolution_m, fp, pose[k], float(want[k]), 0.0
            )
        return out

    def _roamed(self, pose: np.ndarray, states: list[ManoeuvreState]) -> list[bool]:
        """Per row, whether the skid is more than ``roam_m`` from its anchor (False without
        one), for all rows at once (the same distances as one ``np.hypot`` per skid)."""
        anchor = np.full((len(states), 2), np.nan)
        has = [k for k, st in enumerate(states) if st.anchor is not None]
        if not has:
            return [False] * len(states)
        anchor[has] = [states[k].anchor for k in has]
        d = pose[:, :2] - anchor
        far = np.hypot(d[:, 0], d[:, 1]) > self.params.roam_m
        return far.tolist()

    def observe(self, view: ControlView, idx: np.ndarray, states, raw, safe) -> None:
        """After the monitor: a manoeuvre it held still for ``blocked_s`` is dropped."""
        p = self.params
        for k, i in enumerate(idx.tolist()):
            st = states[i]
            if st.segments is None:  # not running
                continue
            # Held: its run stopped, or its turn on the spot stopped. A run stopped while a
            # trace of its heading correction still passes is held too (found on a perturbed
            # hallway run: 1e-4 rad/s kept a stopped reverse run "moving" for 5 s).
            run = abs(raw[k, 0]) > 1e-6
            moving = abs(safe[k, 0]) > 1e-6 if run else abs(safe[k, 1]) > 1e-6
            held = (run or abs(raw[k, 1]) > 1e-6) and not moving
            st.blocked_s = st.blocked_s + view.dt if held else 0.0
            if st.blocked_s >= p.blocked_s:
                st.stop(view.t, p.retry_s)
                st.roomy = True

    # ------------------------------------------------------------------ planning

    def _window(
        self,
        view: ControlView,
        i: int,
        leave_out: np.ndarray | None = None,
        goal: np.ndarray | None = None,
        margin_m: float | None = None,
    ):
        """The occupancy of the window around skid ``i`` and its goal (or ``goal``): the map,
        the other skids where they stand (grown by ``skid_margin_m``; not those in
        ``leave_out``) and the people. ``margin_m``: the window's margin, ``window_margin_m``
        if None (a wider one for a goal whose own window is within ``max_window_m``)."""
        p = self.params
        grid = view.grid
        res = grid.resolution_m
        goal = view.goals[i] if goal is None else goal
        pts = np.vstack([view.poses[i, :2], goal[:2]])
        margin = p.window_margin_m if margin_m is None else margin_m
        lo = pts.min(axis=0) - margin
        hi = pts.max(axis=0) + margin
        if np.any(hi - lo > p.max_window_m + 2.0 * (margin - p.window_margin_m)):
            return None
        h, w = grid.shape
        c0 = max(int(np.floor((lo[0] - grid.origin[0]) / res)), 0)
        r0 = max(int(np.floor((lo[1] - grid.origin[1]) / res)), 0)
        c1 = min(int(np.ceil((hi[0] - grid.origin[0]) / res)), w)
        r1 = min(int(np.ceil((hi[1] - grid.origin[1]) / res)), h)
        if r1 - r0 < 3 or c1 - c0 < 3:
            return None
        occ = grid.occupied[r0:r1, c0:c1].copy()
        origin = np.array([grid.origin[0] + c0 * res, grid.origin[1] + r0 * res])
        # On a coarse map the lattice is searched on cells of at most max_cell_m (each map
        # cell split): the other skids are stamped at that resolution, and the footprint's
        # checks err by half a cell. At 10 cm a turn between two parked neighbours passed the
        # search that the monitor (3 cm margin, exact rectangles) then refused, again and
        # again (a generated open deck: 50 s, to the end of the run).
        split = int(np.ceil(res / p.max_cell_m - 1e-9))
        if split > 1:
            # The walls on the finer cells from the solids the monitor checks against, not
            # the coarse cells split: those err outwards by up to a whole coarse cell.
            occ = refine_occupancy(occ, origin, res, split, view.static_pieces)
            res = res / split
        for j in range(len(view.poses)):
            if j != i and (leave_out is None or not leave_out[j]):
                stamp_footprint(
                    occ, origin, res, view.poses[j], view.footprints[j], p.skid_margin_m
                )
        for xy, rad in zip(view.people_xy, view.people_radius, strict=True):
            rr, cc = np.mgrid[0 : occ.shape[0], 0 : occ.shape[1]]
            d = np.hypot(origin[0] + (cc + 0.5) * res - xy[0], origin[1] + (rr + 0.5) * res - xy[1])
            occ |= d <= rad + p.person_margin_m
        return occ, origin, res

    def _start(
        self,
        view: ControlView,
        i: int,
        st: ManoeuvreState,
        settled: np.ndarray | None = None,
        path: PathState | None = None,
        turn_to: float | None = None,
    ) -> None:
        p = self.params
        st.planned += 1
        # A cramped skid first tries the straight way out to where it can turn.
        segments = None if turn_to is None else self._unwedge(view, i, turn_to)
        win = None if segments else self._window(view, i)
        # A manoeuvre planned at the bare margin can leave the skid, stopped a few cm off a
        # planned turn point, inside the monitor's margin, which then holds it there (found on
        # a perturbed suite run: a turn in a doorway, planned again and held again for 150 s).
        # After such a hold the next one is planned roomy first.
        grows = (*p.roomy_grow_m, p.grow_m) if st.roomy else (p.grow_m,)
        if segments:
            pass  # no lattice search
        elif win is None and path is not None:
            segments = self._via(view, i, path, grows)
        elif win is not None:
            for grow in grows:
                segments = self._plan(view, i, *win, grow)
                if segments:
                    if self._detour(view, i, st, segments, grow):
                        st.stop(view.t, p.retry_s)
                        return
                    break
        if not segments:
            # Walled in by settled skids: no way in a wider window either, but a way with
            # them left out.
            others = settled is not None and np.any(np.delete(settled, i))
            if win is not None and others and not st.walled:
                if p.wide_margin_m > p.window_margin_m:
                    wide = self._window(view, i, margin_m=p.wide_margin_m)
                    segments = self._plan(view, i, *wide, p.grow_m) if wide else None
                    if segments and self._detour(view, i, st, segments, p.grow_m):
                        st.stop(view.t, p.retry_s)
                        return
                if not segments:
                    occ = self._window(view, i, leave_out=settled)
                    st.walled = bool(self._plan(view, i, *occ, p.grow_m))
            if win is not None and not st.walled and p.goal_tol_m > 0:
                # Last, where the walls alone leave no way to the goal's cell, a way that ends
                # beside it (a spot by a wall reached only along a line of cell centres beside
                # its own). Not where other skids are what is in the way: they move, and a
                # skid parked a few cm off its spot narrows its neighbours' (the suite's
                # walled-in row: a neighbour that had made room could not get back in).
                bare = self._window(view, i, leave_out=np.ones(len(view.poses), dtype=bool))
                if bare is not None and not self._plan(view, i, *bare, p.grow_m):
                    segments = self._plan(view, i, *win, p.grow_m, p.goal_tol_m)
        if not segments:
            st.failed += 1
            st.stop(view.t, p.retry_s)
            return
        st.segments, st.seg, st.blocked_s = segments, 0, 0.0
        st.seg_deadline = np.inf
        st.goal = view.goals[i].copy()

    def _detour(self, view: ControlView, i: int, st: ManoeuvreState, segments, grow: float) -> bool:
        """Whether skid ``i`` should wait rather than drive ``segments``: they take more than
        ``detour_ratio`` times, and ``detour_s`` more than, a manoeuvre planned with the
        skids on the move left out (they will be gone), and it has not yet waited
        ``detour_wait_s`` for its goal."""
        p = self.params
        if p.detour_ratio <= 0:
            return False
        moving = (np.abs(view.vel[:, 0]) >= STILL_MPS) | (np.abs(view.vel[:, 1]) >= STILL_RADPS)
        moving[i] = False
        if not moving.any():
            return False
        goal = view.goals[i]
        if st.detour_goal is None or np.any(st.detour_goal != goal):
            st.detour_goal, st.detour_t = goal.copy(), view.t
        if view.t - st.detour_t >= p.detour_wait_s:
            return False
        win = self._window(view, i, leave_out=moving)
        short = self._plan(view, i, *win, grow) if win is not None else None
        if not short:
            return False
        long_s, short_s = self._duration(view, i, segments), self._duration(view, i, short)
        return long_s > p.detour_ratio * short_s and long_s - short_s > p.detour_s

    def _duration(self, view: ControlView, i: int, segments) -> float:
        """How long skid ``i`` takes to drive ``segments`` at the manoeuvre's speed (s)."""
        share = self.params.speed_share
        speed, rate = float(view.max_speed[i]) * share, float(view.max_yaw_rate[i]) * share
        return sum(segment_time(seg, speed, rate) for seg in segments)

    def _plan(
        self,
        view: ControlView,
        i: int,
        occ,
        origin,
        res,
        grow_m: float,
        goal_tol_m: float = 0.0,
        goal: np.ndarray | None = None,
    ) -> list | None:
        """The segments of a manoeuvre from where skid ``i`` stands (ending within
        ``goal_tol_m`` of the goal's cell, :func:`~swarmpark.plan.lattice.plan_manoeuvre`); a
        wedged skid (its footprint not clear at the nearest grid heading) first backs or
        drives straight out along its own heading to the nearest clear pose (found on a
        generated L-bay: a skid 2.5 cm from a parked neighbour whose every planned first turn
        the monitor refused)."""
        p = self.params
        fp = view.footprints[i]
        kw = {
            "speed_mps": float(view.max_speed[i]) * p.speed_share,
            "yaw_rate_radps": float(view.max_yaw_rate[i]) * p.speed_share,
            "grow_m": grow_m,
            "reverse_cost": p.reverse_cost,
            "budget": p.budget,
            "goal_tol_m": goal_tol_m,
        }
        pose = view.poses[i]
        goal = view.goals[i] if goal is None else goal
        kw["masks"] = free_masks(occ, fp, res, grow_m)  # the same for every search below
        plan = plan_manoeuvre(occ, origin, res, fp, pose, goal, **kw)
        if plan is not None and plan.start_free:
            return plan.segments() if len(plan.poses) >= 2 else None
        grow = grow_m + res * np.sqrt(0.5)

        def clear(out):
            return footprint_clear(occ, origin, res, fp, out, grow)

        for kind, out in self._straight_out(occ, origin, res, fp, pose, clear):
            rest = plan_manoeuvre(occ, origin, res, fp, out, goal, **kw)
            if rest is not None and len(rest.poses) >= 2:
                return [(kind, pose.copy(), out), *rest.segments()]
        return plan.segments() if plan is not None and len(plan.poses) >= 2 else None

    def _unwedge(self, view: ControlView, i: int, want: float) -> list | None:
        """For a skid that cannot turn on the spot to heading ``want``: straight back, or on,
        along its own heading to the nearest pose where it can (``escape_step_m`` steps, up to
        ``escape_max_m``), then that turn; the path follower takes over from there. Checked
        on the window round the skid (the map, the other skids and people) as :meth:`_plan`
        checks a wedged skid's way out. None if there is no such pose."""
        win = self._window(view, i, goal=view.poses[i])
        if win is None:
            return None
        occ, origin, res = win
        fp = view.footprints[i]
        pose = view.poses[i]
        grow = self.params.grow_m + res * np.sqrt(0.5)

        def turns(out):
            return turn_clear(occ, origin, res, fp, out, want, grow)

        end = next(self._straight_out(occ, origin, res, fp, pose, turns), None)
        if end is None:
            return None
        kind, out = end
        return [(kind, pose.copy(), out), ("turn", out, np.array([*out[:2], want]))]

    def _straight_out(self, occ, origin, res: float, fp, pose: np.ndarray, good):
        """Poses straight back, or on, along the skid's own heading (``escape_step_m`` steps
        up to ``escape_max_m``, the nearest first, back before on) where ``good(pose)`` holds
        and the way there is clear, as ``(kind, pose)``. The way is checked on the footprint
        shrunk by half a cell diagonal and by the margin the other skids are stamped with:
        the skid may already stand within those (the monitor keeps 3 cm; with only the half
        cell, every way out failed and a skid by a pillar stood 16 s, 0.5 m from its spot, on
        a generated hangar). A solid in the way still fails it; the collision monitor guards
        the run itself."""
        p = self.params
        shrink = -(res * np.sqrt(0.5) + p.skid_margin_m)
        head = np.array([np.cos(pose[2]), np.sin(pose[2]), 0.0])
        for d in np.arange(p.escape_step_m, p.escape_max_m + 1e-9, p.escape_step_m):
            for sign, kind in ((-1.0, "reverse"), (1.0, "forward")):
                out = pose + sign * d * head
                if not good(out):
                    continue
                way = [pose + sign * x * head for x in np.arange(0.05, d, 0.05)]
                if all(footprint_clear(occ, origin, res, fp, q, shrink) for q in way):
                    yield kind, out

    def _via(self, view: ControlView, i: int, path: PathState, grows) -> list | None:
        """A manoeuvre to a pose on skid ``i``'s path ahead, for a skid stuck farther from its
        goal than one window reaches: ``via_m`` along the path from where it stands (the
        nearest first that is clear), at the path's heading there; the path follower takes
        over where it ends. Without it such a skid never had a manoeuvre: a skid parked on an
        elevator, sent to a bay 10 m beyond the door, nose to the elevator's side wall with no
        room to turn on the spot, shuffled to and fro for the rest of the run."""
        p = self.params
        if path.path is None or len(path.path) < 2 or not path.is_for(view.goals[i]):
            return None
        geom = path.geometry()
        cum, _, here = station(path.path, view.poses[i, :2], geom)
        fp = view.footprints[i]
        vias = []
        for d in p.via_m:
            s = here + d
            if s + p.via_tangent_m > cum[-1]:
                continue  # the goal is near along the path: not this manoeuvre's case
            (back, _), (xy, _), (ahead, _) = (
                point_at(path.path, cum, s + e) for e in (-p.via_tangent_m, 0.0, p.via_tangent_m)
            )
            vias.append(np.array([*xy, np.arctan2(*(ahead - back)[::-1])]))
        windows: dict[int, tuple | None] = {}  # each via's window, built when first needed
        for grow in grows:  # the roomiest first, at every distance
            for k, via in enumerate(vias):
                if k not in windows:
                    windows[k] = self._window(view, i, goal=via)
                win = windows[k]
                if win is not None and footprint_clear(*win, fp, via, grow):
                    segments = self._plan(view, i, *win, grow, goal=via)
                    if segments:
                        return segments
        return None

    # ------------------------------------------------------------------ driving

    def _stop_rate(self, left: float, view: ControlView, i: int, *, yaw: bool = False) -> float:
        """The speed (or yaw rate) from which skid ``i`` stops in ``left`` metres (radians)
        braking at ``brake_share`` of its acceleration limit: ``sqrt(2 a left)``. Without
        acceleration limits or with ``brake_share`` 0, the proportional law ``k_speed *
        left`` (``k_yaw``)."""
        p = self.params
        if yaw:
            acc = None if view.max_yaw_accel is None else float(view.max_yaw_accel[i])
            k = p.k_yaw
        else:
            acc, k = float(view.max_accel[i]), p.k_speed
        if acc is None or not np.isfinite(acc) or p.brake_share <= 0:
            return k * left
        return float(np.sqrt(2.0 * p.brake_share * acc * left))

    def _drive(self, view: ControlView, i: int, st: ManoeuvreState) -> np.ndarray | None:
        """The command along the current segment; moves to the next one when it is done and
        ends the manoeuvre after the last (None: ended, the docking manoeuvre takes over)."""
        p = self.params
        pose = view.poses[i]
        v_max = float(view.max_speed[i]) * p.speed_share
        w_max = float(view.max_yaw_rate[i]) * p.speed_share
        if view.t > st.seg_deadline:
            st.stop(view.t, p.retry_s)  # the segment takes far too long: plan again later
            st.roomy = True
            return None
        while st.seg < len(st.segments):
            kind, a, b = st.segments[st.seg]
            if not np.isfinite(st.seg_deadline):
                expect = segment_time(st.segments[st.seg], v_max, w_max)
                st.seg_deadline = view.t + p.timeout_factor * expect + p.timeout_s
            if kind == "turn":
                err = wrap_angle(b[2] - pose[2])
                if abs(err) > p.done_rad:
                    w = min(self._stop_rate(abs(err), view, i, yaw=True), w_max)
                    return np.array([0.0, np.sign(err) * max(w, p.min_yaw_rate_radps)])
            else:
                d = 1.0 if kind == "forward" else -1.0
                u = np.array([np.cos(b[2]), np.sin(b[2])])
                along = float(np.dot(b[:2] - pose[:2], u)) * d
                if along > p.done_m:
                    # Off the line through the run's end (the same line as through its
                    # start, but for the last run to the exact goal, which may start a
                    # little beside the goal's axis: plan_manoeuvre's goal_tol_m).
                    rel = pose[:2] - b[:2]
                    lateral = float(u[0] * rel[1] - u[1] * rel[0])  # left of the run: > 0
                    aim = b[2] - d * np.arctan(p.k_lateral * lateral)
                    err = wrap_angle(aim - pose[2])
                    speed = np.clip(self._stop_rate(along, view, i), p.min_speed_mps, v_max)
                    speed *= max(np.cos(err), 0.0)
                    return np.array([d * speed, np.clip(p.k_yaw * err, -w_max, w_max)])
            st.seg += 1
            st.seg_deadline = np.inf
        st.segments, st.seg, st.roomy = None, 0, False
        st.best_left_m, st.best_t = np.inf, view.t
        return None
