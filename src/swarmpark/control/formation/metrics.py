"""Formation error: the desired offsets along the paths (eq. 6, blended between keypoints), the
pair errors ``q^e_ij`` (eq. 9) and ``Q^e`` (eq. 10) of planned or simulated motion."""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from swarmpark.control.formation.problem import FormationPlan, FormationProblem
from swarmpark.control.formation.tracking import sample_reference

__all__ = [
    "FormationMetrics",
    "blend_offsets",
    "desired_offsets",
    "pair_errors",
    "formation_metrics",
    "formation_error",
]


def _smoothstep(x, lib):
    """C1 step 0 -> 1 on [0, 1], flat outside (``lib`` is numpy or casadi)."""
    if lib is np:
        xc = np.clip(x, 0.0, 1.0)
    else:
        xc = ca.fmin(ca.fmax(x, 0.0), 1.0)
    return xc * xc * (3.0 - 2.0 * xc)


def blend_offsets(at, offsets_m, sigma) -> np.ndarray:
    """Desired offsets ``(E, ..., 2)`` at path fractions ``sigma`` ``(E, ...)``.

    ``at`` ``(E, K)`` and ``offsets_m`` ``(E, K, 2)`` are keypoints as in
    :class:`FormationProblem`: exact at a keypoint, a C1 smoothstep blend between keypoints,
    held outside.

    Examples
    --------
    >>> at, off = np.array([[0.0, 1.0]]), np.array([[[0.0, 0.0], [1.0, 2.0]]])
    >>> blend_offsets(at, off, np.array([[0.0, 0.5, 1.0, 2.0]]))[0].tolist()
    [[0.0, 0.0], [0.5, 1.0], [1.0, 2.0], [1.0, 2.0]]
    """
    at = np.asarray(at, dtype=float)
    off = np.asarray(offsets_m, dtype=float)
    sigma = np.asarray(sigma, dtype=float)
    shape = (slice(None),) + (None,) * (sigma.ndim - 1)
    out = np.broadcast_to(off[:, 0][shape + (slice(None),)], (*sigma.shape, 2)).copy()
    for k in range(off.shape[1] - 1):
        w = _smoothstep((sigma - at[:, k][shape]) / (at[:, k + 1] - at[:, k])[shape], np)
        out += w[..., None] * (off[:, k + 1] - off[:, k])[shape + (slice(None),)]
    return out


def desired_offsets(problem: FormationProblem, s_i) -> np.ndarray:
    """Desired offsets ``(E, ..., 2)`` in robot ``i``'s frame for each edge at ``s_i``.

    ``s_i`` has shape ``(E, ...)``: the travel distance of each edge's first robot.
    """
    s_i = np.asarray(s_i, dtype=float)
    shape = (slice(None),) + (None,) * (s_i.ndim - 1)
    length = problem.lengths_m[problem.edges[:, 0]][shape]
    return blend_offsets(problem.offset_at, problem.offsets_m, s_i / length)


def pair_errors(problem: FormationProblem, poses, s) -> np.ndarray:
    """Formation errors ``q^e_ij`` (eq. 9) ``(..., E, 2)`` in the world frame.

    Parameters
    ----------
    poses
        ``(..., R, 3)`` robot poses (planned, or actual ones from a simulation).
    s
        ``(..., R)`` travel distances that select the desired offsets (eq. 6 uses ``s_i``).
    """
    poses = np.asarray(poses, dtype=float)
    s = np.asarray(s, dtype=float)
    i, j = problem.edges[:, 0], problem.edges[:, 1]
    d = desired_offsets(problem, np.moveaxis(s[..., i], -1, 0))  # (E, ..., 2)
    d = np.moveaxis(d, 0, -2)  # (..., E, 2)
    th = poses[..., i, 2]
    c, sn = np.cos(th), np.sin(th)
    d_world = np.stack([c * d[..., 0] - sn * d[..., 1], sn * d[..., 0] + c * d[..., 1]], -1)
    return poses[..., j, :2] - poses[..., i, :2] - d_world


@dataclass(frozen=True, eq=False)
class FormationMetrics:
    """Formation error of a motion sampled at ``times_s``.

    Attributes
    ----------
    times_s : ndarray (T,)
    pair_error_m : ndarray (E, T)
        ``||q^e_ij(t)||`` per edge.
    q_e_m2 : float
        ``Q^e`` of eq. (10): sum over the sample times of ``sum_ij ||q^e_ij||^2`` (the paper's
        value when the samples are the plan instants ``m dt``).
    integral_m2s : float
        Time integral of ``sum_ij ||q^e_ij||^2`` (trapezoid rule), independent of sampling.
    max_pair_error_m : float
    """

    times_s: np.ndarray
    pair_error_m: np.ndarray
    q_e_m2: float
    integral_m2s: float
    max_pair_error_m: float


def formation_metrics(problem: FormationProblem, times_s, poses, s) -> FormationMetrics:
    """Formation error of poses ``(T, R, 3)`` with travel distances ``(T, R)`` at ``times_s``.

    Use it on a simulated run: pass the skids' actual poses and the reference ``s`` of
    :func:`sample_reference` at the same times.
    """
    times = np.asarray(times_s, dtype=float)
    err = pair_errors(problem, poses, s)  # (T, E, 2)
    sq = np.sum(err**2, axis=(-1, -2))  # (T,)
    norms = np.linalg.norm(err, axis=-1).T  # (E, T)
    integral = float(np.sum(0.5 * (sq[1:] + sq[:-1]) * np.diff(times))) if times.size > 1 else 0.0
    return FormationMetrics(
        times_s=times,
        pair_error_m=norms,
        q_e_m2=float(sq.sum()),
        integral_m2s=integral,
        max_pair_error_m=float(norms.max(initial=0.0)),
    )


def formation_error(plan: FormationPlan, times_s=None) -> FormationMetrics:
    """Formation error of a plan (warp included) sampled at ``times_s``.

    By default the samples are ``0, dt, 2 dt, ...`` up to the plan's duration, i.e. the
    paper's ``Q^e`` for an unmodified plan.
    """
    if times_s is None:
        dt = plan.problem.dt_s
        times_s = np.arange(0.0, plan.duration_s + 0.5 * dt, dt)
    times = np.atleast_1d(np.asarray(times_s, dtype=float))
    ref = sample_reference(plan, times)
    return formation_metrics(plan.problem, times, ref.poses, ref.s)
