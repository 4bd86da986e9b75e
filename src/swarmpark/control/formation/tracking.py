"""Executing a plan: reference poses and velocities at any time, time warp included
(:func:`sample_reference`), and a tracking law for non-holonomic skids (:func:`track_unicycle`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from swarmpark.control.formation.problem import FormationPlan, _as_float
from swarmpark.core.geometry import wrap_angle

__all__ = ["Reference", "TrackingGains", "sample_reference", "track_unicycle"]


class Reference(NamedTuple):
    """Reference state of every robot at one time (or ``(T, ...)`` for T times)."""

    poses: np.ndarray  #: (R, 3) reference poses (x, y, yaw)
    v: np.ndarray  #: (R,) reference speed along the heading (negative when retracing)
    omega: np.ndarray  #: (R,) reference yaw rate, k(s) v (eq. 4)
    s: np.ndarray  #: (R,) travel distance along each path


def _warp(plan: FormationPlan, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Plan time ``tau(t)`` and its slope ``dtau/dt`` (right derivative at knots)."""
    wt, wtau = plan.warp_t_s, plan.warp_tau_s
    slopes = np.append(np.diff(wtau) / np.diff(wt), 1.0)
    k = np.clip(np.searchsorted(wt, t, side="right") - 1, 0, wt.size - 1)
    slope = np.where(t < wt[0], 1.0, slopes[k])
    return wtau[k] + slope * (t - wt[k]), slope


def _base_state(plan: FormationPlan, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distances and speeds ``(..., R)`` of the base plan at plan times ``tau``."""
    dt = plan.problem.dt_s
    n_steps = plan.t_s.size - 1
    m = np.clip(np.floor(tau / dt).astype(int), 0, n_steps - 1)
    rr = np.clip(tau - m * dt, 0.0, dt)[..., None]
    s0, s1 = plan.s_m.T[m], plan.s_m.T[m + 1]
    v0, v1 = plan.v_mps.T[m], plan.v_mps.T[m + 1]
    dv = v1 - v0
    s = s0 + v0 * rr + dv * rr**2 / (2.0 * dt)
    # Pin the knots exactly (the quadratic reproduces them up to round-off).
    s = np.where(rr >= dt, s1, s)
    v = v0 + dv * rr / dt
    return s, v


def sample_reference(plan: FormationPlan, t) -> Reference:
    """Reference poses, speeds and yaw rates of every robot at time(s) ``t`` (seconds).

    Pure and vectorized over times: scalar ``t`` gives ``(R, 3)``/``(R,)`` arrays, an array
    of ``T`` times gives ``(T, R, 3)``/``(T, R)``. Before 0 and after the plan ends the
    robots hold their start and goal poses with zero velocity. Speeds are negative while an
    online modification retraces the plan (eq. 19); the heading stays the path's.
    """
    t_arr = np.asarray(t, dtype=float)
    if not np.all(np.isfinite(t_arr)):
        raise ValueError(f"t: times must be finite (got {t!r})")
    flat = np.atleast_1d(t_arr).ravel()
    tau, slope = _warp(plan, flat)
    s, v = _base_state(plan, tau)
    v = v * slope[:, None]
    poses = np.empty((flat.size, plan.problem.n_robots, 3))
    kappa = np.empty((flat.size, plan.problem.n_robots))
    for i, p in enumerate(plan.problem.paths):
        poses[:, i], kappa[:, i] = p.frame(s[:, i])
    omega = kappa * v
    shape = t_arr.shape
    return Reference(
        poses.reshape(*shape, -1, 3),
        v.reshape(*shape, -1),
        omega.reshape(*shape, -1),
        s.reshape(*shape, -1),
    )


@dataclass(frozen=True)
class TrackingGains:
    """Gains of :func:`track_unicycle`.

    ``k_x`` (1/s) closes along-track error, ``k_y`` (1/m^2) cross-track error and ``k_theta``
    (1/m) heading error; ``k_theta = 2 sqrt(k_y)`` damps the cross-track response critically.
    """

    k_x: float = 1.0
    k_y: float = 4.0
    k_theta: float = 4.0

    def __post_init__(self) -> None:
        for name in ("k_x", "k_y", "k_theta"):
            _as_float(getattr(self, name), f"gains.{name}")


def track_unicycle(poses, ref_poses, ref_v, ref_omega, gains: TrackingGains | None = None):
    """Kanayama tracking law for unicycles, vectorized over robots; returns ``(v, omega)``.

    With the error in the robot frame ``(e_x, e_y, e_theta)``::

        v     = v_r cos(e_theta) + k_x e_x
        omega = omega_r + v_r k_y e_y + k_theta |v_r| sin(e_theta)

    Kanayama et al. (1990) use ``v_r k_theta``; ``|v_r|`` keeps the Lyapunov function
    ``(e_x^2 + e_y^2) / 2 + (1 - cos e_theta) / k_y`` decreasing when the reference drives
    backwards (a retraced plan). Saturating ``v``/``omega`` is the caller's job.

    Parameters
    ----------
    poses, ref_poses
        ``(R, 3)`` actual and reference poses.
    ref_v, ref_omega
        ``(R,)`` reference speeds and yaw rates.
    """
    g = gains or TrackingGains()
    poses = np.asarray(poses, dtype=float)
    ref = np.asarray(ref_poses, dtype=float)
    vr = np.asarray(ref_v, dtype=float)
    wr = np.asarray(ref_omega, dtype=float)
    dx, dy = ref[..., 0] - poses[..., 0], ref[..., 1] - poses[..., 1]
    c, s = np.cos(poses[..., 2]), np.sin(poses[..., 2])
    ex, ey = c * dx + s * dy, -s * dx + c * dy
    eth = wrap_angle(ref[..., 2] - poses[..., 2])
    v = vr * np.cos(eth) + g.k_x * ex
    omega = wr + vr * g.k_y * ey + g.k_theta * np.abs(vr) * np.sin(eth)
    return v, omega
