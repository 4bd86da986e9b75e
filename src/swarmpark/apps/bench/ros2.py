"""ROS 2 link benchmarks, over loopback DDS with the rclpy fake fleet in a second process.

``ros2.latency``: odometry from the fleet's rclpy publisher to swarmpark's Cyclone reader
(the message's header stamp against the wall clock when :meth:`Ros2Link.receive` returns
it; polled every millisecond, so up to 1 ms of the figure is the polling).

``ros2.tick``: one supervisor tick over the ROS 2 link for 50 skids, each sent to a goal a
few metres ahead (``goto``), with the link's own share (taking and decoding what arrived,
encoding and writing the commands) measured apart.

Skipped (a row saying why) when rclpy or cyclonedds is missing.
"""

from __future__ import annotations

import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from swarmpark.apps.bench import register

DOMAIN = 230  # (the tests use 100..219)
#: Ticks left out of the tick statistics (planning every skid's first path).
WARMUP = 5


def _missing() -> str | None:
    for mod in ("rclpy", "cyclonedds", "rosbags"):
        try:
            __import__(mod)
        except ImportError:
            return mod
    return None


def _scenario(n: int, path: Path, with_goals: bool) -> None:
    """A hangar with ``n`` skids on a lattice (the simulator benchmark's), as YAML."""
    import yaml

    from swarmpark.apps.bench.sim import HANGAR_WALLS

    cols = int(np.ceil(np.sqrt(n * 1.5)))
    robots, commands = [], []
    for k in range(n):
        r, c = divmod(k, cols)
        x, y = 2.0 + 2.0 * c, 1.5 + 1.5 * r
        robots.append({"id": f"s{k}", "pose": [x, y, 0.0]})
        if with_goals:
            commands.append({"at_s": 0, "goto": {"robot": f"s{k}", "pose": [x + 1.0, y, 0.0]}})
    data = {
        "name": f"bench-ros2-{n}",
        "duration_s": 600,
        "map": {"size_m": [50, 40], "resolution_m": 0.05, "walls": HANGAR_WALLS},
        "robots": robots,
        "commands": commands,
    }
    path.write_text(yaml.safe_dump(data))


class _Fleet:
    """The fake fleet as a subprocess (terminated on exit)."""

    def __init__(self, scenario: Path, workdir: Path, *args: str) -> None:
        from swarmpark.links.ros2_qos import loopback_env

        env = loopback_env(DOMAIN, workdir)
        src = str(Path(__file__).resolve().parents[3])
        env["PYTHONPATH"] = src + os.pathsep + env.get("PYTHONPATH", "")
        cmd = [sys.executable, "-m", "swarmpark.links.fake_fleet", "--scenario", str(scenario)]
        self.proc = subprocess.Popen(
            [*cmd, *args], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
        )

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.proc.send_signal(signal.SIGTERM)
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


def _link(world):
    from swarmpark.links.ros2 import Ros2Link, Ros2Options

    return Ros2Link(
        world, Ros2Options(domain_id=DOMAIN, loopback=True, connect_timeout_s=60, paced=False)
    )


@register("ros2.latency", "odometry publish (rclpy) -> received (swarmpark), loopback DDS")
def bench_latency(quick: bool) -> list[dict]:
    from swarmpark.links.base import Odometry
    from swarmpark.world.scenario import build_world, load_scenario

    if (m := _missing()) is not None:
        return [{"case": f"skipped: {m} is not installed"}]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for n in (6,) if quick else (6, 50):
            scn = tmp / f"fleet{n}.yaml"
            _scenario(n, scn, with_goals=False)
            world = build_world(load_scenario(scn))
            with _Fleet(scn, tmp, "--scan-hz", "0"):
                link = _link(world)
                try:
                    link.connect()
                    lat = []
                    t_end = time.monotonic() + (2.0 if quick else 5.0)
                    while time.monotonic() < t_end:
                        got = link.receive()
                        now = link.now()
                        lat += [now - m.stamp for m in got if isinstance(m, Odometry)]
                        time.sleep(0.001)
                finally:
                    link.close()
            ms = np.array(lat) * 1e3
            rows.append(
                {
                    "case": f"N={n} odom at 25 Hz",
                    "messages": len(ms),
                    "mean_ms": float(ms.mean()),
                    "median_ms": float(np.median(ms)),
                    "p99_ms": float(np.percentile(ms, 99)),
                }
            )
    return rows


@register(
    "ros2.tick",
    "one supervisor tick over the ROS 2 link, 50 skids with goals (link share apart)",
    target="< 50 ms (the control period) at N = 50",
)
def bench_tick(quick: bool) -> list[dict]:
    from swarmpark.supervisor.core import Supervisor
    from swarmpark.world.scenario import build_world, load_scenario

    if (m := _missing()) is not None:
        return [{"case": f"skipped: {m} is not installed"}]
    n = 50
    ticks = WARMUP + (40 if quick else 200)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        scn = tmp / "fleet.yaml"
        _scenario(n, scn, with_goals=True)
        world = build_world(load_scenario(scn))
        with _Fleet(scn, tmp, "--scan-hz", "5"):
            link = _link(world)
            recv_ms, send_ms = [], []
            receive, send = link.receive, link.send

            def timed_receive():
                t0 = time.perf_counter()
                out = receive()
                recv_ms.append((time.perf_counter() - t0) * 1e3)
                return out

            def timed_send(cmds):
                t0 = time.perf_counter()
                send(cmds)
                send_ms.append((time.perf_counter() - t0) * 1e3)

            link.receive, link.send = timed_receive, timed_send
            try:
                sup = Supervisor(world, link=link)
                tick_ms = []
                for _ in range(ticks):
                    t0 = time.perf_counter()
                    sup.tick()
                    link.sync(sup)
                    ms = (time.perf_counter() - t0) * 1e3
                    tick_ms.append(ms)
                    time.sleep(max(0.0, sup.info.dt_s - ms / 1e3))  # the control period
                lost = int(sup.health.lost.sum())
            finally:
                link.close()
    first = tick_ms[:WARMUP]
    tick_ms = tick_ms[WARMUP:]  # the first ticks plan every path
    return [
        {
            "case": f"N={n}, {ticks} ticks",
            "first_ticks_max_ms": max(first),
            "tick_median_ms": statistics.median(tick_ms),
            "tick_mean_ms": statistics.fmean(tick_ms),
            "tick_p99_ms": float(np.percentile(tick_ms, 99)),
            "link_receive_mean_ms": statistics.fmean(recv_ms),
            "link_send_mean_ms": statistics.fmean(send_ms),
            "robots_lost_at_end": lost,
        }
    ]
