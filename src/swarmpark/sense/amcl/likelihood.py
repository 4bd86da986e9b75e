"""The likelihood-field sensor model of a map (Thrun, Burgard and Fox 2005, Table 6.3), as ROS
``amcl`` uses it: each scan end point scores by its distance to the nearest obstacle surface."""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from swarmpark.core.gridmap import OccupancyGrid

__all__ = ["LikelihoodField", "OFF_MAP_DISTANCE_M"]

#: Distance given to scan end points off the map (far enough for the Gaussian to vanish).
OFF_MAP_DISTANCE_M = 1e3


class LikelihoodField:
    """Likelihood-field sensor model of a map (Thrun Table 6.3), precomputed once per map.

    The log-likelihood of a scan end point is tabulated on a lattice of half a cell (cell
    corners, edge midpoints and centres) and looked up at the nearest lattice point. Distances
    are measured to the surfaces of the occupied cells (from either side) and to the map edge,
    so an end point lying on a wall's face scores as a hit whichever side the wall faces.
    Unknown cells count as free.

    Parameters
    ----------
    grid
        The map.
    sigma_hit_m
        Standard deviation of the Gaussian around obstacles.
    z_hit, z_rand
        Mixture weights of the hit and uniform components (``z_rand`` is spread over
        ``max_range_m``).
    max_range_m
        Range of the scanner that the model scores.
    min_clearance_m
        Random and global particles are only placed in known free cells at least this far from
        an obstacle (a skid's pivot cannot be closer to a wall than its half width).
    """

    def __init__(
        self,
        grid: OccupancyGrid,
        *,
        sigma_hit_m: float = 0.1,
        z_hit: float = 0.9,
        z_rand: float = 0.1,
        max_range_m: float = 5.0,
        min_clearance_m: float = 0.0,
    ) -> None:
        if not sigma_hit_m > 0:
            raise ValueError(f"likelihood.sigma_hit_m must be > 0 (got {sigma_hit_m})")
        if not (z_hit >= 0 and z_rand > 0):
            raise ValueError(
                f"likelihood.z_hit must be >= 0 and z_rand > 0 (got {z_hit}, {z_rand})"
            )
        if not max_range_m > 0:
            raise ValueError(f"likelihood.max_range_m must be > 0 (got {max_range_m})")
        self.resolution_m = float(grid.resolution_m)
        self.origin = (float(grid.origin[0]), float(grid.origin[1]))
        self.sigma_hit_m = float(sigma_hit_m)
        self.z_hit, self.z_rand = float(z_hit), float(z_rand)
        self.max_range_m = float(max_range_m)
        self.shape = grid.shape
        h, w = grid.shape
        # Lattice point (2r+1, 2c+1) is the centre of cell (r, c); its 3x3 block is the square.
        centre = np.zeros((2 * h + 1, 2 * w + 1), dtype=bool)
        centre[1::2, 1::2] = grid.occupied
        on_obstacle = ndimage.binary_dilation(centre, structure=np.ones((3, 3), dtype=bool))
        on_obstacle[[0, -1], :] = True  # the map edge counts as a wall, as for the lidar
        on_obstacle[:, [0, -1]] = True
        self.step_m = 0.5 * self.resolution_m
        # Distance to the obstacles' *surfaces*, from outside and from inside alike: returns
        # lie on faces, and with a field that is 0 all through a thick wall, end points could
        # sink into the wall for free -- a skid that sees one wall only (a hangar) would be
        # pulled toward it by up to the wall's thickness.
        surface = on_obstacle & ~ndimage.binary_erosion(
            on_obstacle, structure=np.ones((3, 3), dtype=bool), border_value=1
        )
        self.distance_m = ndimage.distance_transform_edt(~surface) * self.step_m
        self.log_p = self._log_p(self.distance_m)
        self.log_p_off_map = float(np.log(self.z_rand / self.max_range_m))
        # Lookup tables with a ring of off-map values: clipping an index then lands on it.
        self._distance_padded = np.pad(self.distance_m, 1, constant_values=OFF_MAP_DISTANCE_M)
        self._log_p_padded = np.pad(self.log_p, 1, constant_values=self.log_p_off_map).astype(
            np.float32
        )
        # Where the filter may place particles: known free cells with enough clearance.
        free = ~grid.occupied & ~grid.unknown
        clear = grid.distance_field() >= min_clearance_m
        self.free_cells = np.argwhere(free & clear)
        if len(self.free_cells) == 0:
            raise ValueError(
                f"likelihood: the map has no free cell with clearance >= {min_clearance_m} m"
            )

    def _log_p(self, d: np.ndarray) -> np.ndarray:
        gauss = np.exp(-0.5 * (d / self.sigma_hit_m) ** 2) / (np.sqrt(2 * np.pi) * self.sigma_hit_m)
        return np.log(self.z_hit * gauss + self.z_rand / self.max_range_m)

    def _lookup(self, table: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Nearest-lattice lookup in a table padded with one ring of the off-map value."""
        rows, cols = table.shape
        j = np.rint((x - self.origin[0]) * (1.0 / self.step_m)).astype(np.int64) + 1
        i = np.rint((y - self.origin[1]) * (1.0 / self.step_m)).astype(np.int64) + 1
        np.clip(j, 0, cols - 1, out=j)
        np.clip(i, 0, rows - 1, out=i)
        return table.ravel()[i * cols + j]

    def distance(self, xy: np.ndarray) -> np.ndarray:
        """Distance (metres, to half a cell) from world points ``(..., 2)`` to the nearest
        obstacle. Points outside the map count as far from everything
        (:data:`OFF_MAP_DISTANCE_M`), as in amcl: a particle that drifted off the map must not
        score its scan as hits on the edge."""
        xy = np.asarray(xy, dtype=float)
        return self._lookup(self._distance_padded, xy[..., 0], xy[..., 1])

    def log_likelihood(self, xy: np.ndarray) -> np.ndarray:
        """Log of the per-beam likelihood ``z_hit * N(d; 0, sigma) + z_rand / max_range`` at
        world end points ``(..., 2)``."""
        xy = np.asarray(xy, dtype=float)
        return self.log_likelihood_xy(xy[..., 0], xy[..., 1])

    def log_likelihood_xy(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """As :meth:`log_likelihood` for separate coordinate arrays (no stacking)."""
        return self._lookup(self._log_p_padded, x, y)

    def sample_free(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``n`` poses uniform over free space (cell, then a point in it) and heading."""
        rc = self.free_cells[rng.integers(0, len(self.free_cells), n)]
        off = rng.random((n, 2))
        x = self.origin[0] + (rc[:, 1] + off[:, 0]) * self.resolution_m
        y = self.origin[1] + (rc[:, 0] + off[:, 1]) * self.resolution_m
        return np.column_stack([x, y, rng.uniform(-np.pi, np.pi, n)])
