"""Cooperative localization: the other skids as moving landmarks in each skid's particle filter.

On an open deck a skid may have nothing of the map within its LIDAR's range, but it sees its
neighbours. Following Fox, Burgard, Kruppa and Thrun (2000), "A probabilistic approach to
collaborative multi-robot localization" (Autonomous Robots 8(3), 325-344), when skid *i*
detects skid *j*, *i*'s particles are weighted by the likelihood of the detection given *j*'s
belief (their Eq. 14-16, here with *j*'s belief summarized by its estimate and covariance, as
Prorok, Bahr and Martinoli 2012 do for range-bearing detections). This is how the fleet shares
one reference frame (the 2018 paper, Sect. 3.5.2): skids that see walls anchor the ones that
see only skids.

The detection comes from the scan alone, never from the simulator's truth: a return is
*j*'s when its end point (at *i*'s predicted pose) lies on or near *j*'s rectangle where *j*'s
predicted estimate puts it (within :attr:`CoopConfig.gate_m` plus twice *j*'s standard
deviation) and is not explained by the map (farther than
:attr:`CoopConfig.min_map_distance_m` from mapped structure). Each such return is scored like
a likelihood-field beam against *j*'s outline (:func:`rectangle_log_likelihood`).

Two rules keep the fleet from talking itself into a shared error:

- *j*'s returns move together with *j*'s estimate error, so together they are one measurement,
  not ``K`` independent ones: each is weighted by ``1 / (1 + K sigma_j^2 / sigma^2)``, which
  gives exactly the information ``1 / (sigma^2 / K + sigma_j^2)`` of a Gaussian offset shared
  by ``K`` returns of noise ``sigma``;
- *i* uses *j* only if *j* is more certain than *i* (variance below
  :attr:`CoopConfig.certainty_ratio` times *i*'s): detections in both directions would count
  the same evidence twice, the over-confidence Fox et al. warn of for the factorial
  representation (Sect. 3.3 there). :attr:`CoopConfig.mutual_inflation` (off by default)
  lets a skid that sees no mapped structure use less certain neighbours too, at twice their
  variance (covariance intersection with omega = 1/2, Julier and Uhlmann 1997), so that a
  block with nothing in range averages its independent odometry errors; on the open-deck
  training sites it gave larger mean errors (docs/sensing.md).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from scipy.spatial import cKDTree

from swarmpark.core.geometry import wrap_angle

__all__ = [
    "CoopConfig",
    "LandmarkBeams",
    "rectangle_distance",
    "rectangle_log_likelihood",
    "compose_odometry",
    "neighbour_beams",
    "pose_variance",
]


@dataclass(frozen=True, kw_only=True)
class CoopConfig:
    """Settings of cooperative localization.

    Parameters
    ----------
    sigma_m
        Standard deviation of a return about a neighbour's outline (range noise, the corners
        a rectangle model lacks).
    gate_m
        A return within this distance of a neighbour's outline (plus twice the neighbour's
        standard deviation) may be the neighbour's.
    min_map_distance_m
        Returns closer than this to mapped structure are the map's, not a neighbour's.
    certainty_ratio
        Skid *i* uses neighbour *j* as it is if ``var_j < certainty_ratio * var_i``.
    mutual_inflation
        A neighbour *j* no more certain than *i* is used with its variance times this
        (``None``: not used): *j* may be using *i* at the same time, and covariance
        intersection with equal weights (omega = 1/2) bounds what the two count twice by
        halving the information of each side (Julier and Uhlmann 1997). It lets the skids
        of a block that sees no structure average their independent odometry errors instead
        of all following the most certain one. Off by default: on the open-deck training
        sites it parked faster but with larger mean errors (docs/sensing.md). Only a skid that sees no mapped structure
        (fewer than ``anchor_returns`` returns the map explains) does this: one that sees
        walls keeps to them and to more certain neighbours.
    anchor_returns
        See ``mutual_inflation``.
    min_returns, max_returns
        A neighbour needs this many returns to count as detected; at most ``max_returns`` of
        them (evenly spread) are scored.
    """

    sigma_m: float = 0.05
    gate_m: float = 0.25
    min_map_distance_m: float = 0.2
    certainty_ratio: float = 1.0
    mutual_inflation: float | None = None
    anchor_returns: int = 10
    min_returns: int = 3
    max_returns: int = 20

    def __post_init__(self) -> None:
        for name in ("sigma_m", "gate_m", "min_map_distance_m", "certainty_ratio"):
            if not getattr(self, name) > 0:
                raise ValueError(f"coop.{name} must be > 0 (got {getattr(self, name)})")
        if self.mutual_inflation is not None and not self.mutual_inflation >= 1:
            raise ValueError(f"coop.mutual_inflation must be >= 1 (got {self.mutual_inflation})")
        if not 1 <= self.min_returns <= self.max_returns:
            raise ValueError(
                "coop.min_returns and max_returns must satisfy 1 <= min <= max "
                f"(got {self.min_returns}, {self.max_returns})"
            )


class LandmarkBeams(NamedTuple):
    """Returns of one skid's scan that hit neighbours, with the neighbour each one hit.

    ``beams`` ``(K,)`` scan indices; ``pose`` ``(K, 3)`` the neighbour's estimated pivot pose;
    ``center_offset`` ``(K,)`` body-x offset of its rectangle's centre from the pivot;
    ``half`` ``(K, 2)`` half length and half width; ``weight`` ``(K,)`` the factor on each
    return's log-likelihood; ``sigma`` the standard deviation about the outline."""

    beams: np.ndarray
    pose: np.ndarray
    center_offset: np.ndarray
    half: np.ndarray
    weight: np.ndarray
    sigma: float


def rectangle_distance(
    x: np.ndarray,
    y: np.ndarray,
    pose: np.ndarray,
    center_offset: np.ndarray,
    half: np.ndarray,
) -> np.ndarray:
    """Distance from world points ``x``, ``y`` ``(..., K)`` to the outline of rectangles
    ``(K,)`` (pivot ``pose`` ``(K, 3)``, centre offset ``(K,)``, ``half`` ``(K, 2)``), from
    outside or inside.

    Examples
    --------
    >>> d = rectangle_distance(np.array([1.0, 0.0]), np.array([0.0, 0.2]),
    ...                        np.zeros((2, 3)), np.zeros(2), np.array([[0.6, 0.4]] * 2))
    >>> np.round(d, 3).tolist()
    [0.4, 0.2]
    """
    c, s = np.cos(pose[:, 2]), np.sin(pose[:, 2])
    cx = pose[:, 0] + c * center_offset
    cy = pose[:, 1] + s * center_offset
    dx, dy = x - cx, y - cy
    q = np.abs(c * dx + s * dy) - half[:, 0]
    r = np.abs(-s * dx + c * dy) - half[:, 1]
    outside = np.hypot(np.maximum(q, 0.0), np.maximum(r, 0.0))
    return np.where((q > 0) | (r > 0), outside, -np.maximum(q, r))


def rectangle_log_likelihood(
    x: np.ndarray, y: np.ndarray, lm: LandmarkBeams, z_hit: float, z_rand_density: float
) -> np.ndarray:
    """Weighted sum over the landmark returns of the likelihood-field log-likelihood of end
    points ``x``, ``y`` ``(M, K)`` against the neighbours' outlines: ``(M,)``."""
    d = rectangle_distance(x, y, lm.pose, lm.center_offset, lm.half)
    gauss = np.exp(-0.5 * (d / lm.sigma) ** 2) / (np.sqrt(2 * np.pi) * lm.sigma)
    return np.log(z_hit * gauss + z_rand_density) @ lm.weight


def compose_odometry(est: np.ndarray, odom_then: np.ndarray, odom_now: np.ndarray) -> np.ndarray:
    """Estimates ``(N, 3)`` made when the odometry read ``odom_then``, carried forward by the
    odometry increment to ``odom_now`` (the increment in the body frame, applied to the
    estimate). Non-finite odometry leaves an estimate as it is."""
    ct, st = np.cos(odom_then[:, 2]), np.sin(odom_then[:, 2])
    dx, dy = odom_now[:, 0] - odom_then[:, 0], odom_now[:, 1] - odom_then[:, 1]
    bx, by = ct * dx + st * dy, -st * dx + ct * dy
    dyaw = wrap_angle(odom_now[:, 2] - odom_then[:, 2])
    c, s = np.cos(est[:, 2]), np.sin(est[:, 2])
    out = np.column_stack(
        [est[:, 0] + c * bx - s * by, est[:, 1] + s * bx + c * by, wrap_angle(est[:, 2] + dyaw)]
    )
    ok = np.all(np.isfinite(out), axis=1)
    out[~ok] = est[~ok]
    return out


def pose_variance(cov: np.ndarray, half_length: np.ndarray) -> np.ndarray:
    """A skid's position variance for a neighbour looking at its outline ``(N,)``: the largest
    eigenvalue of the x-y covariance plus the yaw variance times the half length squared
    (a turned rectangle moves its ends)."""
    xy = np.linalg.eigvalsh(cov[:, :2, :2])[:, -1]
    return np.maximum(xy, 0.0) + np.maximum(cov[:, 2, 2], 0.0) * half_length**2


def _candidate_distance(wx, wy, pose, center_offset, half, cand) -> np.ndarray:
    """Distance ``(P, k)`` from points ``(P,)`` to the outlines of their candidate rectangles
    ``cand`` ``(P, k)`` (indices into ``pose``, ``center_offset``, ``half``)."""
    p = pose[cand]
    c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
    dx = wx[:, None] - (p[..., 0] + c * center_offset[cand])
    dy = wy[:, None] - (p[..., 1] + s * center_offset[cand])
    q = np.abs(c * dx + s * dy) - half[cand, 0]
    r = np.abs(-s * dx + c * dy) - half[cand, 1]
    outside = np.hypot(np.maximum(q, 0.0), np.maximum(r, 0.0))
    return np.where((q > 0) | (r > 0), outside, -np.maximum(q, r))


def neighbour_beams(
    i: int,
    ranges: np.ndarray,
    beam_dirs: np.ndarray,
    mount_xy: tuple[float, float],
    max_range_m: float,
    poses: np.ndarray,
    variances: np.ndarray,
    center_offsets: np.ndarray,
    halves: np.ndarray,
    map_distance,
    config: CoopConfig,
) -> LandmarkBeams | None:
    """Skid ``i``'s returns (``ranges`` ``(B,)``) that its neighbours explain and the map does
    not, each with the neighbour it hit, seen from the predicted ``poses`` ``(N, 3)``
    (``variances`` ``(N,)`` from :func:`pose_variance`); ``None`` when no neighbour that is
    more certain than ``i`` is detected. ``map_distance`` maps world points ``(P, 2)`` to
    their distance from mapped structure."""
    cfg = config
    p = poses[i]
    ok = np.isfinite(ranges) & (ranges < max_range_m)
    more_certain = variances < cfg.certainty_ratio * variances[i]
    if cfg.mutual_inflation is not None:
        # The less certain neighbours too, at an inflated variance (see CoopConfig).
        variances = np.where(more_certain, variances, cfg.mutual_inflation * variances)
    usable = more_certain if cfg.mutual_inflation is None else np.ones(len(poses), bool)
    others = np.flatnonzero(
        (np.arange(len(poses)) != i)
        & usable
        & (np.hypot(*(poses[:, :2] - p[:2]).T) < max_range_m + 2 * halves[:, 0] + 1.0)
        & np.all(np.isfinite(poses), axis=1)
    )
    if not len(others) or not ok.any():
        return None
    b = np.flatnonzero(ok)
    r, a = ranges[b], beam_dirs[b]
    lx, ly = mount_xy[0] + r * np.cos(a), mount_xy[1] + r * np.sin(a)
    c, s = np.cos(p[2]), np.sin(p[2])
    wx, wy = p[0] + c * lx - s * ly, p[1] + s * lx + c * ly
    unexplained = map_distance(np.column_stack([wx, wy])) > cfg.min_map_distance_m
    if cfg.mutual_inflation is not None and (~unexplained).sum() >= cfg.anchor_returns:
        # i sees mapped structure: it takes only neighbours more certain than itself.
        others = others[more_certain[others]]
        if not len(others):
            return None
    b, wx, wy = b[unexplained], wx[unexplained], wy[unexplained]
    if not len(b):
        return None
    # Candidates: the two neighbours whose rectangle centres are nearest each end point
    # (rectangles do not overlap), then the distance to those outlines only.
    gate = cfg.gate_m + 2.0 * np.sqrt(variances[others])
    op = poses[others]
    centres = op[:, :2] + center_offsets[others, None] * np.column_stack(
        [np.cos(op[:, 2]), np.sin(op[:, 2])]
    )
    reach = float(np.max(np.hypot(halves[others, 0], halves[others, 1]) + gate))
    n_cand = min(2, len(others))
    _, cand = cKDTree(centres).query(
        np.column_stack([wx, wy]), k=n_cand, distance_upper_bound=reach
    )
    cand = cand.reshape(len(b), n_cand)
    valid = cand < len(others)
    cj = np.where(valid, cand, 0)
    d = _candidate_distance(wx, wy, op, center_offsets[others], halves[others], cj)
    d = np.where(valid & (d <= gate[cj]), d, np.inf)
    pick = np.argmin(d, axis=1)
    rows = np.arange(len(b))
    hit = np.isfinite(d[rows, pick])
    near = cj[rows, pick]
    beams, owner = [], []
    for k, j in enumerate(others):
        mine = b[hit & (near == k)]
        if len(mine) < cfg.min_returns:
            continue
        if len(mine) > cfg.max_returns:
            mine = mine[np.linspace(0, len(mine) - 1, cfg.max_returns).round().astype(np.int64)]
        beams.append(mine)
        owner.append(np.full(len(mine), j))
    if not beams:
        return None
    beams_a, owner_a = np.concatenate(beams), np.concatenate(owner)
    count = np.bincount(owner_a, minlength=len(poses))[owner_a]
    weight = 1.0 / (1.0 + count * variances[owner_a] / cfg.sigma_m**2)
    return LandmarkBeams(
        beams_a, poses[owner_a], center_offsets[owner_a], halves[owner_a], weight, cfg.sigma_m
    )
