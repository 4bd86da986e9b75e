"""Obstacle detection: scan points the static map does not explain, kept per skid with decay.

Hing et al. 2018, Sect. 3.5.1: each skid puts what its sensors detect into its local map and
plans with it; parts of other skids it sees are obstacles. :class:`LocalCostmap` does this for
a whole fleet at once, like the obstacle layer of ROS costmap_2d: a scan end point farther than
a tolerance from the map's occupied cells marks its cell, a marked cell is cleared when a later
beam of the same skid passes through it (the space is seen empty) or when it has not been seen
for ``decay_s`` (a person who walked out of view). Storage is sparse (only marked cells), so
memory does not grow with fleet size times map size.

The fleet's layer (:class:`FleetLayer`) merges the skids' layers so that one skid with a wrong
pose estimate (kidnapped, not yet found again) cannot blind the fleet: its scans then do not
fit the map, and what it alone sees is kept only for ``unconfirmed_s`` from when it first
appeared, unless another skid sees it too or the skid fits the map again.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarmpark.core.geometry import wrap_angle
from swarmpark.core.gridmap import OccupancyGrid
from swarmpark.sense.lidar import LidarSpec, scan_points, sensor_poses

__all__ = ["CostmapConfig", "FleetLayer", "FleetLayerConfig", "LocalCostmap", "Obstacles"]


@dataclass(frozen=True, kw_only=True)
class CostmapConfig:
    """Obstacle-layer settings.

    Parameters
    ----------
    map_tolerance_m
        A scan point within this distance of an occupied map cell is explained by the map (a
        wall) and ignored. It must exceed the localization error, or walls seen from a slightly
        wrong pose show up as obstacles.
    decay_s
        A marked cell not seen again for longer than this is cleared.
    clear_on_pass
        A beam that passes through a marked cell (its return is farther, or it has none) clears
        the cell at once.
    clear_margin_m
        A beam clears a cell only if it passes at least this far beyond the cell's centre
        (``None``: two cells), so that the beam that marked a cell never clears it.
    """

    map_tolerance_m: float = 0.15
    decay_s: float = 2.0
    clear_on_pass: bool = True
    clear_margin_m: float | None = None

    def __post_init__(self) -> None:
        if not self.map_tolerance_m >= 0:
            raise ValueError(f"costmap.map_tolerance_m must be >= 0 (got {self.map_tolerance_m})")
        if not self.decay_s > 0:
            raise ValueError(f"costmap.decay_s must be > 0 (got {self.decay_s})")
        if self.clear_margin_m is not None and not self.clear_margin_m >= 0:
            raise ValueError(f"costmap.clear_margin_m must be >= 0 (got {self.clear_margin_m})")


@dataclass(frozen=True)
class Obstacles:
    """Detected obstacle cells of one skid: ``cells`` ``(M, 2)`` (row, col), ``points``
    ``(M, 2)`` their world centres and ``age_s`` ``(M,)`` time since each was last seen."""

    cells: np.ndarray
    points: np.ndarray
    age_s: np.ndarray


class LocalCostmap:
    """Obstacle layer for ``n_robots`` skids on one static map (the map's grid is reused).

    Parameters
    ----------
    grid
        The static map; detected obstacles live in its cells.
    n_robots
        Number of skids.
    spec
        The scanner all skids carry.
    config
        Settings.

    Examples
    --------
    >>> from swarmpark.sense.lidar import LidarSpec, scan
    >>> g = OccupancyGrid(np.zeros((60, 60), bool), 0.1)  # 6 m room
    >>> spec = LidarSpec(num_beams=360)
    >>> cm = LocalCostmap(g, 1, spec)
    >>> pose = np.array([[1.0, 3.0, 0.0]])
    >>> person = dict(discs=np.array([[3.0, 3.0]]), disc_radii=np.array([0.25]))
    >>> cm.update(0.0, pose, scan(spec, pose, g, **person))
    >>> len(cm.obstacles(0, 0.0).cells) > 0
    True
    >>> cm.update(0.1, pose, scan(spec, pose, g))  # the person left: beams pass, cells clear
    >>> len(cm.obstacles(0, 0.1).cells)
    0
    """

    def __init__(
        self,
        grid: OccupancyGrid,
        n_robots: int,
        spec: LidarSpec,
        config: CostmapConfig | None = None,
    ) -> None:
        if n_robots < 1:
            raise ValueError(f"costmap.n_robots must be >= 1 (got {n_robots})")
        self.grid = grid
        self.n_robots = int(n_robots)
        self.spec = spec
        self.config = config if config is not None else CostmapConfig()
        self._dist = grid.distance_field()
        self._cells = grid.shape[0] * grid.shape[1]
        # Sorted keys robot * H * W + row * W + col of marked cells, and when each was seen.
        self._keys = np.zeros(0, dtype=np.int64)
        self._seen = np.zeros(0)
        self._time = -np.inf
        #: ``(N,)`` share of each skid's last scan returns the map explains (1 before any).
        self.explained_share = np.ones(self.n_robots)

    @property
    def clear_margin_m(self) -> float:
        m = self.config.clear_margin_m
        return 2.0 * self.grid.resolution_m if m is None else float(m)

    def update(self, t: float, poses: np.ndarray, ranges: np.ndarray) -> None:
        """Add the scans ``ranges`` ``(N, B)`` taken at ``poses`` ``(N, 3)`` (the poses the
        skids believe they are at) at time ``t`` (s, not decreasing)."""
        poses = np.asarray(poses, dtype=float).reshape(-1, 3)
        if len(poses) != self.n_robots:
            raise ValueError(
                f"costmap.update: poses has {len(poses)} rows, expected {self.n_robots}"
            )
        ranges = np.asarray(ranges, dtype=float).reshape(self.n_robots, self.spec.num_beams)
        if t < self._time:
            raise ValueError(f"costmap.update: time went back ({t} < {self._time})")
        self._time = float(t)
        h, w = self.grid.shape
        if self.config.clear_on_pass and len(self._keys):
            self._clear_passed(poses, ranges)
        robot, rc, _ = self._unexplained(poses, ranges)
        new = np.unique(robot.astype(np.int64) * self._cells + rc[:, 0] * w + rc[:, 1])
        # Old entries not re-observed keep their time; re-observed and new ones get t.
        old = ~np.isin(self._keys, new, assume_unique=True)
        fresh = t - self._seen <= self.config.decay_s
        keep = old & fresh
        keys = np.concatenate([self._keys[keep], new])
        seen = np.concatenate([self._seen[keep], np.full(len(new), float(t))])
        order = np.argsort(keys, kind="stable")
        self._keys, self._seen = keys[order], seen[order]

    def _unexplained(self, poses: np.ndarray, ranges: np.ndarray):
        """The scan end points the map does not explain: per point its skid ``(M,)``, cell
        ``(M, 2)`` and world position ``(M, 2)``."""
        pts = scan_points(self.spec, poses, ranges)  # (N, B, 2)
        returned = np.isfinite(ranges) & (ranges < self.spec.max_range_m)
        robot = np.broadcast_to(np.arange(self.n_robots)[:, None], ranges.shape)[returned]
        xy = pts[returned]
        rc = self.grid.world_to_cell(xy)
        inside = self.grid.in_bounds(rc)
        robot, rc, xy = robot[inside], rc[inside], xy[inside]
        unexplained = self._dist[rc[:, 0], rc[:, 1]] > self.config.map_tolerance_m
        # How well each skid's scan fits the map (for the fleet's layer): the share of its
        # returns the map explains; a skid with no return keeps its last value.
        total = np.bincount(robot, minlength=self.n_robots)
        bad = np.bincount(robot[unexplained], minlength=self.n_robots)
        seen = total > 0
        self.explained_share[seen] = 1.0 - bad[seen] / total[seen]
        return robot[unexplained], rc[unexplained], xy[unexplained]

    def unexplained_points(self, poses: np.ndarray, ranges: np.ndarray) -> np.ndarray:
        """World end points ``(M, 2)`` of the scans ``ranges`` ``(N, B)`` taken at ``poses``
        that the map does not explain (what a people tracker clusters)."""
        poses = np.asarray(poses, dtype=float).reshape(-1, 3)
        ranges = np.asarray(ranges, dtype=float).reshape(self.n_robots, self.spec.num_beams)
        return self._unexplained(poses, ranges)[2]

    def _clear_passed(self, poses: np.ndarray, ranges: np.ndarray) -> None:
        """Forget marked cells that a beam of the same skid has just passed through."""
        h, w = self.grid.shape
        robot = self._keys // self._cells
        lin = self._keys % self._cells
        centre = self.grid.cell_to_world(np.column_stack([lin // w, lin % w]))
        sensors = sensor_poses(self.spec, poses)[robot]
        rel = centre - sensors[:, :2]
        dist = np.hypot(rel[:, 0], rel[:, 1])
        bearing = wrap_angle(np.arctan2(rel[:, 1], rel[:, 0]) - sensors[:, 2])
        spec = self.spec
        beam = np.rint((bearing - spec.angle_min_rad) / spec.angle_increment_rad).astype(np.int64)
        if spec.full_circle:
            beam %= spec.num_beams
        in_fov = (beam >= 0) & (beam < spec.num_beams)
        beam = np.clip(beam, 0, spec.num_beams - 1)
        r = ranges[robot, beam]
        reach = dist + self.clear_margin_m
        # No return means free out to the maximum range; a dropout (nan) tells nothing.
        passed = in_fov & (reach < spec.max_range_m) & ((np.isposinf(r)) | (r > reach))
        self._keys, self._seen = self._keys[~passed], self._seen[~passed]

    def obstacles(
        self,
        robot: int,
        t: float,
        *,
        center: np.ndarray | None = None,
        radius_m: float | None = None,
    ) -> Obstacles:
        """Obstacle cells skid ``robot`` knows of at time ``t`` (seen within ``decay_s``),
        optionally only those within ``radius_m`` of ``center`` (world x, y)."""
        if not 0 <= robot < self.n_robots:
            raise ValueError(
                f"costmap.obstacles: robot must be in [0, {self.n_robots}) (got {robot})"
            )
        lo, hi = np.searchsorted(self._keys, [robot * self._cells, (robot + 1) * self._cells])
        keys, seen = self._keys[lo:hi], self._seen[lo:hi]
        age = t - seen
        fresh = age <= self.config.decay_s
        keys, age = keys[fresh], age[fresh]
        w = self.grid.shape[1]
        lin = keys - robot * self._cells
        cells = np.column_stack([lin // w, lin % w])
        points = self.grid.cell_to_world(cells)
        if radius_m is not None:
            c = np.asarray(center, dtype=float).reshape(2)
            near = np.hypot(points[:, 0] - c[0], points[:, 1] - c[1]) <= radius_m
            cells, points, age = cells[near], points[near], age[near]
        return Obstacles(cells, points, age)

    def obstacle_mask(self, robot: int, t: float) -> np.ndarray:
        """``(H, W)`` bool of skid ``robot``'s detected obstacle cells."""
        mask = np.zeros(self.grid.shape, dtype=bool)
        cells = self.obstacles(robot, t).cells
        mask[cells[:, 0], cells[:, 1]] = True
        return mask

    def costmap(self, robot: int, t: float) -> OccupancyGrid:
        """The static map with skid ``robot``'s detected obstacles marked occupied (what its
        planner should search; inflate it as usual)."""
        out = self.grid.copy()
        out.occupied |= self.obstacle_mask(robot, t)
        out.unknown &= ~out.occupied
        return out


@dataclass(frozen=True, kw_only=True)
class FleetLayerConfig:
    """How the skids' layers merge into the fleet's (:class:`FleetLayer`).

    Parameters
    ----------
    unconfirmed_s
        A cell only one skid sees, while that skid's scans do not fit the map, is kept this
        long from when it first appeared (the obstacle layer's own ``decay_s``).
    trust_share
        A skid whose last scan the map explains at least this share of is trusted alone (a
        kidnapped skid's scan fits the map it believes it is in only where walls happen to
        line up: a few tenths at most; a well-localized skid's, except for what really is
        new, nearly all).
    """

    unconfirmed_s: float = 2.0
    trust_share: float = 0.5

    def __post_init__(self) -> None:
        if not (np.isfinite(self.unconfirmed_s) and self.unconfirmed_s > 0):
            raise ValueError(
                f"fleet_layer.unconfirmed_s must be a finite number > 0 (got {self.unconfirmed_s!r})"
            )
        if not 0 <= self.trust_share <= 1:
            raise ValueError(
                f"fleet_layer.trust_share must be in [0, 1] (got {self.trust_share!r})"
            )


class FleetLayer:
    """The fleet's obstacle layer: the skids' layers of a :class:`LocalCostmap` merged.

    A cell is in the fleet's layer if two skids see it, or one skid whose scan fits the map
    (:attr:`LocalCostmap.explained_share` at least ``trust_share``), or, seen by one skid only
    whose scan does not fit the map, for ``unconfirmed_s`` after it first appeared: a kidnapped
    skid's false detections fade out of the fleet's layer even while that skid keeps seeing
    them, so they cannot block the other skids' paths.
    """

    def __init__(self, costmap: LocalCostmap, config: FleetLayerConfig | None = None) -> None:
        self.costmap = costmap
        self.config = config if config is not None else FleetLayerConfig()
        self._first_lin = np.zeros(0, dtype=np.int64)  # sorted cells, when first in a layer
        self._first_t = np.zeros(0)

    def merge(self, t: float) -> np.ndarray:
        """The fleet's obstacle cells ``(M, 2)`` (row, col; sorted) at time ``t``."""
        cm, cfg = self.costmap, self.config
        w = cm.grid.shape[1]
        lins, robots = [], []
        for i in range(cm.n_robots):
            cells = cm.obstacles(i, t).cells
            lins.append(cells[:, 0].astype(np.int64) * w + cells[:, 1])
            robots.append(np.full(len(cells), i))
        lin, robot = np.concatenate(lins), np.concatenate(robots)
        cells, inv, count = np.unique(lin, return_inverse=True, return_counts=True)
        trusted = cm.explained_share[robot] >= cfg.trust_share
        confirmed = (count >= 2) | (np.bincount(inv, weights=trusted, minlength=len(cells)) > 0)
        # When each cell first appeared (kept while some skid still has it).
        known = np.isin(cells, self._first_lin, assume_unique=True)
        first = np.full(len(cells), float(t))
        first[known] = self._first_t[np.searchsorted(self._first_lin, cells[known])]
        self._first_lin, self._first_t = cells, first
        keep = confirmed | (t - first <= cfg.unconfirmed_s)
        cells = cells[keep]
        return np.column_stack([cells // w, cells % w])
