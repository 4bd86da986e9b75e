"""Run metrics: success, time to park, collisions, clearance, path length, deadlocks, bounds.

:class:`MetricsRecorder` is fed once per tick with the state after the step and produces the
result dictionary of the ``swarmpark run --json`` contract. Wall-clock tick times are measured
by the runner and passed in; nothing here reads a clock.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from swarmpark.assign import AssignmentError, bottleneck_assignment
from swarmpark.core.activity import ACTIVITIES
from swarmpark.core.geometry import point_segment_distance, wrap_angle
from swarmpark.core.gridmap import OccupancyGrid
from swarmpark.core.progress import (
    REPORT_HEADING_LEVER_M,
    REPORT_PROGRESS_M,
    made_progress,
    remaining_m,
)
from swarmpark.plan.grid import build_costmap, path_length_matrix
from swarmpark.plan.spot_reach import as_report

__all__ = [
    "POSITION_TOL_M",
    "HEADING_TOL_RAD",
    "DEADLOCK_WINDOW_S",
    "LOST_TIME",
    "MetricsRecorder",
    "lower_bound_s",
]

POSITION_TOL_M = 0.10
HEADING_TOL_RAD = np.deg2rad(5.0)
#: A robot with an unreached goal and no progress for this long is in deadlock.
DEADLOCK_WINDOW_S = 10.0
#: Progress (defined in core.progress): the remaining distance, heading counted at this lever
#: arm (m per rad), fell by at least this much below its best so far.
HEADING_LEVER_M = REPORT_HEADING_LEVER_M
PROGRESS_M = REPORT_PROGRESS_M
#: What the time a robot loses against its top speed on the way to its goal is put down
#: to (the run result's ``time_lost_s``): the controller's activities
#: (:data:`~swarmpark.core.activity.ACTIVITIES`: held by the fill order, queued at a
#: bottleneck, manoeuvring, held by the collision monitor, making room) and otherwise
#: ``parking`` within :data:`LOST_NEAR_M` of its goal, ``in_traffic`` with another robot
#: within :data:`LOST_NEAR_M`, else ``driving`` (turning, accelerating, a curve).
LOST_TIME = (*ACTIVITIES, "parking", "in_traffic")
_LOST = {name: k for k, name in enumerate(LOST_TIME)}
LOST_NEAR_M = 2.0
#: Above this many goals the lower bound uses straight-line distances (no Dijkstra runs).
LOWER_BOUND_PATH_GOALS = 30
#: Largest ratio of an 8-connected grid path length to the Euclidean length it stands for.
OCTILE_RATIO = float(np.hypot(1.0, np.sqrt(2.0) - 1.0))


@dataclass
class Deadlock:
    """A deadlock episode: a robot with an unreached goal and no progress since ``start_s``
    (reported once that has lasted :data:`DEADLOCK_WINDOW_S`, so every reported episode is a
    defect), until progress or a pause ends it, and what the controller said held it when it
    was reported (``cause``), with where it stood then (``pose``, x, y, heading in rad) and
    how far from its goal (``goal_distance_m``): at its spot, or held up on the way."""

    robot: str
    start_s: float
    end_s: float | None = None
    resolved_by: str | None = None
    cause: str | None = None
    pose: tuple[float, float, float] | None = None
    goal_distance_m: float | None = None

    def as_dict(self) -> dict:
        dur = None if self.end_s is None else round(self.end_s - self.start_s, 3)
        return {
            "robot": self.robot,
            "start_s": round(self.start_s, 3),
            "end_s": None if self.end_s is None else round(self.end_s, 3),
            "cleared_after_s": dur,
            "resolved_by": self.resolved_by,
            "cause": self.cause,
            "pose": None if self.pose is None else _pose_deg(self.pose),
            "goal_distance_m": None
            if self.goal_distance_m is None
            else round(self.goal_distance_m, 3),
        }


def _pose_deg(pose) -> list[float]:
    """A pose (x, y in m, heading in rad) as the run result gives it: heading in degrees."""
    return [
        round(float(pose[0]), 4),
        round(float(pose[1]), 4),
        round(float(np.rad2deg(pose[2])), 3),
    ]


def goal_errors(poses: np.ndarray, goals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Position error (m) and absolute heading error (rad) of poses against goals."""
    pos = np.linalg.norm(poses[:, :2] - goals[:, :2], axis=1)
    head = np.abs(wrap_angle(poses[:, 2] - goals[:, 2]))
    return pos, head


@dataclass
class MetricsRecorder:
    ids: list[str]
    start_poses: np.ndarray
    path_length: np.ndarray = field(init=False)
    collisions: list[dict] = field(default_factory=list)
    min_clearance_robot: float = np.inf
    min_clearance_static: float = np.inf
    first_goal_s: float | None = None
    #: What holds robot ``i`` up, asked when a deadlock is reported (the supervisor sets it
    #: from the controller); None: the cause is not reported.
    explain: Callable[[int], str] | None = None
    #: ``(N,)`` each robot's top speed (m/s), for the time lost against it; None: not kept.
    max_speed_mps: np.ndarray | None = None

    def __post_init__(self) -> None:
        n = len(self.ids)
        # The lower bound is not needed to act: the inputs of each park command are kept and
        # it is computed (once) when asked for, outside the control tick.
        self._bound_inputs: list[tuple] = []
        self._spot_checks: list[tuple] = []
        self._spots: list[dict] = []
        self._bound: float | None = None
        self.path_length = np.zeros(n)
        self._prev = np.asarray(self.start_poses, float).copy()
        self._commanded = np.zeros(n, dtype=bool)
        self._entered = np.full(n, np.nan)  # when the robot last entered its goal tolerance
        self._best = np.full(n, np.inf)  # best remaining distance since the last progress
        self._best_t = np.zeros(n)
        self._deadlock: list[Deadlock | None] = [None] * n
        self.deadlocks: list[Deadlock] = []
        self.tick_ms: list[float] = []
        # The straight leg from where each robot got its goal to the goal, and the largest
        # distance of the robot from it since (the detour it took).
        self._leg = np.repeat(self._prev[:, None, :2], 2, axis=1)
        self._lateral = np.zeros(n)
        self._t = 0.0
        self._lost = np.zeros((n, len(LOST_TIME)))

    def defer_lower_bound(
        self,
        grid: OccupancyGrid,
        starts: np.ndarray,
        goals: np.ndarray,
        inscribed_m: float,
        max_speed_mps: np.ndarray,
    ) -> None:
        """Keep the inputs of :func:`lower_bound_s` for a park command (copies); the bound
        is computed lazily by :attr:`lower_bound`, not inside the control tick."""
        if self._bound is not None:
            return
        self._bound_inputs.append(
            (
                grid,
                np.array(starts, float),
                np.array(goals, float),
                float(inscribed_m),
                np.array(max_speed_mps, float),
            )
        )

    def defer_spot_check(self, t_s: float, check: Callable[[], list]) -> None:
        """Keep the manoeuvre check of a park command's spots (``check()`` gives the
        :class:`~swarmpark.plan.spot_reach.SpotReach` flags), run by
        :attr:`unreachable_spots` after the run, not inside the control tick."""
        self._spot_checks.append((float(t_s), check))

    @property
    def unreachable_spots(self) -> list[dict]:
        """The spots of the run's park commands that no manoeuvre reaches in fill order, each
        with the time of its command (``t_s``); each check runs once, on first use."""
        while self._spot_checks:
            t_s, check = self._spot_checks.pop(0)
            self._spots += [{"t_s": round(t_s, 3), **f} for f in as_report(check())]
        return list(self._spots)

    @property
    def lower_bound(self) -> float | None:
        """:func:`lower_bound_s` of the first park command that has one (None if none has),
        computed on first use."""
        while self._bound is None and self._bound_inputs:
            self._bound = lower_bound_s(*self._bound_inputs.pop(0))
        return self._bound

    def on_goal(self, t: float, idx: np.ndarray, goals: np.ndarray | None = None) -> None:
        """Robots ``idx`` got a new goal at time ``t`` (``goals``: their poses, if known)."""
        idx = np.atleast_1d(idx)
        if goals is not None:
            self._leg[idx, 0] = self._prev[idx, :2]
            self._leg[idx, 1] = np.asarray(goals, float).reshape(-1, 3)[:, :2]
            self._lateral[idx] = 0.0
        if self.first_goal_s is None and len(idx):
            self.first_goal_s = t
        self._commanded[idx] = True
        self._entered[idx] = np.nan
        self._best[idx] = np.inf
        self._best_t[idx] = t

    def on_step(
        self,
        t: float,
        poses: np.ndarray,
        goals: np.ndarray,
        has_goal: np.ndarray,
        paused: np.ndarray,
        step,
        activity: np.ndarray | None = None,
    ) -> None:
        """Record the state after one step (``paused``: stopped or e-stopped robots;
        ``activity``: what the controller had each robot do, codes into
        :data:`~swarmpark.core.activity.ACTIVITIES`)."""
        moved = np.linalg.norm(poses[:, :2] - self._prev[:, :2], axis=1)
        self.path_length += moved
        off_leg = point_segment_distance(poses[:, :2], self._leg[:, 0], self._leg[:, 1])
        self._lateral = np.maximum(self._lateral, off_leg)
        self._prev = poses.copy()
        for c in step.new_contacts:
            self.collisions.append(c.as_dict())
        if step.clearance_robot_m is not None and len(poses) > 1:
            self.min_clearance_robot = min(
                self.min_clearance_robot, float(step.clearance_robot_m.min())
            )
        if step.clearance_static_m is not None and len(poses):
            self.min_clearance_static = min(
                self.min_clearance_static, float(step.clearance_static_m.min())
            )

        # Parking: when did each robot last enter its tolerance.
        pos_err, head_err = goal_errors(poses, np.where(has_goal[:, None], goals, poses))
        inside = has_goal & (pos_err <= POSITION_TOL_M) & (head_err <= HEADING_TOL_RAD)
        newly = inside & np.isnan(self._entered)
        self._entered[newly] = t
        self._entered[~inside] = np.nan
        self._lose_time(t, poses, moved, has_goal & ~inside, pos_err, activity)

        # Deadlocks: an unreached goal and no progress for DEADLOCK_WINDOW_S.
        remaining = remaining_m(pos_err, head_err, HEADING_LEVER_M)
        improved = made_progress(remaining, self._best, PROGRESS_M)
        reset = improved | paused | inside | ~has_goal
        self._best = np.where(reset, remaining, self._best)
        self._best_t = np.where(reset, t, self._best_t)
        # Only the skids whose state changes are visited (in index order, as one loop would).
        open_ = self.stuck()
        starts = ~open_ & (t - self._best_t >= DEADLOCK_WINDOW_S) & has_goal
        ends = open_ & reset
        for i in np.flatnonzero(starts | ends).tolist():
            dl = self._deadlock[i]
            if dl is None:
                dl = Deadlock(
                    self.ids[i],
                    float(self._best_t[i]),
                    cause=None if self.explain is None else self.explain(i),
                    pose=tuple(float(v) for v in poses[i, :3]),
                    goal_distance_m=float(pos_err[i]),
                )
                self._deadlock[i] = dl
                self.deadlocks.append(dl)
            else:
                dl.end_s = t
                dl.resolved_by = "progress" if improved[i] or inside[i] else "paused"
                self._deadlock[i] = None

    def moved_by_hand(self, i: int, pose: np.ndarray) -> None:
        """Robot ``i`` was carried to ``pose``: the jump is not driven path length."""
        self._prev[i] = np.asarray(pose, float)

    def _lose_time(self, t, poses, moved, going, pos_err, activity) -> None:
        """Add each robot ``going`` to its goal's time lost this step against its top speed,
        ``dt * (1 - speed / top speed)``, to what it was doing (:data:`LOST_TIME`)."""
        dt, self._t = t - self._t, t
        if self.max_speed_mps is None or dt <= 0.0 or not going.any():
            return
        rows = np.flatnonzero(going)
        speed = moved[rows] / dt
        lost = dt * (1.0 - np.clip(speed / self.max_speed_mps[rows], 0.0, 1.0))
        cat = np.zeros(len(rows), dtype=int)  # driving
        tree = cKDTree(poses[:, :2])
        near = tree.query_ball_point(poses[rows, :2], LOST_NEAR_M, return_length=True) > 1
        cat[near] = _LOST["in_traffic"]
        cat[pos_err[rows] < LOST_NEAR_M] = _LOST["parking"]
        if activity is not None:
            act = np.asarray(activity)[rows]
            mine = act > 0
            cat[mine] = [_LOST[ACTIVITIES[a]] for a in act[mine]]
        np.add.at(self._lost, (rows, cat), lost)

    @property
    def time_lost(self) -> dict[str, float]:
        """Seconds lost against top speed by all robots together, per :data:`LOST_TIME`."""
        total = self._lost.sum(axis=0)
        return {name: round(float(v), 3) for name, v in zip(LOST_TIME, total, strict=True)}

    def stuck(self) -> np.ndarray:
        """Robots currently in a deadlock."""
        return np.array([d is not None for d in self._deadlock], dtype=bool)

    def parked(self) -> np.ndarray:
        return ~np.isnan(self._entered)

    def fleet_collisions(self) -> list[dict]:
        """Contacts the fleet caused: all but a person walking into a skid standing still."""
        return [c for c in self.collisions if c.get("kind") != "person-robot"]

    def result(
        self, t_end: float, poses: np.ndarray, goals: np.ndarray, has_goal: np.ndarray
    ) -> dict:
        pos_err, head_err = goal_errors(poses, np.where(has_goal[:, None], goals, poses))
        cmd = self._commanded & has_goal
        parked = self.parked() & cmd
        all_parked = bool(np.all(parked[cmd])) and bool(cmd.any())
        # A person walking into a skid that stands still is reported, not counted against
        # the fleet (the simulator's kind "person-robot").
        success = all_parked and not self.fleet_collisions()
        time_to_park = None
        if all_parked and self.first_goal_s is not None:
            time_to_park = round(float(np.nanmax(self._entered[cmd])) - self.first_goal_s, 3)
        clear = min(self.min_clearance_robot, self.min_clearance_static)
        robots = {}
        for i, rid in enumerate(self.ids):
            robots[rid] = {
                "commanded": bool(cmd[i]),
                "parked": bool(parked[i]),
                "parked_at_s": None
                if np.isnan(self._entered[i])
                else round(float(self._entered[i]), 3),
                "path_length_m": round(float(self.path_length[i]), 4),
                # Largest distance from the straight line between where the robot got its
                # last goal and that goal (how far it detoured, e.g. to avoid another).
                "max_lateral_deviation_m": round(float(self._lateral[i]), 4) if cmd[i] else None,
                "final_position_error_m": round(float(pos_err[i]), 4) if has_goal[i] else None,
                "final_heading_error_deg": round(float(np.rad2deg(head_err[i])), 3)
                if has_goal[i]
                else None,
                "final_pose": _pose_deg(poses[i]),
            }
            if self.max_speed_mps is not None and cmd[i]:
                robots[rid]["time_lost_s"] = {
                    name: round(float(v), 3)
                    for name, v in zip(LOST_TIME, self._lost[i], strict=True)
                    if v > 0.0
                }
        ticks = np.asarray(self.tick_ms) if self.tick_ms else np.zeros(1)
        return {
            "success": bool(success),
            "time_to_park_s": time_to_park,
            "lower_bound_s": None if (bound := self.lower_bound) is None else round(bound, 3),
            "collisions": list(self.collisions),
            "min_clearance_m": None if not np.isfinite(clear) else round(float(clear), 4),
            "min_clearance_robot_m": None
            if not np.isfinite(self.min_clearance_robot)
            else round(self.min_clearance_robot, 4),
            "min_clearance_wall_m": None
            if not np.isfinite(self.min_clearance_static)
            else round(self.min_clearance_static, 4),
            "path_length_m": {rid: robots[rid]["path_length_m"] for rid in self.ids},
            "deadlocks": [d.as_dict() for d in self.deadlocks],
            "unreachable_spots": self.unreachable_spots,
            "time_lost_s": self.time_lost if self.max_speed_mps is not None else None,
            "tick_ms": {
                "mean": round(float(ticks.mean()), 4),
                "p99": round(float(np.percentile(ticks, 99)), 4),
            },
            "sim_time_s": round(t_end, 3),
            "robots": robots,
        }


def lower_bound_s(
    grid: OccupancyGrid,
    starts: np.ndarray,
    goals: np.ndarray,
    inscribed_m: float,
    max_speed_mps: np.ndarray,
) -> float | None:
    """Makespan a perfect swarm would need: bottleneck-optimal assignment of shortest
    free-space path lengths (each divided by that robot's max speed).

    The free space is the map inflated by ``inscribed_m`` (the smallest inscribed radius in
    the group), so every path is at most as long as one a real skid could drive: a bound.
    """
    starts = np.asarray(starts, float).reshape(-1, 3)
    goals = np.asarray(goals, float).reshape(-1, 3)
    if len(goals) > LOWER_BOUND_PATH_GOALS:
        # One Dijkstra per goal gets expensive for big groups; straight lines are a bound too.
        straight = np.linalg.norm(starts[:, None, :2] - goals[None, :, :2], axis=-1)
        try:
            return bottleneck_assignment(straight / np.asarray(max_speed_mps, float)[:, None])[1]
        except AssignmentError:
            return None
    # Rasterized walls are conservative by up to a cell, and cell-centre tests by another half:
    # inflate by less so the grid's free space contains the true one.
    radius = max(inscribed_m - 2.0 * grid.resolution_m, 0.0)
    d = path_length_matrix(build_costmap(grid, radius, radius), starts[:, :2], goals[:, :2])
    # 8-connected grid lengths exceed the true length by up to OCTILE_RATIO (and start and
    # goal cells by a cell each): shrink them so the bound stays a bound. The straight line is
    # a bound too; take the larger of the two where the grid found a path.
    straight = np.linalg.norm(starts[:, None, :2] - goals[None, :, :2], axis=-1)
    shrunk = d / OCTILE_RATIO - 2 * grid.resolution_m
    times = np.where(np.isfinite(d), np.maximum(shrunk, straight), np.inf)
    times /= np.asarray(max_speed_mps, float)[:, None]
    try:
        _, worst = bottleneck_assignment(times)
    except AssignmentError:
        return None
    return worst
