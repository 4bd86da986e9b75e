"""Occupancy-grid mapping from scans with scan matching (the agreement of a built map with a
ground truth is in :mod:`swarmpark.sense.agreement`).

:class:`GridMapper` keeps clamped log-odds (Thrun, *Probabilistic Robotics*, Table 9.1). A scan
clears the star-shaped region between the sensor and its end points (rasterized in one call
with Pillow's scan-line polygon fill instead of walking 1000 rays) and marks the end points'
cells occupied. Before a scan is inserted, the odometry guess is corrected by point-to-line ICP
(Censi 2008) of the scan against the end points already in the map (a scipy KD-tree), so a skid
with drifting odometry builds a consistent map. This is the front end of a SLAM system without
loop closure: fine for a hangar-sized route, not a replacement for GMapping's particle filter
on long loops.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from PIL import Image, ImageDraw
from scipy.spatial import cKDTree

from swarmpark.core.geometry import wrap_angle
from swarmpark.core.gridmap import DEFAULT_FREE_THRESH, DEFAULT_OCCUPIED_THRESH, OccupancyGrid
from swarmpark.sense.agreement import map_agreement  # moved there; re-exported for old callers
from swarmpark.sense.lidar import LidarSpec, beam_angles, sensor_poses

__all__ = [
    "MapperConfig",
    "GridMapper",
    "MatchResult",
    "compose",
    "relative_pose",
    "map_agreement",
]


#: Neighbours used to estimate the surface normal at a reference point.
NORMAL_NEIGHBOURS = 7
#: ICP stops when a step moves less than this (and the gate is at its floor).
MATCH_CONVERGED_M = 1e-4
MATCH_CONVERGED_RAD = 1e-4


def _logit(p: float) -> float:
    return float(np.log(p / (1.0 - p)))


def compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Pose composition ``a (+) b`` of poses ``(..., 3)``: ``b`` expressed in ``a``'s frame."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    return np.stack(
        [
            a[..., 0] + c * b[..., 0] - s * b[..., 1],
            a[..., 1] + s * b[..., 0] + c * b[..., 1],
            wrap_angle(a[..., 2] + b[..., 2]),
        ],
        -1,
    )


def relative_pose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Pose of ``b`` in ``a``'s frame (``a^-1 (+) b``), poses ``(..., 3)``.

    Examples
    --------
    >>> a, b = np.array([1.0, 2.0, 0.5]), np.array([-1.0, 0.3, 2.0])
    >>> np.allclose(compose(a, relative_pose(a, b)), b)
    True
    """
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    dx, dy = b[..., 0] - a[..., 0], b[..., 1] - a[..., 1]
    return np.stack([c * dx + s * dy, -s * dx + c * dy, wrap_angle(b[..., 2] - a[..., 2])], -1)


@dataclass(frozen=True, kw_only=True)
class MapperConfig:
    """Mapping and scan-matching settings.

    Parameters
    ----------
    l_occ, l_free
        Log-odds added to a cell per scan that hits it / passes through it.
    l_min, l_max
        Clamping of the log-odds, so that a cell can change its mind after a change.
    clear_no_return
        Beams with no return clear the cells up to the maximum range (the space is open).
    free_margin_cells
        Clearing stops this many cells short of an end point, so that range noise and the
        polygon fill's rounding do not erase the wall being hit.
    hit_depth_cells
        A return marks the cell this far behind its end point along the beam (returns lie on
        faces; without depth, noise would mark the free cell in front half of the time).
    match
        Correct the odometry guess by scan matching before inserting a scan.
    match_points
        Scan points used by the matcher (spread evenly over the returns).
    match_iterations
        Iteration cap of ICP.
    match_max_dist_m
        Correspondences farther than this are rejected (first iteration; the gate shrinks to
        ``match_min_dist_m`` over the iterations).
    match_min_dist_m
        Final correspondence gate.
    match_min_inliers
        Share of scan points that must find a correspondence, else the odometry guess is kept.
    match_max_correction_m, match_max_correction_rad
        A correction larger than this is not trusted (the odometry guess is kept).
    match_prior_weight
        Weight of a damping term that holds the solution near the odometry guess in directions
        the scan does not constrain (a long corridor).
    match_degenerate_ratio
        Directions of the pose in which the scan's information (eigenvalue of the Gauss-Newton
        matrix) is below this share of the best-constrained direction are left at the
        odometry guess.
    reference_refresh_scans
        The matcher's reference (KD-tree of the map's end points and their normals) is rebuilt
        after this many inserted scans (1 = every scan).
    insert_min_d_m, insert_min_a_rad
        :meth:`GridMapper.update` matches every scan but inserts one into the map only after
        the skid moved this far or turned this much since the last inserted scan (as
        GMapping's ``linearUpdate``/``angularUpdate``). Each insertion passes its small
        alignment error on to the map that later scans are matched against; at 20 scans per
        metre these errors add up to a bent map (a 25 m wall 0.3 deg askew), at 2 per metre
        to a third of that. ``0`` inserts every scan.
    """

    l_occ: float = 0.85
    l_free: float = -0.4
    l_min: float = -4.0
    l_max: float = 4.0
    clear_no_return: bool = True
    free_margin_cells: float = 0.5
    hit_depth_cells: float = 0.5
    match: bool = True
    match_points: int = 250
    match_iterations: int = 20
    match_max_dist_m: float = 0.5
    match_min_dist_m: float = 0.1
    match_min_inliers: float = 0.3
    match_max_correction_m: float = 0.5
    match_max_correction_rad: float = np.radians(15.0)
    match_prior_weight: float = 1e-3
    match_degenerate_ratio: float = 0.02
    reference_refresh_scans: int = 5
    insert_min_d_m: float = 0.5
    insert_min_a_rad: float = np.radians(15.0)

    def __post_init__(self) -> None:
        if not (self.l_occ > 0 and self.l_free < 0):
            raise ValueError(
                f"mapper.l_occ must be > 0 and l_free < 0 (got {self.l_occ}, {self.l_free})"
            )
        if not self.l_min < 0 < self.l_max:
            raise ValueError(f"mapper.l_min must be < 0 < l_max (got {self.l_min}, {self.l_max})")
        if not (self.insert_min_d_m >= 0 and self.insert_min_a_rad >= 0):
            raise ValueError(
                "mapper.insert_min_d_m and insert_min_a_rad must be >= 0 "
                f"(got {self.insert_min_d_m}, {self.insert_min_a_rad})"
            )
        if self.reference_refresh_scans < 1:
            raise ValueError(
                f"mapper.reference_refresh_scans must be >= 1 (got {self.reference_refresh_scans})"
            )
        if self.match_points < 3 or self.match_iterations < 1:
            raise ValueError(
                "mapper.match_points must be >= 3 and match_iterations >= 1 "
                f"(got {self.match_points}, {self.match_iterations})"
            )
        if not 0 < self.match_min_dist_m <= self.match_max_dist_m:
            raise ValueError(
                "mapper.match_min_dist_m must be in (0, match_max_dist_m] "
                f"(got {self.match_min_dist_m}, {self.match_max_dist_m})"
            )


@dataclass(frozen=True)
class MatchResult:
    """Outcome of one scan match: the pose used, whether the match was accepted, the share of
    scan points with a correspondence, the RMS point-to-line residual and the iterations."""

    pose: np.ndarray
    accepted: bool
    inlier_share: float
    rms_m: float
    iterations: int


class GridMapper:
    """Log-odds occupancy-grid mapping of one skid's scans, with scan matching.

    Parameters
    ----------
    shape
        ``(H, W)`` cells of the map.
    resolution_m
        Cell size.
    origin
        World ``(x, y)`` of the lower-left corner of cell ``(0, 0)``.
    spec
        The scanner.
    config
        Settings.

    Use :meth:`update` with odometry poses (it tracks the corrected pose), or :meth:`insert`
    with poses known otherwise. The map frame is the frame of the first pose given: a skid that
    maps from scratch starts where :meth:`update`'s ``initial_pose`` puts it (Hing 2018, Sect.
    3.5.2: other skids then share this frame by localizing in the map).
    """

    def __init__(
        self,
        shape: tuple[int, int],
        resolution_m: float,
        origin: tuple[float, float] = (0.0, 0.0),
        *,
        spec: LidarSpec,
        config: MapperConfig | None = None,
    ) -> None:
        h, w = (int(shape[0]), int(shape[1]))
        if h < 1 or w < 1:
            raise ValueError(f"mapper.shape must be positive (got {tuple(shape)})")
        if not resolution_m > 0:
            raise ValueError(f"mapper.resolution_m must be > 0 (got {resolution_m})")
        self.shape = (h, w)
        self.resolution_m = float(resolution_m)
        self.origin = (float(origin[0]), float(origin[1]))
        self.spec = spec
        self.config = config if config is not None else MapperConfig()
        self.log_odds = np.zeros(self.shape)
        self.observed = np.zeros(self.shape, dtype=bool)
        # Sum and count of end points per cell: the matcher's reference points are their means,
        # which keeps the wall where it was seen rather than at the centres of its cells.
        self._hit_sum = np.zeros((*self.shape, 2))
        self._hit_count = np.zeros(self.shape, dtype=np.int64)
        self._angles = beam_angles(spec)
        self.pose: np.ndarray | None = None
        self._odom: np.ndarray | None = None
        self._ref: tuple[cKDTree, np.ndarray, np.ndarray] | None = None
        self._ref_scan = 0
        self.scans = 0
        self._inserted_at: np.ndarray | None = None  # pose of the last inserted scan

    @classmethod
    def like(
        cls, grid: OccupancyGrid, *, spec: LidarSpec, config: MapperConfig | None = None
    ) -> GridMapper:
        """A mapper with the extent and resolution of ``grid`` (the map is not copied)."""
        return cls(grid.shape, grid.resolution_m, grid.origin, spec=spec, config=config)

    # -- scan geometry ------------------------------------------------------------------
    def _body_points(self, ranges: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Returns ``(hit_points (K, 2), hit_mask (B,))`` in the robot's body frame."""
        r = np.asarray(ranges, dtype=float).reshape(self.spec.num_beams)
        hit = np.isfinite(r) & (r < self.spec.max_range_m)
        a = self._angles + self.spec.mount_yaw_rad
        pts = np.column_stack(
            [
                self.spec.mount_x_m + r[hit] * np.cos(a[hit]),
                self.spec.mount_y_m + r[hit] * np.sin(a[hit]),
            ]
        )
        return pts, hit

    # -- insertion ----------------------------------------------------------------------
    def insert(self, pose: np.ndarray, ranges: np.ndarray) -> None:
        """Add a scan ``(B,)`` taken at ``pose`` (the skid's pivot) to the map."""
        cfg = self.config
        pose = np.asarray(pose, dtype=float).reshape(3)
        r = np.asarray(ranges, dtype=float).reshape(self.spec.num_beams)
        sensor = sensor_poses(self.spec, pose[None])[0]
        res = self.resolution_m
        h, w = self.shape
        ang = sensor[2] + self._angles
        finite = np.isfinite(r)
        clear_r = np.where(finite, r - cfg.free_margin_cells * res, np.nan)
        if cfg.clear_no_return:
            clear_r = np.where(np.isposinf(r), self.spec.max_range_m, clear_r)
        ok = np.isfinite(clear_r)
        clear_r = np.maximum(clear_r, 0.0)
        # Everything a scan touches lies within its range of the sensor (plus the hit depth):
        # work on that window only, so the cost does not grow with the map.
        reach = (self.spec.max_range_m + (cfg.hit_depth_cells + 1.0) * res) / res
        cx, cy = (sensor[0] - self.origin[0]) / res, (sensor[1] - self.origin[1]) / res
        c0, c1 = max(int(np.floor(cx - reach)), 0), min(int(np.ceil(cx + reach)) + 1, w)
        r0, r1 = max(int(np.floor(cy - reach)), 0), min(int(np.ceil(cy + reach)) + 1, h)
        if c1 <= c0 or r1 <= r0:
            self.scans += 1
            return
        # Clearing: the star polygon through the shortened end points, filled by Pillow in
        # pixel-centre coordinates (column u, row v) of the window.
        free = np.zeros((r1 - r0, c1 - c0), dtype=bool)
        if ok.sum() >= 2:
            u = (sensor[0] + clear_r[ok] * np.cos(ang[ok]) - self.origin[0]) / res - 0.5 - c0
            v = (sensor[1] + clear_r[ok] * np.sin(ang[ok]) - self.origin[1]) / res - 0.5 - r0
            img = Image.new("1", (c1 - c0, r1 - r0), 0)
            ImageDraw.Draw(img).polygon(np.column_stack([u, v]).ravel().tolist(), fill=1, outline=1)
            free = np.array(img, dtype=bool)
        # Hits: a return lies on the obstacle's face, so mark the cell a little behind it; range
        # noise smaller than that depth then does not thicken walls toward the robot.
        hit = finite & (r < self.spec.max_range_m)
        nudge = cfg.hit_depth_cells * res
        hx = sensor[0] + (r[hit] + nudge) * np.cos(ang[hit])
        hy = sensor[1] + (r[hit] + nudge) * np.sin(ang[hit])
        col = np.floor((hx - self.origin[0]) / res).astype(np.int64)
        row = np.floor((hy - self.origin[1]) / res).astype(np.int64)
        inside = (row >= r0) & (row < r1) & (col >= c0) & (col < c1)
        row, col = row[inside], col[inside]
        occ = np.zeros_like(free)
        occ[row - r0, col - c0] = True
        free &= ~occ  # a cell both passed and hit in one scan counts as hit
        win = self.log_odds[r0:r1, c0:c1]
        win += cfg.l_free * free + cfg.l_occ * occ
        np.clip(win, cfg.l_min, cfg.l_max, out=win)
        self.observed[r0:r1, c0:c1] |= free | occ
        # Exact end points (not nudged) for the matcher's reference cloud.
        ex = sensor[0] + r[hit][inside] * np.cos(ang[hit][inside])
        ey = sensor[1] + r[hit][inside] * np.sin(ang[hit][inside])
        np.add.at(self._hit_sum, (row, col), np.column_stack([ex, ey]))
        np.add.at(self._hit_count, (row, col), 1)
        self.scans += 1
        if self.scans - self._ref_scan >= self.config.reference_refresh_scans:
            self._ref = None

    # -- scan matching ------------------------------------------------------------------
    def _reference(self) -> tuple[cKDTree, np.ndarray, np.ndarray] | None:
        """KD-tree of the map's occupied cells' mean end points, and unit normals of the local
        surface there (principal axis of the nearest neighbours)."""
        if self._ref is not None:
            return self._ref
        cells = (self.log_odds > 0) & (self._hit_count > 0)
        if cells.sum() < 10:
            return None
        pts = self._hit_sum[cells] / self._hit_count[cells][:, None]
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
        self._ref = (tree, pts, normals)
        self._ref_scan = self.scans
        return self._ref

    def match(self, guess: np.ndarray, ranges: np.ndarray) -> MatchResult:
        """Point-to-line ICP of a scan against the map, starting from pose ``guess``."""
        cfg = self.config
        guess = np.asarray(guess, dtype=float).reshape(3)
        ref = self._reference()
        body, _ = self._body_points(ranges)
        if ref is None or len(body) < 3:
            return MatchResult(guess, False, 0.0, float("nan"), 0)
        tree, ref_pts, normals = ref
        if len(body) > cfg.match_points:
            body = body[np.linspace(0, len(body) - 1, cfg.match_points).round().astype(int)]
        pose = guess.copy()
        inlier_share, rms, it = 0.0, float("nan"), 0
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
        corr = pose - guess
        accepted = (
            inlier_share >= cfg.match_min_inliers
            and np.hypot(corr[0], corr[1]) <= cfg.match_max_correction_m
            and abs(wrap_angle(corr[2])) <= cfg.match_max_correction_rad
        )
        return MatchResult(pose if accepted else guess, bool(accepted), inlier_share, rms, it)

    def update(
        self,
        odom: np.ndarray,
        ranges: np.ndarray,
        *,
        initial_pose: np.ndarray | None = None,
    ) -> MatchResult:
        """Insert a scan taken at odometry pose ``odom``; returns the match with the corrected
        map-frame pose (also kept as :attr:`pose`).

        The first call places the skid at ``initial_pose`` (default: the odometry pose) and
        inserts the scan unmatched; later calls move the last corrected pose by the odometry
        increment, match, then insert.
        """
        odom = np.asarray(odom, dtype=float).reshape(3)
        if self.pose is None:
            start = odom if initial_pose is None else np.asarray(initial_pose, float).reshape(3)
            self.pose, self._odom = start.copy(), odom.copy()
            self.insert(self.pose, ranges)
            self._inserted_at = self.pose.copy()
            return MatchResult(self.pose.copy(), False, 0.0, float("nan"), 0)
        guess = compose(self.pose, relative_pose(self._odom, odom))
        result = (
            self.match(guess, ranges)
            if self.config.match
            else MatchResult(guess, False, 0.0, float("nan"), 0)
        )
        self.pose, self._odom = result.pose.copy(), odom.copy()
        cfg = self.config
        last = self._inserted_at if self._inserted_at is not None else self.pose
        moved = np.hypot(*(self.pose[:2] - last[:2])) >= cfg.insert_min_d_m
        turned = abs(wrap_angle(self.pose[2] - last[2])) >= cfg.insert_min_a_rad
        if moved or turned or cfg.insert_min_d_m == 0:
            self.insert(self.pose, ranges)
            self._inserted_at = self.pose.copy()
        return result

    # -- output -------------------------------------------------------------------------
    def probability(self) -> np.ndarray:
        """Occupancy probability ``(H, W)`` (0.5 where never observed)."""
        return 1.0 / (1.0 + np.exp(-self.log_odds))

    def to_occupancy_grid(
        self,
        occupied_thresh: float = DEFAULT_OCCUPIED_THRESH,
        free_thresh: float = DEFAULT_FREE_THRESH,
    ) -> OccupancyGrid:
        """The map as an :class:`OccupancyGrid` with map_server's trinary thresholds: cells
        above ``occupied_thresh`` are occupied, below ``free_thresh`` free, the rest (and
        everything never observed) unknown. Save it with
        :func:`swarmpark.core.gridmap.save_map_yaml`."""
        if not 0 < free_thresh < occupied_thresh < 1:
            raise ValueError(
                "mapper: need 0 < free_thresh < occupied_thresh < 1 "
                f"(got {free_thresh}, {occupied_thresh})"
            )
        occ = self.log_odds > _logit(occupied_thresh)
        free = self.log_odds < _logit(free_thresh)
        return OccupancyGrid(occ, self.resolution_m, self.origin, unknown=~(occ | free))
