"""The default stack (collision monitor) with priorities and oncoming traffic, no scenario key:
skids meeting head-on keep right, parked skids make room for a skid of higher priority and
only for one (issue 15, "one default stack"). The same scenarios with velocity obstacles are in
tests/test_rvo_scenarios.py."""

import numpy as np
import pytest
from helpers import SCENARIOS, make_world

from swarmpark.apps.run import run_world
from swarmpark.control.nav.follower import PathState
from swarmpark.control.nav.make_room import MakeRoom, RoomState
from swarmpark.control.nav.navigator import Navigator, NavParams, RobotNav
from swarmpark.control.nav.params import KeepRightParams, MakeRoomParams
from swarmpark.supervisor.core import Supervisor
from swarmpark.world.scenario import build_world, load_scenario, parse_scenario


def _view(a_pose, b_pose, **kw):
    world = make_world(robots=[{"id": "a", "pose": a_pose}, {"id": "b", "pose": b_pose}], **kw)
    return Supervisor(world).view()


@pytest.mark.parametrize(
    ("y", "share"),
    [(3.0, 1.0), (1.5, 1.0 / 3.0)],  # open (3 m from the walls), then 1.5 m from a wall
)
def test_oncoming_skids_turn_their_lookahead_points_clockwise(y, share):
    # a heading +x, b 4 m ahead heading -x, each aiming 1.2 m ahead on its way.
    view = _view([3.0, y, 0.0], [7.0, y, 180.0])
    nav = Navigator(NavParams())
    nav.scene.update(view)
    targets = np.array([[4.2, y, 0.0], [5.8, y, np.pi]])
    both, movers = np.array([0, 1]), np.array([True, True])

    def turned(prio, u_targets=targets):
        return nav.keep_right.turn_targets(
            view.poses, u_targets, view.goals, np.asarray(prio, float), both, movers, nav.scene
        )

    out = turned([1.0, 1.0])
    turn = nav.params.keep_right.rad * share
    # Each turns right of its way by the same angle: a to -y, b (heading -x) to +y.
    assert np.arctan2(out[0, 1] - y, out[0, 0] - 3.0) == pytest.approx(-turn)
    assert np.arctan2(y - out[1, 1], 7.0 - out[1, 0]) == pytest.approx(-turn)
    assert out[:, 2] == pytest.approx(targets[:, 2] - turn)
    # The lower priority (b: a third of a's) turns more.
    low = turned([3.0, 1.0])
    assert abs(low[1, 1] - y) > 1.5 * abs(low[0, 1] - y) > 0.0
    # Going the same way: no turn, the targets come back as they were.
    same = np.array([[4.2, y, 0.0], [8.2, y, 0.0]])
    assert np.array_equal(turned([1.0, 1.0], same), same)
    # Off, nothing turns.
    nav_off = Navigator(NavParams(keep_right=KeepRightParams(enabled=False)))
    off = nav_off.keep_right.turn_targets(
        view.poses, targets, view.goals, np.ones(2), both, movers, nav.scene
    )
    assert np.array_equal(off, targets)


def test_a_parked_skid_makes_room_only_for_a_skid_of_higher_priority():
    # b parked across a's way (heading +y at x = 5); a drives along +x through it.
    view = _view([2.0, 3.0, 0.0], [5.0, 3.0, 90.0])
    view.active[:] = True  # both have orders: a to the east, b its spot
    nav = Navigator(NavParams())
    nav.scene.update(view)
    paths = [PathState(path=np.array([[2.0, 3.0], [8.0, 3.0]])), PathState()]
    settled = np.array([False, True])
    room = MakeRoom(MakeRoomParams())

    def step(prio):
        view.priority[:] = prio
        return room.step(
            view, settled, paths, [RoomState(), RoomState()], nav.scene, by_priority=True
        )

    same = step([0.0, 0.0])
    assert not same.aside.any() and not same.speed.any()  # equal priority: b keeps its spot
    lower = step([0.0, 5.0])
    assert not lower.aside.any()  # a skid of lower priority does not move a parked one
    higher = step([5.0, 0.0])
    assert higher.aside[1] and abs(higher.speed[1]) > 0.1 and higher.undock[1]
    assert not higher.aside[0]


def test_a_walled_in_skid_ranks_above_all_until_it_docks_and_parked_skids_make_room():
    # b parked across a's way, equal priorities: b keeps its spot, until a's manoeuvre
    # search finds no way round it (a is walled in); then a outranks b and b moves aside.
    view = _view([2.0, 3.0, 0.0], [5.0, 3.0, 90.0])
    view.active[:] = True
    nav = Navigator(NavParams())
    nav.robots = [RobotNav(), RobotNav()]
    nav.scene.update(view)
    paths = [PathState(path=np.array([[2.0, 3.0], [8.0, 3.0]])), PathState()]
    settled = np.array([False, True])

    def room_for(v):
        rooms = [RoomState(), RoomState()]
        return nav.make_room.step(v, settled, paths, rooms, nav.scene, by_priority=True)

    assert nav._inherit(view) is view  # nobody walled in: the view as it was
    assert not room_for(view).aside.any()
    nav.robots[0].manoeuvre.walled = True
    ranked = nav._inherit(view)
    assert ranked.priority[0] > ranked.priority[1] == view.priority[1]
    moved = room_for(ranked)
    assert moved.aside[1] and abs(moved.speed[1]) > 0.1 and moved.undock[1]
    # Docked on its goal (or given a new one), a is walled in no more.
    nav.robots[0].dock.docked = True
    assert nav._inherit(view) is view and not nav.robots[0].manoeuvre.walled
    # Off: the ranks stay as they were.
    off = Navigator(NavParams(make_room=MakeRoomParams(for_walled=False)))
    off.robots = [RobotNav(), RobotNav()]
    off.robots[0].manoeuvre.walled = True
    assert off._inherit(view) is view


def _walled_row() -> dict:
    """Two skids parked side by side facing east with a spot between them 6 cm wider than a
    skid on each side; the third skid, sent there 20 s later from the south-east, has to
    come round and cannot get in past its neighbours."""
    return {
        "name": "walled-in-row",
        "seed": 0,
        "dt_s": 0.05,
        "duration_s": 90,
        "map": {"size_m": [16, 12], "resolution_m": 0.05},
        "robots": [
            {"id": "n1", "pose": [8.6, 1.5, 90.0]},
            {"id": "n2", "pose": [10.5, 1.5, 90.0]},
            {"id": "a", "pose": [12.0, 1.5, 90.0]},
        ],
        "commands": [
            {"at_s": 0, "goto": {"robot": "n1", "pose": [10.0, 5.14, 0.0]}},
            {"at_s": 0, "goto": {"robot": "n2", "pose": [10.0, 6.86, 0.0]}},
            {"at_s": 20, "goto": {"robot": "a", "pose": [10.0, 6.0, 0.0]}},
        ],
    }


@pytest.mark.slow
def test_a_walled_in_spot_is_reached_once_its_neighbours_make_room():
    # Its manoeuvre search finds no way in past the parked neighbours but one with them
    # left out: walled in, it outranks them, they drive along their axis out of its way and
    # dock again once it is in.
    r = run_world(build_world(parse_scenario(_walled_row()))).result
    assert r["success"] and r["collisions"] == []
    assert all(s["final_position_error_m"] <= 0.05 for s in r["robots"].values())
    assert r["min_clearance_robot_m"] > 0.02
    # Without the rule the neighbours keep their spots and it stays half a metre out.
    off = Navigator(NavParams(make_room=MakeRoomParams(for_walled=False)))
    r_off = run_world(build_world(parse_scenario(_walled_row())), controller=off).result
    assert not r_off["success"] and r_off["collisions"] == []
    assert r_off["robots"]["a"]["final_position_error_m"] > 0.3
    assert r_off["robots"]["n1"]["final_position_error_m"] <= 0.05


@pytest.mark.slow
def test_head_on_without_a_key_the_lower_priority_takes_the_larger_detour():
    world = build_world(load_scenario(SCENARIOS / "head-on-fig11.yaml"))
    assert world.scenario.navigation.avoidance == "monitor"
    r = run_world(world).result
    assert r["success"] and r["collisions"] == [] and r["deadlocks"] == []
    low = r["robots"]["top"]["max_lateral_deviation_m"]
    high = r["robots"]["bottom"]["max_lateral_deviation_m"]
    assert low > 1.5 * high > 0.0
    assert r["min_clearance_robot_m"] > 0.1


@pytest.mark.slow
def test_pass_through_without_a_key_the_formation_opens_and_restores():
    world = build_world(load_scenario(SCENARIOS / "pass-through-fig6.yaml"))
    assert world.scenario.navigation.avoidance == "monitor"
    r = run_world(world).result
    assert r["success"] and r["collisions"] == [] and r["deadlocks"] == []
    robots = r["robots"]
    # The rows beside the runner's lane opened (> 0.2 m) and every skid is back on its spot.
    for rid in ("p21", "p22", "p23", "p31", "p32", "p33"):
        assert robots[rid]["max_lateral_deviation_m"] > 0.2, rid
    for rid, s in robots.items():
        assert s["final_position_error_m"] <= 0.05, rid


def test_skipping_the_search_for_a_one_way_fleet_changes_no_turn(monkeypatch):
    # Random fleets, some driving one way (within 80 deg), some every way: the turns with the
    # shortcut equal those of the full neighbour search.
    from swarmpark.control.nav import keep_right as kr

    view = _view([2.0, 1.0, 0.0], [8.0, 5.0, 0.0])
    nav = Navigator(NavParams())
    nav.scene.update(view)
    rng = np.random.default_rng(3)
    p = nav.params.keep_right
    skipped = turned = 0
    for spread in [np.radians(80.0), 2 * np.pi] * 10:
        n = 12
        centres = rng.uniform([1.0, 1.0], [9.0, 5.0], size=(n, 2))
        ang = rng.uniform(0.0, spread, n)
        u = np.column_stack([np.cos(ang), np.sin(ang)])
        prio = rng.integers(0, 3, n).astype(float)
        cruising = np.flatnonzero(rng.random(n) < 0.7)
        movers = rng.random(n) < 0.8
        fast = kr.keep_right_turns(centres, u, prio, cruising, movers, nav.scene, p)
        monkeypatch.setattr(kr, "_one_way", lambda u: False)
        full = kr.keep_right_turns(centres, u, prio, cruising, movers, nav.scene, p)
        monkeypatch.undo()
        assert np.array_equal(fast, full)
        turned += bool(full.any())
        skipped += kr._one_way(u[np.union1d(np.flatnonzero(movers), cruising)])
    assert 0 < skipped < 20  # both ways were taken ...
    assert turned > 0  # ... and some skids did turn
