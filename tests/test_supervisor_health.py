"""Robot faults through the simulator's link (no DDS): a robot whose messages are dropped is
stopped, flagged, avoided and rejoins; a robot that does not follow its commands is flagged
and stopped; commands never go to a robot never heard from."""

import numpy as np
import pytest
from helpers import DATA

from swarmpark.apps.run import run_world
from swarmpark.links.base import VelocityCommand
from swarmpark.sim.link import CMD_TIMEOUT_S, SimLink
from swarmpark.supervisor.core import Supervisor
from swarmpark.supervisor.health import Health, HealthParams
from swarmpark.world.scenario import build_world, load_scenario

SCENARIO = DATA / "ros2-open.yaml"


def _world(faults=()):
    scn = load_scenario(SCENARIO)
    return build_world(scn.model_copy(update={"faults": list(faults)}))


def _drop(robot, t0, t1):
    from swarmpark.world.scenario import FaultSpec

    return FaultSpec(robot=robot, from_s=t0, to_s=t1, drop=True)


def test_a_silent_robot_is_stopped_flagged_and_an_obstacle_then_rejoins():
    world = _world([_drop("s3", 3.0, 6.0)])
    sup = Supervisor(world)
    i = sup.index["s3"]
    while sup.t < 3.0 + 0.6 - 1e-9:
        sup.tick()
    assert sup.health.lost[i]
    assert sup.modes()[i] == "lost"
    assert sup.snapshot()["robots"][i]["fault"] == "lost"
    view = sup.view()
    assert not view.active[i] and view.stopped[i]  # neighbours plan around it, immobile
    # The supervisor commands it nothing but zero; the link drops even that, so the robot's
    # own dead-man (the SimLink's, 0.5 s) is what stops it.
    assert sup._sent[i].tolist() == [0.0, 0.0]
    assert sup.sim.t - sup.link._cmd_t[i] > CMD_TIMEOUT_S
    ev = sup.health.events[0]
    assert (ev["robot"], ev["kind"]) == ("s3", "lost")
    assert 3.5 - 1e-6 <= ev["from_s"] <= 3.6
    others = [k for k in range(sup.n) if k != i]
    before = sup.sim.poses[others, :2].copy()
    while sup.t < 6.2:
        sup.tick()
    assert np.linalg.norm(sup.sim.poses[others, :2] - before, axis=1).sum() > 1.0
    assert not sup.health.lost[i] and ev["to_s"] == pytest.approx(6.05, abs=0.06)


def test_a_run_with_a_silent_robot_still_parks_everyone():
    out = run_world(_world([_drop("s3", 3.0, 6.0)]))
    r = out.result
    assert r["success"] and r["collisions"] == []
    assert [(f["robot"], f["kind"]) for f in r["link_faults"]] == [("s3", "lost")]


class _BrokenMotor(SimLink):
    """A link whose robot ``s2`` ignores its commands (it stands still)."""

    def send(self, commands):
        super().send(
            [c if c.robot != "s2" else VelocityCommand("s2", c.stamp, 0, 0) for c in commands]
        )


def test_a_robot_that_does_not_follow_its_commands_is_flagged_and_stopped():
    world = _world()
    sup = Supervisor(world, link=_BrokenMotor(world))
    i = sup.index["s2"]
    while sup.t < 4.0:
        sup.tick()
    assert sup.health.not_following[i] and sup.stopped[i]
    assert sup.modes()[i] == "stopped"
    assert sup.snapshot()["robots"][i]["fault"] == "not_following"
    assert sup.health.not_following.sum() == 1
    assert sup._sent[i].tolist() == [0.0, 0.0]
    ev = [e for e in sup.health.events if e["kind"] == "not_following"]
    assert ev[0]["robot"] == "s2" and ev[0]["from_s"] <= 2.5
    sup.resume(["s2"])  # the operator takes responsibility
    assert not sup.health.not_following[i] and not sup.stopped[i]


def test_no_command_goes_to_a_robot_never_heard_from():
    world = _world([_drop("s5", 0.0, 0.3)])  # silent from the start
    world = build_world(world.scenario.model_copy(update={"commands": []}))
    link = SimLink(world)
    sent = []
    orig = link.send
    link.send = lambda cmds: (sent.append([c.robot for c in cmds]), orig(cmds))
    sup = Supervisor(world, link=link)
    for _ in range(5):
        sup.tick()
    assert sup.health.unknown[sup.index["s5"]]
    assert all("s5" not in robots for robots in sent) and all(len(r) == 5 for r in sent)
    while sup.t < 0.5:
        sup.tick()
    assert not sup.health.unknown[sup.index["s5"]] and "s5" in sent[-1]


def test_health_limits_are_checked_by_name():
    with pytest.raises(ValueError, match="heartbeat_s"):
        HealthParams(heartbeat_s=0)
    with pytest.raises(ValueError, match="follow_tol"):
        HealthParams(follow_tol=float("nan"))


def test_a_late_supervisor_does_not_blame_the_robots():
    world = _world()
    sup = Supervisor(world)
    h = Health(sup.ids, sup.info)
    n, watch = sup.n, np.ones(sup.n, dtype=bool)
    cmd, still = np.tile([0.8, 0.0], (n, 1)), np.zeros((n, 2))
    for k in range(10):  # the robots follow
        h.follow(0.05 * k, 0.05, cmd, np.minimum(cmd, 0.8 * 0.05 * (k + 1)), watch)
    # a 1 s stall of the supervisor: the robots' dead-men stopped them; that is not theirs
    for k in range(40):
        h.follow(1.5 + 0.05 * k, 0.05, cmd if k < 20 else still, still, watch & (k >= 20))
    assert not h.not_following.any()
