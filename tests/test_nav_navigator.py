"""The composed navigator on hand-built views (no scenario): it parks a skid in both avoidance
modes, its caches follow the scene by value, and its parameters are validated."""

from dataclasses import replace

import numpy as np
import pytest
import shapely
from navkit import FOOTPRINT, advance, make_view
from shapely.geometry import box

from swarmpark.control.nav import AVOIDANCE_MODES, Navigator, NavParams
from swarmpark.control.nav.hold import hold_outside
from swarmpark.control.nav.params import DockingParams, HoldParams
from swarmpark.control.nav.scene import Scene
from swarmpark.control.orca.kernel import OrcaParams
from swarmpark.core.geometry import footprint_corners, wrap_angle


@pytest.mark.parametrize("mode", AVOIDANCE_MODES)
def test_navigator_parks_one_skid_around_a_box(mode):
    nav = Navigator(NavParams(avoidance=mode))
    goal = [8.0, 3.0, np.pi / 2]
    view = make_view([[1.5, 3.0, 0.0]], [goal], goal_changed=[True], boxes=[(4.0, 2.0, 5.0, 4.0)])
    first_path = None
    for _ in range(600):
        cmd = nav.compute(view)
        if first_path is None:
            first_path = nav.paths()[0]
        if nav.robots[0].dock.docked:
            break
        view = advance(view, cmd)
    p = DockingParams()
    assert nav.robots[0].dock.docked
    assert np.linalg.norm(view.poses[0, :2] - goal[:2]) < p.resume_pos_m
    assert abs(wrap_angle(view.poses[0, 2] - goal[2])) < p.parked_yaw_rad
    # The path was planned once (display code compares arrays by identity).
    assert nav.paths()[0] is first_path and len(first_path) >= 2
    assert nav.recoveries == []


def test_inactive_skids_get_zero_commands():
    nav = Navigator()
    view = make_view([[1.5, 3.0, 0.0]], [[8.0, 3.0, 0.0]], active=[False])
    assert np.array_equal(nav.compute(view), np.zeros((1, 2)))


def test_orca_params_are_built_once_from_the_nav_params():
    nav = Navigator(NavParams(avoidance="rvo"))
    orca = nav.avoidance.orca
    assert orca == OrcaParams(min_share=nav.params.rvo.min_share, time_horizon_s=5.0)
    view = make_view([[1.5, 3.0, 0.0]], [[8.0, 3.0, 0.0]], goal_changed=[True])
    nav.compute(view)
    nav.compute(advance(view, np.zeros((1, 2))))
    assert nav.avoidance.orca is orca


def test_scene_rebuilds_by_value_not_by_identity():
    view = make_view([[1.5, 3.0, 0.0]], boxes=[(4.0, 2.0, 5.0, 4.0)])
    scene = Scene(0.1, 0.03).update(view)
    static, skids = scene.static, scene.skids
    # A new array with the same coordinates: nothing is rebuilt.
    same = make_view([[2.0, 3.0, 0.0]], boxes=[(4.0, 2.0, 5.0, 4.0)])
    assert scene.update(same).static is static and scene.skids is skids
    # The same array changed in place: rebuilt.
    view.static_pieces[0] += 1.0
    assert scene.update(view).static is not static
    assert scene.static.points.min(axis=0) == pytest.approx([5.0, 3.0])


def test_nav_params_refuse_unknown_modes_and_wrong_components():
    with pytest.raises(
        ValueError, match=r"NavParams.avoidance must be one of \['monitor', 'rvo'\]"
    ):
        NavParams(avoidance="potential")
    with pytest.raises(ValueError, match="NavParams.docking"):
        NavParams(docking=0.3)
    with pytest.raises(ValueError, match="Navigator.params"):
        Navigator({"avoidance": "rvo"})
    with pytest.raises(TypeError):
        NavParams(lookahead_m=1.0)  # the flat fields are gone: NavParams(follower=...)


def test_held_skids_stop_outside_their_boundary_but_may_back_off():
    # Boundary from x = 5 m; the skid's front is 1.1 m from it.
    view = make_view([[3.3, 3.0, 0.0]])
    view = replace(view, hold=np.array([True]), hold_zones=(box(5.0, 0.0, 9.0, 6.0),))
    towards = np.array([[0.5, 0.0]])
    hold_outside(view, np.array([0]), towards, HoldParams())
    assert np.array_equal(towards, np.zeros((1, 2)))
    away = np.array([[-0.5, 0.0]])
    hold_outside(view, np.array([0]), away, HoldParams())
    assert away[0, 0] == -0.5
    # Not held (fill order lets it go): it drives on.
    free = np.array([[0.5, 0.0]])
    hold_outside(replace(view, hold=np.array([False])), np.array([0]), free, HoldParams())
    assert free[0, 0] == 0.5


def test_a_skid_held_outside_its_boundary_waits_without_backing_up():
    # Held by the fill order 1.1 m short of its boundary for 6 s (three times the stall
    # watch's time): it stops short and waits there; it does not back up as a stuck skid.
    nav = Navigator()
    zone = box(5.0, 0.0, 9.0, 6.0)
    view = make_view([[3.3, 3.0, 0.0]], [[7.0, 3.0, 0.0]], goal_changed=[True], dt=0.05)
    view = replace(view, hold=np.array([True]), hold_zones=(zone,))
    speeds = []
    for _ in range(120):
        cmd = nav.compute(view)
        speeds.append(cmd[0, 0])
        view = advance(view, cmd, hold=np.array([True]), hold_zones=(zone,))
    assert min(speeds) >= 0.0 and nav.robots[0].stall.stalled_s == 0.0
    assert 0.0 < zone.exterior.distance(shapely.Point(view.poses[0, :2])) - 0.6 <= 1.1


def test_a_held_skid_far_from_its_stop_drives_on_to_it():
    # Skid 0 is held back by the fill order (its zone 4.9 m ahead) while skid 1 crosses its
    # lane. Held is not waiting until it reaches its stop: it must not stand aside and stay
    # there for the whole hold (a follower stood 21 m from its spot for 65 s on a generated
    # corridor site). It drives on to its stop, 1 m short of the zone (plus the half second
    # the hold looks ahead, at full speed), and waits there.
    nav = Navigator()
    zone = box(8.5, 2.0, 10.0, 4.0)
    hold = np.array([True, False])
    view = make_view(
        [[3.0, 3.0, 0.0], [3.0, 5.3, -np.pi / 2]],
        [[9.2, 3.0, 0.0], [3.0, 0.8, -np.pi / 2]],
        goal_changed=[True, True],
        dt=0.05,
    )
    view = replace(view, hold=hold, hold_zones=(zone, None))
    nav.compute(view)
    assert not nav.at_hold[0]  # on its way: not waiting yet
    for _ in range(400):
        cmd = nav.compute(view)
        view = advance(view, cmd, hold=hold, hold_zones=(zone, None))
    gap = shapely.Polygon(footprint_corners(view.poses[:1], FOOTPRINT.corners_body()[None])[0])
    p = HoldParams()
    assert p.gap_m <= gap.distance(zone) <= p.gap_m + 0.5 * p.lookahead_s + 0.05
    assert nav.at_hold[0] and not nav.at_hold[1]
    assert np.hypot(*(view.poses[1, :2] - [3.0, 0.8])) < 0.1  # the crossing skid parked
    # The hold ends: it is no longer waiting, and drives in.
    view = replace(view, hold=np.array([False, False]))
    nav.compute(view)
    assert not nav.at_hold.any()


def test_a_held_skid_whose_stop_moves_on_drives_on_to_it():
    """Held outside its boundary, a skid waits at its stop; when the skid it follows is on
    its way in, its hold moves to short of its own spot, farther on: it is on its way again,
    not waiting (latched, a skid stood 4 m outside a dead-end bay until the one ahead had
    parked, its command held still as a waiting skid's)."""
    nav = Navigator()
    boundary = box(6.0, 2.0, 10.0, 4.0)
    spot = box(8.0, 2.6, 9.6, 3.4)
    hold = np.array([True])
    view = replace(
        make_view([[3.0, 3.0, 0.0]], [[8.8, 3.0, 0.0]], goal_changed=[True], dt=0.05),
        hold=hold,
        hold_zones=(boundary,),
    )
    for _ in range(300):
        cmd = nav.compute(view)
        view = advance(view, cmd, hold=hold, hold_zones=(boundary,))
    assert nav.at_hold[0]
    x_stop = view.poses[0, 0]
    view = replace(view, hold_zones=(spot,))
    cmd = nav.compute(view)
    assert not nav.at_hold[0] and cmd[0, 0] > 0.0  # on its way again
    view = advance(view, cmd, hold=hold, hold_zones=(spot,))
    for _ in range(300):
        cmd = nav.compute(view)
        view = advance(view, cmd, hold=hold, hold_zones=(spot,))
    # ... to its new stop, where it waits.
    assert view.poses[0, 0] > x_stop + 1.5 and nav.at_hold[0]
    front = shapely.Polygon(footprint_corners(view.poses[:1], FOOTPRINT.corners_body()[None])[0])
    assert HoldParams().gap_m <= front.distance(spot) <= HoldParams().gap_m + 0.3


def test_a_queued_skid_names_the_skids_holding_its_zone():
    """For the deadlock report: a skid queued at a bottleneck names the skids holding that
    zone's grant (not those of another zone), and says it is queued behind them."""
    from swarmpark.control.nav.navigator import RobotNav

    nav = Navigator()
    nav.robots = [RobotNav() for _ in range(4)]
    nav.robots[0].traffic.zone = 1  # holds zone 1
    nav.robots[1].traffic.waiting = 1  # queued for zone 1
    nav.robots[2].traffic.zone = 2  # holds another zone
    nav.robots[3].traffic.zone = 1  # holds zone 1 too (a convoy)
    nav.queued = np.array([False, True, False, False])
    assert nav.queue_holders(1) == [0, 3]
    assert nav.queue_holders(0) == [] and nav.queue_holders(2) == []
    assert nav.explain(1) == ("queued at a bottleneck held by skids that make no progress", [0, 3])
    nav.queued[1] = False  # its turn came
    assert nav.queue_holders(1) == []


@pytest.mark.parametrize("outside", [True, False])
def test_a_skid_held_outside_and_kept_still_on_its_way_waits_where_it_stands(outside):
    # Skid 0 is held outside a boundary 5 m ahead, not yet at its stop, and has been kept
    # still for hold.stuck_s: it is queued behind the skids held before it, so it waits where
    # it stands (its stall clock stops, no back-up) and, waiting, makes room for skid 1,
    # which drives down across it. Held short of its own spot instead (following a skid
    # bound deeper, perhaps the one the others wait for), it is still on its way.
    nav = Navigator()
    zone = box(8.5, 2.0, 10.0, 4.0)
    view = make_view(
        [[3.0, 3.0, 0.0], [3.0, 5.3, -np.pi / 2]],
        [[9.2, 3.0, 0.0], [3.0, 0.8, -np.pi / 2]],
        goal_changed=[True, True],
        dt=0.05,
    )
    view = replace(
        view,
        hold=np.array([True, False]),
        hold_zones=(zone, None),
        hold_outside=np.array([outside, False]),
    )
    nav.compute(view)
    assert not nav.at_hold[0]
    nav.robots[0].stall.stalled_s = HoldParams().stuck_s
    view = replace(view, goal_changed=np.zeros(2, bool))
    nav.compute(view)
    assert nav.at_hold[0] == outside
    cmd = nav.compute(view)  # waiting from the last tick on: it makes room
    assert nav.at_hold[0] == outside and nav.making_room[0] == outside
    if outside:
        assert abs(cmd[0, 0]) > 0.0 and cmd[0, 1] == 0.0


def test_a_skid_held_outside_but_standing_in_its_boundary_does_not_wait_there():
    # Held outside, and kept still for hold.stuck_s, but with its front already in its
    # boundary (in the door of an elevator's car, say): it is not in the queue for the
    # boundary but in the way of the skids bound deeper, so it does not wait where it stands.
    # (Traced on a 10-skid training car: a skid kept still so in the car's door waited there,
    # queued, for a skid bound deeper that stood behind it.)
    nav = Navigator()
    zone = box(3.4, 2.0, 10.0, 4.0)
    view = make_view([[3.0, 3.0, 0.0]], [[9.2, 3.0, 0.0]], goal_changed=[True], dt=0.05)
    view = replace(view, hold=np.array([True]), hold_zones=(zone,), hold_outside=np.array([True]))
    nav.compute(view)
    nav.robots[0].stall.stalled_s = HoldParams().stuck_s
    view = replace(view, goal_changed=np.zeros(1, bool))
    nav.compute(view)
    assert not nav.at_hold[0]
    # The same skid 0.2 m short of the boundary waits where it stands.
    nav = Navigator()
    view = replace(view, poses=np.array([[2.6, 3.0, 0.0]]), goal_changed=np.ones(1, bool))
    nav.compute(view)
    nav.robots[0].stall.stalled_s = HoldParams().stuck_s
    nav.compute(replace(view, goal_changed=np.zeros(1, bool)))
    assert nav.at_hold[0]
