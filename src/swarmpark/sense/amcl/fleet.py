"""AMCL for a whole fleet (:class:`FleetLocalizer`: one onboard :class:`RobotLocalizer` per
skid, fed with the odometry and scans the skids report; beams that hit other skids masked) and
the run's localization error against the truth (:func:`pose_error_summary`, for reports)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import shapely

from swarmpark.core.geometry import Footprint, footprint_corners, pad_polygons, wrap_angle
from swarmpark.sense.amcl.config import FilterConfig
from swarmpark.sense.amcl.coop import (
    CoopConfig,
    LandmarkBeams,
    compose_odometry,
    neighbour_beams,
    pose_variance,
)
from swarmpark.sense.amcl.filter import ParticleFilter
from swarmpark.sense.amcl.likelihood import LikelihoodField
from swarmpark.sense.lidar import LidarSpec, beam_angles, scan

__all__ = ["FleetLocalizer", "RobotLocalizer", "pose_error_summary"]


def _grow_convex(polys: np.ndarray, margin_m: float) -> np.ndarray:
    """Convex polygons ``(P, K, 2)`` grown by ``margin_m`` (mitred corners, via shapely),
    counter-clockwise and padded to a common vertex count."""
    geoms = shapely.buffer(shapely.polygons(polys), margin_m, join_style="mitre")
    rings = [np.asarray(g.exterior.coords)[:-1] for g in geoms]
    rings = [r if shapely.LinearRing(r).is_ccw else r[::-1] for r in rings]
    return pad_polygons(rings, max(len(r) for r in rings))


class RobotLocalizer:
    """One skid's onboard AMCL: its particle filter, fed with the odometry and the scans the
    skid reports, as the ``amcl`` node on the robot would be.

    The filter predicts with each odometry increment and, once the skid has moved far enough
    since its last sensor update (amcl's ``update_min_d`` / ``update_min_a``), weighs its
    particles by the scan. The odometry's frame does not matter, only its increments.

    Parameters
    ----------
    filter
        The skid's :class:`ParticleFilter`.
    odom_start
        The odometry pose ``(3,)`` the skid reported when the filter was seeded (``None``: the
        first :meth:`step` only records its odometry).
    update_min_d_m, update_min_a_rad
        Sensor-update thresholds (0 = every step).
    """

    def __init__(
        self,
        filter: ParticleFilter,
        odom_start: np.ndarray | None = None,
        *,
        update_min_d_m: float = 0.0,
        update_min_a_rad: float = 0.0,
    ) -> None:
        self.filter = filter
        self.update_min_d_m = float(update_min_d_m)
        self.update_min_a_rad = float(update_min_a_rad)
        self._odom_prev = None if odom_start is None else np.asarray(odom_start, float).copy()
        self._odom_at_update = np.full(3, np.nan)  # nan: update at the first scan

    def step(self, odom: np.ndarray, ranges: np.ndarray, ignore: np.ndarray | None = None):
        """Predict to the odometry pose ``odom`` ``(3,)``, weigh by ``ranges`` ``(B,)`` (beams in
        ``ignore`` not scored) if moved enough; returns the :class:`PoseEstimate`."""
        self.predict(odom)
        return self.correct(odom, ranges, ignore)

    def predict(self, odom: np.ndarray) -> None:
        """Move the particles by the odometry increment to ``odom`` ``(3,)``."""
        odom = np.asarray(odom, float)
        if self._odom_prev is not None:
            self.filter.predict(self._odom_prev, odom)
        self._odom_prev = odom.copy()

    def correct(
        self,
        odom: np.ndarray,
        ranges: np.ndarray,
        ignore: np.ndarray | None = None,
        landmarks: LandmarkBeams | None = None,
    ):
        """After :meth:`predict` to ``odom``: weigh by ``ranges`` (and the neighbours'
        ``landmarks``, see :mod:`.coop`) if moved enough; returns the :class:`PoseEstimate`."""
        odom = np.asarray(odom, float)
        pf = self.filter
        last = self._odom_at_update
        moved = np.isnan(last[0]) or (
            np.hypot(*(odom[:2] - last[:2])) >= self.update_min_d_m
            or abs(wrap_angle(odom[2] - last[2])) >= self.update_min_a_rad
        )
        if moved:
            pf.update(ranges, ignore, landmarks)
            self._odom_at_update = odom.copy()
        return pf.estimate()


class FleetLocalizer:
    """AMCL for every skid of a fleet: one :class:`RobotLocalizer` per skid, fed with what the
    skids report (odometry and scans), and the fleet's knowledge of where the skids are used
    to mask the beams that hit each other.

    Parameters
    ----------
    field
        The shared map's :class:`LikelihoodField`.
    spec
        The scanner (the same on every skid).
    start_poses
        ``(N, 3)`` initial poses in the map (the operator's initial pose estimate).
    rng
        Generator; every skid's filter gets its own child stream (child ``i`` for skid ``i``).
    config
        Filter settings for all skids.
    initial_std
        Spread of the initial particle clouds around ``start_poses``; ``None`` starts every
        filter uniform over free space (global localization).
    odom_start
        ``(N, 3)`` the odometry poses the skids reported at the start (``None``: the first
        :meth:`step` only records them).
    footprint, other_skid_margin_m
        With a footprint, beams that run into another skid's footprint at its current estimate
        (grown by the margin) are not scored: a neighbour a metre away hides a large part of
        the walls, and its outline in the scan fits no map, which otherwise makes the filter
        inject particles and jump to a wrong pose that happens to fit the occluded scan.
    update_min_d_m, update_min_a_rad
        A skid's scan is used only after it moved this far or turned this much since its last
        sensor update (0 = every step).
    coop
        Cooperative localization (:mod:`.coop`): the returns off neighbouring skids are
        scored against their outlines at their estimates (``None``: not scored, only masked).
    footprints
        Every skid's footprint for ``coop`` (default: ``footprint`` for all).

    Examples
    --------
    >>> from swarmpark.core.gridmap import OccupancyGrid
    >>> from swarmpark.sense.lidar import scan
    >>> g = OccupancyGrid(np.zeros((60, 80), bool), 0.1)
    >>> spec = LidarSpec(num_beams=360)
    >>> start = np.array([[2.0, 3.0, 0.0], [6.0, 3.0, np.pi]])
    >>> loc = FleetLocalizer(LikelihoodField(g), spec, start, rng=np.random.default_rng(0),
    ...                      odom_start=start)
    >>> est = loc.step(start, scan(spec, start, g))  # odometry: the skids stood still
    >>> bool(np.all(np.hypot(*(est[:, :2] - start[:, :2]).T) < 0.1))
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
        odom_start: np.ndarray | None = None,
        update_min_d_m: float = 0.0,
        update_min_a_rad: float = 0.0,
        footprint: Footprint | None = None,
        other_skid_margin_m: float = 0.25,
        coop: CoopConfig | None = None,
        footprints: list[Footprint] | tuple[Footprint, ...] | None = None,
    ) -> None:
        start = np.asarray(start_poses, dtype=float).reshape(-1, 3)
        n = len(start)
        self.coop = coop
        self.field = field
        if coop is not None:
            fps = list(footprints) if footprints is not None else [footprint] * n
            if len(fps) != n or any(f is None for f in fps):
                raise ValueError(f"fleet: coop needs a footprint for each of the {n} skids")
            self._halves = np.array([[f.length_m / 2, f.width_m / 2] for f in fps])
            self._center_offsets = np.array([f.center_offset_m for f in fps])
            self._beam_dirs = beam_angles(spec) + spec.mount_yaw_rad
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
        if odom_start is not None:
            odom_start = np.asarray(odom_start, dtype=float)
            if odom_start.shape != start.shape:
                raise ValueError(
                    f"fleet: odom_start is {odom_start.shape}, start_poses {start.shape}"
                )
        streams = rng.spawn(n)
        self.robots = [
            RobotLocalizer(
                ParticleFilter(
                    field,
                    spec,
                    config=config,
                    rng=streams[i],
                    initial_pose=None if initial_std is None else start[i],
                    initial_std=initial_std if initial_std is not None else (0.0, 0.0, 0.0),
                ),
                None if odom_start is None else odom_start[i],
                update_min_d_m=update_min_d_m,
                update_min_a_rad=update_min_a_rad,
            )
            for i in range(n)
        ]
        self.estimates = start.copy() if initial_std is not None else np.full_like(start, np.nan)
        self.covariances = np.zeros((n, 3, 3))
        # The odometry each estimate was made at (to carry neighbours' estimates forward).
        self._odom_at_estimate = (
            np.full_like(start, np.nan) if odom_start is None else odom_start.copy()
        )

    @property
    def filters(self) -> list[ParticleFilter]:
        return [r.filter for r in self.robots]

    def step(
        self,
        odom: np.ndarray,
        ranges: np.ndarray,
        known_polygons: np.ndarray | None = None,
        robots: np.ndarray | None = None,
    ) -> np.ndarray:
        """Localize the skids with their odometry poses ``odom`` ``(N, 3)`` and the scans
        ``ranges`` ``(N, B)`` they took there; returns the pose estimates ``(N, 3)`` (also
        kept in :attr:`estimates`).

        ``robots`` limits the step to the skids with a new report (the others keep their
        estimates and catch up with their odometry at their next report). ``known_polygons``
        ``(P, K, 2)`` are obstacles whose place is known but which the map lacks (skids
        outside this localizer, pallets placed by the operator); beams that run into them
        (grown by the margin) are not scored, as for the fleet's own skids."""
        odom = np.asarray(odom, dtype=float).reshape(len(self.robots), 3)
        ranges = np.asarray(ranges, dtype=float).reshape(len(self.robots), -1)
        ignore = self.other_skid_beams(ranges, known_polygons)
        todo = range(len(self.robots)) if robots is None else np.asarray(robots, dtype=int)
        if self.coop is not None:
            self._step_coop(odom, ranges, ignore, todo)
            return self.estimates.copy()
        for i in todo:
            est = self.robots[i].step(odom[i], ranges[i], None if ignore is None else ignore[i])
            self.estimates[i] = est.pose
            self.covariances[i] = est.cov
        return self.estimates.copy()

    def _step_coop(self, odom, ranges, ignore, todo) -> None:
        """Cooperative step: every reporting skid predicts, then each weighs its scan with the
        neighbours it detects as landmarks at their estimates carried forward by their
        odometry (all from before this step's updates, so the order of the skids does not
        matter)."""
        todo = np.asarray(list(todo), dtype=int)
        predicted = compose_odometry(self.estimates, self._odom_at_estimate, odom)
        var = pose_variance(self.covariances, self._halves[:, 0])
        mount = (self.spec.mount_x_m, self.spec.mount_y_m)
        for i in todo:
            self.robots[i].predict(odom[i])
        for i in todo:
            ig = None if ignore is None else ignore[i]
            lm = neighbour_beams(
                i, ranges[i], self._beam_dirs, mount, self.spec.max_range_m, predicted, var,
                self._center_offsets, self._halves, self.field.distance, self.coop,
            )  # fmt: skip
            if lm is not None:
                ig = np.zeros(ranges.shape[1], bool) if ig is None else ig.copy()
                ig[lm.beams] = True
            est = self.robots[i].correct(odom[i], ranges[i], ig, lm)
            self.estimates[i] = est.pose
            self.covariances[i] = est.cov
        self._odom_at_estimate[todo] = odom[todo]

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
