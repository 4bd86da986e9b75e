"""Odometry motion model of the particle filter (Thrun, Burgard and Fox 2005, Table 5.6):
a pose increment as ``(rot1, trans, rot2)`` and sampling noisy poses from it."""

from __future__ import annotations

import numpy as np

from swarmpark.core.geometry import wrap_angle

__all__ = ["relative_motion", "MIN_TRANSLATION_FOR_HEADING_M"]

#: Below this translation (metres) the heading of the motion (rot1) is meaningless: turn in
#: place, as amcl does.
MIN_TRANSLATION_FOR_HEADING_M = 0.01


def relative_motion(prev: np.ndarray, now: np.ndarray) -> tuple[np.ndarray, ...]:
    """Odometry increment ``(rot1, trans, rot2)`` between poses ``(..., 3)`` (Thrun Table 5.6).

    Below :data:`MIN_TRANSLATION_FOR_HEADING_M` the direction of the motion is noise: it counts
    as straight ahead (``rot1 = 0``) or, when the skid moved backwards, straight back
    (``rot1 = pi``). Calling every short step "ahead" made a skid reversing slower than
    0.2 m/s at 20 Hz move forwards in its odometry and its filter.
    """
    prev, now = np.asarray(prev, dtype=float), np.asarray(now, dtype=float)
    dx, dy = now[..., 0] - prev[..., 0], now[..., 1] - prev[..., 1]
    trans = np.hypot(dx, dy)
    heading = np.arctan2(dy, dx)
    backwards = dx * np.cos(prev[..., 2]) + dy * np.sin(prev[..., 2]) < 0
    rot1 = np.where(
        trans < MIN_TRANSLATION_FOR_HEADING_M,
        np.where(backwards, np.pi, 0.0),
        wrap_angle(heading - prev[..., 2]),
    )
    rot2 = wrap_angle(now[..., 2] - prev[..., 2] - rot1)
    return rot1, trans, rot2


def _turn_magnitude(rot: np.ndarray) -> np.ndarray:
    """The smaller of ``|rot|`` and ``|rot - pi|``: how far the wheels really turn for a
    rotation of the odometry increment (driving backwards is ``rot1 = pi``, not a half turn)."""
    return np.minimum(np.abs(wrap_angle(rot)), np.abs(wrap_angle(rot - np.pi)))


def _sample_odometry(
    poses: np.ndarray,
    rot1: np.ndarray,
    trans: np.ndarray,
    rot2: np.ndarray,
    alphas: tuple[float, float, float, float],
    rng: np.random.Generator,
) -> np.ndarray:
    """Thrun's sample_motion_model_odometry for poses ``(M, 3)``. As in amcl, the rotation noise
    uses the smaller of a rotation and its reverse, so that driving backwards (rot1 near pi)
    is not treated as a half turn."""
    a1, a2, a3, a4 = alphas
    m = len(poses)
    r1n, r2n = _turn_magnitude(rot1), _turn_magnitude(rot2)
    sd_r1 = np.sqrt(a1 * r1n**2 + a2 * trans**2)
    sd_tr = np.sqrt(a3 * trans**2 + a4 * (r1n**2 + r2n**2))
    sd_r2 = np.sqrt(a1 * r2n**2 + a2 * trans**2)
    z = rng.standard_normal((m, 3))
    h1 = rot1 + sd_r1 * z[:, 0]
    tr = trans + sd_tr * z[:, 1]
    h2 = rot2 + sd_r2 * z[:, 2]
    out = np.empty_like(poses)
    th = poses[:, 2] + h1
    out[:, 0] = poses[:, 0] + tr * np.cos(th)
    out[:, 1] = poses[:, 1] + tr * np.sin(th)
    out[:, 2] = wrap_angle(th + h2)
    return out
