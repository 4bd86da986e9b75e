"""The action-point field's repulsion split and turn throttle (control.nav.apf)."""

import numpy as np
import pytest
from navkit import make_view

from swarmpark.control.nav.apf import forces_to_command, repulsion, turn_throttle
from swarmpark.control.nav.field import PotentialField
from swarmpark.control.nav.params import FieldParams
from swarmpark.control.nav.scene import Scene

# A 1.2 m x 0.8 m skid with its pivot in the middle: action points at body x = -0.6 and 0.6.
X_REAR, X_FRONT, HALF_W = -0.6, 0.6, 0.4


def _push(x: float, *, lever: bool) -> tuple[np.ndarray, np.ndarray]:
    """Front and rear forces of one obstacle point 0.1 m off the skid's right side at body x."""
    one = np.ones(1)
    front, rear, _ = repulsion(
        np.zeros(1, int),
        np.array([[x, -HALF_W - 0.1]]),
        np.full(1, 0.004),
        X_REAR * one,
        X_FRONT * one,
        HALF_W * one,
        np.full(1, 0.5),
        lever,
    )
    return front[0], rear[0]


def _turn(x: float, *, lever: bool) -> float:
    front, rear = _push(x, lever=lever)
    cmd = forces_to_command(
        np.zeros((1, 2)),
        np.array([X_FRONT]),
        front[None],
        rear[None],
        np.array([X_FRONT]),
        np.array([X_REAR]),
    )
    return float(cmd[0, 1])


def test_lever_split_keeps_force_and_moment():
    front, rear = _push(0.3, lever=True)
    whole_f, whole_r = _push(0.3, lever=False)
    total = whole_f + whole_r  # the paper's rule puts it all at one end
    np.testing.assert_allclose(front + rear, total)
    # The pair has the point's moment about the pivot: F_y * x.
    assert front[1] * X_FRONT + rear[1] * X_REAR == pytest.approx(total[1] * 0.3)
    np.testing.assert_allclose(front, 0.75 * total)


def test_a_push_beside_the_pivot_turns_a_centred_skid_not_at_all():
    assert _turn(0.0, lever=True) == pytest.approx(0.0, abs=1e-12)
    # The paper's rule: the turn flips as the point crosses the pivot, the chatter a skid with
    # a neighbour alongside shows.
    before, after = _turn(-0.01, lever=False), _turn(0.01, lever=False)
    assert before * after < 0 and abs(before - after) > 0.5 * abs(before)
    lever_jump = abs(_turn(0.01, lever=True) - _turn(-0.01, lever=True))
    assert lever_jump < 0.05 * abs(before)


def test_points_beyond_the_ends_push_only_that_end():
    front, rear = _push(1.0, lever=True)
    assert np.all(rear == 0.0) and front[1] > 0
    front, rear = _push(-1.0, lever=True)
    assert np.all(front == 0.0) and rear[1] > 0


def test_throttle_cuts_speed_only_as_far_as_the_skid_turns():
    # The goal force 60 degrees to the left of the body axis: cos^2 = 0.25.
    f_goal = np.array([[np.cos(np.pi / 3), np.sin(np.pi / 3)]] * 3)
    x_goal = np.full(3, 0.6)
    w_goal = f_goal[0, 1] / 0.6
    w_net = np.array([w_goal, 0.0, -w_goal])  # turning freely, held, pushed the other way
    np.testing.assert_allclose(turn_throttle(f_goal, x_goal, w_net), [0.25, 1.0, 1.0])
    np.testing.assert_allclose(turn_throttle(f_goal[:1], x_goal[:1], 0.5 * w_net[:1]), [0.625])
    np.testing.assert_allclose(
        turn_throttle(f_goal, x_goal, w_net, follow_turn=False), [0.25, 0.25, 0.25]
    )
    # A goal straight ahead keeps the full speed whatever the turn.
    ahead = turn_throttle(np.array([[1.0, 0.0]]), np.array([0.6]), np.array([0.8]))
    np.testing.assert_allclose(ahead, [1.0])


def _rear_push(ignore: bool, reverse: bool) -> tuple[np.ndarray, np.ndarray]:
    """Front and rear forces on skid 0 from skid 1 right behind it (0.3 m gap, off to the
    left by 0.3 m), skid 0 driving forwards or in reverse."""
    view = make_view([[5.0, 3.0, 0.0], [3.5, 3.3, 0.0]])
    field = PotentialField(FieldParams(ignore_followers=ignore))
    scene = Scene(0.1, 0.03).update(view)
    idx = np.array([0])
    fp = view.footprints[0]
    return field.repulsion(
        view,
        idx,
        scene,
        np.array([fp.length_m - fp.pivot]),
        np.array([-fp.pivot]),
        np.array([fp.width_m / 2]),
        np.array([0.5]),
        np.array([reverse]),
    )


def test_a_skid_following_behind_does_not_push_the_leader():
    front, rear = _rear_push(ignore=False, reverse=False)
    assert rear[0, 1] < 0 and rear[0, 0] > 0  # without the rule: pushed on and turned
    front, rear = _rear_push(ignore=True, reverse=False)
    assert np.all(front == 0) and np.all(rear == 0)
    # Driving in reverse, the skid behind is ahead in the direction of travel: it pushes.
    front, rear = _rear_push(ignore=True, reverse=True)
    assert rear[0, 1] < 0
