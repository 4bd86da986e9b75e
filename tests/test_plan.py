"""Grid planning: paths avoid the inflated walls, unreachable goals give None, coarsening is
conservative, one Dijkstra run serves many goals."""

import numpy as np
import pytest
from shapely.geometry import LineString, box

from swarmpark.core.gridmap import grid_from_walls
from swarmpark.plan.grid import build_costmap, entry_points, path_length, paths_from, plan_path

WALL = box(4, 0, 4.5, 4.5)


def grid():
    return grid_from_walls((10, 6), 0.05, [WALL])


def test_path_goes_around_the_wall_with_clearance():
    cm = build_costmap(grid(), 0.4, 0.7)
    path = plan_path(cm, (2.0, 1.0), (7.0, 1.0))
    assert path is not None
    assert path[0] == pytest.approx([2.0, 1.0]) and path[-1] == pytest.approx([7.0, 1.0])
    # Every segment stays at least the inscribed radius (less a cell) from the wall.
    assert LineString(path).distance(WALL) >= 0.4 - 0.05
    assert path_length(path) > 2 * 3.5  # it had to go over the top of the wall
    # Line-of-sight shortcutting leaves a few corners, not every cell (the cells number > 100).
    assert len(path) < 20


def test_paths_into_an_area_arrive_where_the_wall_lets_them():
    """Skids west of the wall (open above y = 4.5) reach an area east of it over the top of
    the wall, not at the point of its edge straight ahead of them; a start outside the map
    has no way in."""
    area = box(6, 0.5, 9, 5.5)
    edge = np.asarray(area.exterior.segmentize(0.05).coords)[:-1]
    got = entry_points(build_costmap(grid(), 0.4, 0.4), [(2.0, 1.0), (2.0, 2.5), (20.0, 1.0)], edge)
    for x, y in got[:2]:
        assert x == pytest.approx(6.0) and 4.6 < y <= 5.5  # above the wall's top, not y 1 or 2.5
    assert np.isnan(got[2]).all()


def test_unreachable_goal_gives_none():
    closed = grid_from_walls((10, 6), 0.05, [box(4, 0, 4.5, 6)])
    assert plan_path(build_costmap(closed, 0.4, 0.7), (2.0, 1.0), (7.0, 1.0)) is None


def test_coarsening_never_frees_an_occupied_cell():
    g = grid()
    c = g.coarsen(2)
    assert c.resolution_m == pytest.approx(0.1)
    fine_centres = g.cell_to_world(np.argwhere(g.occupied))
    assert c.is_occupied(fine_centres).all()


def test_one_run_serves_many_goals():
    cm = build_costmap(grid(), 0.4, 0.7)
    goals = np.array([[7.0, 1.0], [7.0, 5.0], [1.0, 5.0]])
    paths = paths_from(cm, (2.0, 1.0), goals)
    assert all(p is not None for p in paths)
    for p, goal in zip(paths, goals, strict=True):
        assert p[-1] == pytest.approx(goal)
        assert LineString(p).distance(WALL) >= 0.4 - 0.05


def _blind_metres(path, cm) -> float:
    """Metres of ``path`` through the coastal costmap's blind cells (sampled every 1 cm)."""
    out = 0.0
    for a, b in zip(path[:-1], path[1:], strict=True):
        n = max(int(np.linalg.norm(b - a) / 0.01), 2)
        pts = a + np.linspace(0, 1, n)[:, None] * (b - a)
        rc = cm.grid.world_to_cell(pts)
        out += cm.blind[rc[:, 0], rc[:, 1]].mean() * np.linalg.norm(b - a)
    return out


def test_coastal_path_keeps_within_sight_of_the_wall():
    """An open deck with one wall along its north side: the coastal costmap (Roy et al. 1999)
    makes the path across it climb to within sight of the wall, and shortcutting must not cut
    the corners it took; with no weight, the straight line."""
    deck = grid_from_walls((20, 12), 0.1, [box(0, 11.8, 20, 12)])
    start, goal = (1.0, 4.0), (19.0, 4.0)
    plain = plan_path(build_costmap(deck, 0.4, 0.7), start, goal)
    assert len(plain) == 2  # straight across
    cm = build_costmap(deck, 0.4, 0.7, seen_within_m=4.0, blind_weight=1.0)
    (mid,), (near,) = (cm.grid.world_to_cell(np.array([xy])) for xy in ([10, 4], [10, 8.5]))
    assert cm.blind[tuple(mid)] and not cm.blind[tuple(near)]
    path = plan_path(cm, start, goal)
    # Out of sight only on the slants up to the seen band (3.8 m of rise) and back down:
    # about 11 m, against 18 m straight across.
    assert _blind_metres(path, cm) < 12.0
    assert path[:, 1].max() >= 7.7
    # The longer way is worth it only while it costs less than the blind metres it saves.
    low = plan_path(
        build_costmap(deck, 0.4, 0.7, seen_within_m=4.0, blind_weight=0.05), start, goal
    )
    assert len(low) == 2


def test_coastal_costmap_needs_something_to_see():
    """With no wall on the map every cell is blind (the map's edge is not seen), and the path
    is the straight line, just costlier."""
    empty = grid_from_walls((10, 6), 0.1, [])
    cm = build_costmap(empty, 0.4, 0.7, seen_within_m=4.0, blind_weight=1.0)
    assert cm.blind.all()
    assert len(plan_path(cm, (1.0, 3.0), (9.0, 3.0))) == 2
