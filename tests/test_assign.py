"""Goal assignment: optimality against brute force, the 2018 Fig. 7 tie, hysteresis, fits."""

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from swarmpark.assign import (
    AssignmentError,
    assign,
    bottleneck_assignment,
    cost_matrix,
    footprint_fits,
    reassign,
    sparse_assign,
)

points = st.lists(st.tuples(st.floats(0, 20), st.floats(0, 20)), min_size=1, max_size=6)


@settings(max_examples=60, deadline=None)
@given(points, points, st.sampled_from(["euclidean", "formation"]))
def test_assignment_equals_brute_force(robots, goals, cost):
    n = min(len(robots), len(goals))
    r, g = np.array(robots[:n]), np.array(goals[:n])
    c = cost_matrix(r, g, cost)
    best = min(sum(c[i, p[i]] for i in range(n)) for p in itertools.permutations(range(n)))
    got = assign(c)
    assert sorted(got.tolist()) == list(range(n))
    assert c[np.arange(n), got].sum() == pytest.approx(best)


@settings(max_examples=60, deadline=None)
@given(points, points)
def test_bottleneck_equals_brute_force(robots, goals):
    n = min(len(robots), len(goals))
    c = cost_matrix(np.array(robots[:n]), np.array(goals[:n]), "euclidean")
    best = min(max(c[i, p[i]] for i in range(n)) for p in itertools.permutations(range(n)))
    _, worst = bottleneck_assignment(c)
    assert worst == pytest.approx(best)


def test_fig7_hallway_tie_and_the_formation_cost():
    # Two skids in a line in a hallway, two goals further down the same line.
    robots = np.array([[6.0, 0.0], [3.0, 0.0]])  # r1 in front, r2 behind
    goals = np.array([[12.8, 0.0], [14.2, 0.0]])  # g1 near, g2 far
    e = cost_matrix(robots, goals, "euclidean")
    # Euclidean totals tie: r1->g1 + r2->g2 == r1->g2 + r2->g1 (2018 paper, Fig. 7).
    assert e[0, 0] + e[1, 1] == pytest.approx(e[0, 1] + e[1, 0])
    # The formation cost sends the front skid to the far goal, so nobody has to pass.
    assert assign(cost_matrix(robots, goals, "formation")).tolist() == [1, 0]


def test_sequential_is_goal_i_to_robot_i():
    c = cost_matrix(np.zeros((3, 2)), np.array([[5, 0], [0, 5], [1, 1]], float), "sequential")
    assert assign(c).tolist() == [0, 1, 2]


def test_hysteresis_keeps_a_near_tie_and_takes_a_clear_gain():
    cost = np.array([[1.0, 1.05], [1.05, 1.0]])
    # The current assignment is 0.1 worse than the optimum: within the margin, kept.
    kept, changed = reassign(cost, np.array([1, 0]))
    assert kept.tolist() == [1, 0] and not changed
    far = np.array([[1.0, 9.0], [9.0, 1.0]])
    new, changed = reassign(far, np.array([1, 0]))
    assert new.tolist() == [0, 1] and changed


def test_goals_go_only_to_skids_that_fit():
    fits = footprint_fits([(1.2, 0.8), (1.6, 0.9)], [(1.6, 0.9), (1.2, 0.8)])
    # The small skid fits both slots; the big one only the big slot.
    assert fits.tolist() == [[True, True], [True, False]]
    c = cost_matrix(
        np.array([[0.0, 0.0], [10.0, 0.0]]),
        np.array([[10.0, 0.0], [0.0, 0.0]]),
        "euclidean",
        fits=fits,
    )
    # The big skid (robot 1) fits only goal 0 (the big slot), however far it is.
    assert assign(c).tolist()[1] == 0


def test_more_robots_than_goals_is_an_error():
    with pytest.raises(AssignmentError, match="3 robots but only 2 goals"):
        assign(np.zeros((3, 2)))


@pytest.mark.parametrize("layout", ["uniform", "cluster-to-grid"])
def test_sparse_k_nearest_assignment_is_within_one_percent_of_the_dense_optimum(layout):
    rng = np.random.default_rng(7)
    n = 400
    if layout == "uniform":
        robots, goals = rng.uniform(0, 60, (n, 2)), rng.uniform(0, 60, (n, 2))
    else:
        gx, gy = np.meshgrid(np.arange(20) * 1.6, np.arange(20) * 1.0)
        goals = np.stack([gx.ravel(), gy.ravel()], -1) + [80.0, 0.0]
        robots = rng.normal(0.0, 8.0, (n, 2))
    c = cost_matrix(robots, goals, "formation")
    idx = np.arange(n)
    dense = c[idx, assign(c)].sum()
    got = sparse_assign(c, k=10)
    assert sorted(got.tolist()) == list(range(n))
    assert dense <= c[idx, got].sum() <= 1.01 * dense


def test_sparse_assignment_falls_back_to_dense_and_keeps_fits():
    # Every robot's favourite is goal 0 and robot 0 is every goal's: the 1-nearest graph
    # has no full matching (robots 1 and 2 only reach goal 0), so the dense solve answers.
    c = np.array([[0.0, 9.0, 9.0], [0.0, 9.5, 9.5], [0.0, 9.5, 9.5]])
    got = sparse_assign(c, k=1)
    assert sorted(got.tolist()) == [0, 1, 2]
    assert c[np.arange(3), got].sum() == pytest.approx(18.5)
    # A pair marked infeasible (footprint does not fit) is never used.
    fits = np.ones((3, 4), bool)
    fits[0, 0] = False
    c2 = cost_matrix(
        np.zeros((3, 2)), np.array([[0, 0], [1, 0], [2, 0], [3, 0]], float), "euclidean", fits=fits
    )
    assert sparse_assign(c2, k=2)[0] != 0
    with pytest.raises(ValueError, match="k must be >= 1"):
        sparse_assign(c2, k=0)


def test_cost_matrix_values_are_the_broadcast_norms():
    rng = np.random.default_rng(3)
    r, g = rng.uniform(-50, 50, (30, 2)), rng.uniform(-50, 50, (40, 2))
    ref = np.linalg.norm(r[:, None] - g[None], axis=-1)
    assert np.array_equal(cost_matrix(r, g, "euclidean"), ref)
    shifted = r - r.mean(axis=0) + g.mean(axis=0)
    form = np.linalg.norm(shifted[:, None] - g[None], axis=-1) + 1e-2 * ref
    assert np.array_equal(cost_matrix(r, g, "formation"), form)
