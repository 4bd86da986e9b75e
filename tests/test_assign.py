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
