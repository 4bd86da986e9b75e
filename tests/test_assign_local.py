"""Re-assignment of large groups by swaps between neighbours (assign.reassign_local)."""

import numpy as np
import pytest

from swarmpark.assign import assign, cost_matrix, pair_costs, reassign_local


@pytest.mark.parametrize("cost", ["euclidean", "formation"])
def test_pair_costs_are_the_matrix_entries(cost):
    rng = np.random.default_rng(3)
    r, g = rng.uniform(0, 20, (30, 2)), rng.uniform(0, 20, (40, 2))
    rows, cols = rng.integers(0, 30, 100), rng.integers(0, 40, 100)
    assert pair_costs(r, g, rows, cols, cost) == pytest.approx(
        cost_matrix(r, g, cost)[rows, cols], rel=1e-12
    )
    with pytest.raises(ValueError, match="pair_costs: cost must be"):
        pair_costs(r, g, rows, cols, "path")


def test_crossed_pairs_swap_and_the_optimum_stays():
    rng = np.random.default_rng(0)
    robots = rng.uniform(0, 50, (300, 2))
    goals = robots + rng.normal(0, 0.2, robots.shape)  # each robot's own goal is next to it
    best = assign(cost_matrix(robots, goals, "euclidean"))
    same, changed = reassign_local(robots, goals, best, "euclidean")
    assert not changed and np.array_equal(same, best)
    crossed = best.copy()
    pairs = [(0, int(np.argsort(np.hypot(*(robots - robots[0]).T))[1]))]
    for a, b in pairs:
        crossed[a], crossed[b] = best[b], best[a]
    out, changed = reassign_local(robots, goals, crossed, "euclidean")
    assert changed and np.array_equal(out, best)
    # A locked robot keeps its goal; a goal it does not fit is never swapped to it.
    locked = np.zeros(300, bool)
    locked[pairs[0][0]] = True
    out, changed = reassign_local(robots, goals, crossed, "euclidean", locked=locked)
    assert not changed and np.array_equal(out, crossed)
    out, changed = reassign_local(
        robots, goals, crossed, "euclidean", fits=lambda rows, cols: cols != best[pairs[0][0]]
    )
    assert not changed
    assert sorted(out.tolist()) == sorted(crossed.tolist())  # still a permutation
