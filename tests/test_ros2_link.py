"""End to end over ROS 2: the rclpy fake fleet in a second process, swarmpark parks it over
loopback DDS (Cyclone on this side, Fast DDS on the fleet's), with and without a robot
whose messages are dropped for 3 s. The fleet knows the truth and reports collisions."""

import itertools
import json
import os
import signal
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rclpy")
pytest.importorskip("cyclonedds")
pytest.importorskip("rosbags")

from helpers import DATA, ROOT  # noqa: E402

from swarmpark.apps.run import run_world  # noqa: E402
from swarmpark.links.ros2 import Ros2Link, Ros2Options  # noqa: E402
from swarmpark.links.ros2_qos import loopback_env  # noqa: E402
from swarmpark.world.scenario import build_world, load_scenario  # noqa: E402

SCENARIO = DATA / "ros2-open.yaml"

pytestmark = pytest.mark.ros2

_DOMAINS = itertools.count()


def _domain() -> int:
    """A ROS domain no other test (or parallel test run) on this machine uses."""
    return 100 + (os.getpid() * 7 + next(_DOMAINS)) % 120


@contextmanager
def fake_fleet(tmp_path: Path, domain: int, *extra: str):
    """Run the fake fleet for the test's duration; yields the path of its JSON report."""
    env = loopback_env(domain, tmp_path)
    env["PYTHONPATH"] = str(ROOT / "src") + os.pathsep + env.get("PYTHONPATH", "")
    report = tmp_path / "fleet.json"
    log = (tmp_path / "fleet.log").open("w")
    cmd = [sys.executable, "-m", "swarmpark.links.fake_fleet", "--scenario", str(SCENARIO)]
    cmd += ["--robots", "6", "--report", str(report), "--duration", "80", *extra]
    proc = subprocess.Popen(cmd, env=env, stdout=log, stderr=subprocess.STDOUT)
    try:
        yield report
    finally:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=5)
        log.close()
    assert report.exists(), (tmp_path / "fleet.log").read_text()[-2000:]


def _park_over_ros2(tmp_path: Path, *fleet_args: str):
    world = build_world(load_scenario(SCENARIO))
    domain = _domain()
    with fake_fleet(tmp_path, domain, *fleet_args) as report:
        link = Ros2Link(world, Ros2Options(domain_id=domain, loopback=True, connect_timeout_s=30))
        try:
            out = run_world(world, link=link)
        finally:
            link.close()
    return out, link, json.loads(report.read_text())


def test_six_skids_park_over_ros2_without_collision(tmp_path):
    out, link, fleet = _park_over_ros2(tmp_path)
    r = out.result
    assert r["success"], r
    assert fleet["collisions"] == []  # the fleet's truth, not what the robots reported
    assert "link_faults" not in r, r["link_faults"]
    assert link.received > 6 * 100  # odometry really flowed
    # The fleet agrees the skids stand where swarmpark believes (its truth vs the reports).
    np.testing.assert_allclose(np.array(fleet["poses"])[:, :2], out.poses[-1][:, :2], atol=0.05)


def test_a_robot_silent_for_3_s_is_stopped_flagged_and_rejoins(tmp_path):
    out, link, fleet = _park_over_ros2(tmp_path, "--drop", "s3:3:6")
    r = out.result
    ev = {(e["kind"], e["robot"]): e["t"] for e in fleet["events"]}
    t_drop, t_back = ev[("drop_start", "s3")], ev[("drop_end", "s3")]
    lost = [f for f in r.get("link_faults", []) if f["robot"] == "s3" and f["kind"] == "lost"]
    assert lost, r.get("link_faults")
    # Flagged by swarmpark (heartbeat 0.5 s) and stopped by its own dead-man (0.5 s).
    flagged = link.t0 + lost[0]["from_s"]
    assert 0.4 <= flagged - t_drop <= 0.6, (flagged - t_drop, r["link_faults"])
    deadman = [e["t"] for e in fleet["events"] if e["kind"] == "deadman" and e["robot"] == "s3"]
    assert any(0.0 <= t - t_drop <= 0.6 for t in deadman), (t_drop, deadman)
    # It rejoined once its messages came back, and nobody else was flagged.
    assert lost[0]["to_s"] is not None
    assert 0.0 <= link.t0 + lost[0]["to_s"] - t_back <= 0.5
    assert {f["robot"] for f in r["link_faults"]} == {"s3"}, r["link_faults"]
    # The others kept parking meanwhile.
    t = out.times + link.t0
    during = (t >= flagged) & (t <= t_back)
    others = [i for i, rid in enumerate(r["robots"]) if rid != "s3"]
    moved = np.linalg.norm(np.diff(out.poses[during][:, others, :2], axis=0), axis=2).sum()
    assert moved > 1.0
    # And s3 finished: every skid parked, no collision.
    assert r["success"], r
    assert fleet["collisions"] == []


def test_robots_stop_when_the_supervisor_dies_and_obey_a_latched_estop(tmp_path):
    """The robot-side dead-man stops skids a dead supervisor leaves driving; an e-stop on the
    latched topic stops every skid whoever sent it, and a supervisor that (re)connects
    hears it."""
    from cyclonedds.domain import DomainParticipant

    from swarmpark.links import ros2_msgs as rm
    from swarmpark.links.ros2 import _Endpoint
    from swarmpark.supervisor.core import Supervisor

    world = build_world(load_scenario(SCENARIO))
    domain = _domain()
    with fake_fleet(tmp_path, domain) as report:
        link = Ros2Link(world, Ros2Options(domain_id=domain, loopback=True, connect_timeout_s=30))
        try:
            sup = Supervisor(world, link=link)
            for _ in range(60):  # 3 s of driving (ticks: the first one plans, for a while)
                sup.tick()
                link.sync(sup)
            died = time.time()  # the supervisor stops ticking: no more cmd_vel
            time.sleep(1.5)
            operator = DomainParticipant(domain)
            estop = _Endpoint(operator, "/swarmpark/estop", "std_msgs/msg/Bool", "latched", True)
            estop.write(rm.msg("std_msgs/msg/Bool")(data=True))
            time.sleep(0.5)
            sup.inbox.absorb(link.receive())  # what piled up while it was dead
            before = sup.inbox.pose.copy()
            t_back = sup.t
            while sup.t < t_back + 2.0:  # back, and commanding again
                sup.tick()
                link.sync(sup)
            assert sup.estopped  # heard on the latched topic
            after = sup.inbox.pose.copy()
        finally:
            link.close()
        time.sleep(1.2)  # the fleet's report is refreshed every second
        fleet = json.loads(report.read_text())
    deadman = [e for e in fleet["events"] if e["kind"] == "deadman" and e["t"] > died - 0.2]
    assert len({e["robot"] for e in deadman}) >= 4, fleet["events"]  # the skids driving
    # 0.5 s after the last command (the fleet's period and scheduling on a loaded machine)
    assert all(0.4 <= e["t"] - died <= 0.75 for e in deadman), [e["t"] - died for e in deadman]
    assert any(e["kind"] == "estop" for e in fleet["events"]), fleet["events"]
    np.testing.assert_allclose(after[:, :2], before[:, :2], atol=0.01)  # nobody moved
