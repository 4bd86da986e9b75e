"""Executing a formation plan on skids: plan once, track the reference, yield to obstacles.

Builds a :class:`~swarmpark.control.formation.problem.FormationProblem` from the skids' poses and a
formation command, solves it once (IPOPT, deterministic), and each tick turns the reference
(with the online stop-and-wait / reverse modification of Sect. II.D applied when a person
comes near the group) into ``(v, omega)`` by Kanayama's tracking law. It records what the
run result needs: the formation error of the actual poses and the reference distances.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from swarmpark.control.formation import (
    FormationProblem,
    OnlineAdjuster,
    TrackingGains,
    formation_metrics,
    plan_velocities,
    sample_reference,
    track_unicycle,
)
from swarmpark.core.geometry import Footprint, rotation
from swarmpark.core.paths import SplinePath

__all__ = ["FormationRun", "FormationError"]

#: People farther than this from every robot of the group are not watched.
WATCH_RANGE_M = 5.0
#: Keep the plan's speed and acceleration this far inside the skids' limits, so the tracking
#: law has room to correct errors.
LIMIT_SHARE = 0.8


class FormationError(ValueError):
    """A formation command that cannot be planned (bad offsets, infeasible in time)."""


#: Spacing of the waypoints of derived follower paths (m).
FOLLOWER_WAYPOINT_STEP_M = 0.5


def _last_heading(pts: np.ndarray) -> float:
    """Paths end heading along their last waypoint segment (no overshoot past the end)."""
    d = pts[-1] - pts[-2]
    return float(np.arctan2(d[1], d[0]))


def _follower_waypoints(leader_wps: np.ndarray, poses: np.ndarray, offsets: np.ndarray):
    """Waypoints for every robot when only the leader's path is given: each follower's path
    is the leader's path carried at its offset in the leader's frame (the first keypoint's
    offset when offsets change along the way; the optimizer blends to the others)."""
    if np.linalg.norm(leader_wps[0] - poses[0, :2]) > 0.01:
        leader_wps = np.vstack([poses[0, :2], leader_wps])
    try:
        lead = SplinePath.through(
            leader_wps,
            start_heading=float(poses[0, 2]),
            end_heading=_last_heading(leader_wps),
            field_name="formation.paths[0]",
        )
    except ValueError as exc:
        raise FormationError(str(exc)) from None
    s = np.linspace(0, lead.length_m, max(int(lead.length_m / FOLLOWER_WAYPOINT_STEP_M), 2) + 1)
    lp = lead.pose(s)  # (S, 3)
    off = offsets if offsets.ndim == 2 else offsets[:, 0]
    out = [leader_wps]
    for dx, dy in off:
        c, sn = np.cos(lp[:, 2]), np.sin(lp[:, 2])
        out.append(np.column_stack([lp[:, 0] + c * dx - sn * dy, lp[:, 1] + sn * dx + c * dy]))
    return out


@dataclass
class FormationRun:
    """One group moving in formation; ``idx`` are the robots' indices in the fleet."""

    idx: np.ndarray
    problem: FormationProblem
    t0: float
    adjuster: OnlineAdjuster
    times: list[float] = field(default_factory=list)
    poses: list[np.ndarray] = field(default_factory=list)
    ref_s: list[np.ndarray] = field(default_factory=list)

    @classmethod
    def start(
        cls,
        idx: np.ndarray,
        poses: np.ndarray,
        footprints: list[Footprint],
        max_speed: np.ndarray,
        max_accel: np.ndarray,
        cmd,
        t0: float,
    ) -> FormationRun:
        """Plan the command from the current ``poses`` (raises :class:`FormationError`)."""
        n = len(idx)
        if cmd.offsets_m is None:
            # Hold the starting shape: followers' positions in the leader's frame.
            offsets = (poses[1:, :2] - poses[0, :2]) @ rotation(poses[0, 2])  # R^T, row-wise
        else:
            offsets = np.asarray(cmd.offsets_m, float)
            want = (n - 1, 2) if offsets.ndim == 2 else (n - 1, offsets.shape[1], 2)
            if offsets.shape != want:
                raise FormationError(
                    f"formation.offsets_m: need one [dx, dy] per follower ({n - 1}), "
                    f"or one per keypoint, got shape {list(offsets.shape)}"
                )
        waypoints = [np.asarray(w, float) for w in cmd.paths]
        if len(waypoints) == 1:
            waypoints = _follower_waypoints(waypoints[0], poses, offsets)
        paths = []
        for k, pts in enumerate(waypoints):
            if np.linalg.norm(pts[0] - poses[k, :2]) > 0.01:
                pts = np.vstack([poses[k, :2], pts])
            try:
                paths.append(
                    SplinePath.through(
                        pts,
                        start_heading=float(poses[k, 2]),
                        end_heading=_last_heading(pts),
                        field_name=f"formation.paths[{k}]",
                    )
                )
            except ValueError as exc:
                raise FormationError(str(exc)) from None
        edges = np.array([[0, j] for j in range(1, n)], dtype=int)
        offset_at = None if cmd.offset_at is None else np.asarray(cmd.offset_at, float)
        v_max = float(np.min(max_speed)) * LIMIT_SHARE
        a_max = float(np.min(max_accel)) * LIMIT_SHARE
        lengths = np.array([p.length_m for p in paths])
        steps = cmd.steps
        if steps is None:
            # Room for the longest path at 2/3 of the speed bound, plus speeding up and down.
            steps = max(4, math.ceil((1.5 * lengths.max() / v_max + 2 * v_max / a_max) / cmd.dt_s))
        d_safe = cmd.d_safe_m or 2.0 * max(f.circumradius_m for f in footprints)
        try:
            problem = FormationProblem(
                paths=tuple(paths),
                edges=edges,
                offsets_m=offsets,
                offset_at=offset_at,
                M=int(steps),
                dt_s=cmd.dt_s,
                v_max_mps=v_max,
                a_max_mps2=a_max,
                d_safe_m=d_safe,
            )
            plan = plan_velocities(problem, cmd.method)
        except ValueError as exc:
            raise FormationError(f"formation: {exc}") from None
        if not plan.success:
            raise FormationError(f"formation: the {cmd.method} plan failed ({plan.status})")
        adj = OnlineAdjuster(plan, min_watch_s=min(3.0, cmd.dt_s * 3), d_obs_m=d_safe)
        return cls(np.asarray(idx, int), problem, t0, adj)

    @property
    def goals(self) -> np.ndarray:
        """Final pivot poses: the path ends, heading along the path."""
        return np.stack([p.pose(p.length_m) for p in self.problem.paths])

    def command(
        self,
        t: float,
        poses: np.ndarray,
        people_xy: np.ndarray,
        max_speed: np.ndarray,
        max_yaw_rate: np.ndarray,
    ) -> np.ndarray:
        """``(v, omega)`` for the group's robots at fleet time ``t``."""
        tau = t - self.t0
        if len(people_xy):
            d = np.linalg.norm(people_xy[:, None, :] - poses[None, :, :2], axis=-1).min(axis=1)
            j = int(np.argmin(d))
            if d[j] < WATCH_RANGE_M:
                self.adjuster.observe(tau, people_xy[j])
        self.adjuster.update(tau)
        ref = sample_reference(self.adjuster.plan, tau)
        v, w = track_unicycle(poses, ref.poses, ref.v, ref.omega, TrackingGains())
        self.times.append(tau)
        self.poses.append(poses.copy())
        self.ref_s.append(np.asarray(ref.s, float))
        return np.column_stack(
            [np.clip(v, -max_speed, max_speed), np.clip(w, -max_yaw_rate, max_yaw_rate)]
        )

    def metrics(self) -> dict:
        if len(self.times) < 2:
            return {}
        fm = formation_metrics(
            self.problem, np.asarray(self.times), np.stack(self.poses), np.stack(self.ref_s)
        )
        return {
            "method": self.adjuster.plan.method,
            "integral_m2s": round(fm.integral_m2s, 6),
            "q_e_m2": round(fm.q_e_m2, 6),
            "max_pair_error_m": round(fm.max_pair_error_m, 4),
            "plan_duration_s": round(float(self.adjuster.plan.duration_s), 3),
        }
