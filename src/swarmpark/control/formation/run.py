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
from swarmpark.core.geometry import (
    Footprint,
    body_corners,
    footprint_corners,
    rotation,
    wrap_angle,
)
from swarmpark.core.paths import SplinePath

__all__ = ["FormationRun", "FormationError", "first_map_conflict"]

#: People farther than this from every robot of the group are not watched.
WATCH_RANGE_M = 5.0
#: The online modification (Sect. II.D) decides at most this often (s), not every control tick:
#: one search for a wait or retreat costs up to a few hundred ms, and the plan's look-ahead
#: (H steps of the plan's dt, 5 s by default) is far longer than this latency.
REPLAN_PERIOD_S = 1.0
#: The obstacle's motion is predicted from the last this many seconds of observations (a
#: person who walked up and stopped is predicted to stand, not to keep walking).
PREDICTION_MEMORY_S = 3.0
#: Longest wait or retreat searched for (s); when none clears the obstacle the group holds
#: where it is until resuming is safe, so a longer search would only cost time.
MAX_DELAY_S = 10.0
#: Keep the plan's speed and acceleration this far inside the skids' limits, so the tracking
#: law has room to correct errors.
LIMIT_SHARE = 0.8


class FormationError(ValueError):
    """A formation command that cannot be planned (bad offsets, infeasible in time)."""


#: Spacing of the waypoints of derived follower paths (m).
FOLLOWER_WAYPOINT_STEP_M = 0.5
#: A path starts at its skid's actual pose and joins the given waypoints this far ahead of the
#: skid's projection on them (about a skid length: room to turn by a start heading error).
JOIN_AHEAD_M = 1.0
#: A skid this close to its path's first waypoint starts there (m).
AT_START_M = 0.01
#: A group starting closer than two circumradii is held at no less than this share of its
#: closest pair's starting distance (the share leaves the tracking law room to err).
START_SHARE = 0.95


def _last_heading(pts: np.ndarray) -> float:
    """Paths end heading along their last waypoint segment (no overshoot past the end)."""
    d = pts[-1] - pts[-2]
    return float(np.arctan2(d[1], d[0]))


def _join(pts: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """Waypoints that start at the skid's actual position and join ``pts`` ahead of it.

    Real skids never stand exactly at a path's first waypoint: prepending the actual position
    to the waypoints makes the spline double back whenever the skid stands a little past the
    first one, and a waypoint just ahead of it bends the spline hard to reach it. Unless the
    skid stands on the first waypoint (within :data:`AT_START_M`), its position is projected
    on the waypoint polyline and the waypoints less than :data:`JOIN_AHEAD_M` past the
    projection are dropped (the last one is always kept).
    """
    xy = np.asarray(pose[:2], float)
    if np.linalg.norm(pts[0] - xy) <= AT_START_M:
        return pts
    seg = np.diff(pts, axis=0)
    seg_len = np.linalg.norm(seg, axis=1)
    t = np.clip(np.einsum("ij,ij->i", xy - pts[:-1], seg) / np.maximum(seg_len**2, 1e-12), 0, 1)
    foot = pts[:-1] + t[:, None] * seg
    k = int(np.argmin(np.linalg.norm(foot - xy, axis=1)))
    cum = np.concatenate([[0.0], np.cumsum(seg_len)])
    s_proj = cum[k] + t[k] * seg_len[k]
    ahead = pts[cum > s_proj + JOIN_AHEAD_M]
    return np.vstack([xy, ahead if len(ahead) else pts[-1:]])


def _spline(pts: np.ndarray, pose: np.ndarray, k: int) -> SplinePath:
    """The path of robot ``k``: from its pose and heading, joining ``pts`` (see :func:`_join`)."""
    pts = _join(pts, pose)
    try:
        return SplinePath.through(
            pts,
            start_heading=float(pose[2]),
            end_heading=_last_heading(pts),
            field_name=f"formation.paths[{k}]",
        )
    except ValueError as exc:
        heading = np.degrees(abs(wrap_angle(_last_heading(pts[:2]) - float(pose[2]))))
        why = (
            f" (robot {k} faces {heading:.0f} deg away from where its path goes: turn it first)"
            if heading > 90.0
            else ""
        )
        raise FormationError(f"{exc}{why}") from None


def _follower_waypoints(leader_wps: np.ndarray, poses: np.ndarray, offsets: np.ndarray):
    """Waypoints for every robot when only the leader's path is given: each follower's path
    is the leader's path carried at its offset in the leader's frame (the first keypoint's
    offset when offsets change along the way; the optimizer blends to the others)."""
    lead = _spline(leader_wps, poses[0], 0)
    s = np.linspace(0, lead.length_m, max(int(lead.length_m / FOLLOWER_WAYPOINT_STEP_M), 2) + 1)
    lp = lead.pose(s)  # (S, 3)
    off = offsets if offsets.ndim == 2 else offsets[:, 0]
    out = [lead.waypoints]
    for dx, dy in off:
        c, sn = np.cos(lp[:, 2]), np.sin(lp[:, 2])
        out.append(np.column_stack([lp[:, 0] + c * dx - sn * dy, lp[:, 1] + sn * dx + c * dy]))
    return out


#: Spacing of the poses at which a formation's paths are checked against the map (m).
MAP_CHECK_STEP_M = 0.05


def first_map_conflict(
    paths, footprints: list[Footprint], grid
) -> tuple[int, float, np.ndarray, bool] | None:
    """The first robot whose footprint, carried along its path at the path's heading, would
    overlap an occupied cell of ``grid`` or reach off it: ``(robot, arc length (m), pose,
    off the map)``, or ``None``.

    The formation plan (Sect. II) times the robots along fixed paths and knows nothing of
    the map, so a path through a wall (a follower's path carried at its offset round a
    corner, typically) would be driven into it. A robot whose start already touches
    something is checked from where its path comes clear.
    """
    for k, (path, fp) in enumerate(zip(paths, footprints, strict=True)):
        n = max(int(math.ceil(path.length_m / MAP_CHECK_STEP_M)), 1) + 1
        s = np.linspace(0.0, path.length_m, n)
        poses = path.pose(s)
        corners = footprint_corners(poses, body_corners([fp] * n))
        hits = grid.footprint_hits(corners)
        if hits[0]:
            clear = np.flatnonzero(~hits)
            hits[: clear[0] if len(clear) else n] = False
        if hits.any():
            j = int(np.argmax(hits))
            (x0, y0, x1, y1), c = grid.bounds, corners[j]
            off = bool(np.any((c < [x0, y0]) | (c > [x1, y1])))
            return k, float(s[j]), poses[j], off
    return None


def _safe_distance(cmd, footprints: list[Footprint], poses: np.ndarray) -> float:
    """Constraint (15)'s distance: the command's, or two circumradii (no two skids' circles
    overlap), but never more than the group's closest pair at its start, so a group that
    starts closer than that is held no closer than it starts instead of being refused."""
    if cmd.d_safe_m:
        return float(cmd.d_safe_m)
    d = 2.0 * max(f.circumradius_m for f in footprints)
    if len(poses) > 1:
        iu, ju = np.triu_indices(len(poses), 1)
        closest = float(np.min(np.linalg.norm(poses[iu, :2] - poses[ju, :2], axis=1)))
        d = min(d, START_SHARE * closest)
    return d


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
        if len(waypoints) != n:
            raise FormationError(
                f"formation.paths: give the leader's path or one per robot ({n}), "
                f"got {len(waypoints)}"
            )
        paths = [_spline(pts, poses[k], k) for k, pts in enumerate(waypoints)]
        edges = np.array([[0, j] for j in range(1, n)], dtype=int)
        offset_at = None if cmd.offset_at is None else np.asarray(cmd.offset_at, float)
        v_max = float(np.min(max_speed)) * LIMIT_SHARE
        a_max = float(np.min(max_accel)) * LIMIT_SHARE
        lengths = np.array([p.length_m for p in paths])
        steps = cmd.steps
        if steps is None:
            # Room for the longest path at 2/3 of the speed bound, plus speeding up and down.
            steps = max(4, math.ceil((1.5 * lengths.max() / v_max + 2 * v_max / a_max) / cmd.dt_s))
        d_safe = _safe_distance(cmd, footprints, poses)
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
        adj = OnlineAdjuster(
            plan,
            min_watch_s=min(3.0, cmd.dt_s * 3),
            replan_period_s=REPLAN_PERIOD_S,
            memory_s=PREDICTION_MEMORY_S,
            d_obs_m=d_safe,
            max_delay_steps=max(1, math.ceil(MAX_DELAY_S / cmd.dt_s - 1e-9)),
        )
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
        """Formation error of the run, and the online decisions (each reported once)."""
        if len(self.times) < 2:
            return {}
        fm = formation_metrics(
            self.problem, np.asarray(self.times), np.stack(self.poses), np.stack(self.ref_s)
        )
        out = {
            "method": self.adjuster.plan.method,
            "integral_m2s": round(fm.integral_m2s, 6),
            "q_e_m2": round(fm.q_e_m2, 6),
            "max_pair_error_m": round(fm.max_pair_error_m, 4),
            "plan_duration_s": round(float(self.adjuster.plan.duration_s), 3),
        }
        if self.adjuster.adjustments:
            out["online"] = self.decisions()
        if self.adjuster.held:
            out["held"] = True
        return out

    def decisions(self) -> list[dict]:
        """The online modifications made so far: fleet time, decision, wait and retreat (s)."""
        return [
            {
                "t_s": round(self.t0 + a.t_obs_s, 3),
                "decision": a.decision,
                "wait_s": round(a.wait_s, 3),
                "reverse_s": round(a.reverse_s, 3),
            }
            for a in self.adjuster.adjustments
        ]
