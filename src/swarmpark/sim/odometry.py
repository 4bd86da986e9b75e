"""Simulated wheel odometry that drifts (:class:`OdometryDrift`): the robot's sensor model, which
turns true motion into the odometry a real skid reports."""

from __future__ import annotations

import numpy as np

from swarmpark.core.geometry import wrap_angle
from swarmpark.sense.amcl.motion import _turn_magnitude, relative_motion

__all__ = ["OdometryDrift"]


class OdometryDrift:
    """Wheel odometry with drift, for ``n`` skids: true motion in, odometry poses out.

    Each step's true increment ``(rot1, trans, rot2)`` is corrupted by fixed per-robot
    errors -- a wheel-calibration scale on the distance, a heading bias per metre driven
    (slightly unequal wheel radii) -- and by random walks whose variance grows with the
    distance driven and the angle turned, so the drift does not depend on the step rate. It is
    integrated onto the odometry pose, whose frame starts at the true start poses.

    Parameters
    ----------
    start
        ``(n, 3)`` true start poses.
    scale_error_std
        Standard deviation of each robot's fixed distance scale error (0.01 = 1 %).
    yaw_bias_std_rad_per_m
        Standard deviation of each robot's fixed heading drift per metre driven.
    trans_noise_m_per_sqrt_m
        Random distance error: its standard deviation after driving ``d`` metres is this
        times ``sqrt(d)``.
    yaw_noise_rad_per_sqrt_m
        Random heading error from driving, likewise per square-root metre.
    turn_noise_rad_per_sqrt_rad
        Random heading error from turning, per square-root radian turned.
    rng
        Random generator (the fixed errors are drawn at construction).

    Examples
    --------
    >>> odo = OdometryDrift(np.zeros((1, 3)), scale_error_std=0.0, yaw_bias_std_rad_per_m=0.0,
    ...                     trans_noise_m_per_sqrt_m=0.0, yaw_noise_rad_per_sqrt_m=0.0,
    ...                     turn_noise_rad_per_sqrt_rad=0.0, rng=np.random.default_rng(0))
    >>> odo.step(np.array([[1.0, 0.0, 0.0]])).tolist()
    [[1.0, 0.0, 0.0]]
    """

    def __init__(
        self,
        start: np.ndarray,
        *,
        scale_error_std: float = 0.01,
        yaw_bias_std_rad_per_m: float = 0.002,
        trans_noise_m_per_sqrt_m: float = 0.005,
        yaw_noise_rad_per_sqrt_m: float = 0.005,
        turn_noise_rad_per_sqrt_rad: float = 0.01,
        rng: np.random.Generator,
    ) -> None:
        start = np.asarray(start, dtype=float).reshape(-1, 3)
        params = {
            "scale_error_std": scale_error_std,
            "yaw_bias_std_rad_per_m": yaw_bias_std_rad_per_m,
            "trans_noise_m_per_sqrt_m": trans_noise_m_per_sqrt_m,
            "yaw_noise_rad_per_sqrt_m": yaw_noise_rad_per_sqrt_m,
            "turn_noise_rad_per_sqrt_rad": turn_noise_rad_per_sqrt_rad,
        }
        for name, value in params.items():
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"odometry.{name} must be >= 0 (got {value})")
        self.rng = rng
        self.trans_noise = float(trans_noise_m_per_sqrt_m)
        self.yaw_noise = float(yaw_noise_rad_per_sqrt_m)
        self.turn_noise = float(turn_noise_rad_per_sqrt_rad)
        n = len(start)
        self.scale = 1.0 + scale_error_std * rng.standard_normal(n)
        self.yaw_bias = yaw_bias_std_rad_per_m * rng.standard_normal(n)
        self.true_prev = start.copy()
        self.odom = start.copy()

    def step(self, true_now: np.ndarray) -> np.ndarray:
        """Advance with the robots' new true poses ``(n, 3)``; returns odometry poses
        ``(n, 3)`` (a copy)."""
        true_now = np.asarray(true_now, dtype=float).reshape(self.odom.shape)
        rot1, trans, rot2 = relative_motion(self.true_prev, true_now)
        n = len(trans)
        z = self.rng.standard_normal((n, 3))
        # Reversing (rot1 near pi, rot2 near -pi) is not a half turn each way: the wheels turn
        # by the smaller of a rotation and its reverse, as in _sample_odometry.
        r1 = _turn_magnitude(rot1)
        turned = r1 + _turn_magnitude(rot2)
        trans_o = trans * self.scale + self.trans_noise * np.sqrt(trans) * z[:, 0]
        rot1_o = rot1 + self.turn_noise * np.sqrt(r1) * z[:, 1]
        rot2_o = (
            rot2
            + self.yaw_bias * trans
            + np.hypot(self.yaw_noise * np.sqrt(trans), self.turn_noise * np.sqrt(turned)) * z[:, 2]
        )
        th = self.odom[:, 2] + rot1_o
        self.odom = np.column_stack(
            [
                self.odom[:, 0] + trans_o * np.cos(th),
                self.odom[:, 1] + trans_o * np.sin(th),
                wrap_angle(th + rot2_o),
            ]
        )
        self.true_prev = true_now.copy()
        return self.odom.copy()

    def kidnap(self, robots, true_poses: np.ndarray) -> None:
        """Robots ``robots`` (index or indices) were carried to ``true_poses`` ``(k, 3)``; their
        odometry does not notice. Call before the next :meth:`step`."""
        idx = np.atleast_1d(np.asarray(robots, dtype=np.int64))
        self.true_prev[idx] = np.asarray(true_poses, dtype=float).reshape(len(idx), 3)
