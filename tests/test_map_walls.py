"""Walls of map_server maps are solid all through (issue 22): starts, kidnaps and goto goals in
an occupied block or off the map are refused with the field and the value, and a skid inside a
block cannot move and is reported in contact."""

import numpy as np
import pytest
from helpers import assert_goto_refused

from swarmpark.core.gridmap import OccupancyGrid, save_map_yaml
from swarmpark.sim.simulator import Simulator
from swarmpark.supervisor import Supervisor
from swarmpark.world.scenario import ScenarioError, build_world, parse_scenario


def _map(tmp_path):
    """A 10 x 8 m room at 5 cm with a 3 x 3 m solid block in the middle (x 3.5-6.5, y 2.5-5.5)."""
    occ = np.zeros((160, 200), bool)
    occ[50:110, 70:130] = True
    return save_map_yaml(OccupancyGrid(occ, 0.05), tmp_path / "block.yaml")


def _scenario(tmp_path, pose, **extra):
    return {
        "name": "block",
        "map": {"yaml": str(_map(tmp_path))},
        "robots": [{"id": "a", "pose": pose}, {"id": "b", "pose": [1.5, 1.0, 0]}],
        **extra,
    }


def test_a_start_inside_an_occupied_block_is_refused(tmp_path):
    with pytest.raises(
        ScenarioError,
        match=r"robots\[0\].pose: robot 'a' starts in an occupied cell of the map or outside the map at \[5.0, 4.0, 0.0\]",
    ):
        build_world(parse_scenario(_scenario(tmp_path, [5.0, 4.0, 0])))


def test_a_start_far_outside_the_map_is_refused(tmp_path):
    with pytest.raises(
        ScenarioError, match=r"robots\[0\].pose: .* outside the map at \[25.0, 4.0, 0.0\]"
    ):
        build_world(parse_scenario(_scenario(tmp_path, [25.0, 4.0, 0])))


def test_a_skid_inside_a_block_cannot_move_and_is_in_contact(tmp_path):
    world = build_world(parse_scenario(_scenario(tmp_path, [1.5, 4.0, 0])))
    sim = Simulator(world)
    sim.poses[0] = [5.0, 4.0, 0.0]  # carried into the block by hand
    contacts = []
    for _ in range(20):
        step = sim.step(np.array([[1.0, 0.0], [0.0, 0.0]]))
        contacts += step.new_contacts
    np.testing.assert_array_equal(sim.poses[0], [5.0, 4.0, 0.0])  # every move rejected
    assert [(c.a, c.b, c.kind) for c in contacts] == [("a", "wall", "robot-wall")]


def test_driving_into_a_block_is_stopped_at_its_face(tmp_path):
    world = build_world(parse_scenario(_scenario(tmp_path, [1.5, 4.0, 0])))
    sim = Simulator(world)
    contacts = []
    for _ in range(200):
        contacts += sim.step(np.array([[0.5, 0.0], [0.0, 0.0]])).new_contacts
    front = sim.poses[0, 0] + 0.6  # pivot at the middle of a 1.2 m skid
    assert front <= 3.5 + 1e-6 and front > 3.4
    assert ("a", "wall", "robot-wall") in [(c.a, c.b, c.kind) for c in contacts]


def test_a_goto_into_a_block_is_refused_and_the_orders_kept(tmp_path):
    sup = Supervisor(build_world(parse_scenario(_scenario(tmp_path, [1.5, 4.0, 0]))))
    ok = sup.command("goto", {"robot": "a", "pose": [1.5, 7.0, 0]})
    assert ok.accepted
    reason = (
        "goto.pose: robot 'a' would be in an occupied cell of the map or outside it at "
        "[5.0, 4.0, 90.0]"
    )
    assert_goto_refused(sup, "a", [5.0, 4.0, 90], reason, kept=[1.5, 7.0, 0.0])


def test_a_goto_to_a_closed_pocket_is_refused_and_the_orders_kept():
    """A 3 x 3 m room walled off on every side: its floor is free, but no skid gets in. The
    goto is refused at once (before, it was accepted, and the skid drove to the wall and
    stood there with "no path to its goal")."""
    walls = [[[6, 1], [10, 1], [10, 1.3], [6, 1.3]], [[6, 4.7], [10, 4.7], [10, 5], [6, 5]]]
    walls += [[[6, 1.3], [6.3, 1.3], [6.3, 4.7], [6, 4.7]], [[9.7, 1.3], [10, 1.3], [10, 4.7]]]
    walls[-1].append([9.7, 4.7])
    data = {"name": "pocket", "map": {"size_m": [12, 6], "walls": walls}}
    data["robots"] = [{"id": "a", "pose": [2.0, 3.0, 0.0]}]
    sup = Supervisor(build_world(parse_scenario(data)))
    assert sup.command("goto", {"robot": "a", "pose": [2.0, 5.0, 0]}).accepted
    reason = (
        "goto.pose: robot 'a' has no way to [8.0, 3.0, 0.0] on the known map (every way there "
        "is narrower than its width, 0.80 m)"
    )
    assert_goto_refused(sup, "a", [8.0, 3.0, 0], reason, kept=[2.0, 5.0, 0.0])
    # A 1 m gap in its west wall opens the room: the goto is taken.
    data["map"]["walls"][2] = [[6, 1.3], [6.3, 1.3], [6.3, 2.5], [6, 2.5]]
    data["map"]["walls"].append([[6, 3.5], [6.3, 3.5], [6.3, 4.7], [6, 4.7]])
    sup = Supervisor(build_world(parse_scenario(data)))
    assert sup.command("goto", {"robot": "a", "pose": [8.0, 3.0, 0]}).accepted
