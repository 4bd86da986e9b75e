"""Simulated planar LIDAR, vectorized over robots and beams.

The default :class:`LidarSpec` is the scanner of Hing et al. 2015, Sect. 3.4: mounted at the
skid's pivot, 360 degrees at 0.36 degree resolution (1000 beams), 5 m range. A scan sees the
static map (an :class:`~swarmpark.core.gridmap.OccupancyGrid`, whose outside counts as occupied),
convex world polygons (other skids' footprints, triangulated static obstacles) and discs
(people). Each robot can be told not to see polygons it owns (its own footprint).

Ranges follow ROS REP-117: a finite value is a return, ``+inf`` means nothing within
``max_range_m`` and ``nan`` is a dropout (the scanner reported nothing usable).

How the grid is traced: sphere tracing on a conservative distance field takes long steps in open
space, and near obstacles each ray walks cell by cell (Amanatides-Woo), so the returned range is
exactly where the ray enters the first occupied cell. Polygons and discs are intersected
analytically, each only against the beams inside the angular sector it subtends from a sensor.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarmpark.core.gridmap import OccupancyGrid

__all__ = ["LidarSpec", "GridField", "prepare_grid", "scan", "scan_points", "beam_angles"]

TWO_PI = 2.0 * np.pi
#: Half the diagonal of a unit cell: a point in a cell is at most this far (in cells) from its
#: centre, so a distance sampled at the centre is a lower bound only after subtracting it.
HALF_DIAGONAL = np.sqrt(0.5)
#: Step past a cell boundary (in metres) so that the next lookup lands in the next cell.
BOUNDARY_NUDGE_M = 1e-9
#: Rays with a direction component smaller than this are treated as parallel to that axis.
PARALLEL_EPS = 1e-12


@dataclass(frozen=True, kw_only=True)
class LidarSpec:
    """A planar scanner.

    Parameters
    ----------
    num_beams
        Beams per scan.
    fov_rad
        Field of view. ``2*pi`` (the default) is a full circle: beam ``i`` points at
        ``-pi + i * 2*pi / num_beams`` in the sensor frame, so beam ``num_beams // 2`` looks
        straight ahead. A smaller field of view spreads the beams evenly over
        ``[-fov/2, +fov/2]`` (both ends included).
    max_range_m
        Nothing farther away is returned (the range is ``+inf``).
    range_noise_std_m
        Standard deviation of zero-mean Gaussian noise added to every return.
    dropout_prob
        Probability that a beam returns ``nan`` instead of a range.
    mount_x_m, mount_y_m, mount_yaw_rad
        Sensor pose in the skid's body frame (origin at the pivot).

    Examples
    --------
    >>> spec = LidarSpec()
    >>> spec.num_beams, round(float(np.degrees(spec.angle_increment_rad)), 2)
    (1000, 0.36)
    """

    num_beams: int = 1000
    fov_rad: float = TWO_PI
    max_range_m: float = 5.0
    range_noise_std_m: float = 0.0
    dropout_prob: float = 0.0
    mount_x_m: float = 0.0
    mount_y_m: float = 0.0
    mount_yaw_rad: float = 0.0

    def __post_init__(self) -> None:
        if not (isinstance(self.num_beams, int | np.integer) and self.num_beams >= 1):
            raise ValueError(f"lidar.num_beams must be an integer >= 1 (got {self.num_beams!r})")
        if not (0.0 < self.fov_rad <= TWO_PI + 1e-12):
            raise ValueError(f"lidar.fov_rad must be in (0, 2*pi] (got {self.fov_rad})")
        if not (np.isfinite(self.max_range_m) and self.max_range_m > 0):
            raise ValueError(f"lidar.max_range_m must be finite and > 0 (got {self.max_range_m})")
        if not (self.range_noise_std_m >= 0 and np.isfinite(self.range_noise_std_m)):
            raise ValueError(f"lidar.range_noise_std_m must be >= 0 (got {self.range_noise_std_m})")
        if not (0.0 <= self.dropout_prob < 1.0):
            raise ValueError(f"lidar.dropout_prob must be in [0, 1) (got {self.dropout_prob})")

    @property
    def full_circle(self) -> bool:
        return self.fov_rad >= TWO_PI - 1e-12

    @property
    def angle_min_rad(self) -> float:
        return -np.pi if self.full_circle else -0.5 * self.fov_rad

    @property
    def angle_increment_rad(self) -> float:
        if self.full_circle:
            return TWO_PI / self.num_beams
        return self.fov_rad / max(self.num_beams - 1, 1)

    @property
    def mount(self) -> np.ndarray:
        return np.array([self.mount_x_m, self.mount_y_m, self.mount_yaw_rad])


def beam_angles(spec: LidarSpec) -> np.ndarray:
    """Beam directions ``(B,)`` in the sensor frame (radians, counter-clockwise from ahead)."""
    return spec.angle_min_rad + spec.angle_increment_rad * np.arange(spec.num_beams)


def sensor_poses(spec: LidarSpec, poses: np.ndarray) -> np.ndarray:
    """World poses ``(N, 3)`` of the sensors on skids at pivot ``poses`` ``(N, 3)``."""
    poses = np.asarray(poses, dtype=float).reshape(-1, 3)
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    x = poses[:, 0] + c * spec.mount_x_m - s * spec.mount_y_m
    y = poses[:, 1] + s * spec.mount_x_m + c * spec.mount_y_m
    return np.column_stack([x, y, poses[:, 2] + spec.mount_yaw_rad])


@dataclass(frozen=True)
class GridField:
    """An occupancy grid prepared for ray tracing (build once per map with :func:`prepare_grid`).

    Attributes
    ----------
    occupied
        ``(H, W)`` bool, from the grid.
    safe_m
        ``(H, W)`` lower bound (metres) of the distance from *any point* of a free cell's
        centre to the nearest occupied cell or the map edge, minus nothing: subtract the
        point's distance from the centre to get a bound for that point.
    """

    occupied: np.ndarray
    safe_m: np.ndarray
    resolution_m: float
    origin: tuple[float, float]

    @property
    def shape(self) -> tuple[int, int]:
        return self.occupied.shape  # type: ignore[return-value]


def prepare_grid(grid: OccupancyGrid) -> GridField:
    """Precompute what :func:`scan` needs from a grid (one distance transform).

    ``grid.distance_field()`` measures from each cell centre to the nearest occupied cell's
    *centre* minus half a cell. To a diagonal neighbour's corner the true distance is shorter,
    so the bound used for sphere tracing subtracts half a diagonal instead of half a cell.
    """
    dist = grid.distance_field()
    res = grid.resolution_m
    # dist = (edt - 0.5) * res in free cells, so edt * res = dist + 0.5 * res.
    safe = np.where(grid.occupied, 0.0, np.maximum(dist + (0.5 - HALF_DIAGONAL) * res, 0.0))
    return GridField(grid.occupied.copy(), safe, float(res), tuple(map(float, grid.origin)))


def _trace_grid(
    field: GridField, origins: np.ndarray, dirs: np.ndarray, max_range: float
) -> np.ndarray:
    """Distance ``(R,)`` along each ray to the first occupied cell or the map edge (``inf`` if
    beyond ``max_range``). ``origins`` and ``dirs`` are ``(R, 2)``; ``dirs`` are unit vectors."""
    res = field.resolution_m
    h, w = field.shape
    ox0, oy0 = field.origin
    occ = field.occupied.ravel()
    safe = field.safe_m.ravel()
    n = len(origins)
    out = np.full(n, np.inf)
    # Ray state, compacted to the still-active rays each iteration.
    idx = np.arange(n)
    ox, oy = origins[:, 0] - ox0, origins[:, 1] - oy0  # in the grid's frame
    dx, dy = dirs[:, 0], dirs[:, 1]
    t = np.zeros(n)
    probe = np.zeros(n)  # where to look up the cell: t, nudged past a boundary we stopped on
    # Every iteration moves a ray at least to the next cell boundary, and a ray crosses at most
    # about sqrt(2) * L / res boundaries within range L: this bound cannot cut a ray short.
    max_iter = int(np.ceil(2.0 * max_range / res)) + 8
    with np.errstate(divide="ignore", invalid="ignore"):
        inv_dx = np.where(np.abs(dx) > PARALLEL_EPS, 1.0 / dx, np.inf)
        inv_dy = np.where(np.abs(dy) > PARALLEL_EPS, 1.0 / dy, np.inf)
    for _ in range(max_iter):
        if len(idx) == 0:
            break
        px = ox + probe * dx
        py = oy + probe * dy
        col = np.floor(px / res).astype(np.int64)
        row = np.floor(py / res).astype(np.int64)
        inside = (row >= 0) & (row < h) & (col >= 0) & (col < w)
        lin = np.where(inside, row * w + col, 0)
        hit = ~inside | occ[lin]
        far = t >= max_range
        done = hit | far
        if done.any():
            hit_now = hit & ~far
            out[idx[hit_now]] = t[hit_now]
            keep = ~done
            idx, ox, oy, dx, dy, inv_dx, inv_dy = (
                a[keep] for a in (idx, ox, oy, dx, dy, inv_dx, inv_dy)
            )
            t, px, py, col, row, lin = (a[keep] for a in (t, px, py, col, row, lin))
        # Sphere step: distance-field bound at the centre minus this point's offset from it.
        cx = (col + 0.5) * res
        cy = (row + 0.5) * res
        bound = safe[lin] - np.hypot(px - cx, py - cy)
        # Cell-walk step: to where the ray leaves the current cell (exact).
        bx = np.where(dx > 0, (col + 1) * res, col * res)
        by = np.where(dy > 0, (row + 1) * res, row * res)
        with np.errstate(invalid="ignore"):
            tx = np.where(np.isfinite(inv_dx), (bx - ox) * inv_dx, np.inf)
            ty = np.where(np.isfinite(inv_dy), (by - oy) * inv_dy, np.inf)
        t_exit = np.minimum(tx, ty)
        t_sphere = t + bound
        walk = t_exit >= t_sphere
        t = np.where(walk, t_exit, t_sphere)
        probe = np.where(walk, t + BOUNDARY_NUDGE_M, t)
    return out


def _sector_pairs(
    spec: LidarSpec,
    sensors: np.ndarray,
    centers: np.ndarray,
    radii: np.ndarray,
    owner: np.ndarray | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Broad phase: the beams of each robot that can meet each object's bounding disc.

    Each object (bounding disc ``centers``, ``radii``) is tested only against the beams inside
    the angular sector it subtends from each sensor within range. Returns the (robot, object)
    pairs ``rn, on`` ``(Q,)`` and, per candidate beam, its pair ``(R,)`` and beam index ``(R,)``.
    """
    b = spec.num_beams
    rel = centers[None, :, :] - sensors[:, None, :2]  # (N, M, 2)
    dist = np.hypot(rel[..., 0], rel[..., 1])
    near = dist - radii[None, :] < spec.max_range_m
    if owner is not None:
        near &= owner[None, :] != np.arange(len(sensors))[:, None]
    rn, on = np.nonzero(near)
    if len(rn) == 0:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty, empty, empty
    d = dist[rn, on]
    bearing = np.arctan2(rel[rn, on, 1], rel[rn, on, 0]) - sensors[rn, 2]
    with np.errstate(invalid="ignore", divide="ignore"):
        half = np.where(d > radii[on], np.arcsin(np.clip(radii[on] / d, 0.0, 1.0)), np.pi)
    inc = spec.angle_increment_rad
    a0 = spec.angle_min_rad
    if spec.full_circle:
        lo_ang = (bearing - half - a0) % TWO_PI  # in [0, 2 pi)
        lo = np.ceil(lo_ang / inc - 1e-9).astype(np.int64)
        count = np.floor(2.0 * half / inc + 1e-9).astype(np.int64) + 1
        count = np.minimum(count, b)
    else:
        centre = (bearing - a0 + np.pi) % TWO_PI - np.pi  # relative to the first beam
        lo = np.maximum(np.ceil((centre - half) / inc - 1e-9).astype(np.int64), 0)
        hi = np.minimum(np.floor((centre + half) / inc + 1e-9).astype(np.int64), b - 1)
        # Objects behind a partial field of view may wrap around: test them fully instead.
        wraps = centre + half > np.pi
        lo = np.where(wraps, 0, lo)
        hi = np.where(wraps, b - 1, hi)
        count = np.maximum(hi - lo + 1, 0)
    total = int(count.sum())
    pair = np.repeat(np.arange(len(rn)), count)
    start = np.cumsum(count) - count
    offset = np.arange(total) - start[pair]
    beam = lo[pair] + offset
    if spec.full_circle:
        beam %= b
    return rn, on, pair, beam


def _edge_planes(polys: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Outward edge normals ``nx, ny`` ``(..., K)`` of counter-clockwise polygons and offsets
    ``c = n . p_k``, so that a point ``q`` is inside when ``n . q <= c`` for every edge."""
    edge = np.roll(polys, -1, axis=-2) - polys
    nx, ny = edge[..., 1], -edge[..., 0]
    return nx, ny, nx * polys[..., 0] + ny * polys[..., 1]


def _convex_entry(num: np.ndarray, denom: np.ndarray) -> np.ndarray:
    """Cyrus-Beck clipping from ``num = c - n . o`` and ``denom = n . d`` ``(R, K)``: entry
    distance ``(R,)`` of each ray into its polygon, ``inf`` on a miss, 0 from inside."""
    r = num.shape[0]
    t_enter = np.full(r, -np.inf)
    t_exit = np.full(r, np.inf)
    miss = np.zeros(r, dtype=bool)
    # One edge at a time over 1-D arrays: K is 3 or 4, and numpy reduces a short last axis
    # slowly.
    with np.errstate(divide="ignore", invalid="ignore"):
        for k in range(num.shape[1]):
            nk, dk = num[:, k], denom[:, k]
            tk = nk / dk
            # Inside means n . (o + t d) <= c, i.e. t * denom <= num.
            entering = dk < -PARALLEL_EPS
            leaving = dk > PARALLEL_EPS
            np.maximum(t_enter, np.where(entering, tk, -np.inf), out=t_enter)
            np.minimum(t_exit, np.where(leaving, tk, np.inf), out=t_exit)
            # A ray parallel to an edge and outside its half-plane misses; degenerate
            # (repeated-vertex) edges have normal 0 and num 0, which constrains nothing.
            miss |= ~entering & ~leaving & (nk < -1e-12)
    ok = ~miss & (t_enter <= t_exit) & (t_exit >= 0)
    return np.where(ok, np.maximum(t_enter, 0.0), np.inf)


def _ray_convex(o: np.ndarray, d: np.ndarray, polys: np.ndarray) -> np.ndarray:
    """Entry distance ``(R,)`` of rays (origins, unit directions ``(R, 2)``) into convex
    counter-clockwise polygons ``(R, K, 2)``; ``inf`` on a miss and 0 from inside."""
    nx, ny, c = _edge_planes(polys)
    num = c - (nx * o[:, 0:1] + ny * o[:, 1:2])
    denom = nx * d[:, 0:1] + ny * d[:, 1:2]
    return _convex_entry(num, denom)


def _ray_disc(o: np.ndarray, d: np.ndarray, c: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Entry distance ``(R,)`` of rays into discs; ``inf`` on a miss, 0 from inside."""
    m = o - c
    bq = np.einsum("rd,rd->r", m, d)
    cq = np.einsum("rd,rd->r", m, m) - r * r
    disc = bq * bq - cq
    with np.errstate(invalid="ignore"):
        sq = np.sqrt(np.maximum(disc, 0.0))
    t0, t1 = -bq - sq, -bq + sq
    ok = (disc >= 0) & (t1 >= 0)
    return np.where(ok, np.where(cq <= 0, 0.0, np.maximum(t0, 0.0)), np.inf)


def scan(
    spec: LidarSpec,
    poses: np.ndarray,
    grid: OccupancyGrid | GridField | None,
    *,
    polygons: np.ndarray | None = None,
    polygon_owner: np.ndarray | None = None,
    discs: np.ndarray | None = None,
    disc_radii: np.ndarray | None = None,
    rng: np.random.Generator | None = None,
) -> np.ndarray:
    """Simulate one scan for every robot.

    Parameters
    ----------
    spec
        The scanner.
    poses
        ``(N, 3)`` pivot poses of the skids carrying the scanner (the mount offset is applied).
    grid
        The static map: an :class:`OccupancyGrid` (its distance field is then recomputed on every
        call), a :class:`GridField` from :func:`prepare_grid` (do this in loops), or ``None``.
    polygons
        ``(P, K, 2)`` convex counter-clockwise world polygons (skid footprints, triangulated
        obstacles); pad shorter ones with :func:`swarmpark.core.geometry.pad_polygons`.
    polygon_owner
        ``(P,)`` int: index of the robot that must not see the polygon (its own footprint), or
        -1 for polygons everyone sees.
    discs, disc_radii
        ``(D, 2)`` centres and ``(D,)`` radii of round obstacles (people).
    rng
        Needed only when the spec has range noise or dropouts.

    Returns
    -------
    ranges
        ``(N, B)`` metres; ``+inf`` where nothing is within range, ``nan`` for a dropout. Noise
        is added to returns only and clipped to ``[0, max_range_m]``.

    Examples
    --------
    >>> from swarmpark.core.gridmap import OccupancyGrid
    >>> g = OccupancyGrid(np.zeros((40, 40), bool), 0.1)  # 4 m square; its edge is a wall
    >>> r = scan(LidarSpec(num_beams=4), np.array([[1.0, 2.0, 0.0]]), g)
    >>> r.round(6).tolist()  # beams look back, right, ahead, left
    [[1.0, 2.0, 3.0, 2.0]]
    """
    poses = np.asarray(poses, dtype=float)
    if poses.ndim != 2 or poses.shape[1] != 3:
        raise ValueError(f"scan: poses must have shape (N, 3) (got {poses.shape})")
    if not np.all(np.isfinite(poses)):
        raise ValueError("scan: poses must be finite")
    n, b = len(poses), spec.num_beams
    sensors = sensor_poses(spec, poses)
    angles = beam_angles(spec)
    world_ang = sensors[:, 2:3] + angles[None, :]  # (N, B)
    dirs = np.stack([np.cos(world_ang), np.sin(world_ang)], -1).reshape(-1, 2)
    origins = np.repeat(sensors[:, :2], b, axis=0)
    if grid is None:
        ranges = np.full(n * b, np.inf)
    else:
        field = prepare_grid(grid) if isinstance(grid, OccupancyGrid) else grid
        ranges = _trace_grid(field, origins, dirs, spec.max_range_m)

    if polygons is not None and len(polygons):
        polys = np.asarray(polygons, dtype=float)
        if polys.ndim != 3 or polys.shape[2] != 2:
            raise ValueError(f"scan: polygons must have shape (P, K, 2) (got {polys.shape})")
        owner = None
        if polygon_owner is not None:
            owner = np.asarray(polygon_owner).astype(np.int64)
            if owner.shape != (len(polys),):
                raise ValueError(
                    f"scan: polygon_owner must have shape ({len(polys)},) (got {owner.shape})"
                )
        centers = polys.mean(axis=1)
        radii = np.linalg.norm(polys - centers[:, None, :], axis=-1).max(axis=1)
        rn, on, pair, beam = _sector_pairs(spec, sensors, centers, radii, owner)
        if len(pair):
            # Per (robot, polygon) pair the edge planes relative to the sensor; per beam only
            # the direction changes.
            nx, ny, c = _edge_planes(polys)
            nxp, nyp = nx[on], ny[on]
            nump = c[on] - (nxp * sensors[rn, 0:1] + nyp * sensors[rn, 1:2])
            ray = rn[pair] * b + beam
            d = dirs[ray]
            denom = nxp[pair] * d[:, 0:1] + nyp[pair] * d[:, 1:2]
            t = _convex_entry(nump[pair], denom)
            hit = t < spec.max_range_m
            np.minimum.at(ranges, ray[hit], t[hit])

    if discs is not None and len(discs):
        cen = np.asarray(discs, dtype=float).reshape(-1, 2)
        rad = np.broadcast_to(np.asarray(disc_radii, dtype=float), (len(cen),))
        if np.any(rad <= 0):
            raise ValueError(f"scan: disc_radii must be > 0 (got {rad.tolist()})")
        rn, on, pair, beam = _sector_pairs(spec, sensors, cen, rad, None)
        if len(pair):
            ray = rn[pair] * b + beam
            obj = on[pair]
            t = _ray_disc(origins[ray], dirs[ray], cen[obj], rad[obj])
            hit = t < spec.max_range_m
            np.minimum.at(ranges, ray[hit], t[hit])

    ranges = ranges.reshape(n, b)
    ranges[ranges > spec.max_range_m] = np.inf
    return _add_noise(spec, ranges, rng)


def _add_noise(spec: LidarSpec, ranges: np.ndarray, rng: np.random.Generator | None) -> np.ndarray:
    """The spec's range noise (on returns only, clipped to ``[0, max_range_m]``) and dropouts
    (``nan``) applied to exact ranges ``(N, B)``, which may be modified in place."""
    if spec.range_noise_std_m > 0 or spec.dropout_prob > 0:
        if rng is None:
            raise ValueError("scan: rng is required when the lidar has noise or dropouts")
        if spec.range_noise_std_m > 0:
            noisy = ranges + spec.range_noise_std_m * rng.standard_normal(ranges.shape)
            ranges = np.where(np.isfinite(ranges), np.clip(noisy, 0.0, spec.max_range_m), ranges)
        if spec.dropout_prob > 0:
            ranges[rng.random(ranges.shape) < spec.dropout_prob] = np.nan
    return ranges


def scan_points(spec: LidarSpec, poses: np.ndarray, ranges: np.ndarray) -> np.ndarray:
    """World end points ``(N, B, 2)`` of scans taken from pivot ``poses`` ``(N, 3)``; ``nan``
    where the range is not finite (no return or dropout)."""
    poses = np.asarray(poses, dtype=float).reshape(-1, 3)
    ranges = np.asarray(ranges, dtype=float).reshape(len(poses), spec.num_beams)
    sensors = sensor_poses(spec, poses)
    ang = sensors[:, 2:3] + beam_angles(spec)[None, :]
    r = np.where(np.isfinite(ranges), ranges, np.nan)
    return np.stack([sensors[:, 0:1] + r * np.cos(ang), sensors[:, 1:2] + r * np.sin(ang)], -1)
