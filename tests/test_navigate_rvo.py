"""Parts of the RVO navigation stack: the monitor's dynamic rollout, the joint check of two
skids turning together, and the keep-right rule."""

import numpy as np
import pytest
from helpers import Scripted, make_world

from swarmpark.control.nav.monitor import CollisionMonitor, rollout
from swarmpark.control.nav.navigator import Navigator, NavParams
from swarmpark.control.nav.params import MonitorParams
from swarmpark.supervisor.core import Supervisor


def _two_skids(a_pose, b_pose):
    """Two skids (poses x, y, yaw in degrees) in the 10 m x 6 m test world."""
    return make_world(robots=[{"id": "a", "pose": a_pose}, {"id": "b", "pose": b_pose}])


def _navigator(view) -> Navigator:
    nav = Navigator(NavParams(avoidance="rvo"))
    nav.scene.update(view)
    return nav


def _check(view, idx, raw, **kw):
    nav = _navigator(view)
    return nav.monitor.check(view, idx, raw, nav.scene, **kw).commands


def test_rollout_follows_the_simulator_within_the_acceleration_limits():
    world = make_world()
    cmd = np.array([[0.1, -1.0]])
    sup = Supervisor(world, controller=Scripted(lambda t: cmd))
    sup.sim.vel[:] = [[0.4, 0.8]]  # turning left fast; told to turn right
    sup.inbox.vel[:] = sup.sim.vel  # as the skid's odometry reports it (the view reads the link)
    view = sup.view()
    times = np.array([0.2, 0.5, 1.0])
    predicted = rollout(view, np.array([0]), cmd[:, 0], cmd[:, 1], times)[0]
    actual = []
    for _ in range(20):
        sup.sim.step(cmd)
        if any(abs(sup.sim.t - t) < 1e-9 for t in times):
            actual.append(sup.sim.poses[0].copy())
    assert np.allclose(predicted, np.array(actual), atol=1e-9)
    # It keeps turning left for 0.4 s before the right turn starts.
    assert predicted[0, 2] > view.poses[0, 2]


def test_joint_check_stops_two_skids_that_would_swing_their_corners_together():
    # Side by side with a 0.25 m gap: each turning in place is clear of the other standing
    # still, but the two front corners swing towards each other at the same time.
    sup = Supervisor(_two_skids([5.0, 2.0, 0.0], [5.0, 3.05, 0.0]))
    view = sup.view()
    raw = np.array([[0.0, 0.3], [0.0, -0.3]])
    idx = np.array([0, 1])
    nav = _navigator(view)
    standing = CollisionMonitor(MonitorParams(pairs_closing=False))  # each against the other still
    alone = standing.check(view, idx, raw, nav.scene).commands
    assert np.array_equal(alone, raw)
    # The monitor mode's pair check stops only the skid of lower rank; the joint check of the
    # RVO mode stops both.
    paired = _check(view, idx, raw)
    assert np.array_equal(paired, [raw[0], [0.0, 0.0]])
    together = _check(view, idx, raw, joint=True)
    assert np.array_equal(together, np.zeros((2, 2)))
    # Turning the same way, the corners move apart in step: both keep their commands.
    same = np.array([[0.0, 0.3], [0.0, 0.3]])
    assert np.array_equal(_check(view, idx, same, joint=True), same)


@pytest.mark.parametrize(
    ("y", "expected"),
    [(3.0, 1.0), (1.5, 1.0 / 3.0)],  # open (3 m from the walls), then 1.5 m from a wall
)
def test_keep_right_turns_oncoming_skids_and_fades_near_walls(y, expected):
    # a heading +x, b 4 m ahead heading -x: they come towards each other.
    sup = Supervisor(_two_skids([3.0, y, 0.0], [7.0, y, 180.0]))
    view = sup.view()
    nav = _navigator(view)
    centres = view.poses[:, :2]
    u = np.array([[0.5, 0.0], [-0.5, 0.0]])
    movers = np.array([True, True])
    both = np.array([0, 1])
    equal = np.array([1.0, 1.0])

    def keep_right(u, prio):
        return nav.avoidance.keep_right(view, centres, u, prio, both, movers, nav.scene)

    turn = keep_right(u, equal)
    assert turn == pytest.approx(nav.params.rvo.keep_right_rad * expected * np.ones(2))
    # The lower priority (b: a third of a's) takes the larger share of the turn.
    low = keep_right(u, np.array([3.0, 1.0]))
    assert low[1] > 1.5 * low[0] > 0.0
    # Going the same way, or with the other one behind: no turn.
    same = np.array([[0.5, 0.0], [0.5, 0.0]])
    assert not keep_right(same, equal).any()
    apart = np.array([[-0.5, 0.0], [0.5, 0.0]])
    assert not keep_right(apart, equal).any()
