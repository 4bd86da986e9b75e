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
