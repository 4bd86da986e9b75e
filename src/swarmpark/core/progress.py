"""What "progress towards a goal" means, defined once for navigation and for the metrics.

A skid's *remaining distance* to its goal pose is its position error plus its heading error
at a lever arm (metres per radian: turning on the spot is progress too). It *makes progress*
when the remaining distance falls at least a step below the best it has reached so far.

Two users apply this one definition with their own lever and step, on purpose:

- the run metrics (:mod:`swarmpark.metrics`) report a deadlock after a long window without
  progress; they count heading at :data:`REPORT_HEADING_LEVER_M` and progress from
  :data:`REPORT_PROGRESS_M`, fine enough that a slow but moving skid is never reported;
- the navigator's deadlock recovery (:mod:`swarmpark.control.nav.recovery`) and its goal
  attraction weight count heading at :data:`NAV_HEADING_LEVER_M` and act after a coarser
  step (``DeadlockParams.progress_m``): a recovery is a costly manoeuvre, only worth it when
  the skid is clearly not getting anywhere.

Unifying the two levers (navigation at 0.5 m/rad as well) was measured on every scenario in
``scenarios/`` (2026-12-01): 18 of 19 give the same result, but circle-20-antipodal (RVO)
changes (time to park 95.95 -> 94.5 s, least clearance 0.093 -> 0.085 m, 14 reported
deadlocks instead of 13). Results must not change in this refactor, so the levers stay two
named values of the one definition.
"""

from __future__ import annotations

__all__ = [
    "NAV_HEADING_LEVER_M",
    "REPORT_HEADING_LEVER_M",
    "REPORT_PROGRESS_M",
    "made_progress",
    "remaining_m",
]

#: Metrics: heading error counts toward the remaining distance at this lever (m per rad).
REPORT_HEADING_LEVER_M = 0.5
#: Metrics: progress means the remaining distance fell at least this much below its best.
REPORT_PROGRESS_M = 0.05
#: Navigation: heading lever of the deadlock watch and of the goal attraction's weight
#: (tuned with the scenario suite; 0.5 changes the 20-skid circle, see above).
NAV_HEADING_LEVER_M = 0.3


def remaining_m(pos_err_m, yaw_err_rad, heading_lever_m: float):
    """Remaining distance to a goal pose: ``pos_err_m + heading_lever_m * yaw_err_rad``.

    Parameters
    ----------
    pos_err_m
        Distance (m) from the goal position, scalar or array.
    yaw_err_rad
        Absolute heading error (rad), same shape.
    heading_lever_m
        Metres of remaining distance per radian of heading error.
    """
    return pos_err_m + heading_lever_m * yaw_err_rad


def made_progress(remaining, best, step_m: float):
    """True where ``remaining`` is at least ``step_m`` below ``best`` (the best so far)."""
    return remaining < best - step_m
