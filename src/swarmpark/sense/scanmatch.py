"""Point-to-line ICP (Censi 2008) of 2-D scan points against a reference point cloud with
surface normals: the one scan matcher of the mapping front end (scan to map,
:meth:`swarmpark.sense.mapping.GridMapper.match`) and of the loop closure (scan to keyframe
scan, :mod:`swarmpark.sense.slam`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial import cKDTree

from swarmpark.core.geometry import wrap_angle

if TYPE_CHECKING:
    from swarmpark.sense.mapping import MapperConfig

__all__ = ["IcpFit", "icp_point_to_line", "surface_reference"]

#: Neighbours used to estimate the surface normal at a reference point.
NORMAL_NEIGHBOURS = 7
#: ICP stops when a step moves less than this (and the gate is at its floor).
MATCH_CONVERGED_M = 1e-4
MATCH_CONVERGED_RAD = 1e-4


def surface_reference(points: np.ndarray) -> tuple[cKDTree, np.ndarray, np.ndarray]:
    """The reference of :func:`icp_point_to_line`: a KD-tree of ``points (M, 2)``, the points
    and the unit normals of the local surface at each (minor principal axis of its
    ``NORMAL_NEIGHBOURS`` nearest neighbours)."""
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    tree = cKDTree(pts)
    k = min(NORMAL_NEIGHBOURS, len(pts))
    _, nb = tree.query(pts, k=k)
    nbp = pts[nb]  # (M, k, 2)
    d = nbp - nbp.mean(axis=1, keepdims=True)
    sxx = np.einsum("mk,mk->m", d[..., 0], d[..., 0])
    syy = np.einsum("mk,mk->m", d[..., 1], d[..., 1])
    sxy = np.einsum("mk,mk->m", d[..., 0], d[..., 1])
    # Direction of least spread of a 2x2 covariance: angle of the major axis plus 90 deg.
    major = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)
    normals = np.column_stack([-np.sin(major), np.cos(major)])
    return tree, pts, normals


@dataclass(frozen=True)
class IcpFit:
    """Outcome of :func:`icp_point_to_line` before any acceptance test: the pose, the share of
    points with a correspondence and the RMS residual at the last iteration, the iterations,
    and the Gauss-Newton matrix ``J^T J`` (3 x 3, unit residual weights) of the last
    iteration, whose eigenvalues say how well the scan constrains each direction."""

    pose: np.ndarray
    inlier_share: float
    rms_m: float
    iterations: int
    hessian: np.ndarray


def icp_point_to_line(
    body: np.ndarray,
    guess: np.ndarray,
    reference: tuple[cKDTree, np.ndarray, np.ndarray],
    cfg: MapperConfig,
) -> IcpFit:
    """Point-to-line ICP (Censi 2008) of ``body (K, 2)`` points, given in the frame of a pose
    to be found, against ``reference`` (:func:`surface_reference`), starting from ``guess``.

    Uses ``cfg.match_iterations``, the gate ``cfg.match_max_dist_m`` halving to
    ``cfg.match_min_dist_m``, the damping ``cfg.match_prior_weight`` toward the guess and the
    degeneracy test ``cfg.match_degenerate_ratio`` (see :class:`MapperConfig`). The scan-to-map
    matcher of :class:`GridMapper` and the scan-to-scan matcher of the loop closure
    (:mod:`swarmpark.sense.slam`) both use it.
    """
    tree, ref_pts, normals = reference
    guess = np.asarray(guess, dtype=float).reshape(3)
    pose = guess.copy()
    inlier_share, rms, it = 0.0, float("nan"), 0
    hess = np.zeros((3, 3))
    eye3 = np.eye(3)
    for it in range(1, cfg.match_iterations + 1):
        # The gate halves each iteration down to its floor: wide first to pull in a poor
        # guess, narrow later so that other surfaces do not bias the fit.
        gate = max(cfg.match_min_dist_m, cfg.match_max_dist_m * 0.5 ** (it - 1))
        c, s = np.cos(pose[2]), np.sin(pose[2])
        px = pose[0] + c * body[:, 0] - s * body[:, 1]
        py = pose[1] + s * body[:, 0] + c * body[:, 1]
        dist, j = tree.query(np.column_stack([px, py]), distance_upper_bound=gate)
        ok = dist < np.inf
        n_ok = int(ok.sum())
        inlier_share = n_ok / len(body)
        if n_ok < 3:
            break
        jo = j[ok]
        nx, ny = normals[jo, 0], normals[jo, 1]
        ex, ey = px[ok] - pose[0], py[ok] - pose[1]  # lever arm: d p / d theta = (-ey, ex)
        res = nx * (px[ok] - ref_pts[jo, 0]) + ny * (py[ok] - ref_pts[jo, 1])
        jac = np.column_stack([nx, ny, nx * -ey + ny * ex])
        lam = cfg.match_prior_weight * n_ok
        prior = pose - guess
        prior[2] = wrap_angle(prior[2])
        hess = jac.T @ jac
        step = np.linalg.solve(hess + lam * eye3, -(jac.T @ res) - lam * prior)
        new = pose + step
        # Degeneracy (Zhang, Kaess and Singh 2016): along a direction the scan hardly
        # constrains -- the length of a wall, when it is all that is in range -- noise in
        # the normals would move the pose at random, scan after scan. Keep the odometry
        # guess there instead.
        evals, evecs = np.linalg.eigh(hess)
        weak = evals < cfg.match_degenerate_ratio * max(evals[-1], 1e-12)
        if weak.any():
            dev = new - guess
            dev[2] = wrap_angle(dev[2])
            coeff = evecs.T @ dev
            coeff[weak] = 0.0
            new = guess + evecs @ coeff
            step = new - pose
            step[2] = wrap_angle(step[2])
        pose = new
        pose[2] = wrap_angle(pose[2])
        rms = float(np.sqrt(np.mean(res * res)))
        small = abs(step[0]) + abs(step[1]) < MATCH_CONVERGED_M and abs(step[2]) < (
            MATCH_CONVERGED_RAD
        )
        if small and gate <= cfg.match_min_dist_m:
            break
    return IcpFit(pose, inlier_share, rms, it, hess)
