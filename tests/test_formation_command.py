"""The `formation` operator command: refusals leave the swarm on its previous orders."""

import numpy as np
import pytest
from helpers import make_world

from swarmpark.supervisor.core import Supervisor
from swarmpark.world.scenario import FormationCmd, ScenarioError

ROBOTS = [{"id": "a", "pose": [3.0, 3.0, 0.0]}, {"id": "b", "pose": [1.5, 3.0, 0.0]}]


def test_bad_offsets_are_refused_and_change_nothing():
    sup = Supervisor(make_world(robots=ROBOTS, commands=[]))
    before = (sup.goals.copy(), sup.has_goal.copy())
    out = sup.formation(
        FormationCmd(
            robots=["a", "b"], paths=[[[3, 3], [8, 3]]], offsets_m=[[1.0, 0.0], [2.0, 0.0]]
        )
    )
    assert not out.accepted
    assert out.reason.startswith("formation.offsets_m: need one [dx, dy] per follower (1)")
    assert np.array_equal(sup.goals, before[0]) and np.array_equal(sup.has_goal, before[1])
    assert sup.formations == []


def test_leader_path_is_carried_to_the_follower():
    sup = Supervisor(make_world(robots=ROBOTS, commands=[]))
    out = sup.formation(FormationCmd(robots=["a", "b"], paths=[[[3, 3], [8, 3]]]))
    assert out.accepted, out.reason
    goals = sup.goals
    # The follower starts 1.5 m behind the leader and ends 1.5 m behind its goal.
    assert goals[0] == pytest.approx([8.0, 3.0, 0.0], abs=1e-6)
    assert goals[1] == pytest.approx([6.5, 3.0, 0.0], abs=1e-6)


def test_paths_must_match_robots():
    with pytest.raises(
        ScenarioError,
        match=r"commands\[0\].formation.paths: give the leader's path or one per robot",
    ):
        make_world(
            robots=ROBOTS + [{"id": "c", "pose": [3.0, 5.0, 0.0]}],
            commands=[
                {
                    "at_s": 0,
                    "formation": {
                        "robots": ["a", "b", "c"],
                        "paths": [[[3, 3], [8, 3]], [[1.5, 3], [6.5, 3]]],
                    },
                }
            ],
        )


def test_skids_off_their_start_are_joined_to_the_path():
    """The leader stands 0.15 m past the first waypoint turned by 10 deg, the follower 0.2 m
    aside: the paths start at their poses (no cusp from doubling back) and join ahead."""
    robots = [
        {"id": "a", "pose": [3.15, 3.0, 10.0]},
        {"id": "b", "pose": [1.5, 3.2, -5.0]},
    ]
    sup = Supervisor(make_world(robots=robots, commands=[], map={"size_m": [14, 6]}))
    out = sup.formation(FormationCmd(robots=["a", "b"], paths=[[[3, 3], [8, 3], [12, 4]]]))
    assert out.accepted, out.reason
    (run,) = sup.formations
    for k, path in enumerate(run.problem.paths):
        assert path.pose(0.0)[:2] == pytest.approx(sup.poses_known[k, :2], abs=1e-9)
        assert path.pose(0.0)[2] == pytest.approx(sup.poses_known[k, 2], abs=1e-9)


def test_a_group_starting_close_is_held_no_closer_than_it_starts():
    """Two skids 1.3 m apart side by side (closer than two circumradii, 1.44 m): accepted,
    with the safe distance taken from their start."""
    robots = [{"id": "a", "pose": [3.0, 3.0, 0.0]}, {"id": "b", "pose": [3.0, 1.7, 0.0]}]
    sup = Supervisor(make_world(robots=robots, commands=[]))
    out = sup.formation(FormationCmd(robots=["a", "b"], paths=[[[3, 3], [9, 3]]]))
    assert out.accepted, out.reason
    assert sup.formations[0].problem.d_safe_m == pytest.approx(0.95 * 1.3)


def test_a_skid_facing_away_from_its_path_is_refused_saying_so():
    robots = [{"id": "a", "pose": [3.0, 3.0, 180.0]}, {"id": "b", "pose": [1.5, 3.0, 0.0]}]
    sup = Supervisor(make_world(robots=robots, commands=[]))
    out = sup.formation(FormationCmd(robots=["a", "b"], paths=[[[3.3, 3], [8, 3]]]))
    assert not out.accepted
    assert "robot 0 faces 180 deg away from where its path goes" in out.reason
    assert sup.formations == []


def test_a_path_through_a_wall_is_refused_naming_the_robot_and_the_place():
    """The plan times the robots along fixed paths and knows no map: a follower's path, the
    leader's carried 1.5 m to its left, would run into a block beside the leader's lane."""
    block = [[6, 3.7], [7, 3.7], [7, 6], [6, 6]]
    robots = [{"id": "a", "pose": [3.0, 2.0, 0.0]}, {"id": "b", "pose": [3.0, 3.5, 0.0]}]
    sup = Supervisor(make_world(robots=robots, map={"size_m": [10, 6], "walls": [block]}))
    before = (sup.goals.copy(), sup.has_goal.copy())
    out = sup.formation(FormationCmd(robots=["a", "b"], paths=[[[3, 2], [9, 2]]]))
    assert not out.accepted
    assert out.reason.startswith(
        "formation.paths: robot 'b' would hit a wall or obstacle 2.5 m along its path, at (5.45, 3.50) m"
    ), out.reason
    assert "the leader's carried at its offset" in out.reason
    assert np.array_equal(sup.goals, before[0]) and np.array_equal(sup.has_goal, before[1])
    assert sup.formations == []
    # Off the map is named as such; a path that stops short of the block is accepted.
    out = sup.formation(FormationCmd(robots=["a", "b"], paths=[[[3, 2], [3, 0.5]]]))
    assert not out.accepted
    assert out.reason.startswith("formation.paths: robot 'a' would leave the map"), out.reason
    out = sup.formation(FormationCmd(robots=["a", "b"], paths=[[[3, 2], [4.5, 2]]]))
    assert out.accepted, out.reason


def test_a_formation_stops_short_of_a_skid_standing_on_its_path():
    """The map check sees walls, not skids: a skid standing on the group's path is left to
    the collision monitor, which holds the formation before it touches."""
    robots = [
        {"id": "a", "pose": [2.5, 3.0, 0.0]},
        {"id": "b", "pose": [1.0, 3.0, 0.0]},
        {"id": "x", "pose": [6.0, 3.0, 90.0]},  # no orders: it stays where it stands
    ]
    sup = Supervisor(make_world(robots=robots))
    out = sup.formation(FormationCmd(robots=["a", "b"], paths=[[[2.5, 3], [9, 3]]]))
    assert out.accepted, out.reason
    for _ in range(int(25 / sup.info.dt_s)):
        sup.tick()
    assert sup.metrics.collisions == []
    gap = sup.sim.poses[2, 0] - 0.4 - (sup.sim.poses[0, 0] + 0.6)  # x's side to a's nose
    assert 0.0 < gap < 1.0, gap
