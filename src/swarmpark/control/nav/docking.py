"""The docking manoeuvre: the last metres to the exact goal pose, in the goal frame.

Near the goal and roughly aligned, the pivot tracks the goal's axis (a Stanley-type law: aim at
``atan(k * lateral error)`` off the axis, forwards or in reverse) while closing the
longitudinal error. A skid too close to fix its lateral error (or held still by the monitor)
backs out along the axis to a run-up with the same law, which also reduces the error, and
comes in again. Inside the parked band it holds still until pushed out of the outer band.
Far off the goal heading next to the goal it first turns in place.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarmpark.control.base import ControlView
from swarmpark.control.nav.params import DockingParams
from swarmpark.control.nav.recovery import BackUp, BackUpState, StallWatch
from swarmpark.core.geometry import wrap_angle

__all__ = ["DockState", "Docking", "goal_frame_errors"]

#: Longitudinal errors below this count as zero when choosing the way in (a numerical floor).
_ON_AXIS_M = 1e-6


@dataclass
class DockState:
    """One skid's docking state machine.

    ``docked``: holding still on the goal (parked). ``runup``: backing out along the goal axis
    from ``runup_from`` (the longitudinal error when it started) to come in again. Neither:
    approaching. ``settled``: reached its current goal once (until a new goal); with RVO it
    yields from then on, also while it returns after being pushed aside.
    """

    docked: bool = False
    runup: bool = False
    runup_from: float = 0.0
    settled: bool = False

    @property
    def phase(self) -> str:
        """``"docked"``, ``"run-up"`` or ``"approach"``."""
        return "docked" if self.docked else "run-up" if self.runup else "approach"

    def new_goal(self) -> None:
        self.docked = self.runup = self.settled = False


def goal_frame_errors(poses: np.ndarray, goals: np.ndarray):
    """Longitudinal error (> 0 past the goal along its heading), lateral error, heading error
    (goal minus current) and distance of ``poses`` from ``goals``, in the goal frame."""
    d = poses[:, :2] - goals[:, :2]
    cg, sg = np.cos(goals[:, 2]), np.sin(goals[:, 2])
    e_long = d[:, 0] * cg + d[:, 1] * sg
    e_lat = -d[:, 0] * sg + d[:, 1] * cg
    e_yaw = wrap_angle(goals[:, 2] - poses[:, 2])
    return e_long, e_lat, e_yaw, np.hypot(e_long, e_lat)


class Docking:
    """The parking manoeuvre of the skids in their final approach.

    Parameters
    ----------
    params
        :class:`~swarmpark.control.nav.params.DockingParams`.
    backup
        The back-up recovery used on the way in, away from the goal's axis, when held still.
    stall_s
        A skid held still this long on the axis is wedged: it runs up again.
    """

    def __init__(self, params: DockingParams, backup: BackUp, *, stall_s: float) -> None:
        self.params = params
        self.backup = backup
        self.stall_s = stall_s

    def step(
        self,
        view: ControlView,
        idx: np.ndarray,
        raw: np.ndarray,
        final: np.ndarray,
        docks: list[DockState],
        stalls: list[StallWatch],
        backups: list[BackUpState],
    ) -> np.ndarray:
        """Commands for robots ``idx``: the manoeuvre where it applies (``final``: in the final
        approach), else ``raw`` (or a back-up). Updates the robots' states."""
        # Per-skid scalars as Python floats, converted once for all (not per skid).
        err = np.column_stack(goal_frame_errors(view.poses[idx], view.goals[idx]))
        errors = err.tolist()
        changed = view.goal_changed[idx].tolist()
        fin = np.asarray(final, dtype=bool).tolist()
        p = self.params
        parked = (
            (np.abs(err[:, 0]) < p.parked_pos_m)
            & (np.abs(err[:, 1]) < p.dock_lateral_m)
            & (np.abs(err[:, 2]) < p.parked_yaw_rad)
        ).tolist()
        stall_s = self.backup.stall_s
        out = raw.copy()
        for k, i in enumerate(idx.tolist()):
            st = docks[i]
            if changed[k]:
                st.new_goal()
            elif not (fin[k] or parked[k] or st.docked or st.settled):
                # On the way, not backing up and not held still long enough to start: what
                # _one would conclude (the field's command stands), without its steps.
                if backups[i].left_m <= 0 and stalls[i].stalled_s < stall_s:
                    st.runup = False
                    continue
            e = tuple(errors[k])
            cmd = self._one(view, i, raw[k], fin[k], e, st, stalls[i], backups[i])
            if cmd is not None:
                out[k] = cmd
        return out

    def _turn(self, view: ControlView, i: int, e_yaw: float) -> tuple[float, float]:
        p = self.params
        w = np.clip(p.k_dock_yaw * e_yaw, -view.max_yaw_rate[i], view.max_yaw_rate[i])
        return (0.0, w)

    def _one(self, view, i, raw, final, e, st: DockState, stall: StallWatch, back: BackUpState):
        """Command of one skid, or None to keep ``raw``."""
        p = self.params
        e_long, e_lat, e_yaw, dist = e
        parked = (
            abs(e_long) < p.parked_pos_m
            and abs(e_lat) < p.dock_lateral_m
            and abs(e_yaw) < p.parked_yaw_rad
        )
        if st.docked and (dist > p.resume_pos_m or abs(e_yaw) > p.resume_yaw_rad):
            st.docked = False
        if st.docked or parked:
            st.docked, st.runup, st.settled = True, False, True
            return (0.0, 0.0)
        close = final and dist < p.manoeuvre_radius_m
        if close and abs(e_yaw) >= p.align_first_rad and back.left_m <= 0:
            # Far off the goal heading next to the goal: turn in place first (a
            # differential-drive skid can); the axis law below needs a rough alignment.
            st.runup = False
            return self._turn(view, i, e_yaw)
        if not (close and abs(e_yaw) < p.align_first_rad):
            st.runup = False
            if st.settled:
                # Pushed off its spot (RVO makes room along the axis): it drives back along
                # the axis; a back-up there only fights whoever pushed it.
                return None
            return self.backup.step(back, stall, raw[0], view.vel[i, 0], view.dt, view.max_speed[i])
        return self._axis_law(view, i, e, st, stall)

    def _update_runup(self, e_long: float, e_lat: float, st: DockState, stall: StallWatch):
        p = self.params
        too_close = abs(e_lat) > p.dock_lateral_m and abs(e_long) < p.dock_radius_m
        wedged = stall.stalled_s >= self.stall_s  # the monitor has held it still: back out
        if (too_close or wedged) and not st.runup:
            st.runup, st.runup_from, stall.stalled_s = True, abs(e_long), 0.0
        backed = abs(e_long) - st.runup_from
        # Held still again, it comes in again: after backing runup_min_back_m, or at once
        # where there was no run-up to gain (already runup_m out: wedged 1.7 m past its goal,
        # nose to the map's edge, a skid of the 20-skid circle backed 5 cm and stood there).
        wedged = stall.stalled_s >= self.stall_s  # (again: the start reset the watch)
        if st.runup and (
            abs(e_lat) < p.runup_done_lateral_m
            or backed > p.runup_m
            or (wedged and (backed > p.runup_min_back_m or st.runup_from >= p.runup_m))
        ):
            st.runup, stall.stalled_s = False, 0.0

    def _axis_law(self, view, i, e, st: DockState, stall: StallWatch):
        """Track the goal axis towards the goal, or away from it during a run-up."""
        p = self.params
        e_long, e_lat, e_yaw, _ = e
        self._update_runup(e_long, e_lat, st, stall)
        to_goal = -np.sign(e_long) if abs(e_long) > _ON_AXIS_M else 1.0
        sgn = -to_goal if st.runup else to_goal
        if abs(e_long) < p.parked_pos_m and not st.runup:
            return self._turn(view, i, e_yaw)  # on the spot: only turn to the goal heading
        # Aim at the axis 1 / k_lateral ahead, or farther out at axis_ahead of the distance
        # left (a skid 1.6 m out and 0.17 m off the axis turned 27 deg, nose into the jamb
        # of the door beside its spot).
        ahead = max(1.0 / p.k_lateral, p.axis_ahead * abs(e_long))
        aim = -sgn * np.arctan(e_lat / ahead)  # heading off the axis, goal frame
        yaw_err = wrap_angle(aim + e_yaw)  # (goal + aim) - current heading
        share = p.max_speed_share
        if not st.runup:
            on_line = max(1.0 - abs(e_lat) / p.aligned_lateral_m, 0.0)
            on_line *= max(1.0 - abs(e_yaw) / p.aligned_yaw_rad, 0.0)
            share += (p.aligned_speed_share - share) * on_line
        if st.runup:
            want = p.k_dock * p.runup_m
        elif p.brake_share > 0 and view.max_accel is not None:
            # Slow down as a skid braking at brake_share of its limit stops on the goal.
            want = np.sqrt(2.0 * p.brake_share * view.max_accel[i] * abs(e_long))
        else:
            want = p.k_dock * abs(e_long)
        speed = np.clip(want, p.min_speed_mps, share * view.max_speed[i])
        v = sgn * speed * max(np.cos(yaw_err), 0.0) ** 2
        w = np.clip(p.k_dock_yaw * yaw_err, -view.max_yaw_rate[i], view.max_yaw_rate[i])
        return (v, w)
