"""A* on the costmap grid (plan/astar.py): the same path costs as skimage's Dijkstra flood,
valid 8-connected cell paths, far fewer cells expanded than a flood, and a budget."""

import numpy as np
import pytest
from skimage.graph import MCP_Geometric

from swarmpark.plan.astar import search


def _random_cost(rng, h, w):
    cost = 1.0 + 4.0 * rng.random((h, w)) * (rng.random((h, w)) < 0.3)
    cost[rng.random((h, w)) < 0.15] = np.inf
    return cost


def _path_cost(cost, cells):
    step = np.sqrt((np.diff(cells, axis=0) ** 2).sum(axis=1))
    c = cost[cells[:, 0], cells[:, 1]]
    return float((step * 0.5 * (c[1:] + c[:-1])).sum())


@pytest.mark.parametrize("seed", range(20))
def test_costs_match_the_dijkstra_flood(seed):
    rng = np.random.default_rng(seed)
    h, w = rng.integers(20, 90, 2)
    cost = _random_cost(rng, h, w)
    start = (int(rng.integers(h)), int(rng.integers(w)))
    cost[start] = 1.0
    goals = np.column_stack([rng.integers(0, h, 3), rng.integers(0, w, 3)])
    cum, _ = MCP_Geometric(cost, fully_connected=True).find_costs([start])
    want = cum[goals[:, 0], goals[:, 1]]
    costs, paths, _ = search(cost, start, goals)
    assert np.array_equal(np.isfinite(costs), np.isfinite(want))
    ok = np.isfinite(want)
    assert costs[ok] == pytest.approx(want[ok], abs=1e-9)
    for k, cells in enumerate(paths):
        if cells is None:
            assert not ok[k]
            continue
        assert tuple(cells[0]) == start and tuple(cells[-1]) == tuple(goals[k])
        assert np.abs(np.diff(cells, axis=0)).max() <= 1  # neighbours, 8-connected
        assert np.isfinite(cost[cells[:, 0], cells[:, 1]]).all()
        assert _path_cost(cost, cells) == pytest.approx(costs[k], abs=1e-9)


def test_open_map_expands_near_the_way_only():
    cost = np.ones((400, 1000))
    goals = np.array([[200, 900], [200, 880], [200, 920]])  # a goal and two staging points
    costs, paths, expanded = search(cost, (210, 50), goals)
    assert all(p is not None for p in paths)
    assert expanded < 0.05 * cost.size  # a flood would expand all 400 000
    # The same costs again on the reused arrays (marks, not clearing).
    again, _, _ = search(cost, (210, 50), goals)
    assert np.array_equal(costs, again)
    cost[100:300, 500] = np.inf  # a wall to go round: the cells before it fill up first
    _, paths, expanded = search(cost, (210, 50), goals)
    assert all(p is not None for p in paths)
    assert expanded < 0.3 * cost.size


def test_budget_stops_the_search():
    cost = np.ones((50, 50))
    costs, paths, expanded = search(cost, (0, 0), np.array([[49, 49]]), budget=10)
    assert expanded == 10 and paths == [None] and costs[0] == np.inf
    costs, paths, _ = search(cost, (0, 0), np.array([[49, 49]]))
    assert costs[0] == pytest.approx(49 * np.sqrt(2))
