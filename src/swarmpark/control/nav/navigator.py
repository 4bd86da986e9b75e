"""Navigation for parking: Dijkstra path, action-point potential field, collision monitor.

As in the 2018 paper (Sect. 3.4), each skid plans a least-cost path on the inflated costmap to
its assigned goal and the potential field of :mod:`swarmpark.control.nav.apf` drives it along the
path: the field attracts the skid to a lookahead pose on the path and, near the end, to the
goal pose itself, which gives the exact parking manoeuvre. Other skids, people and known
obstacles push the skid away (1/d^3). A collision monitor (as Navigation2's) then simulates
the command forward over a short horizon and slows or stops the skid before any contact.

Planning happens when the goal changes, when the path becomes blocked, and at most every
``replan_period_s`` otherwise. Everything is batched over robots except the per-robot plan.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np
import shapely
from scipy.spatial import cKDTree

from swarmpark.control.base import ControlView
from swarmpark.control.nav.apf import arc_length, attraction, forces_to_command, repulsion
from swarmpark.core.geometry import (
    TOUCH_TOLERANCE_M,
    Footprint,
    convex_overlap,
    footprint_corners,
    integrate_unicycle,
    rect_disc_gap,
    rotation,
    transform_points,
    wrap_angle,
)
from swarmpark.plan.grid import Costmap, build_costmap, path_length, paths_from, shortcut

__all__ = ["NavParams", "Navigator"]


@dataclass(frozen=True)
class NavParams:
    """Tuning of the navigation stack (SI units)."""

    lookahead_m: float = 1.2
    #: Within this distance of the goal the field attracts the goal pose itself.
    approach_m: float = 2.0
    #: The goal force falls linearly inside this distance (2015 paper, extension 3) ...
    slow_radius_m: float = 1.2
    #: ... but not below this (m/s), so the skid still creeps into its spot.
    min_goal_speed_mps: float = 0.06
    #: Repulsion gains (force in m/s at 1 m is gain * (1 - 1/influence^3)) and reach.
    k_static: float = 0.004
    k_robot: float = 0.004
    k_person: float = 0.008
    influence_m: float = 0.5
    #: Near its goal a skid ignores obstacles farther than this (parked neighbours sit there).
    influence_at_goal_m: float = 0.15
    #: Skid-skid avoidance: "rvo" (ORCA with priorities on the skids' effective centres,
    #: issue 5) or "monitor" (the collision monitor alone, with right of way at bottlenecks).
    avoidance: str = "monitor"
    #: Priority given to skids holding still on their goal or with no goal: they yield.
    parked_priority: float = 0.0
    #: Every skid keeps at least this share of the avoidance (a boxed-in skid cannot yield).
    rvo_min_share: float = 0.1
    #: Making room (RVO): a parked skid whose footprint lies in the corridor another skid
    #: will sweep (its path from its rear to this far ahead) or a walking person will cross
    #: (this far ahead along their velocity) drives along its own axis out of the corridor,
    #: which is the passing skid's half-width plus ``room_clearance_m`` to either side.
    room_lookahead_m: float = 4.0
    room_clearance_m: float = 0.3
    #: Speed (m/s) per metre still to go while making room, and the priority meanwhile
    #: (above ``parked_priority``, so it pushes still-parked neighbours on along their axes).
    room_gain: float = 1.5
    room_priority: float = 0.5
    #: With RVO a skid on its path aims its effective centre this far ahead on the path (a
    #: long lookahead, so that a sidestep does not turn into a pull back onto the path).
    rvo_lookahead_m: float = 3.0
    #: Deadlocks with RVO: no progress of this much (m) for this long (s) bumps the priority;
    #: each further ``rvo_stuck_s`` without progress, the skid side-steps to the right of its
    #: path for ``rvo_sidestep_s``; held still (by ORCA or the collision monitor) for
    #: ``stall_s``, it backs out straight along its axis for ``backup_m``.
    rvo_progress_m: float = 0.1
    rvo_stuck_s: float = 3.0
    rvo_bump: float = 2.0
    rvo_sidestep_s: float = 2.0
    #: Keep right: a skid on its path with another skid on the move coming the other way
    #: within ``rvo_keep_right_range_m`` turns its preferred velocity this much clockwise, so
    #: that crossings resolve as a roundabout instead of stalling in symmetric jams (RVO2's
    #: examples break the symmetry with noise).
    rvo_keep_right_rad: float = 1.0
    rvo_keep_right_range_m: float = 4.0
    #: ... fully with static solids at least ``rvo_keep_right_open_m`` away, fading out to
    #: none at ``rvo_keep_right_tight_m`` (in a door both keeping right wedge on the jambs).
    rvo_keep_right_open_m: float = 2.5
    rvo_keep_right_tight_m: float = 1.0
    #: Extra margin (m) around skids on the move in the velocity obstacles.
    rvo_margin_m: float = 0.1
    #: Horizon (s) of the velocity obstacles between skids: avoid this early.
    rvo_horizon_s: float = 5.0
    replan_period_s: float = 3.0
    #: At most this many paths are planned in one tick.
    max_plans_per_tick: int = 8
    #: Paths are searched on the map coarsened to this resolution (conservatively); None
    #: searches at the map's own resolution. Coarser plans are faster (see the nav.plan
    #: benchmark) but narrow the passages by up to a cell, which costs time in tight spaces.
    plan_resolution_m: float | None = None
    #: Collision monitor: look this far ahead in time, at these fractions of the command.
    monitor_horizon_s: float = 1.0
    monitor_samples: int = 5
    monitor_scales: tuple[float, ...] = (1.0, 0.6, 0.3, 0.0)
    #: Extra clearance the monitor keeps (m).
    monitor_margin_m: float = 0.03
    #: Switch driving end only if the other end's arc is shorter by this factor (hysteresis).
    switch_ratio: float = 0.75
    #: Docking: within this distance of the goal, align the heading and close the remaining
    #: distance straight along the goal heading (if the lateral error allows it).
    dock_radius_m: float = 0.3
    dock_lateral_m: float = 0.07
    #: Gain of the goal-axis tracking law (rad of aim per m of lateral error, via atan).
    k_lateral: float = 3.0
    #: Otherwise back out to this run-up distance along the goal heading and come in again.
    runup_m: float = 0.9
    #: A docked skid holds still inside these errors and resumes beyond the outer ones.
    parked_pos_m: float = 0.03
    parked_yaw_rad: float = np.deg2rad(1.5)
    resume_pos_m: float = 0.09
    resume_yaw_rad: float = np.deg2rad(4.0)
    k_dock: float = 1.0
    k_dock_yaw: float = 1.5
    #: Give way: after being held up this long by a skid of higher rank, back away from it for
    #: at most this long, or until this far (centre to centre) from it.
    yield_after_s: float = 1.0
    #: A skid near its goal held still this long by the monitor backs out and tries again.
    stall_s: float = 2.0
    stall_speed_mps: float = 0.02
    stall_yaw_rate_radps: float = 0.05
    #: Elsewhere it backs up this far (Navigation2's back-up recovery).
    backup_m: float = 0.5
    yield_s: float = 3.0
    yield_clear_m: float = 2.5
    #: Skids held back by the fill order wait this far outside their parking boundary.
    hold_gap_m: float = 1.0
    #: Sampling of obstacle outlines for the field.
    outline_step_m: float = 0.1


def _station(path: np.ndarray, xy: np.ndarray) -> tuple[np.ndarray, int, float]:
    """Where ``xy`` projects onto a polyline: the cumulative arc lengths of its vertices,
    the segment it projects onto, and the arc length there."""
    seg = np.diff(path, axis=0)
    seg_len = np.linalg.norm(seg, axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg_len)])
    rel = xy - path[:-1]
    t = np.clip(np.einsum("ij,ij->i", rel, seg) / np.maximum(seg_len**2, 1e-12), 0, 1)
    proj = path[:-1] + t[:, None] * seg
    j = int(np.argmin(np.linalg.norm(proj - xy, axis=1)))
    return cum, j, float(cum[j] + t[j] * seg_len[j])


def _point_at(path: np.ndarray, cum: np.ndarray, s: float) -> tuple[np.ndarray, int]:
    """The point at arc length ``s`` (within ``[0, cum[-1]]``) of a polyline and its segment."""
    m = int(np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(path) - 2))
    f = (s - cum[m]) / max(cum[m + 1] - cum[m], 1e-12)
    return path[m] + f * (path[m + 1] - path[m]), m


@dataclass
class _RobotNav:
    path: np.ndarray | None = None
    path_goal: np.ndarray | None = None
    planned_t: float = -np.inf
    reverse: bool = False
    failed: bool = False
    docked: bool = False
    #: Reached its current goal once (reset by a new goal): with RVO it yields from then on,
    #: also while it returns after being pushed aside.
    settled: bool = False
    #: Side (+1 along the heading, -1 against it) this skid last made room to, or 0.
    room_side: int = 0
    #: RVO deadlock watch: best remaining distance to the goal, when it was reached, and the
    #: open recovery record (a priority bump) while the skid is stuck.
    best_remaining: float = np.inf
    best_t: float = 0.0
    recovery: dict | None = None
    sidestep_until: float = -np.inf
    #: RVO back-out: metres left and the direction (+1 forwards, -1 backwards) along the axis.
    backout_left: float = 0.0
    backout_dir: float = 0.0
    runup: bool = False
    runup_from: float = 0.0
    backup_left: float = 0.0
    stalled_s: float = 0.0
    blockers: set = field(default_factory=set)
    blocked_s: float = 0.0
    yield_until: float = -np.inf
    yield_from: int = -1


@dataclass
class Navigator:
    """The default controller: plan, follow with the potential field, monitor for collisions."""

    params: NavParams = field(default_factory=NavParams)

    def __post_init__(self) -> None:
        self._robots: list[_RobotNav] = []
        # Inflated costmaps per footprint, for the grid in _costmap_grid.
        self._costmaps: dict[tuple[float, float], Costmap] = {}
        self._costmap_grid = None
        self._static_pts: np.ndarray | None = None
        self._static_key: int | None = None
        self._static_tree = None
        self._static_kd = None
        #: (N,) skids standing aside for another on purpose this tick (RVO; not deadlocked).
        self.making_room = np.zeros(0, dtype=bool)
        #: Deadlock recoveries (RVO): robot index, start, action, time to clear.
        self.recoveries: list[dict] = []

    # ------------------------------------------------------------------ helpers

    def paths(self) -> list[np.ndarray | None]:
        """Current planned paths (world points), for display."""
        return [r.path for r in self._robots]

    def _costmap(self, view: ControlView, fp: Footprint) -> Costmap:
        key = (round(fp.width_m / 2, 4), round(fp.reach_m, 4))
        if self._costmap_grid is not view.grid:  # a new map (detected obstacles)
            self._costmaps, self._costmap_grid = {}, view.grid
        if key not in self._costmaps:
            self._costmaps[key] = build_costmap(
                view.grid, key[0], key[1], resolution_m=self.params.plan_resolution_m
            )
        return self._costmaps[key]

    def _static_points(self, view: ControlView) -> np.ndarray:
        """Outline points of every known static solid (sampled once)."""
        key = id(view.static_pieces)
        if self._static_key != key:
            pts = []
            step = self.params.outline_step_m
            for piece in view.static_pieces:
                nxt = np.roll(piece, -1, axis=0)
                for a, b in zip(piece, nxt, strict=True):
                    n = max(int(np.ceil(np.linalg.norm(b - a) / step)), 1)
                    pts.append(a + np.linspace(0, 1, n, endpoint=False)[:, None] * (b - a))
            self._static_pts = np.vstack(pts) if pts else np.zeros((0, 2))
            self._static_key = key
            self._static_kd = cKDTree(self._static_pts) if len(self._static_pts) else None
            lo, hi = view.static_pieces.min(axis=1), view.static_pieces.max(axis=1)
            self._static_tree = shapely.STRtree(shapely.box(lo[:, 0], lo[:, 1], hi[:, 0], hi[:, 1]))
        return self._static_pts  # type: ignore[return-value]

    # ------------------------------------------------------------------ planning

    def _update_plans(self, view: ControlView) -> None:
        p = self.params
        wanted = []
        for i in np.flatnonzero(view.active):
            nav = self._robots[i]
            goal = view.goals[i]
            stale = nav.path_goal is None or np.any(np.abs(nav.path_goal - goal) > 1e-9)
            due = view.t - nav.planned_t >= p.replan_period_s
            if stale or view.goal_changed[i] or (due and nav.failed):
                wanted.append(i)
        # A bounded number of plans per tick (longest waiting first), so a park command for a
        # hundred skids does not stall the loop; the others wait for their path.
        wanted.sort(key=lambda i: (self._robots[i].planned_t, i))
        for i in wanted[: p.max_plans_per_tick]:
            nav = self._robots[i]
            goal = view.goals[i]
            cm = self._costmap(view, view.footprints[i])
            path = self._plan_with_staging(cm, view.poses[i], goal)
            nav.path, nav.path_goal, nav.planned_t = path, goal.copy(), view.t
            nav.failed = path is None
            if path is not None:
                nav.reverse = self._choose_end(view, i, path)

    def _plan_with_staging(self, cm: Costmap, pose: np.ndarray, goal: np.ndarray):
        """A path that ends with a straight run along the goal's axis.

        The path is planned to a staging point ``runup_m`` before the goal on its axis (behind
        it, to drive in forwards, or in front of it, to back in: whichever plans shorter) and
        the goal is appended, so the skid arrives aligned. Falls back to a direct path when
        neither staging point can be reached or the skid is already close.
        """
        p = self.params
        axis = np.array([np.cos(goal[2]), np.sin(goal[2])])
        stages = [goal[:2] + side * p.runup_m * axis for side in (-1.0, 1.0)]  # behind, ahead
        # One Dijkstra run serves the direct path and both staging points.
        direct, *heads = paths_from(cm, pose[:2], np.vstack([goal[:2], *stages]))
        if direct is not None:
            direct = shortcut(direct, cm.cost, cm.grid)
        if direct is None or np.linalg.norm(goal[:2] - pose[:2]) < 2 * p.runup_m:
            return direct
        best = None
        for stage, head in zip(stages, heads, strict=True):
            # The straight run from the staging point to the goal must be free.
            run = goal[:2][None] + np.linspace(0, 1, 10)[:, None] * (stage - goal[:2])[None]
            rc = cm.grid.world_to_cell(run)
            if (
                head is None
                or not cm.grid.in_bounds(rc).all()
                or cm.grid.occupied[rc[:, 0], rc[:, 1]].any()
            ):
                continue
            cand = np.vstack([shortcut(head, cm.cost, cm.grid), goal[:2][None]])
            if best is None or path_length(cand) < path_length(best):
                best = cand
        return best if best is not None else direct

    def _choose_end(self, view: ControlView, i: int, path: np.ndarray) -> bool:
        """Which end leads along a path: the one facing the path's first stretch, forwards
        unless the skid faces clearly away from it (it may turn in place). The parking end
        is chosen again near the goal by the shorter arc (2015 paper, extension 1)."""
        if len(path) < 2:
            return self._shorter_end(view, np.array([i]))[0]
        ahead = path[min(len(path) - 1, 1)] - path[0]
        tangent = np.arctan2(ahead[1], ahead[0])
        return bool(abs(wrap_angle(view.poses[i, 2] - tangent)) > np.deg2rad(120))

    def _end_arcs(self, view: ControlView, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Arc lengths to the goal of the front and of the rear action point (2015 paper,
        extension 1: the skid leads with whichever end has the shorter arc)."""
        fps = [view.footprints[i] for i in idx]
        xf = np.array([f.length_m - f.pivot for f in fps])
        xr = -np.array([f.pivot for f in fps])
        pose, goal = view.poses[idx], view.goals[idx]
        u = np.column_stack([np.cos(pose[:, 2]), np.sin(pose[:, 2])])
        ug = np.column_stack([np.cos(goal[:, 2]), np.sin(goal[:, 2])])
        front = arc_length(
            pose[:, :2] + xf[:, None] * u, goal[:, :2] + xf[:, None] * ug, goal[:, 2]
        )
        rear = arc_length(
            pose[:, :2] + xr[:, None] * u, goal[:, :2] + xr[:, None] * ug, goal[:, 2] + np.pi
        )
        return front, rear

    def _shorter_end(self, view: ControlView, idx: np.ndarray) -> np.ndarray:
        """True where the rear action point has the shorter arc to the goal."""
        front, rear = self._end_arcs(view, idx)
        return rear < front

    # ------------------------------------------------------------------ targets

    def _targets(
        self, view: ControlView, idx: np.ndarray, lookahead_m: float | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Temporary goal pose per robot (lookahead on the path, or the goal) and whether the
        robot is in its final approach."""
        p = self.params
        lookahead_m = p.lookahead_m if lookahead_m is None else lookahead_m
        targets = view.goals[idx].copy()
        final = np.ones(len(idx), dtype=bool)
        for k, i in enumerate(idx):
            nav = self._robots[i]
            path = nav.path
            if path is None or len(path) < 2:
                continue
            cum, _, s_here = _station(path, view.poses[i, :2])
            if cum[-1] - s_here <= p.approach_m:
                continue
            final[k] = False
            pt, m = _point_at(path, cum, min(s_here + lookahead_m, cum[-1]))
            seg = path[m + 1] - path[m]
            heading = np.arctan2(seg[1], seg[0]) + (np.pi if nav.reverse else 0.0)
            targets[k] = [pt[0], pt[1], wrap_angle(heading)]
        return targets, final

    # ------------------------------------------------------------------ the tick

    def compute(self, view: ControlView) -> np.ndarray:
        p = self.params
        n = len(view.poses)
        while len(self._robots) < n:
            self._robots.append(_RobotNav())
        cmd = np.zeros((n, 2))
        idx = np.flatnonzero(view.active)
        if len(idx) == 0:
            return cmd
        self._update_plans(view)
        fps = view.footprints
        x_front = np.array([fps[i].length_m - fps[i].pivot for i in idx])
        x_rear = -np.array([fps[i].pivot for i in idx])
        half_w = np.array([fps[i].width_m / 2 for i in idx])
        poses = view.poses[idx]
        targets, final = self._targets(view, idx)
        # Skids whose path is for an older goal (queued for planning) hold still meanwhile.
        waiting = np.array(
            [
                self._robots[i].path_goal is None
                or bool(np.any(np.abs(self._robots[i].path_goal - view.goals[i]) > 1e-9))
                for i in idx
            ]
        )

        # Which end leads: fixed along a path; by the shorter arc (with hysteresis) at the end.
        reverse = np.array([self._robots[i].reverse for i in idx])
        if final.any():
            cur = reverse[final]
            lf, lr = self._end_arcs(view, idx[final])
            # Switch ends only for a clearly shorter arc (hysteresis).
            switch = np.where(cur, lf < p.switch_ratio * lr, lr < p.switch_ratio * lf)
            new = np.where(switch, ~cur, cur)
            reverse[final] = new
            for k, i in enumerate(idx[final]):
                self._robots[i].reverse = bool(new[k])

        # Attraction, weighted by the distance to the (final) goal.
        dist_goal = np.linalg.norm(view.goals[idx, :2] - poses[:, :2], axis=1)
        head_err = np.abs(wrap_angle(view.goals[idx, 2] - poses[:, 2]))
        weight = np.clip(
            view.max_speed[idx] * (dist_goal + 0.3 * head_err) / p.slow_radius_m,
            p.min_goal_speed_mps,
            view.max_speed[idx],
        )
        f_goal, x_goal = attraction(poses, targets, x_front, x_rear, reverse, weight)

        # Repulsion from static outlines, other skids' outlines and people.
        influence = np.where(
            final & (dist_goal < p.approach_m), p.influence_at_goal_m, p.influence_m
        )
        f_front, f_rear = self._repulsion(view, idx, x_front, x_rear, half_w, influence)
        raw = forces_to_command(f_goal, x_goal, f_front, f_rear, x_front, x_rear)

        # Turn before driving when the wanted direction is far off (the skid can spin in place).
        rel = np.arctan2(f_goal[:, 1], np.abs(f_goal[:, 0]))
        raw[:, 0] *= np.clip(np.cos(rel), 0.0, 1.0) ** 2
        raw[:, 0] = np.clip(raw[:, 0], -view.max_speed[idx], view.max_speed[idx])
        raw[:, 1] = np.clip(raw[:, 1], -view.max_yaw_rate[idx], view.max_yaw_rate[idx])
        # At the goal position, only turn to the goal heading.
        raw[waiting] = 0.0
        raw = self._dock(view, idx, raw, targets, final & ~waiting)
        if p.avoidance == "rvo":
            full = np.zeros((n, 2))
            full[idx] = raw
            cruising = ~final & ~waiting
            aims, _ = self._targets(view, idx[cruising], p.rvo_lookahead_m)
            full = self._orca(view, full, idx[cruising], aims)
            moving = np.flatnonzero(np.any(np.abs(full) > 0, axis=1) | view.active)
            cmd[moving] = self._monitor(view, moving, full[moving], joint=True)
            self._hold_outside(view, idx, cmd)
            self._track_stalls(view, idx, cmd)
            return cmd
        raw = self._give_way(view, idx, raw, dist_goal)
        cmd[idx] = self._monitor(view, idx, raw)
        self._hold_outside(view, idx, cmd)
        self._track_stalls(view, idx, cmd)
        return cmd

    def _track_stalls(self, view: ControlView, idx: np.ndarray, cmd: np.ndarray) -> None:
        p = self.params
        for i in idx:  # how long the monitor or the field has kept a skid (nearly) still
            nav = self._robots[i]
            still = (
                abs(cmd[i, 0]) < p.stall_speed_mps
                and abs(cmd[i, 1]) < p.stall_yaw_rate_radps
                and not nav.docked
            )
            nav.stalled_s = nav.stalled_s + view.dt if still else 0.0

    def _dock(self, view: ControlView, idx, raw, targets, final) -> np.ndarray:
        """The parking manoeuvre to the exact pose, in the goal frame.

        Within ``runup_m`` of the goal and roughly aligned, the pivot tracks the goal's axis
        (a Stanley-type law: aim at ``atan(k * lateral error)`` off the axis, forwards or in
        reverse) while closing the longitudinal error. A skid too close to fix its lateral
        error backs out along the axis with the same law, which also reduces it, and comes in
        again. Inside the parked band it holds still until pushed out of the outer band.
        """
        p = self.params
        goals = view.goals[idx]
        pose = view.poses[idx]
        d = pose[:, :2] - goals[:, :2]
        cg, sg = np.cos(goals[:, 2]), np.sin(goals[:, 2])
        e_long = d[:, 0] * cg + d[:, 1] * sg  # > 0 when past the goal along its heading
        e_lat = -d[:, 0] * sg + d[:, 1] * cg
        e_yaw = wrap_angle(goals[:, 2] - pose[:, 2])
        dist = np.hypot(e_long, e_lat)
        out = raw.copy()
        for k, i in enumerate(idx):
            nav = self._robots[i]
            if view.goal_changed[i]:
                nav.docked = nav.runup = nav.settled = False
            parked = (
                abs(e_long[k]) < p.parked_pos_m
                and abs(e_lat[k]) < p.dock_lateral_m
                and abs(e_yaw[k]) < p.parked_yaw_rad
            )
            if nav.docked and (dist[k] > p.resume_pos_m or abs(e_yaw[k]) > p.resume_yaw_rad):
                nav.docked = False
            if nav.docked or parked:
                nav.docked, nav.runup, nav.settled = True, False, True
                out[k] = 0.0
                continue
            close = final[k] and dist[k] < p.runup_m * 2.0
            if close and abs(e_yaw[k]) >= np.deg2rad(75) and nav.backup_left <= 0:
                # Far off the goal heading next to the goal: turn in place first (a
                # differential-drive skid can); the axis law below needs a rough alignment.
                nav.runup = False
                w = np.clip(p.k_dock_yaw * e_yaw[k], -view.max_yaw_rate[i], view.max_yaw_rate[i])
                out[k] = (0.0, w)
                continue
            near = close and abs(e_yaw[k]) < np.deg2rad(75)
            if not near:
                nav.runup = False
                if nav.stalled_s >= p.stall_s and nav.backup_left <= 0:
                    nav.backup_left, nav.stalled_s = p.backup_m, 0.0
                if nav.backup_left > 0:
                    # Recovery (as Navigation2's back-up): reverse straight, away from whatever
                    # holds the skid, then let the field try again.
                    step = abs(view.vel[i, 0]) * view.dt
                    nav.backup_left -= max(step, 0.0) if abs(view.vel[i, 0]) > 1e-3 else 0.0
                    if nav.stalled_s >= p.stall_s:  # backing is blocked too
                        nav.backup_left = 0.0
                    out[k] = (-np.sign(raw[k, 0] + 1e-9) * 0.5 * view.max_speed[i], 0.0)
                continue
            too_close = abs(e_lat[k]) > p.dock_lateral_m and abs(e_long[k]) < p.dock_radius_m
            wedged = nav.stalled_s >= p.stall_s  # the monitor has held it still: back out
            if (too_close or wedged) and not nav.runup:
                nav.runup, nav.runup_from, nav.stalled_s = True, abs(e_long[k]), 0.0
            backed = abs(e_long[k]) - nav.runup_from
            if nav.runup and (
                abs(e_lat[k]) < 0.5 * p.dock_lateral_m
                or backed > p.runup_m
                or (backed > 0.2 and nav.stalled_s >= p.stall_s)
            ):
                nav.runup, nav.stalled_s = False, 0.0
            # Travel direction: towards the goal along its axis, or away from it (run-up).
            to_goal = -np.sign(e_long[k]) if abs(e_long[k]) > 1e-6 else 1.0
            sgn = -to_goal if nav.runup else to_goal
            if abs(e_long[k]) < p.parked_pos_m and not nav.runup:
                # On the spot: only turn to the goal heading.
                w = np.clip(p.k_dock_yaw * e_yaw[k], -view.max_yaw_rate[i], view.max_yaw_rate[i])
                out[k] = (0.0, w)
                continue
            aim = -sgn * np.arctan(p.k_lateral * e_lat[k])  # heading off the axis, goal frame
            yaw_err = wrap_angle(aim + e_yaw[k])  # (goal + aim) - current heading
            speed = np.clip(
                p.k_dock * (p.runup_m if nav.runup else abs(e_long[k])),
                p.min_goal_speed_mps,
                0.5 * view.max_speed[i],
            )
            v = sgn * speed * max(np.cos(yaw_err), 0.0) ** 2
            w = np.clip(p.k_dock_yaw * yaw_err, -view.max_yaw_rate[i], view.max_yaw_rate[i])
            out[k] = (v, w)
        return out

    def _give_way(self, view: ControlView, idx, raw, dist_goal) -> np.ndarray:
        """Right of way at bottlenecks: a skid held up by a skid of higher rank (priority, then
        nearer its goal, then lower index) for ``yield_after_s`` backs away from it for up to
        ``yield_s``, so the other can pass. Docking skids never give way."""
        p = self.params
        out = raw.copy()
        rank = {int(i): (-view.priority[i], dist_goal[k], int(i)) for k, i in enumerate(idx)}
        for k, i in enumerate(idx):
            nav = self._robots[i]
            if nav.docked or dist_goal[k] < p.dock_radius_m * 2:
                nav.yield_until = -np.inf
                continue
            if view.t >= nav.yield_until and nav.blocked_s >= p.yield_after_s:
                better = [j for j in nav.blockers if j in rank and rank[j] < rank[int(i)]]
                better += [j for j in nav.blockers if j not in rank]  # idle/parked skids
                if better:
                    nav.yield_from = min(better, key=lambda j: rank.get(j, (-np.inf,)))
                    nav.yield_until = view.t + p.yield_s
                    nav.blocked_s = 0.0
            if view.t < nav.yield_until:
                j = nav.yield_from
                away = view.poses[i, :2] - view.poses[j, :2]
                if np.linalg.norm(away) > p.yield_clear_m:
                    nav.yield_until = -np.inf
                    continue
                out[k] = (0.5 * view.max_speed[i] * self._axis_away(view, i, j), 0.0)
        return out

    def _hold_outside(self, view: ControlView, idx: np.ndarray, cmd: np.ndarray) -> None:
        """Held skids (fill order) stop before they come within ``hold_gap_m`` of their
        parking boundary; moving away from it stays allowed."""
        if view.hold is None or not view.hold[idx].any():
            return
        gap = self.params.hold_gap_m
        for i in idx[view.hold[idx]]:
            zone = view.hold_zones[i] if i < len(view.hold_zones) else None
            if zone is None:
                continue
            fp = view.footprints[i]
            now = shapely.Polygon(
                footprint_corners(view.poses[i][None], fp.corners_body()[None])[0]
            )
            if now.intersects(zone):
                continue  # already inside: never freeze in the middle of the formation
            v, w = cmd[i]
            ahead = (
                view.poses[i]
                + np.array([v * np.cos(view.poses[i, 2]), v * np.sin(view.poses[i, 2]), w]) * 0.5
            )
            nxt = shapely.Polygon(footprint_corners(ahead[None], fp.corners_body()[None])[0])
            d_now, d_next = now.distance(zone), nxt.distance(zone)
            if d_next < gap and d_next <= d_now:
                cmd[i] = 0.0

    def _outlines(self, view: ControlView) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Body-frame outline samples of every skid (cached), their owners, and grown monitor
        rectangles per skid."""
        key = tuple(view.footprints)
        if getattr(self, "_outline_key", None) != key:
            step, grow = self.params.outline_step_m, self.params.monitor_margin_m
            pts, owner = [], []
            for j, fp in enumerate(view.footprints):
                c = fp.corners_body()
                for a, b in zip(c, np.roll(c, -1, axis=0), strict=True):
                    m = max(int(np.ceil(np.linalg.norm(b - a) / step)), 1)
                    pts.append(a + np.linspace(0, 1, m, endpoint=False)[:, None] * (b - a))
                    owner.append(np.full(m, j))
            self._outline_pts = np.vstack(pts)
            self._outline_owner = np.concatenate(owner)
            self._plain = np.stack([f.corners_body() for f in view.footprints])
            self._grown = np.stack(
                [
                    Footprint(
                        f.length_m + 2 * grow, f.width_m + 2 * grow, f.pivot + grow
                    ).corners_body()
                    for f in view.footprints
                ]
            )
            self._outline_key = key
        return self._outline_pts, self._outline_owner, self._grown

    def _repulsion(self, view, idx, x_front, x_rear, half_w, influence):
        p = self.params
        n_act = len(idx)
        self._static_points(view)
        body_pts, body_owner, _ = self._outlines(view)
        # Other skids' outlines in the world, and people (their rims are handled below).
        # With RVO, skids and people are left to the velocity obstacles: the field only
        # follows the path and keeps off static solids.
        robot_pts = transform_points(view.poses[body_owner], body_pts[:, None, :])[:, 0]
        dyn = np.vstack([robot_pts, view.people_xy])
        dyn_owner = np.concatenate([body_owner, np.full(len(view.people_xy), -2)])
        if p.avoidance == "rvo":
            dyn, dyn_owner = dyn[:0], dyn_owner[:0]
        reach = np.array([view.footprints[i].reach_m for i in idx]) + influence
        rob_l, pt_l, src_l = [], [], []
        if self._static_kd is not None:
            hits = self._static_kd.query_ball_point(view.poses[idx, :2], reach)
            lens = np.fromiter((len(h) for h in hits), int, len(hits))
            if lens.sum():
                rob_l.append(np.repeat(np.arange(n_act), lens))
                pt_l.append(np.concatenate([np.asarray(h, int) for h in hits if len(h)]))
                src_l.append(np.zeros(lens.sum(), int))
        if len(dyn):
            rim = view.people_radius.max(initial=0.0)
            hits = cKDTree(dyn).query_ball_point(view.poses[idx, :2], reach + rim)
            lens = np.fromiter((len(h) for h in hits), int, len(hits))
            if lens.sum():
                rob_l.append(np.repeat(np.arange(n_act), lens))
                pt_l.append(np.concatenate([np.asarray(h, int) for h in hits if len(h)]))
                src_l.append(np.ones(lens.sum(), int))
        if not rob_l:
            z = np.zeros((n_act, 2))
            return z, z.copy()
        rob, pt, src = np.concatenate(rob_l), np.concatenate(pt_l), np.concatenate(src_l)
        is_dyn = src == 1
        owner = np.full(len(pt), -1)
        owner[is_dyn] = dyn_owner[pt[is_dyn]]
        keep = owner != idx[rob]
        rob, pt, is_dyn, owner = rob[keep], pt[keep], is_dyn[keep], owner[keep]
        world = np.empty((len(pt), 2))
        world[is_dyn] = dyn[pt[is_dyn]]
        world[~is_dyn] = self._static_pts[pt[~is_dyn]]
        gain = np.where(owner == -1, p.k_static, np.where(owner == -2, p.k_person, p.k_robot))
        pose = view.poses[idx[rob]]
        d = world - pose[:, :2]
        c, s = np.cos(pose[:, 2]), np.sin(pose[:, 2])
        body = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]])
        person = owner == -2
        if person.any():
            # A person's rim is closer than the centre by the radius: move the point inwards.
            rad = view.people_radius[pt[person] - len(robot_pts)]
            nrm = np.linalg.norm(body[person], axis=1, keepdims=True)
            body[person] *= np.maximum(1 - rad[:, None] / np.maximum(nrm, 1e-9), 0.0)
        front, rear, _ = repulsion(
            rob, body, gain, x_rear[rob], x_front[rob], half_w[rob], influence[rob]
        )
        out_f, out_r = np.zeros((n_act, 2)), np.zeros((n_act, 2))
        out_f[: len(front)] = front
        out_r[: len(rear)] = rear
        return out_f, out_r

    def _monitor(
        self,
        view: ControlView,
        idx: np.ndarray,
        raw: np.ndarray,
        *,
        robots: bool = True,
        joint: bool = False,
    ) -> np.ndarray:
        """Scale each command down until its short forward simulation is collision-free
        (others where they are now); with ``joint``, also stop pairs whose commands together
        would bring them into contact (:meth:`_joint_check`)."""
        p = self.params
        n_act = len(idx)
        scales = np.asarray(p.monitor_scales)
        times = np.linspace(
            p.monitor_horizon_s / p.monitor_samples, p.monitor_horizon_s, p.monitor_samples
        )
        fps = view.footprints
        grow = p.monitor_margin_m
        body = self._outlines(view)[2][idx]
        plain = self._plain[idx]
        # A skid already inside its margin of something is judged by its plain footprint, or it
        # could never move away again.
        body = np.where(self._within_margin(view, idx, body)[:, None, None], plain, body)
        # Poses for every (robot, scale, time): from the current velocity towards the command
        # within the acceleration limits (a skid turning fast cannot stop turning at once),
        # integrated in control steps.
        S, T = len(scales), len(times)
        v_cmd = (raw[:, 0][:, None] * scales[None, :]).ravel()
        w_cmd = np.repeat(raw[:, 1], S)
        pose = self._rollout(view, np.repeat(idx, S), v_cmd, w_cmd, times).reshape(-1, 3)
        owner = np.repeat(np.arange(n_act), S * T)
        corners = footprint_corners(pose, np.repeat(body, S * T, axis=0))
        bad = np.zeros(len(pose), dtype=bool)

        # Static solids.
        self._static_points(view)
        lo, hi = corners.min(axis=1), corners.max(axis=1)
        qi, si = self._static_tree.query(shapely.box(lo[:, 0], lo[:, 1], hi[:, 0], hi[:, 1]))
        if len(qi):
            hit = convex_overlap(corners[qi], view.static_pieces[si]) > TOUCH_TOLERANCE_M
            bad[qi[hit]] = True
        # Other skids where they are now (they run their own monitor).
        others = footprint_corners(view.poses, self._plain)
        centers = others.mean(axis=1)
        tree = cKDTree(centers)
        radius = max(f.circumradius_m for f in fps) * 2 + grow
        cand = tree.query_ball_point(corners.mean(axis=1), radius)
        lens = np.fromiter(map(len, cand), int, len(cand))
        qa = np.repeat(np.arange(len(cand)), lens)
        qb = np.fromiter(itertools.chain.from_iterable(cand), int, int(lens.sum()))
        keep = (qb != idx[owner[qa]]) & robots
        qa, qb = qa[keep], qb[keep]
        blockers: list[set[int]] = [set() for _ in range(n_act)]
        if len(qa):
            hit = convex_overlap(corners[qa], others[qb]) > TOUCH_TOLERANCE_M
            bad[qa[hit]] = True
            full_speed = (qa // T) % S == 0
            for a, b in zip(owner[qa[hit & full_speed]], qb[hit & full_speed], strict=True):
                blockers[a].add(int(b))
        # People, moving on with their current velocity.
        if len(view.people_xy):
            tt = np.tile(np.repeat(times, 1), n_act * S)
            for k in range(len(view.people_xy)):
                centre = view.people_xy[k] + view.people_vel[k] * tt[:, None]
                gap = rect_disc_gap(corners, centre, np.full(len(corners), view.people_radius[k]))
                bad |= gap < 0
        bad = bad.reshape(n_act, S, T)
        # The fastest safe scale; if even turning in place collides, stop turning as well.
        safe = ~bad.any(axis=2)
        first_safe = np.where(safe.any(axis=1), np.argmax(safe, axis=1), S - 1)
        out = raw.copy()
        out[:, 0] *= scales[first_safe]
        out[~safe[:, -1]] = 0.0
        slowed = first_safe > 0
        for k, i in enumerate(idx):
            nav = self._robots[i]
            nav.blockers = blockers[k] if slowed[k] else set()
            nav.blocked_s = nav.blocked_s + view.dt if nav.blockers else 0.0
        if joint and robots:
            self._joint_check(view, idx, out, body, times)
        return out

    def guard(self, view: ControlView, idx: np.ndarray, raw: np.ndarray) -> np.ndarray:
        """Commands ``raw`` of skids ``idx`` not driven by this controller (teleop), scaled
        down by the collision monitor until their short forward simulation is free."""
        self._outlines(view)  # (cached) the outlines and static solids the monitor uses
        self._static_points(view)
        if len(self._robots) != len(view.poses):
            self.compute(view)  # the per-skid state (a first tick with nothing active)
        return self._monitor(view, np.asarray(idx, int), np.asarray(raw, float))

    def _rollout(
        self, view: ControlView, rows: np.ndarray, v_cmd: np.ndarray, w_cmd, times: np.ndarray
    ) -> np.ndarray:
        """Poses ``(len(rows), T, 3)`` of skids ``rows`` at ``times`` under the commands held,
        from their current velocities within the acceleration limits (a skid turning fast
        cannot stop turning at once), integrated in control steps."""
        n_sub = max(1, int(round(times[-1] / view.dt)))
        sub_dt = times[-1] / n_sub
        record = np.clip(np.round(times / sub_dt), 1, n_sub).astype(int)
        v, w = view.vel[rows, 0], view.vel[rows, 1]
        dv = view.max_accel[rows] * sub_dt
        dw = np.inf if view.max_yaw_accel is None else view.max_yaw_accel[rows] * sub_dt
        now = view.poses[rows]
        pose = np.empty((len(rows), len(times), 3))
        for step in range(1, n_sub + 1):
            v = v + np.clip(v_cmd - v, -dv, dv)
            w = w + np.clip(w_cmd - w, -dw, dw)
            now = integrate_unicycle(now, v, w, sub_dt)
            pose[:, record == step] = now[:, None]
        return pose

    def _joint_check(
        self, view: ControlView, idx: np.ndarray, out: np.ndarray, body: np.ndarray, times
    ) -> None:
        """Stop the pairs of skids whose commands, held together, bring them into contact
        within the monitor horizon (in place on ``out``).

        Each skid's own check treats the others as standing still; two skids turning in
        place next to each other, each safe alone, can still swing their corners together.
        ORCA should prevent that, but its guarantee is for one step and holonomic centres.
        The stopped skids' braking is rolled out again, until no new pair is found.
        """
        T = len(times)
        reach = max(f.circumradius_m for f in view.footprints) * 2.0
        speed = np.abs(view.vel[idx, 0]).max(initial=0.0) + view.max_speed[idx].max()
        pairs = cKDTree(view.poses[idx, :2]).query_pairs(
            reach + 2.0 * speed * times[-1], output_type="ndarray"
        )
        while len(pairs):
            pose = self._rollout(view, idx, out[:, 0], out[:, 1], times)
            corners = footprint_corners(pose.reshape(-1, 3), np.repeat(body, T, axis=0))
            corners = corners.reshape(len(idx), T, 4, 2)
            a = np.repeat(pairs[:, 0], T)
            b = np.repeat(pairs[:, 1], T)
            tk = np.tile(np.arange(T), len(pairs))
            hit = convex_overlap(corners[a, tk], corners[b, tk]) > TOUCH_TOLERANCE_M
            bad = np.unique(pairs[hit.reshape(len(pairs), T).any(axis=1)])
            bad = bad[np.any(out[bad] != 0.0, axis=1)]
            if not len(bad):
                return
            out[bad] = 0.0

    def _path_ahead(self, view: ControlView, i: int, length: float) -> np.ndarray | None:
        """Skid ``i``'s path from its rear to ``length`` ahead of its pivot (a polyline)."""
        path = self._robots[i].path
        pose = view.poses[i]
        fp = view.footprints[i]
        head = np.array([np.cos(pose[2]), np.sin(pose[2])])
        back = pose[:2] - head * (fp.length_m - fp.pivot if self._robots[i].reverse else fp.pivot)
        if path is None or len(path) < 2:
            return np.vstack([back, pose[:2]])
        cum, j, s_here = _station(path, pose[:2])
        s_end = min(s_here + length, cum[-1])
        inner = path[j + 1 :][cum[j + 1 :] < s_end]
        tip, _ = _point_at(path, cum, s_end)
        return np.vstack([back, pose[:2], inner, tip])

    def _make_room(self, view: ControlView, settled: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Signed speed along its own axis for each settled skid that stands in another's way,
        and which settled skids are standing aside (making room, or waiting aside while their
        own spot is in the way).

        The corridors are the paths (rear to ``room_lookahead_m`` ahead) of the skids on the
        move and the walks of people, widened by the mover's half-width plus
        ``room_clearance_m``. A settled skid inside one drives along its axis to the nearer
        side that is clear of every corridor and of static solids, keeping the side it chose
        while it stays in the way.
        """
        p = self.params
        n = len(view.poses)
        speed = np.zeros(n)
        aside = np.zeros(n, dtype=bool)
        corridors = []
        movers = np.flatnonzero(view.active & ~settled)
        for j in movers:
            line = self._path_ahead(view, j, p.room_lookahead_m)
            half = view.footprints[j].width_m / 2 + p.room_clearance_m
            corridors.append(shapely.LineString(line).buffer(half, cap_style="flat"))
            # The skid itself as it stands (it may be turning on the spot).
            corridors.append(shapely.Polygon(self._corners_now(view, j)).buffer(p.room_clearance_m))
        walking = np.linalg.norm(view.people_vel, axis=1) > 1e-6 if len(view.people_xy) else []
        for k in np.flatnonzero(walking):
            v = view.people_vel[k]
            ahead = view.people_xy[k] + v / np.linalg.norm(v) * p.room_lookahead_m
            half = view.people_radius[k] + p.room_clearance_m
            corridors.append(shapely.LineString([view.people_xy[k], ahead]).buffer(half))
        cand = (
            np.flatnonzero(settled & ~view.stopped)
            if view.stopped is not None
            else np.flatnonzero(settled)
        )
        if not corridors or not len(cand):
            for i in cand:
                self._robots[i].room_side = 0
            return speed, aside
        way = shapely.union_all(corridors)
        shapely.prepare(way)
        feet = shapely.polygons(footprint_corners(view.poses[cand], self._plain[cand]))
        inside = shapely.intersects(way, feet)
        self._static_points(view)
        steps = np.arange(1, 41) * 0.05
        shifts = np.concatenate([steps, -steps])  # candidate moves along the axis, m
        # Skids that stood aside wait there while their own spot is still in the way.
        goal_feet = shapely.polygons(footprint_corners(view.goals[cand], self._plain[cand]))
        spot_taken = shapely.intersects(way, goal_feet)
        for i, hit, taken in zip(cand, inside, spot_taken, strict=True):
            nav = self._robots[i]
            if not hit:
                if nav.room_side and taken:
                    aside[i] = True
                else:
                    nav.room_side = 0
                continue
            head = np.array([np.cos(view.poses[i, 2]), np.sin(view.poses[i, 2])])
            poses = np.repeat(view.poses[i][None], len(shifts), axis=0)
            poses[:, :2] += shifts[:, None] * head
            moved = shapely.polygons(footprint_corners(poses, self._plain[[i] * len(shifts)]))
            free = ~shapely.intersects(way, moved)
            blocked, _ = self._static_tree.query(moved, predicate="intersects")
            free[blocked] = False
            best = None
            for side in ([nav.room_side] if nav.room_side else []) + [1, -1]:
                ok = np.flatnonzero(free & (np.sign(shifts) == side))
                if len(ok):
                    t = shifts[ok[np.argmin(np.abs(shifts[ok]))]]
                    if best is None or (side == nav.room_side) or abs(t) < abs(best):
                        best = t
                    if side == nav.room_side:
                        break
            aside[i] = True
            if best is None:
                continue
            nav.room_side = int(np.sign(best))
            nav.docked = False  # dock again precisely once the way is clear
            speed[i] = np.clip(
                p.room_gain * (best + np.sign(best) * 0.05), -view.max_speed[i], view.max_speed[i]
            )
        return speed, aside

    def _deadlock_recovery(self, view: ControlView, settled: np.ndarray) -> np.ndarray:
        """Detect and resolve deadlocks between skids on the move (RVO); returns the
        priority bumps.

        A skid with an unreached goal that has not come ``rvo_progress_m`` closer for
        ``rvo_stuck_s`` is deadlocked (symmetric jams, where every ORCA solution is to wait).
        The recovery escalates while it stays stuck:

        1. a priority bump of ``rvo_bump`` plus up to one more the nearer it is to its goal,
           so the jam is ordered (nearest first, whatever the robots' order) and the others
           make way;
        2. every further ``rvo_stuck_s``, a side step: for ``rvo_sidestep_s`` its preferred
           velocity points to the right of its path (:meth:`_orca`);
        3. when it has been held still for ``stall_s`` (typically by the collision monitor,
           when ORCA's holonomic centre asks for a turn its corners have no room for), it
           backs out straight along its axis, away from the skid nearest it, for
           ``backup_m``.

        The recovery ends when the skid makes progress again. Each episode is recorded in
        :attr:`recoveries` with the actions taken and the time it took to clear.
        """
        p = self.params
        bump = np.zeros(len(view.poses))
        remaining = np.linalg.norm(view.goals[:, :2] - view.poses[:, :2], axis=1) + 0.3 * np.abs(
            wrap_angle(view.goals[:, 2] - view.poses[:, 2])
        )
        for i in range(len(view.poses)):
            nav = self._robots[i]
            if view.goal_changed[i] or not view.active[i] or settled[i]:
                nav.best_remaining, nav.best_t = remaining[i], view.t
                nav.sidestep_until, nav.backout_left = -np.inf, 0.0
                if nav.recovery is not None and (not view.active[i] or settled[i]):
                    self._close_recovery(nav, view.t)
                continue
            if remaining[i] < nav.best_remaining - p.rvo_progress_m:
                nav.best_remaining, nav.best_t = remaining[i], view.t
                if nav.recovery is not None:
                    self._close_recovery(nav, view.t)
            stuck_for = view.t - nav.best_t
            if stuck_for < p.rvo_stuck_s:
                continue
            if nav.recovery is None:
                nav.recovery = {
                    "robot": i,
                    "start_s": round(view.t, 3),
                    "actions": ["priority bump"],
                }
                self.recoveries.append(nav.recovery)
            bump[i] = p.rvo_bump * (1.0 + 1.0 / (1.0 + remaining[i]))
            acts = nav.recovery["actions"]
            if nav.backout_left <= 0 and nav.stalled_s >= p.stall_s:
                nav.backout_left = p.backup_m
                nav.backout_dir = self._away_from_nearest(view, i)
                nav.stalled_s = 0.0
                acts.append("back out")
            elif (
                nav.backout_left <= 0
                and p.rvo_sidestep_s > 0
                and view.t >= nav.sidestep_until + p.rvo_stuck_s
                and stuck_for >= 2 * p.rvo_stuck_s
            ):
                nav.sidestep_until = view.t + p.rvo_sidestep_s
                acts.append("side step")
        return bump

    @staticmethod
    def _axis_away(view: ControlView, i: int, j: int) -> float:
        """+1 or -1: the direction along skid ``i``'s axis away from skid ``j``."""
        away = view.poses[i, :2] - view.poses[j, :2]
        th = view.poses[i, 2]
        return float(np.sign(away[0] * np.cos(th) + away[1] * np.sin(th) + 1e-9))

    def _away_from_nearest(self, view: ControlView, i: int) -> float:
        """+1 or -1: the direction along skid ``i``'s axis away from the nearest other skid."""
        others = np.delete(np.arange(len(view.poses)), i)
        if not len(others):
            return -1.0
        d = np.linalg.norm(view.poses[others, :2] - view.poses[i, :2], axis=1)
        return self._axis_away(view, i, int(others[np.argmin(d)]))

    @staticmethod
    def _close_recovery(nav: _RobotNav, t: float) -> None:
        nav.recovery["cleared_after_s"] = round(t - nav.recovery["start_s"], 3)
        nav.recovery = None
        nav.sidestep_until, nav.backout_left = -np.inf, 0.0

    def _corners_now(self, view: ControlView, i: int) -> np.ndarray:
        return footprint_corners(view.poses[i][None], self._plain[i][None])[0]

    def _orca(
        self, view: ControlView, raw: np.ndarray, cruising: np.ndarray, aims: np.ndarray
    ) -> np.ndarray:
        """ORCA with priorities on every skid's effective centre (see :mod:`.rvo`).

        Skids following a path (``cruising``, with lookahead points ``aims``) prefer to move
        their effective centre straight at the lookahead point at full speed (RVO's
        preferred velocity); near the goal the field's and the docking command is the
        preferred velocity, as it is without RVO. Skids that have reached their goal
        (``settled``) take ``parked_priority`` and move only along their own axis: they make
        room for skids on the move and people (:meth:`_make_room`, at ``room_priority``),
        yield to everyone, and dock back afterwards. Stopped skids and skids without orders
        are immobile: everyone else takes the full share against them. Deadlocked skids get
        the recoveries of :meth:`_deadlock_recovery`: a skid side-stepping prefers the right
        of its path, one backing out moves only along its axis, like a settled skid.
        """
        from swarmpark.control.orca.kernel import (
            OrcaParams,
            effective_reach,
            holonomic_speed_limit,
            holonomic_to_unicycle,
            orca_step,
            prepare_obstacles,
            skid_shapes,
            tracking_error_bound,
            unicycle_to_holonomic,
        )

        p = self.params
        self._outlines(view)
        if getattr(self, "_orca_key", None) != id(view.static_pieces):
            # Static pieces are convex (triangles and squares padded to 4 corners).
            pieces = [np.unique(pc, axis=0) for pc in view.static_pieces]
            polys = []
            for pc in pieces:
                c = pc.mean(axis=0)
                order = np.argsort(np.arctan2(pc[:, 1] - c[1], pc[:, 0] - c[0]))
                polys.append(pc[order])
            self._orca_obstacles = prepare_obstacles(polys)
            self._orca_key = id(view.static_pieces)
        d = view.max_speed / view.max_yaw_rate  # effective centre: full speed is reachable
        u_lim = holonomic_speed_limit(view.max_speed, view.max_yaw_rate, d)
        err = tracking_error_bound(
            u_lim, view.max_yaw_rate, effective_reach(self._plain, d), view.dt
        )
        h = np.column_stack([np.cos(view.poses[:, 2]), np.sin(view.poses[:, 2])])
        u_now = unicycle_to_holonomic(view.poses, view.vel[:, 0], view.vel[:, 1], offset_m=d)
        u_pref = unicycle_to_holonomic(view.poses, raw[:, 0], raw[:, 1], offset_m=d)
        immobile = ~view.active
        if view.stopped is not None:
            immobile |= view.stopped
        settled = np.array([r.settled for r in self._robots], dtype=bool) & ~immobile
        room, aside = self._make_room(view, settled)
        self.making_room = aside
        # Settled skids move along their axis only: turning in a tight formation would sweep
        # their corners into their neighbours.
        along_pref = np.where(aside, room, raw[:, 0])
        u_pref[settled] = along_pref[settled, None] * h[settled]
        # Skids on the move keep a little more room (rvo_margin_m) than the tracking bound:
        # their turns lag the command by the yaw acceleration limit. Parked ones only move
        # straight and sit close together, so they keep the bound alone.
        margin = err + np.where(settled | immobile, 0.0, p.rvo_margin_m)
        centres, shapes = skid_shapes(view.poses, self._plain, offset_m=d, margin_m=margin)
        bump = self._deadlock_recovery(view, settled)
        steered = np.zeros(len(view.poses), dtype=bool)  # preferred velocity turned off the path
        if len(cruising):
            to_aim = aims[:, :2] - centres[cruising]
            dist = np.linalg.norm(to_aim, axis=1, keepdims=True)
            u_pref[cruising] = to_aim / np.maximum(dist, 1e-9) * u_lim[cruising, None]
            movers = ~settled & ~immobile & view.active
            prio_now = view.priority + bump
            turn = self._keep_right(view, centres, u_pref, prio_now, cruising, movers)
            side = np.array([view.t < self._robots[i].sidestep_until for i in cruising], bool)
            turn[side] = np.pi / 2
            u_pref[cruising] = np.einsum("nij,nj->ni", rotation(-turn), u_pref[cruising])
            steered[cruising] = turn != 0
        # Backing out (a recovery): straight along the axis at half speed.
        backing = np.array([r.backout_left > 0 for r in self._robots], dtype=bool) & ~immobile
        for i in np.flatnonzero(backing):
            u_pref[i] = self._robots[i].backout_dir * 0.5 * view.max_speed[i] * h[i]
        prio = np.where(settled, p.parked_priority, view.priority + bump)
        prio = np.where(room != 0, p.room_priority, prio)
        on_axis = settled | backing
        axes = np.where(on_axis[:, None], h, np.nan)
        res = orca_step(
            centres,
            u_now,
            u_pref,
            u_lim,
            prio,
            shapes,
            dt_s=view.dt,
            params=OrcaParams(min_share=p.rvo_min_share, time_horizon_s=p.rvo_horizon_s),
            immobile=immobile,
            people_positions=view.people_xy,
            people_velocities=view.people_vel,
            people_radii=view.people_radius,
            obstacles=self._orca_obstacles,
            axes=axes,
        )
        v, w = holonomic_to_unicycle(
            view.poses,
            res.velocities,
            offset_m=d,
            v_max=view.max_speed,
            omega_max=view.max_yaw_rate,
        )
        out = np.column_stack([v, w])
        along = np.clip(np.einsum("ij,ij->i", res.velocities, h), -view.max_speed, view.max_speed)
        out[on_axis] = np.column_stack([along, np.zeros_like(along)])[on_axis]
        for i in np.flatnonzero(settled & (np.abs(along) > 1e-3)):
            self._robots[i].docked = False  # pushed aside: dock again precisely afterwards
        for i in np.flatnonzero(backing):
            nav = self._robots[i]
            nav.backout_left -= abs(view.vel[i, 0]) * view.dt
            if nav.stalled_s >= p.stall_s:  # backing out is blocked too
                nav.backout_left = 0.0
        # Pure turns in place (u = 0 at the centre would drop them) pass through when ORCA
        # left the preferred velocity unchanged (and it was the path's, not kept right).
        same = (np.linalg.norm(res.velocities - u_pref, axis=1) < 1e-9) & ~on_axis & ~steered
        out[same] = raw[same]
        out[immobile] = 0.0
        return out

    def _keep_right(
        self,
        view: ControlView,
        centres: np.ndarray,
        u_pref: np.ndarray,
        prio: np.ndarray,
        cruising: np.ndarray,
        movers: np.ndarray,
    ) -> np.ndarray:
        """Clockwise turn (rad) of each cruising skid's preferred velocity where another skid
        on the move within ``rvo_keep_right_range_m`` ahead comes the other way (their
        preferred velocities more than 90 degrees apart), else 0.

        The turn is ``rvo_keep_right_rad`` times twice the skid's largest ORCA share against
        those skids (:func:`.rvo.responsibility_shares`), at most 90 degrees: between equal
        priorities each turns ``rvo_keep_right_rad``, and the lower priority turns more.
        """
        from swarmpark.control.orca.kernel import responsibility_shares

        p = self.params
        turn = np.zeros(len(cruising))
        if p.rvo_keep_right_rad == 0 or movers.sum() < 2:
            return turn
        others = np.flatnonzero(movers)
        near = cKDTree(centres[others]).query_ball_point(
            centres[cruising], p.rvo_keep_right_range_m
        )
        for k, (i, cand) in enumerate(zip(cruising, near, strict=True)):
            j = others[cand]
            j = j[j != i]
            ahead = (centres[j] - centres[i]) @ u_pref[i] > 0
            oncoming = u_pref[j] @ u_pref[i] < 0
            meet = j[ahead & oncoming]
            if len(meet):
                share = responsibility_shares(prio[i], prio[meet], p.rvo_min_share).max()
                turn[k] = min(2.0 * share * p.rvo_keep_right_rad, np.pi / 2)
        self._static_points(view)
        if self._static_kd is not None and turn.any():
            clear, _ = self._static_kd.query(centres[cruising], distance_upper_bound=100.0)
            fade = (clear - p.rvo_keep_right_tight_m) / (
                p.rvo_keep_right_open_m - p.rvo_keep_right_tight_m
            )
            turn *= np.clip(fade, 0.0, 1.0)
        return turn

    def _within_margin(self, view: ControlView, idx: np.ndarray, grown: np.ndarray) -> np.ndarray:
        """Skids whose grown footprint overlaps a static solid or another skid right now."""
        corners = footprint_corners(view.poses[idx], grown)
        out = np.zeros(len(idx), dtype=bool)
        lo, hi = corners.min(axis=1), corners.max(axis=1)
        qi, si = self._static_tree.query(shapely.box(lo[:, 0], lo[:, 1], hi[:, 0], hi[:, 1]))
        if len(qi):
            hit = convex_overlap(corners[qi], view.static_pieces[si]) > TOUCH_TOLERANCE_M
            out[qi[hit]] = True
        others = footprint_corners(view.poses, self._plain)
        ia, ib = np.meshgrid(np.arange(len(idx)), np.arange(len(view.poses)), indexing="ij")
        ia, ib = ia.ravel(), ib.ravel()
        near = np.linalg.norm(view.poses[idx[ia], :2] - view.poses[ib, :2], axis=1) < 3.0
        near &= idx[ia] != ib
        ia, ib = ia[near], ib[near]
        if len(ia):
            hit = convex_overlap(corners[ia], others[ib]) > TOUCH_TOLERANCE_M
            out[ia[hit]] = True
        return out
