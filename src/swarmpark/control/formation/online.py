"""Online modification of a plan for a moving obstacle (Liu, Sun & Zhu 2010, Sect. II.D):
predict the obstacle (:func:`predict_obstacle`) and, when (16) fails, make the whole group wait
(17)-(18) or retrace its plan and wait (19) by one shared time warp
(:func:`adjust_for_obstacle`, :class:`OnlineAdjuster` for a control loop)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from swarmpark.control.formation.problem import FormationPlan, _as_float
from swarmpark.control.formation.tracking import _warp, sample_reference

__all__ = ["ObstacleAdjustment", "OnlineAdjuster", "predict_obstacle", "adjust_for_obstacle"]


def predict_obstacle(obs_t_s, obs_xy, t_s, *, degree: int = 1) -> np.ndarray:
    """Predict obstacle positions ``(..., 2)`` at times ``t_s`` from observations.

    A least-squares polynomial in time per axis (degree 1: constant velocity; lower when
    there are too few observations; one observation means a standing obstacle).
    """
    ot = np.asarray(obs_t_s, dtype=float).ravel()
    oxy = np.asarray(obs_xy, dtype=float).reshape(-1, 2)
    if ot.size == 0 or ot.size != oxy.shape[0]:
        raise ValueError(
            f"obs_t_s/obs_xy: need matching, non-empty observations (got {ot.size} times, "
            f"{oxy.shape[0]} positions)"
        )
    if not (np.all(np.isfinite(ot)) and np.all(np.isfinite(oxy))):
        raise ValueError("obs_t_s/obs_xy: observations must be finite")
    deg = min(int(degree), np.unique(ot).size - 1)
    t = np.asarray(t_s, dtype=float)
    if deg <= 0:
        return np.broadcast_to(oxy.mean(axis=0), (*t.shape, 2)).copy()
    t_ref = ot.max()  # centre the fit for conditioning
    coef = np.polynomial.polynomial.polyfit(ot - t_ref, oxy, deg)  # (deg + 1, 2)
    return np.polynomial.polynomial.polyval(t - t_ref, coef).transpose(*range(1, t.ndim + 1), 0)


@dataclass(frozen=True, eq=False)
class ObstacleAdjustment:
    """Outcome of :func:`adjust_for_obstacle`.

    Attributes
    ----------
    plan
        The plan to execute from now on (the input plan when ``decision == "continue"``).
    decision
        ``"continue"`` ((16) holds), ``"wait"`` ((17) holds: eq. 18), ``"reverse"`` (eq. 19) or
        ``"unresolved"`` (no wait or retreat within ``max_delay_steps`` clears the predicted
        obstacle; the returned plan stops and waits that long, and the caller should escalate).
    t_obs_s, wait_s, reverse_s
        Decision time ``t_obs``, waiting time (``dt_d`` or ``dt'_d``) and retreat time ``dt_r``.
    min_distance_m
        Smallest predicted robot-obstacle distance over the checked window with the returned
        plan.
    """

    plan: FormationPlan
    decision: str
    t_obs_s: float
    wait_s: float
    reverse_s: float
    min_distance_m: float


def _knots_wait(wt, wtau, t_obs: float, tau_obs: float, delay: float):
    before = wt < t_obs
    after = wt > t_obs
    t_new = np.concatenate([wt[before], [t_obs, t_obs + delay], wt[after] + delay])
    tau_new = np.concatenate([wtau[before], [tau_obs, tau_obs], wtau[after]])
    return _dedupe(t_new, tau_new)


def _knots_reverse(plan, t_obs: float, back: float, delay: float):
    wt, wtau = plan.warp_t_s, plan.warp_tau_s
    tau_obs = float(_warp(plan, np.array([t_obs]))[0][0])
    tau_back = float(_warp(plan, np.array([t_obs - back]))[0][0])
    mid = (wt > t_obs - back) & (wt < t_obs)
    after = wt > t_obs - back
    shift = 2.0 * back + delay
    t_new = np.concatenate(
        [
            wt[wt < t_obs],
            [t_obs],
            (2.0 * t_obs - wt[mid])[::-1],
            [t_obs + back, t_obs + back + delay],
            wt[after] + shift,
        ]
    )
    tau_new = np.concatenate(
        [wtau[wt < t_obs], [tau_obs], wtau[mid][::-1], [tau_back, tau_back], wtau[after]]
    )
    return _dedupe(t_new, tau_new)


def _dedupe(t, tau):
    keep = np.concatenate([[True], np.diff(t) > 1e-12])
    return t[keep], tau[keep]


def adjust_for_obstacle(
    plan: FormationPlan,
    obs_t_s,
    obs_xy,
    t_obs_s: float,
    *,
    d_obs_m: float | None = None,
    horizon_steps: int = 5,
    max_delay_steps: int | None = None,
    substeps: int = 10,
    degree: int = 1,
) -> ObstacleAdjustment:
    """Online modification of a plan for a moving obstacle (Sect. II.D, eqs. 16-19).

    The obstacle's trajectory is predicted from the observations made up to ``t_obs_s``
    (:func:`predict_obstacle`). If every robot keeps ``d_obs_m`` from it over the next
    ``H = horizon_steps`` steps (16), the plan is kept. Otherwise, if stopping where they are
    keeps that distance (17), the group stops and waits ``dt_d`` (18); if not, it retraces its
    plan for ``dt_r``, waits ``dt'_d`` and resumes (19). The shortest delay (``dt_d``, or
    ``2 dt_r + dt'_d``, in steps of ``dt``) is chosen for which the modified plan keeps
    ``d_obs_m`` from the predicted obstacle from ``t_obs`` until ``H`` steps after the group
    resumes. Distances are checked at ``substeps`` points per step, not only at ``m dt``.

    Parameters
    ----------
    plan
        The plan being executed (possibly already modified).
    obs_t_s, obs_xy
        Observation times ``(K,)`` and obstacle positions ``(K, 2)``; those after ``t_obs_s``
        are ignored.
    t_obs_s
        Decision time.
    d_obs_m
        Safe robot-obstacle distance ``D_obs``; defaults to the problem's ``d_safe_m``.
    horizon_steps
        ``H`` of (16)-(17).
    max_delay_steps
        Longest delay considered; defaults to ``M``.
    """
    problem = plan.problem
    dt = problem.dt_s
    t_obs = _as_float(t_obs_s, "t_obs_s", allow_zero=True)
    d_obs = problem.d_safe_m if d_obs_m is None else _as_float(d_obs_m, "d_obs_m")
    if int(horizon_steps) != horizon_steps or horizon_steps < 1:
        raise ValueError(f"horizon_steps: must be an integer >= 1 (got {horizon_steps!r})")
    if int(substeps) != substeps or substeps < 1:
        raise ValueError(f"substeps: must be an integer >= 1 (got {substeps!r})")
    max_delay = problem.M if max_delay_steps is None else int(max_delay_steps)
    if max_delay < 1:
        raise ValueError(f"max_delay_steps: must be >= 1 (got {max_delay_steps!r})")
    ot = np.asarray(obs_t_s, dtype=float).ravel()
    oxy = np.asarray(obs_xy, dtype=float).reshape(-1, 2)
    if ot.size != oxy.shape[0]:
        raise ValueError(f"obs_t_s/obs_xy: {ot.size} times but {oxy.shape[0]} positions")
    past = ot <= t_obs + 1e-9
    if not past.any():
        raise ValueError(
            f"obs_t_s: no observation at or before t_obs_s={t_obs} (got {ot.tolist()})"
        )
    ot, oxy = ot[past], oxy[past]

    def window(t_end: float) -> np.ndarray:
        n = max(1, math.ceil(round((t_end - t_obs) / dt, 9) * substeps))
        return t_obs + np.linspace(0.0, t_end - t_obs, n + 1)

    def clearance(candidate: FormationPlan, t_end: float) -> float:
        tt = window(t_end)
        xy = sample_reference(candidate, tt).poses[..., :2]  # (T, R, 2)
        obs = predict_obstacle(ot, oxy, tt, degree=degree)  # (T, 2)
        return float(np.linalg.norm(xy - obs[:, None, :], axis=-1).min())

    h_end = t_obs + horizon_steps * dt
    d16 = clearance(plan, h_end)
    if d16 >= d_obs:
        return ObstacleAdjustment(plan, "continue", t_obs, 0.0, 0.0, d16)

    tau_obs = float(_warp(plan, np.array([t_obs]))[0][0])
    wt, wtau = plan.warp_t_s, plan.warp_tau_s

    def waited(k: int) -> FormationPlan:
        t_new, tau_new = _knots_wait(wt, wtau, t_obs, tau_obs, k * dt)
        return replace(plan, warp_t_s=t_new, warp_tau_s=tau_new)

    # (17): the group standing still at its poses of t_obs over the next H steps.
    standing = waited(horizon_steps)
    d17 = clearance(standing, h_end)
    if d17 >= d_obs:
        for k in range(1, max_delay + 1):
            cand = waited(k)
            d = clearance(cand, t_obs + (k + horizon_steps) * dt)
            if d >= d_obs:
                return ObstacleAdjustment(cand, "wait", t_obs, k * dt, 0.0, d)

    # (19): retrace the plan for k_r steps, wait k_d steps, resume; shortest total delay.
    max_back = min(max_delay, math.floor(t_obs / dt + 1e-9))
    options = sorted(
        (
            (2 * kr + kd, kr, kd)
            for kr in range(1, max_back + 1)
            for kd in range(0, max_delay + 1)
            if 2 * kr + kd <= 2 * max_delay
        ),
    )
    for _, kr, kd in options:
        t_new, tau_new = _knots_reverse(plan, t_obs, kr * dt, kd * dt)
        cand = replace(plan, warp_t_s=t_new, warp_tau_s=tau_new)
        d = clearance(cand, t_obs + (kr + kd + horizon_steps) * dt)
        if d >= d_obs:
            return ObstacleAdjustment(cand, "reverse", t_obs, kd * dt, kr * dt, d)

    cand = waited(max_delay)
    d = clearance(cand, t_obs + (max_delay + horizon_steps) * dt)
    return ObstacleAdjustment(cand, "unresolved", t_obs, max_delay * dt, 0.0, d)


class OnlineAdjuster:
    """Stateful wrapper around :func:`adjust_for_obstacle` for a control loop.

    Feed obstacle observations with :meth:`observe`; call :meth:`update` at decision times
    (e.g. every ``dt``). Once the obstacle has been watched for ``min_watch_s`` (the paper's
    robots see it at 5 s and act at 8 s), each update checks (16) on the current plan and
    modifies it when needed; :attr:`plan` is always the plan to track and
    :attr:`adjustments` the modifications made. Deterministic: no clocks, no threads.

    Parameters
    ----------
    plan
        The offline plan.
    min_watch_s
        Observation time needed before predicting the obstacle.
    **kwargs
        Passed to :func:`adjust_for_obstacle` (``d_obs_m``, ``horizon_steps``, ...).
    """

    def __init__(self, plan: FormationPlan, *, min_watch_s: float = 0.0, **kwargs) -> None:
        allowed = {"d_obs_m", "horizon_steps", "max_delay_steps", "substeps", "degree"}
        unknown = set(kwargs) - allowed
        if unknown:
            raise TypeError(f"OnlineAdjuster: unknown keyword(s) {sorted(unknown)}")
        self.plan = plan
        self.min_watch_s = _as_float(min_watch_s, "min_watch_s", allow_zero=True)
        self._kwargs = kwargs
        self._obs_t: list[float] = []
        self._obs_xy: list[tuple[float, float]] = []
        self.adjustments: list[ObstacleAdjustment] = []

    def observe(self, t_s: float, xy: Sequence[float]) -> None:
        """Record the obstacle at ``xy`` (metres) at time ``t_s``."""
        xy_arr = np.asarray(xy, dtype=float).reshape(2)
        if not np.all(np.isfinite(xy_arr)) or not math.isfinite(float(t_s)):
            raise ValueError(f"observe: non-finite observation t={t_s!r}, xy={xy!r}")
        self._obs_t.append(float(t_s))
        self._obs_xy.append((float(xy_arr[0]), float(xy_arr[1])))

    def update(self, t_s: float) -> ObstacleAdjustment | None:
        """Decide at time ``t_s``; returns the modification made, or ``None``.

        Every call re-checks (16) on the current (possibly already modified) plan with all
        observations so far, so a changed prediction leads to a further modification.
        """
        if not self._obs_t or t_s - self._obs_t[0] < self.min_watch_s - 1e-9:
            return None
        adj = adjust_for_obstacle(self.plan, self._obs_t, self._obs_xy, t_s, **self._kwargs)
        if adj.decision == "continue":
            return None
        self.plan = adj.plan
        self.adjustments.append(adj)
        return adj
