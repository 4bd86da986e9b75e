"""Grid path planning on an inflated costmap.

The costmap follows Navigation2's idea: cells closer to an obstacle than the skid's inscribed
radius are lethal; between the inscribed and circumscribed radius the cost rises so paths keep
to the middle of corridors; beyond it the cost is the travelled distance. Paths are searched
by A* (:mod:`.astar`, the metric of ``skimage.graph.MCP_Geometric``: 8-connected, diagonal
moves weighted by length), which expands the cells near the way rather than flooding the map;
whole-map fields (:func:`distance_field_from`) are skimage's Dijkstra floods.
"""

from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from skimage.graph import MCP_Geometric

from swarmpark.core.gridmap import OccupancyGrid
from swarmpark.plan.astar import search

__all__ = [
    "paths_from",
    "Costmap",
    "build_costmap",
    "plan_path",
    "distance_field_from",
    "entry_points",
    "path_length",
    "shortcut",
]

#: Extra cost (per metre travelled) at the inscribed radius, falling to 0 at the circumscribed.
INFLATION_WEIGHT = 4.0


@dataclass(frozen=True)
class Costmap:
    """Traversal cost per cell (``inf`` where lethal) for one skid size."""

    cost: np.ndarray  # (H, W) float, >= 1 or inf
    grid: OccupancyGrid
    inscribed_m: float
    circumscribed_m: float
    #: Cells with no wall within the LIDAR's reach (coastal navigation, see
    #: :func:`build_costmap`); None when paths do not care.
    blind: np.ndarray | None = None

    def lethal(self) -> np.ndarray:
        return ~np.isfinite(self.cost)


def build_costmap(
    grid: OccupancyGrid,
    inscribed_m: float,
    circumscribed_m: float,
    extra_occupied: np.ndarray | None = None,
    *,
    resolution_m: float | None = None,
    seen_within_m: float | None = None,
    blind_weight: float = 0.0,
    wide_at=None,
    wide_band_m: float = 0.0,
) -> Costmap:
    """Inflate ``grid`` (plus ``extra_occupied`` cells, e.g. detected obstacles) for a skid.

    With ``resolution_m`` coarser than the map, the map is first coarsened conservatively
    (a coarse cell is occupied if any of its cells is): fewer cells to search.

    ``wide_at``: a function of world points ``(K, 2)`` giving ``(K,)`` bool; in the cells
    whose centres it marks (the navigator's planner marks doors) the inflation band reaches
    ``wide_band_m`` farther than ``circumscribed_m``, so a path through them keeps to the
    middle (as a Navigation2 inflation radius beyond the circumscribed one) while elsewhere
    it may pass as close as the circumscribed radius.

    Coastal navigation (Roy, Burgard, Fox and Thrun, "Coastal navigation - mobile robot
    navigation with uncertainty in dynamic environments", ICRA 1999): a skid that localizes
    with its LIDAR drifts on its odometry wherever no wall is in range. With ``seen_within_m``,
    cells farther than that from every occupied cell (the map's edge does not count: it is not
    seen) are *blind*, and each metre through them costs ``blind_weight`` metres more, so paths
    keep within sight of structure when that is not much longer.
    """
    if extra_occupied is not None:
        grid = OccupancyGrid(grid.occupied | extra_occupied, grid.resolution_m, grid.origin)
    if resolution_m is not None and resolution_m > grid.resolution_m * 1.5:
        grid = grid.coarsen(int(round(resolution_m / grid.resolution_m)))
    occ = grid.occupied
    # Distance from each cell centre to the nearest occupied cell's edge (the map edge too).
    d = np.maximum(ndimage.distance_transform_edt(np.pad(~occ, 1))[1:-1, 1:-1] - 0.5, 0.0)
    d *= grid.resolution_m
    span = max(circumscribed_m - inscribed_m, 1e-9)
    cost = 1.0 + INFLATION_WEIGHT * np.clip((circumscribed_m - d) / span, 0.0, 1.0)
    if wide_at is not None and wide_band_m > 0.0:
        rows, cols = np.indices(occ.shape)
        centres = grid.cell_to_world(np.column_stack([rows.ravel(), cols.ravel()]))
        wide = np.asarray(wide_at(centres), dtype=bool).reshape(occ.shape)
        outer = circumscribed_m + wide_band_m
        band = 1.0 + INFLATION_WEIGHT * np.clip((outer - d) / (outer - inscribed_m), 0.0, 1.0)
        cost = np.where(wide, band, cost)
    cost[d < inscribed_m] = np.inf
    blind = None
    if seen_within_m is not None:
        if occ.any():
            seen = ndimage.distance_transform_edt(~occ) * grid.resolution_m <= seen_within_m
        else:
            seen = np.zeros_like(occ)
        blind = ~seen
        cost[blind] += blind_weight
    return Costmap(cost, grid, inscribed_m, circumscribed_m, blind)


def _free_disc(
    cost: np.ndarray, grid: OccupancyGrid, xy: np.ndarray, radius_m: float
) -> np.ndarray:
    """Make the lethal-by-inflation cells within ``radius_m`` of ``xy`` passable (not walls).

    A skid parked close to a wall sits inside its own inflation; it must still be able to
    leave, and a goal next to a wall must still be reachable.
    """
    rc = grid.world_to_cell(xy[None])[0]
    r = int(np.ceil(radius_m / grid.resolution_m))
    h, w = cost.shape
    r0, r1 = max(rc[0] - r, 0), min(rc[0] + r + 1, h)
    c0, c1 = max(rc[1] - r, 0), min(rc[1] + r + 1, w)
    if r0 >= r1 or c0 >= c1:
        return cost
    rr, cc = np.mgrid[r0:r1, c0:c1]
    near = (rr - rc[0]) ** 2 + (cc - rc[1]) ** 2 <= r * r
    win = cost[r0:r1, c0:c1]
    fix = near & ~np.isfinite(win) & ~grid.occupied[r0:r1, c0:c1]
    if fix.any():
        cost = cost.copy()
        cost[r0:r1, c0:c1][fix] = 1.0 + INFLATION_WEIGHT
    return cost


@contextmanager
def _freed(costmap: Costmap, points, radius_m: float):
    """The costmap's cost array with :func:`_free_disc` applied around each of ``points``,
    changed in place for the duration of the block and restored after it (a copy of a large
    map per plan would cost more than the search)."""
    cost, grid = costmap.cost, costmap.grid
    h, w = cost.shape
    r = int(np.ceil(radius_m / grid.resolution_m))
    rcs = grid.world_to_cell(np.asarray(points, float).reshape(-1, 2))
    changed = []
    for rc in rcs:
        r0, r1 = max(rc[0] - r, 0), min(rc[0] + r + 1, h)
        c0, c1 = max(rc[1] - r, 0), min(rc[1] + r + 1, w)
        if r0 >= r1 or c0 >= c1:
            continue
        rr, cc = np.mgrid[r0:r1, c0:c1]
        near = (rr - rc[0]) ** 2 + (cc - rc[1]) ** 2 <= r * r
        fix = near & ~np.isfinite(cost[r0:r1, c0:c1]) & ~grid.occupied[r0:r1, c0:c1]
        if fix.any():
            rows, cols = np.nonzero(fix)
            flat = (rows + r0) * w + (cols + c0)
            changed.append(flat)
            cost.flat[flat] = 1.0 + INFLATION_WEIGHT
    try:
        yield cost
    finally:
        for flat in changed:
            cost.flat[flat] = np.inf


def plan_path(costmap: Costmap, start_xy, goal_xy, *, free_radius_m: float | None = None):
    """Least-cost path from ``start_xy`` to ``goal_xy`` as world points ``(K, 2)``.

    Returns ``None`` when the goal cannot be reached. The first point is ``start_xy`` and the
    last ``goal_xy``; the interior points are grid cell centres, shortcut by line of sight.
    """
    grid = costmap.grid
    start_xy = np.asarray(start_xy, float)
    goal_xy = np.asarray(goal_xy, float)
    r_free = costmap.inscribed_m if free_radius_m is None else free_radius_m
    s, g = grid.world_to_cell(np.stack([start_xy, goal_xy]))
    if not (grid.in_bounds(s[None])[0] and grid.in_bounds(g[None])[0]):
        return None
    with _freed(costmap, [start_xy, goal_xy], r_free) as cost:
        if not (np.isfinite(cost[tuple(s)]) and np.isfinite(cost[tuple(g)])):
            return None
        _, (cells,), _ = search(cost, s, g[None])
        if cells is None:
            return None
        pts = grid.cell_to_world(cells)
        pts[0], pts[-1] = start_xy, goal_xy
        return shortcut(pts, cost, grid, costmap.blind)


def paths_from(
    costmap: Costmap,
    start_xy,
    goals_xy,
    *,
    costs: list | None = None,
    budget: int | None = None,
    expanded: list | None = None,
) -> list[np.ndarray | None]:
    """Least-cost paths from one start to many goals with a single search.

    ``costs``: if given (a list), the accumulated cost of each path (``inf`` for none) is
    appended to it, in metres weighted by the cells' costs. ``budget``: at most this many
    cells are expanded (goals not reached by then get None). ``expanded``: if given (a list),
    the number of cells expanded is appended to it (the work done, for planning budgets).
    """
    grid = costmap.grid
    start_xy = np.asarray(start_xy, float)
    goals_xy = np.asarray(goals_xy, float).reshape(-1, 2)
    out: list[np.ndarray | None] = [None] * len(goals_xy)
    found = np.full(len(goals_xy), np.inf)
    s = grid.world_to_cell(start_xy[None])[0]
    cells = grid.world_to_cell(goals_xy)
    inb = grid.in_bounds(cells)
    work = 0
    with _freed(costmap, np.vstack([start_xy[None], goals_xy]), costmap.inscribed_m) as cost:
        if grid.in_bounds(s[None])[0] and np.isfinite(cost[tuple(s)]) and inb.any():
            ends = np.flatnonzero(inb)
            c, p, work = search(
                cost, s, cells[ends], budget=(1 << 62) if budget is None else budget
            )
            for k, cost_k, cells_k in zip(ends.tolist(), c, p, strict=True):
                if cells_k is None:
                    continue
                found[k] = cost_k * grid.resolution_m
                pts = grid.cell_to_world(cells_k)
                pts[0], pts[-1] = start_xy, goals_xy[k]
                out[k] = pts
    if costs is not None:
        costs += found.tolist()
    if expanded is not None:
        expanded.append(work)
    return out


def shortcut(
    path: np.ndarray, cost: np.ndarray, grid: OccupancyGrid, blind: np.ndarray | None = None
) -> np.ndarray:
    """Drop waypoints that can be skipped by a straight segment through no costlier cells.

    A segment is allowed if every cell it crosses is passable and no costlier than the worst
    cell of the path it replaces (or 1, the cost outside every inflation band), and, given the
    ``blind`` cells of a coastal costmap (:func:`build_costmap`), if it runs no farther through
    them than the path it replaces (plus a cell): a straight line must not cut the corner a
    coastal path took to stay in sight of a wall. From each kept
    waypoint the farthest allowed one is found by galloping and bisection, so a path of K
    cells takes O(log K) line-of-sight checks per kept segment.
    """
    if len(path) <= 2:
        return path
    rc_path = grid.world_to_cell(path)
    inb = grid.in_bounds(rc_path)
    along = np.full(len(path), np.inf)
    along[inb] = cost[rc_path[inb, 0], rc_path[inb, 1]]
    step_m = grid.resolution_m / 2
    h, w = cost.shape
    if blind is not None:
        # Blind metres along the path up to each waypoint (a step counts if it starts blind).
        on = np.ones(len(path), bool)
        on[inb] = blind[rc_path[inb, 0], rc_path[inb, 1]]
        steps = np.linalg.norm(np.diff(path, axis=0), axis=1) * on[:-1]
        blind_to = np.concatenate([[0.0], np.cumsum(steps)])

    def visible(i: int, j: int) -> bool:
        a, b = path[i], path[j]
        n = max(int(np.linalg.norm(b - a) / step_m), 2)
        t = np.linspace(0.0, 1.0, n)[:, None]
        xy = a + t * (b - a)
        col = np.floor((xy[:, 0] - grid.origin[0]) / grid.resolution_m).astype(int)
        row = np.floor((xy[:, 1] - grid.origin[1]) / grid.resolution_m).astype(int)
        if row.min() < 0 or col.min() < 0 or row.max() >= h or col.max() >= w:
            return False
        seg = cost[row, col]
        if not (np.all(np.isfinite(seg)) and seg.max() <= max(along[i : j + 1].max(), 1.0)):
            return False
        if blind is None:
            return True
        blind_m = np.count_nonzero(blind[row, col]) * np.linalg.norm(b - a) / n
        return bool(blind_m <= blind_to[j] - blind_to[i] + grid.resolution_m)

    out = [path[0]]
    i, last = 0, len(path) - 1
    while i < last:
        j, step = i + 1, 1
        while j + step <= last and visible(i, j + step):
            j += step
            step *= 2
        lo, hi = j, min(j + step, last + 1)
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if visible(i, mid):
                lo = mid
            else:
                hi = mid
        out.append(path[lo])
        i = lo
    return np.asarray(out)


def distance_field_from(
    costmap: Costmap, goal_xy, *, free_radius_m: float | None = None
) -> np.ndarray:
    """Free-space path length (m, ``inf`` if unreachable) from every cell to ``goal_xy``.

    One Dijkstra run per goal serves every robot (a column of the ``path`` cost matrix).
    Inflation bands count as plain distance here (cost 1), so it is a length, not a cost.
    """
    grid = costmap.grid
    goal_xy = np.asarray(goal_xy, float)
    r_free = costmap.inscribed_m if free_radius_m is None else free_radius_m
    lethal = ~np.isfinite(_free_disc(costmap.cost, grid, goal_xy, r_free))
    unit = np.where(lethal, np.inf, 1.0)
    g = grid.world_to_cell(goal_xy[None])[0]
    if not grid.in_bounds(g[None])[0] or lethal[tuple(g)]:
        return np.full(unit.shape, np.inf)
    cum, _ = MCP_Geometric(unit, fully_connected=True).find_costs([tuple(g)])
    return cum * grid.resolution_m


def entry_points(costmap: Costmap, starts_xy, points_xy) -> np.ndarray:
    """For each start ``(S, 2)``: the point of ``points_xy`` ``(P, 2)`` (an area's edge) at
    which its shortest free-space path into the area arrives, ``(S, 2)`` (NaN for a start
    with no path). One Dijkstra flood from the points; every start's path is traced back to
    the point it came from at once (a step per cell of the longest path)."""
    grid = costmap.grid
    lethal = costmap.lethal()
    starts = np.asarray(starts_xy, float).reshape(-1, 2)
    out = np.full((len(starts), 2), np.nan)
    pts = np.asarray(points_xy, float).reshape(-1, 2)
    pc = grid.world_to_cell(pts)
    ok = grid.in_bounds(pc)
    ok[ok] = ~lethal[pc[ok, 0], pc[ok, 1]]
    if not ok.any():
        return out
    mcp = MCP_Geometric(np.where(lethal, np.inf, 1.0), fully_connected=True)
    cum, back = mcp.find_costs([tuple(c) for c in pc[ok]])
    point_at = np.full(lethal.shape, -1)
    point_at[pc[ok, 0], pc[ok, 1]] = np.flatnonzero(ok)
    rc = grid.world_to_cell(starts)
    live = grid.in_bounds(rc)
    live[live] = np.isfinite(cum[rc[live, 0], rc[live, 1]])
    cur = rc[live].copy()
    offsets = np.asarray(mcp.offsets)
    while len(cur):
        step = back[cur[:, 0], cur[:, 1]]
        on = step >= 0  # -1 at the flood's sources
        if not on.any():
            break
        cur[on] -= offsets[step[on]]
    out[live] = pts[point_at[cur[:, 0], cur[:, 1]]]
    return out


def path_length_matrix(costmap: Costmap, starts_xy, goals_xy) -> np.ndarray:
    """Free-space path lengths ``(R, G)`` from every start to every goal (``inf`` where there
    is none): one Dijkstra run per goal, read at the starts' cells."""
    grid = costmap.grid
    starts_xy = np.asarray(starts_xy, float).reshape(-1, 2)
    goals_xy = np.asarray(goals_xy, float).reshape(-1, 2)
    rc = grid.world_to_cell(starts_xy)
    inb = grid.in_bounds(rc)
    out = np.full((len(starts_xy), len(goals_xy)), np.inf)
    for g, goal in enumerate(goals_xy):
        field_m = distance_field_from(costmap, goal)
        out[inb, g] = field_m[rc[inb, 0], rc[inb, 1]]
    return out


def path_length(path: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(np.asarray(path), axis=0), axis=1).sum())
