"""Simulator: kinematic limits, exact integration, collision rejection and recording."""

import numpy as np
import pytest
from helpers import make_world
from hypothesis import given, settings
from hypothesis import strategies as st

from swarmpark.core.geometry import integrate_unicycle
from swarmpark.sim.simulator import Simulator
from swarmpark.supervisor.core import Supervisor


def test_unicycle_arc_is_exact():
    # A quarter circle of radius 1: v = 1, omega = 1 for pi/2 s ends at (1, 1) facing +y.
    p = integrate_unicycle(np.array([[0.0, 0.0, 0.0]]), np.array([1.0]), np.array([1.0]), np.pi / 2)
    assert p[0] == pytest.approx([1.0, 1.0, np.pi / 2])


@settings(max_examples=30, deadline=None)
@given(st.lists(st.tuples(st.floats(-3, 3), st.floats(-5, 5)), min_size=20, max_size=60))
def test_limits_are_never_exceeded(cmds):
    world = make_world(robots=[{"id": "a", "pose": [5.0, 3.0, 0.0]}])
    sim = Simulator(world)
    prev = sim.vel.copy()
    for v, w in cmds:
        sim.step(np.array([[v, w]]))
        if sim.tick and not np.any(sim.vel != sim.vel):  # no NaN
            pass
        assert abs(sim.vel[0, 0]) <= 0.5 + 1e-12
        assert abs(sim.vel[0, 1]) <= 1.0 + 1e-12
        assert abs(sim.vel[0, 0] - prev[0, 0]) <= 0.5 * sim.dt + 1e-12
        assert abs(sim.vel[0, 1] - prev[0, 1]) <= 2.0 * sim.dt + 1e-12
        prev = sim.vel.copy()


def test_driving_into_a_wall_is_rejected_and_recorded_once():
    world = make_world(
        map={
            "size_m": [10, 6],
            "resolution_m": 0.05,
            "walls": [[[4, 0], [4.5, 0], [4.5, 6], [4, 6]]],
        },
        robots=[{"id": "a", "pose": [2.0, 3.0, 0.0]}],
    )
    sim = Simulator(world)
    contacts = []
    for _ in range(200):
        contacts += sim.step(np.array([[0.5, 0.0]])).new_contacts
    # Front edge at x = pivot + 0.6 never passes the wall face at x = 4.
    assert sim.poses[0, 0] + 0.6 <= 4.0 + 1e-9
    assert sim.poses[0, 0] + 0.6 > 4.0 - 0.5 * sim.dt  # stopped within one step of the wall
    assert len(contacts) == 1
    c = contacts[0]
    assert (c.a, c.b, c.kind) == ("a", "wall", "robot-wall")


def test_robot_robot_contact_names_both_and_nothing_tunnels():
    world = make_world(
        robots=[{"id": "a", "pose": [2.0, 3.0, 0.0]}, {"id": "b", "pose": [6.0, 3.0, 180.0]}]
    )
    sim = Simulator(world)
    contacts = []
    for _ in range(300):
        contacts += sim.step(np.array([[0.5, 0.0], [0.5, 0.0]])).new_contacts
        gap = (sim.poses[1, 0] - 0.6) - (sim.poses[0, 0] + 0.6)
        assert gap >= -1e-9
    assert [(c.a, c.b, c.kind) for c in contacts] == [("a", "b", "robot-robot")]


def test_person_who_does_not_react_walks_into_a_robot_in_its_way():
    world = make_world(
        robots=[{"id": "a", "pose": [5.0, 3.0, 0.0]}],
        obstacles=[
            {
                "radius_m": 0.3,
                "waypoints": [[5.0, 5.5], [5.0, 0.5]],
                "speed_mps": 1.0,
                "reacts": False,
            }
        ],
    )
    sim = Simulator(world)
    contacts = []
    for _ in range(200):
        contacts += sim.step(np.zeros((1, 2))).new_contacts
    p = sim.person_positions()[0]
    assert p[1] - 0.3 >= 3.4 - 1e-9  # stopped at the robot's left side (y = 3 + 0.4)
    # The skid stood still: the person walked into it (reported, not the fleet's fault).
    assert [(c.a, c.b, c.kind) for c in contacts] == [("a", "person0", "person-robot")]


def test_a_skid_driving_into_a_standing_person_is_the_fleets_contact():
    world = make_world(
        robots=[{"id": "a", "pose": [2.0, 3.0, 0.0]}],
        obstacles=[
            {
                "radius_m": 0.3,
                "waypoints": [[4.0, 3.0], [4.0, 5.0]],
                "speed_mps": 1.0,
                "start_s": 100,
            }
        ],
    )
    sim = Simulator(world)
    contacts = []
    for _ in range(100):
        contacts += sim.step(np.array([[0.5, 0.0]])).new_contacts
    assert sim.poses[0, 0] + 0.6 <= 4.0 - 0.3 + 1e-9  # stopped at the person's rim
    assert [(c.a, c.b, c.kind) for c in contacts] == [("a", "person0", "robot-person")]


def test_person_walks_the_route_and_loops():
    world = make_world(
        obstacles=[
            {
                "radius_m": 0.2,
                "waypoints": [[7.0, 1.0], [9.0, 1.0], [9.0, 2.0], [7.0, 2.0]],
                "speed_mps": 1.0,
                "start_s": 1.0,
                "loop": True,
            }
        ],
    )
    sim = Simulator(world)
    for _ in range(20):  # 1 s: not started yet
        sim.step(np.zeros((1, 2)))
    assert sim.person_positions()[0] == pytest.approx([7.0, 1.0])
    for _ in range(50):  # 2.5 s walking: 2 m along x then 0.5 m up
        sim.step(np.zeros((1, 2)))
    assert sim.person_positions()[0] == pytest.approx([9.0, 1.5])
    for _ in range(120):  # a lap is 6 m: 6 s later it is back at the same point
        sim.step(np.zeros((1, 2)))
    assert sim.person_positions()[0] == pytest.approx([9.0, 1.5], abs=1e-9)


def test_estop_is_latched_until_resume():
    world = make_world(
        commands=[
            {"at_s": 0, "goto": {"robot": "a", "pose": [8, 3, 0]}},
            {"at_s": 1.0, "estop": True},
            {"at_s": 3.0, "resume": ["a"]},
            {"at_s": 4.0, "resume": "all"},
        ]
    )
    sup = Supervisor(world)
    xs = []
    for _ in range(100):
        sup.tick()
        xs.append(sup.sim.poses[0, 0])
    xs = np.array(xs)
    # Ticks 21..80 (t = 1.05 .. 4.0) do not move; the resume ['a'] at 3 s is refused.
    assert np.all(np.diff(xs[20:80]) == 0)
    assert xs[-1] > xs[80]
    refused = [o for o in sup.outcomes if not o.accepted]
    assert len(refused) == 1 and "e-stop is latched" in refused[0].reason


def test_same_seed_same_result():
    from swarmpark.apps.run import run_world

    data = dict(
        robots=[{"id": "a", "pose": [2.0, 2.0, 0.0]}, {"id": "b", "pose": [2.0, 4.0, 0.0]}],
        commands=[
            {"at_s": 0, "goto": {"robot": "a", "pose": [8, 4, 90]}},
            {"at_s": 0, "goto": {"robot": "b", "pose": [8, 2, -90]}},
        ],
    )
    r1 = run_world(make_world(**data))
    r2 = run_world(make_world(**data))
    assert np.array_equal(r1.poses, r2.poses)
    strip = lambda r: {k: v for k, v in r.items() if k != "tick_ms"}  # noqa: E731
    assert strip(r1.result) == strip(r2.result)
