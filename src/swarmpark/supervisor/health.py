"""Per-robot health over a link: heartbeat and command following.

A robot is **lost** while its newest odometry is older than :attr:`HealthParams.heartbeat_s`
(or it never reported): the supervisor sends it no motion (a zero command, which a broken
link may not deliver -- the robot's own dead-man stops it then), flags it, and its neighbours
plan around it as an immobile obstacle at its last known pose. It rejoins by itself when its
odometry is fresh again.

A robot **does not follow** its commands when its measured velocity stays far from what a
robot within its acceleration limits would have reached under the commands sent to it: the
normalized error ``|v - v*| / v_max + |w - w*| / w_max`` averaged over
:attr:`HealthParams.follow_window_s` exceeds :attr:`HealthParams.follow_tol`. It is flagged
and stopped (like an operator ``stop``; ``resume`` releases it). A robot whose status says
it is ``blocked`` (in contact: the simulator's link reports it) is not judged.

Both are recorded as events (robot, kind, from, to) for the run result and the UI.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Health", "HealthParams", "FOLLOW_GAP_PERIODS"]

#: A check later than this many control periods after the previous one restarts the
#: command-following window.
FOLLOW_GAP_PERIODS = 4


@dataclass(frozen=True)
class HealthParams:
    heartbeat_s: float = 0.5
    follow_window_s: float = 1.5
    follow_tol: float = 0.6

    def __post_init__(self) -> None:
        for name in ("heartbeat_s", "follow_window_s", "follow_tol"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"health: {name} must be > 0 (got {v})")


class Health:
    """Heartbeat and command-following checks of ``n`` robots (see the module docstring)."""

    def __init__(self, ids, info, params: HealthParams | None = None) -> None:
        self.ids = list(ids)
        self.p = params or HealthParams()
        n = len(self.ids)
        self.lost = np.zeros(n, dtype=bool)
        self.unknown = np.ones(n, dtype=bool)
        self.not_following = np.zeros(n, dtype=bool)
        self._vmax = np.asarray(info.max_speed_mps, float)
        self._wmax = np.asarray(info.max_yaw_rate_radps, float)
        self._amax = np.asarray(info.max_accel_mps2, float)
        self._alpha = np.asarray(info.max_yaw_accel_radps2, float)
        self._ideal = np.zeros((n, 2))  # the velocity a compliant robot would have now
        self._err: list[tuple[float, np.ndarray]] = []  # (t, per-robot error) over the window
        self._open: dict[tuple[int, str], float] = {}
        self.events: list[dict] = []

    @property
    def faulted(self) -> np.ndarray:
        return self.lost | self.not_following

    def fault_names(self) -> dict[str, str]:
        """Robot id -> its current fault (``"lost"``, ``"not_following"``)."""
        out = {}
        for i, rid in enumerate(self.ids):
            if self.lost[i]:
                out[rid] = "lost"
            elif self.not_following[i]:
                out[rid] = "not_following"
        return out

    def heartbeat(self, t: float, odom_stamp: np.ndarray) -> np.ndarray:
        """Update who is lost at time ``t``; returns the robots lost just now."""
        self.unknown = ~np.isfinite(odom_stamp)
        lost = self.unknown | (t - odom_stamp > self.p.heartbeat_s + 1e-9)
        new = lost & ~self.lost
        self._events(t, lost, "lost")
        self.lost = lost
        return new

    def follow(
        self, t: float, dt: float, sent: np.ndarray, vel: np.ndarray, watch: np.ndarray
    ) -> np.ndarray:
        """Compare the measured ``vel`` with the response to the commands ``sent`` last period,
        for robots in ``watch`` (others restart from their measured velocity); returns the
        robots found not following just now."""
        if self._err and t - self._err[-1][0] > FOLLOW_GAP_PERIODS * dt:
            # The supervisor itself was late: the robots' dead-men may have stopped them.
            # Judge only what follows.
            self._err.clear()
            watch = np.zeros_like(watch)
        step = np.stack([self._amax, self._alpha], 1) * dt
        self._ideal = np.where(
            watch[:, None], self._ideal + np.clip(sent - self._ideal, -step, step), vel
        )
        err = (
            np.abs(vel[:, 0] - self._ideal[:, 0]) / self._vmax
            + np.abs(vel[:, 1] - self._ideal[:, 1]) / self._wmax
        )
        err = np.where(watch, err, 0.0)
        self._err.append((t, err))
        while self._err and self._err[0][0] < t - self.p.follow_window_s + 1e-9:
            self._err.pop(0)
        full = self._err[-1][0] - self._err[0][0] >= self.p.follow_window_s - 2 * dt
        bad = np.zeros_like(watch)
        if full:
            errs = np.stack([e for _, e in self._err])
            bad = watch & (errs.mean(0) > self.p.follow_tol) & np.all(errs > 0, 0)
        new = bad & ~self.not_following
        self.not_following |= bad
        self._events(t, self.not_following, "not_following")
        return new

    def release(self, idx) -> None:
        """The operator resumed these robots: forget their command-following fault."""
        self.not_following[idx] = False
        self._ideal[idx] = 0.0
        for k in range(len(self._err)):
            e = self._err[k][1].copy()
            e[idx] = 0.0
            self._err[k] = (self._err[k][0], e)

    def _events(self, t: float, now: np.ndarray, kind: str) -> None:
        for i in np.flatnonzero(now):
            if (i, kind) not in self._open:
                self._open[(i, kind)] = t
                self.events.append(
                    {"robot": self.ids[i], "kind": kind, "from_s": round(t, 3), "to_s": None}
                )
        for i, k in list(self._open):
            if k == kind and not now[i]:
                del self._open[(i, k)]
                for ev in reversed(self.events):
                    if ev["robot"] == self.ids[i] and ev["kind"] == kind and ev["to_s"] is None:
                        ev["to_s"] = round(t, 3)
                        break
