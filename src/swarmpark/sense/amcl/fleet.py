"""AMCL for a whole fleet (:class:`FleetLocalizer`: one :class:`ParticleFilter` per skid,
beams that hit other skids masked) and the run's localization error (:func:`pose_error_summary`)."""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np
import shapely

from swarmpark.core.geometry import Footprint, footprint_corners, pad_polygons, wrap_angle
from swarmpark.sense.amcl.config import FilterConfig
from swarmpark.sense.amcl.filter import ParticleFilter
from swarmpark.sense.amcl.likelihood import LikelihoodField
from swarmpark.sense.lidar import LidarSpec, scan

if TYPE_CHECKING:
    from swarmpark.sim.odometry import OdometryDrift

__all__ = ["FleetLocalizer", "pose_error_summary"]


def _grow_convex(polys: np.ndarray, margin_m: float) -> np.ndarray:
    """Convex polygons ``(P, K, 2)`` grown by ``margin_m`` (mitred corners, via shapely),
    counter-clockwise and padded to a common vertex count."""
    geoms = shapely.buffer(shapely.polygons(polys), margin_m, join_style="mitre")
    rings = [np.asarray(g.exterior.coords)[:-1] for g in geoms]
    rings = [r if shapely.LinearRing(r).is_ccw else r[::-1] for r in rings]
    return pad_polygons(rings, max(len(r) for r in rings))


class FleetLocalizer:
    """AMCL for every skid of a fleet, fed with simulated drifting odometry.

    One call per simulation step turns the skids' true poses and their scans into pose
    estimates: the odometry model drifts from the true motion, each skid's filter predicts
    with its odometry increment and, once it has moved far enough (amcl's ``update_min_d`` /
    ``update_min_a``), weighs its particles by its scan.

    Parameters
    ----------
    field
        The shared map's :class:`LikelihoodField`.
    spec
        The scanner (the same on every skid).
    start_poses
        ``(N, 3)`` true start poses (the odometry starts there).
    rng
        Generator; every skid's filter and the odometry get their own child stream.
    config
        Filter settings for all skids.
    initial_std
        Spread of the initial particle clouds around ``start_poses``; ``None`` starts every
        filter uniform over free space (global localization).
    odometry
        Drift model; ``None`` builds the default :class:`OdometryDrift`.
    footprint, other_skid_margin_m
        With a footprint, beams that run into another skid's footprint at its current estimate
        (grown by the margin) are not scored: a neighbour a metre away hides a large part of
        the walls, and its outline in the scan fits no map, which otherwise makes the filter
        inject particles and jump to a wrong pose that happens to fit the occluded scan.
    update_min_d_m, update_min_a_rad
        A skid's scan is used only after it moved this far or turned this much since its last
        sensor update (0 = every step).

    Examples
    --------
    >>> from swarmpark.core.gridmap import OccupancyGrid
    >>> from swarmpark.sense.lidar import scan
    >>> g = OccupancyGrid(np.zeros((60, 80), bool), 0.1)
    >>> spec = LidarSpec(num_beams=360)
    >>> start = np.array([[2.0, 3.0, 0.0], [6.0, 3.0, np.pi]])
    >>> loc = FleetLocalizer(LikelihoodField(g), spec, start, rng=np.random.default_rng(0))
    >>> est = loc.step(start, scan(spec, start, g))
    >>> bool(np.all(loc.errors(start)[0] < 0.1))
    True
    """

    def __init__(
        self,
        field: LikelihoodField,
        spec: LidarSpec,
        start_poses: np.ndarray,
        *,
        rng: np.random.Generator,
        config: FilterConfig | None = None,
        initial_std: tuple[float, float, float] | None = (0.05, 0.05, np.radians(2.0)),
        odometry: OdometryDrift | None = None,
        update_min_d_m: float = 0.0,
        update_min_a_rad: float = 0.0,
        footprint: Footprint | None = None,
        other_skid_margin_m: float = 0.25,
    ) -> None:
        start = np.asarray(start_poses, dtype=float).reshape(-1, 3)
        n = len(start)
        self.spec = spec
        self._grown_body = None
        self.other_skid_margin_m = float(other_skid_margin_m)
        if footprint is not None:
            grown = Footprint(
                length_m=footprint.length_m + 2 * other_skid_margin_m,
                width_m=footprint.width_m + 2 * other_skid_margin_m,
                pivot_from_rear_m=footprint.pivot + other_skid_margin_m,
            )
            self._grown_body = grown.corners_body()
        streams = rng.spawn(n + 1)
        if odometry is None:
            # Imported here: the simulated odometry is the robot's sensor model (sim/), which
            # itself uses this package's motion model.
            from swarmpark.sim.odometry import OdometryDrift

            odometry = OdometryDrift(start, rng=streams[n])
        self.odometry = odometry
        if self.odometry.odom.shape != start.shape:
            raise ValueError(
                f"fleet: odometry is for {len(self.odometry.odom)} skids, start_poses for {n}"
            )
        self.filters = [
            ParticleFilter(
                field,
                spec,
                config=config,
                rng=streams[i],
                initial_pose=None if initial_std is None else start[i],
                initial_std=initial_std if initial_std is not None else (0.0, 0.0, 0.0),
            )
            for i in range(n)
        ]
        self.update_min_d_m = float(update_min_d_m)
        self.update_min_a_rad = float(update_min_a_rad)
        self._odom_prev = self.odometry.odom.copy()
        self._odom_at_update = np.full_like(start, np.nan)  # nan: update at the first scan
        self.estimates = start.copy() if initial_std is not None else np.full_like(start, np.nan)
        self.covariances = np.zeros((n, 3, 3))

    def step(
        self,
        true_poses: np.ndarray,
        ranges: np.ndarray,
        known_polygons: np.ndarray | None = None,
    ) -> np.ndarray:
        """Advance all skids to ``true_poses`` ``(N, 3)`` with their scans ``(N, B)`` taken
        there; returns the pose estimates ``(N, 3)`` (also kept in :attr:`estimates`).

        ``known_polygons`` ``(P, K, 2)`` are obstacles whose place is known but which the map
        lacks (skids outside this localizer, pallets placed by the operator); beams that run
        into them (grown by the margin) are not scored, as for the fleet's own skids."""
        odom = self.odometry.step(true_poses)
        ranges = np.asarray(ranges, dtype=float).reshape(len(self.filters), -1)
        ignore = self.other_skid_beams(ranges, known_polygons)
        for i, pf in enumerate(self.filters):
            pf.predict(self._odom_prev[i], odom[i])
            last = self._odom_at_update[i]
            moved = np.isnan(last[0]) or (
                np.hypot(*(odom[i, :2] - last[:2])) >= self.update_min_d_m
                or abs(wrap_angle(odom[i, 2] - last[2])) >= self.update_min_a_rad
            )
            if moved:
                pf.update(ranges[i], None if ignore is None else ignore[i])
                self._odom_at_update[i] = odom[i]
            est = pf.estimate()
            self.estimates[i] = est.pose
            self.covariances[i] = est.cov
        self._odom_prev = odom
        return self.estimates.copy()

    def other_skid_beams(
        self, ranges: np.ndarray, known_polygons: np.ndarray | None = None
    ) -> np.ndarray | None:
        """``(N, B)`` beams of each skid that reach another skid's grown footprint at its
        current estimate, or one of ``known_polygons`` (``None`` if there is nothing to mask
        or no estimate yet)."""
        est = self.estimates
        n = len(est)
        if not np.all(np.isfinite(est)):
            return None
        polys, owner = [], []
        if self._grown_body is not None and n > 1:
            polys.append(footprint_corners(est, np.broadcast_to(self._grown_body, (n, 4, 2))))
            owner.append(np.arange(n))
        if known_polygons is not None and len(known_polygons):
            polys.append(
                _grow_convex(np.asarray(known_polygons, dtype=float), self.other_skid_margin_m)
            )
            owner.append(np.full(len(polys[-1]), -1))
        if not polys:
            return None
        k = max(p.shape[1] for p in polys)
        polys = [p if p.shape[1] == k else pad_polygons(list(p), k) for p in polys]
        exact = replace(self.spec, range_noise_std_m=0.0, dropout_prob=0.0)
        reach = scan(
            exact, est, None, polygons=np.concatenate(polys), polygon_owner=np.concatenate(owner)
        )
        # A return no shorter than where the beam meets the polygon (less the margin: range
        # noise, and known polygons are not grown) may come from it.
        with np.errstate(invalid="ignore"):
            return np.isfinite(reach) & ~(ranges < reach - self.other_skid_margin_m)

    def kidnap(self, robots, true_poses: np.ndarray) -> None:
        """Skids ``robots`` (index or indices) were carried to ``true_poses`` ``(k, 3)``; their
        odometry does not notice (call before the next :meth:`step`)."""
        self.odometry.kidnap(robots, true_poses)

    def errors(self, true_poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Position (m) and absolute yaw (rad) errors ``(N,)`` of the current estimates."""
        t = np.asarray(true_poses, dtype=float).reshape(self.estimates.shape)
        pos = np.hypot(self.estimates[:, 0] - t[:, 0], self.estimates[:, 1] - t[:, 1])
        return pos, np.abs(wrap_angle(self.estimates[:, 2] - t[:, 2]))


def pose_error_summary(estimates: np.ndarray, truth: np.ndarray) -> dict[str, float]:
    """Localization error over a run: ``estimates`` and ``truth`` ``(T, N, 3)`` (or
    ``(T, 3)``) give ``mean_m``, ``p95_m``, ``max_m`` of the position error and ``mean_yaw_rad``,
    ``max_yaw_rad`` (the run-result figures of issue 6).

    Examples
    --------
    >>> truth = np.zeros((2, 3))
    >>> est = np.array([[0.03, 0.04, 0.1], [0.0, 0.0, -0.2]])
    >>> {k: round(v, 3) for k, v in pose_error_summary(est, truth).items()}
    {'mean_m': 0.025, 'p95_m': 0.048, 'max_m': 0.05, 'mean_yaw_rad': 0.15, 'max_yaw_rad': 0.2}
    """
    e = np.asarray(estimates, dtype=float)
    t = np.asarray(truth, dtype=float)
    if e.shape != t.shape or e.shape[-1] != 3:
        raise ValueError(
            f"pose_error_summary: estimates {e.shape} and truth {t.shape} must both be (..., 3)"
        )
    pos = np.hypot(e[..., 0] - t[..., 0], e[..., 1] - t[..., 1]).ravel()
    yaw = np.abs(wrap_angle(e[..., 2] - t[..., 2])).ravel()
    return {
        "mean_m": float(pos.mean()),
        "p95_m": float(np.percentile(pos, 95)),
        "max_m": float(pos.max()),
        "mean_yaw_rad": float(yaw.mean()),
        "max_yaw_rad": float(yaw.max()),
    }
