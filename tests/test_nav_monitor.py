"""The collision monitor on hand-built views: it leaves a free path alone, slows or stops before
contact with walls, skids and people, and its rollout is the simulator's integration."""

from dataclasses import replace

import numpy as np
import pytest
from navkit import advance, make_view
from shapely.geometry import Polygon

from swarmpark.control.nav.monitor import CollisionMonitor, rollout
from swarmpark.control.nav.params import MonitorParams
from swarmpark.control.nav.scene import Scene
from swarmpark.core.geometry import Footprint, footprint_corners, integrate_unicycle

WALL = (4.0, 0.0, 4.3, 6.0)  # across the hall at x = 4 m


def _check(view, raw, **kw):
    scene = Scene(0.1, MonitorParams().margin_m).update(view)
    mon = CollisionMonitor(MonitorParams())
    return mon.check(view, np.arange(len(view.poses)), np.asarray(raw, float), scene, **kw)


def test_leaves_a_free_path_alone():
    raw = np.array([[0.5, 0.2]])
    res = _check(make_view([[2.0, 3.0, 0.0]], vel=raw), raw)
    assert np.array_equal(res.commands, raw)
    assert not res.slowed[0] and res.blockers == [set()]


def test_slows_before_a_wall_and_stops_short_of_it():
    # Front at 3.6 m driving at 0.5 m/s: within the 1 s horizon it would reach the wall.
    raw = np.array([[0.5, 0.0]])
    res = _check(make_view([[3.0, 3.0, 0.0]], vel=raw, boxes=[WALL]), raw)
    assert 0 <= res.commands[0, 0] < 0.5 and res.slowed[0]


def test_closed_loop_never_touches_the_wall_and_gets_close():
    raw = np.array([[0.5, 0.0]])
    view = make_view([[1.0, 3.0, 0.0]], boxes=[WALL])
    for _ in range(150):
        cmd = _check(view, raw).commands
        view = advance(view, cmd)
        front = view.poses[0, 0] + 0.6
        assert front <= WALL[0]
    assert front > WALL[0] - 0.4  # it does not stop needlessly early


def test_stops_behind_a_standing_skid_and_names_it():
    raw = np.array([[0.5, 0.0], [0.0, 0.0]])
    view = make_view([[3.0, 3.0, 0.0], [4.6, 3.0, 0.0]], vel=raw)
    res = _check(view, raw)
    assert res.commands[0, 0] < 0.5
    assert res.blockers[0] == {1}
    # Without the other skids in the check it would go on.
    assert _check(view, raw, robots=False).commands[0, 0] == 0.5


def test_stops_for_a_person_walking_into_the_way():
    raw = np.array([[0.5, 0.0]])
    # A person 1.2 m to the side of the skid's way 0.9 m ahead, walking across it.
    view = make_view([[2.0, 3.0, 0.0]], vel=raw, people_xy=[[3.3, 1.8]], people_vel=[[0.0, 1.2]])
    assert _check(view, raw).commands[0, 0] < 0.5
    # Walking away from it: no reason to slow.
    view = make_view([[2.0, 3.0, 0.0]], vel=raw, people_xy=[[3.3, 1.8]], people_vel=[[0.0, -1.2]])
    assert _check(view, raw).commands[0, 0] == 0.5


def test_turning_into_a_wall_in_place_is_stopped_too():
    # The corner already at the wall: turning in place would sweep it into the wall.
    view = make_view([[3.3, 3.0, 0.0]], boxes=[WALL])
    res = _check(view, np.array([[0.0, 1.0]]))
    assert np.array_equal(res.commands, np.zeros((1, 2)))


def test_a_skid_whose_turn_in_place_would_hit_still_drives_out_turning():
    # The rear-right corner (1.4, 2.6) 2 cm above a box behind it: turning in place swings it
    # into the box, driving forwards while turning takes it clear. The monitor once stopped
    # every command whose turn in place was unsafe, even with a safe speed (a skid in a
    # generated elevator stood 50 s beside a parked neighbour, its manoeuvre held each time).
    view = make_view([[2.0, 3.0, 0.0]], boxes=[(0.5, 2.0, 1.45, 2.58)])
    assert np.array_equal(_check(view, [[0.0, 0.3]]).commands, np.zeros((1, 2)))
    raw = np.array([[0.5, 0.3]])
    assert np.array_equal(_check(view, raw, straight=True).commands, raw)


def test_a_turn_on_the_spot_that_would_overrun_into_a_neighbour_is_slowed_not_stopped():
    # A generated open deck (seed 3040): skid 1 turns on the spot 10 deg short of its goal
    # heading beside a parked neighbour (skid 3). Held at 0.5 rad/s for the 1 s horizon the
    # turn sweeps 29 deg, into the neighbour; at 0.3 rad/s it is safe. Refused outright, the
    # turn stopped there for good.
    small = Footprint(1.0, 0.7, 0.5)
    poses = np.array(
        [
            [4.8728, 1.7581, -0.0247],
            [4.992, 3.2747, -0.1771],
            [3.1093, 3.1347, 0.0259],
            [6.1079, 2.8464, 0.025],
            [6.109, 3.9703, -0.0037],
        ]
    )
    fps = (small, small, Footprint(1.2, 0.8, 0.6), small, small)
    view = replace(make_view(poses), footprints=fps, max_yaw_accel=np.full(5, 2.0))
    scene = Scene(0.1, MonitorParams().margin_m).update(view)
    mon = CollisionMonitor(MonitorParams())
    res = mon.check(view, np.array([1]), np.array([[0.0, 0.5]]), scene)
    assert np.allclose(res.commands, [[0.0, 0.3]]) and res.blockers == [{3}]


def test_rollout_is_the_unicycle_integration_at_steady_speed():
    cmd = np.array([[0.4, 0.7]])
    view = make_view([[2.0, 3.0, 0.3]], vel=cmd, dt=0.1)
    times = np.array([0.2, 0.5, 1.0])
    pred = rollout(view, np.array([0]), cmd[:, 0], cmd[:, 1], times)[0]
    pose, expected = view.poses.copy(), []
    for k in range(1, 11):
        pose = integrate_unicycle(pose, cmd[:, 0], cmd[:, 1], 0.1)
        if any(abs(k * 0.1 - t) < 1e-9 for t in times):
            expected.append(pose[0])
    assert np.allclose(pred, np.array(expected), atol=1e-12)


def test_rollout_respects_the_acceleration_limit():
    view = make_view([[2.0, 3.0, 0.0]], dt=0.1, max_accel=0.5)
    pred = rollout(view, np.array([0]), np.array([0.5]), np.array([0.0]), np.array([1.0]))[0]
    # From rest at 0.5 m/s^2, speed 0.05 k after step k: 0.1 * 0.05 * (1 + ... + 10).
    assert pred[0, 0] == pytest.approx(2.0 + 0.1 * 0.05 * 55)


@pytest.mark.parametrize(
    ("kw", "name"),
    [
        ({"scales": (1.0, 0.5)}, "scales"),
        ({"samples": 0}, "samples"),
        ({"horizon_s": 0}, "horizon_s"),
        ({"step_samples_s": -0.1}, "step_samples_s"),
    ],
)
def test_monitor_params_name_the_bad_field(kw, name):
    with pytest.raises(ValueError, match=f"MonitorParams.{name}"):
        MonitorParams(**kw)


def test_a_turn_into_a_wall_alongside_drives_on_straight():
    """A skid running along a wall with its corner 6 cm from it, commanded to turn towards
    the wall: every speed with that turn swings the corner into the wall, driving straight
    does not, so it drives on straight (it used to be stopped for good)."""
    wall = (0.0, 5.7, 10.0, 6.0)  # a wall above, along the skid
    raw = np.array([[0.5, 0.6]])  # forwards, turning left (towards the wall)
    view = make_view([[3.0, 5.24, -0.1]], vel=[[0.5, 0.0]], boxes=[wall])
    assert np.array_equal(_check(view, raw).commands, [[0.0, 0.0]])  # the plain check
    res = _check(view, raw, straight=True)
    assert res.commands[0, 0] > 0.0 and res.commands[0, 1] == 0.0
    # Without the wall the turn is left alone.
    open_hall = make_view([[3.0, 5.24, -0.1]], vel=[[0.5, 0.0]])
    assert np.array_equal(_check(open_hall, raw, straight=True).commands, raw)


def _joint_gap(view, cmd, steps: int = 20) -> float:
    """Smallest gap between two skids driving ``cmd`` together for ``steps`` ticks."""
    plain = np.stack([fp.corners_body() for fp in view.footprints])
    gap = np.inf
    for _ in range(steps):
        view = advance(view, cmd)
        a, b = footprint_corners(view.poses, plain)
        gap = min(gap, Polygon(a).distance(Polygon(b)))
    return gap


def test_of_two_skids_side_by_side_whose_moves_together_touch_the_lower_rank_stops():
    """Taken from a contact on a generated L bay: a 1.0 m skid drives east under the front
    corner of a 1.4 m skid 3 cm above it, which drives on down past the first one's corner.
    Each move is safe against the other standing; together the corner meets the side."""
    poses = [[3.256, 2.985, 0.021], [3.279, 4.067, -0.427]]
    goals = [[4.19, 3.82, np.pi / 2], [6.31, 2.45, np.pi / 2]]  # the first skid is nearer
    raw = np.array([[0.25, 0.0], [0.25, 0.0]])
    view = make_view(poses, goals, vel=[[0.1, 0.0], [0.025, 0.0]], dt=0.05)
    view = replace(view, footprints=(Footprint(1.0, 0.7, 0.5), Footprint(1.4, 0.9, 0.7)))
    assert _joint_gap(view, raw) == 0.0  # the commands as asked touch
    res = _check(view, raw)
    assert np.array_equal(res.commands[0], raw[0])  # the skid of higher rank goes on
    assert np.array_equal(res.commands[1], [0.0, 0.0]) and res.blockers[1] == {0}
    assert _joint_gap(view, res.commands) > 0.0
    # Ranked the other way (priority first), the other one stops.
    res = _check(replace(view, priority=np.array([1.0, 2.0])), raw)
    assert np.array_equal(res.commands[0], [0.0, 0.0])
    assert np.array_equal(res.commands[1], raw[1])


def _closing(view, raw, pairs_closing: bool):
    scene = Scene(0.1, MonitorParams().margin_m).update(view)
    mon = CollisionMonitor(MonitorParams(pairs_closing=pairs_closing))
    return mon.check(view, np.arange(len(view.poses)), np.asarray(raw, float), scene)


def test_a_skid_driving_up_to_one_turning_in_place_stops_before_its_corner():
    """Taken from a contact on a generated hangar: g9 turns in place (1 rad/s) while g5 drives
    up behind it. The monitor slows g5 against g9 standing, but g9's corner swings out into
    g5's way: neither is within its margin of the other yet, so the pair was not checked
    together and they touched."""
    poses = [[15.94, 6.17, np.deg2rad(1.9)], [17.58, 6.34, np.deg2rad(78.5)]]
    goals = [[17.4, 5.3, 0.0], [18.5, 5.3, 0.0]]  # the turning skid is nearer its goal
    raw = np.array([[0.5, 0.0], [0.0, 1.0]])
    view = make_view(poses, goals, vel=[[0.5, 0.0], [0.0, 1.0]], dt=0.05)
    view = replace(view, footprints=(Footprint(1.2, 0.8, 0.6), Footprint(1.4, 0.9, 0.7)))
    before = _closing(view, raw, pairs_closing=False)
    assert 0.0 < before.commands[0, 0] < raw[0, 0] and before.commands[1, 1] == 1.0
    assert _joint_gap(view, before.commands) == 0.0  # slowed, but they still meet
    res = _closing(view, raw, pairs_closing=True)
    assert np.array_equal(res.commands[0], [0.0, 0.0]) and res.blockers[0] == {1}
    assert np.array_equal(res.commands[1], raw[1])
    assert _joint_gap(view, res.commands) > 0.0


def test_two_skids_turning_towards_each_other_keep_the_margin():
    """Taken from a contact on a generated open deck with onboard localization: a 1.0 m skid
    and a 1.2 m skid turn towards each other, each safe against the other standing. Judged by
    their plain footprints the pair closed to 1 cm between their estimates, and 1.2 cm of
    relative localization error made that a contact; now they keep the monitor's margin."""
    poses = [[13.525, 5.696, np.deg2rad(56.7)], [14.599, 6.497, np.deg2rad(97.8)]]
    goals = [[13.634, 6.094, np.pi / 2], [14.737, 6.229, np.pi / 2]]
    raw = np.array([[0.23, 0.40], [0.18, -0.85]])
    view = make_view(poses, goals, vel=[[0.04, 0.10], [0.09, -0.85]], dt=0.05)
    view = replace(view, footprints=(Footprint(1.0, 0.7, 0.5), Footprint(1.2, 0.8, 0.6)))
    plain = np.stack([fp.corners_body() for fp in view.footprints])
    assert _joint_gap(view, raw, steps=30) == 0.0  # the commands as asked touch
    gap, moved = np.inf, 0.0
    for _ in range(40):
        cmd = _check(view, raw).commands
        moved += np.abs(cmd[:, 0]).sum() * view.dt
        view = advance(view, cmd)
        a, b = footprint_corners(view.poses, plain)
        gap = min(gap, Polygon(a).distance(Polygon(b)))
    assert gap >= 0.9 * MonitorParams().margin_m
    assert moved > 0.1  # not both frozen


def test_two_skids_closing_head_on_are_checked_together_before_they_are_within_reach():
    """Two skids drive head-on at each other at full speed, 0.8 m apart: each is safe against
    the other standing (it covers 0.5 m in the 1 s horizon), together they close 1 m. Their
    pivots are 2 m apart, beyond the reach of their corners (1.5 m), so the pair check must
    look as far as both travel over the horizon, or they come into it too late to brake."""
    poses = [[3.0, 3.0, 0.0], [5.0, 3.0, np.pi]]
    goals = [[4.0, 3.0, 0.0], [9.0, 3.0, np.pi]]  # the first skid is nearer its goal
    raw = np.array([[0.5, 0.0], [0.5, 0.0]])
    view = make_view(poses, goals, vel=raw, dt=0.05)
    plain = np.stack([fp.corners_body() for fp in view.footprints])
    a, b = footprint_corners(view.poses, plain)
    assert Polygon(a).distance(Polygon(b)) == pytest.approx(0.8)
    assert _joint_gap(view, raw, steps=20) == 0.0  # the commands as asked touch within 1 s
    for i in range(2):  # each is left at full speed with the other standing
        one = raw * (np.arange(2) == i)[:, None]
        assert np.array_equal(_check(view, one).commands, one)
    res = _check(view, raw)
    assert np.array_equal(res.commands[0], raw[0])  # the skid of higher rank goes on
    assert np.array_equal(res.commands[1], [0.0, 0.0]) and res.blockers[1] == {0}


def test_a_corner_swinging_past_a_standing_skid_between_samples_is_caught():
    # A generated elevator (seed 1001, starts moved by 1 cm, session 38's variant B): skid 1
    # (1.0 x 0.7 m) backs and turns beside skid 0 (1.2 x 0.8 m) standing. Its corner passes
    # skid 0's within 0.15 s and swings clear again, between the rollout's 0.2 s samples; the
    # next ticks' contacts fell between samples too (0.10 s, then 0.05 s ahead), until the
    # simulator stopped it in contact.
    poses = np.array([[7.31890751, 9.95852936, 0.09199988], [8.2956422, 10.87174615, 0.25658308]])
    fps = (Footprint(1.2, 0.8, 0.6), Footprint(1.0, 0.7, 0.5))
    view = replace(
        make_view(poses, dt=0.05, max_accel=0.5),
        vel=np.array([[0.0, 0.0], [-0.04115996, 0.06150305]]),
        footprints=fps,
        max_yaw_accel=np.full(2, 2.0),
    )
    raw = np.array([[-0.13224664, -0.28173253]])
    mon = CollisionMonitor(MonitorParams())
    body = [f.corners_body() for f in fps]
    limit = np.array([view.max_accel[1], view.max_yaw_accel[1]]) * view.dt
    scene = Scene(0.1, MonitorParams().margin_m)
    for _ in range(20):
        scene.update(view)
        cmd = mon.check(view, np.array([1]), raw, scene, straight=True).commands
        # The simulator's step: the command within the acceleration limits, then integrated.
        dv = np.clip(cmd[0] - view.vel[1], -limit, limit)
        vel = np.array([[0.0, 0.0], view.vel[1] + dv])
        view = advance(view, vel)
        a, b = (Polygon(footprint_corners(view.poses[k][None], body[k][None])[0]) for k in (0, 1))
        assert a.distance(b) > 0.0, f"touched at t = {view.t:.2f} s"
