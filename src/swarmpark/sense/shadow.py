"""What lies behind a detection: the cells a scan cannot tell free, for laying out spots.

A scan sees the face of an obstacle the map lacks, not its depth: a crate seen from one side
marks a line of cells, and its inside is as unknown as the space behind it. A layout on the
map plus the detected cells alone would put a spot right behind that face, on the crate.
:func:`shadowed_cells` gives the cells behind detected returns (each beam that ends on
something the map does not explain, from its end point :data:`SHADOW_DEPTH_M` further) that
no beam of any of the scans passed through (seen free): the layout keeps off them as it keeps off
the detections (:mod:`swarmpark.supervisor.known_map`). Walls of the map cast no shadow: the
map says what is behind them.
"""

from __future__ import annotations

import numpy as np

from swarmpark.core.gridmap import OccupancyGrid
from swarmpark.sense.lidar import LidarSpec, beam_angles, sensor_poses

__all__ = ["SHADOW_DEPTH_M", "shadowed_cells"]

#: How deep an obstacle the map lacks is taken to be behind the face a scan sees: the things
#: that stand where the map shows floor are crates, pallets (1.2 x 1.0 m), carts, people; a
#: wall the map lacks is seen end to end sooner or later. Beyond this the prior map holds.
SHADOW_DEPTH_M = 1.5


def _mark(grid: OccupancyGrid, xy: np.ndarray) -> np.ndarray:
    mask = np.zeros(grid.shape, dtype=bool)
    rc = grid.world_to_cell(xy)
    rc = rc[grid.in_bounds(rc)]
    mask[rc[:, 0], rc[:, 1]] = True
    return mask


def _samples(origin: np.ndarray, direction: np.ndarray, start: np.ndarray, stop: np.ndarray, step):
    """Points every ``step`` along rays ``origin + s * direction`` for ``start <= s < stop``
    (one row per ray; rays with ``stop <= start`` give none)."""
    n = np.maximum(np.ceil((stop - start) / step).astype(np.int64), 0)
    if not n.sum():
        return np.zeros((0, 2))
    ray = np.repeat(np.arange(len(n)), n)
    first = np.cumsum(n) - n
    s = start[ray] + step * (np.arange(n.sum()) - first[ray])
    return origin[ray] + s[:, None] * direction[ray]


def shadowed_cells(
    grid: OccupancyGrid,
    spec: LidarSpec,
    poses: np.ndarray,
    ranges: np.ndarray,
    *,
    map_tolerance_m: float = 0.15,
    depth_m: float = SHADOW_DEPTH_M,
    free_margin_m: float | None = None,
) -> np.ndarray:
    """``(H, W)`` bool: cells of ``grid`` behind detected returns that no beam saw free.

    Parameters
    ----------
    grid
        The prior map (a return within ``map_tolerance_m`` of its occupied cells is a wall).
    spec
        The scanner.
    poses
        ``(N, 3)`` poses the scans were taken at (the skids' estimates).
    ranges
        ``(N, B)`` the scans; ``nan`` beams (dropouts, returns off other skids) tell nothing,
        ``inf`` (no return) is free out to the range.
    map_tolerance_m
        As the obstacle layer's (:class:`~swarmpark.sense.costmap.CostmapConfig`).
    depth_m
        How far behind a detected return the shadow reaches (out to the scanner's range
        at most).
    free_margin_m
        A beam sees free space up to this short of its return (default two cells), so the
        detected face itself is not cleared.

    Examples
    --------
    >>> from swarmpark.sense.lidar import scan
    >>> g = OccupancyGrid(np.zeros((60, 100), bool), 0.1)  # 10 x 6 m, no walls
    >>> spec = LidarSpec(num_beams=720)
    >>> pose = np.array([[1.0, 3.0, 0.0]])
    >>> crate = np.array([[[4.0, 2.5], [5.0, 2.5], [5.0, 3.5], [4.0, 3.5]]])
    >>> r = scan(spec, pose, g, polygons=crate)
    >>> sh = shadowed_cells(g, spec, pose, r)
    >>> bool(sh[30, 45]), bool(sh[30, 35]), bool(sh[10, 45])  # inside, in front, beside
    (True, False, False)
    """
    poses = np.asarray(poses, dtype=float).reshape(-1, 3)
    ranges = np.asarray(ranges, dtype=float).reshape(len(poses), spec.num_beams)
    res = grid.resolution_m
    margin = 2.0 * res if free_margin_m is None else float(free_margin_m)
    sensors = sensor_poses(spec, poses)
    ang = sensors[:, 2:3] + beam_angles(spec)[None, :]
    direction = np.stack([np.cos(ang), np.sin(ang)], -1).reshape(-1, 2)
    origin = np.repeat(sensors[:, :2], spec.num_beams, axis=0)
    r = ranges.reshape(-1)
    rmax = spec.max_range_m
    returned = np.isfinite(r) & (r < rmax)
    end = origin + np.where(returned, r, 0.0)[:, None] * direction
    rc = grid.world_to_cell(end)
    inside = grid.in_bounds(rc)
    detected = np.zeros(len(r), dtype=bool)
    dist = grid.distance_field()
    ok = returned & inside
    detected[ok] = dist[rc[ok, 0], rc[ok, 1]] > map_tolerance_m
    step = 0.5 * res
    far = np.minimum(r[detected] + depth_m, rmax)
    behind = _samples(origin[detected], direction[detected], r[detected] + step, far, step)
    shadow = _mark(grid, behind)
    if not shadow.any():
        return shadow
    seen = np.isposinf(r) | returned
    reach = np.where(np.isposinf(r), rmax, r) - margin
    free = _samples(origin[seen], direction[seen], np.zeros(seen.sum()), reach[seen], step)
    return shadow & ~_mark(grid, free)
