"""Grid planning: paths avoid the inflated walls, unreachable goals give None, coarsening is
conservative, one Dijkstra run serves many goals."""

import numpy as np
import pytest
from shapely.geometry import LineString, box

from swarmpark.core.gridmap import grid_from_walls
from swarmpark.plan.grid import build_costmap, path_length, paths_from, plan_path

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
