"""Simulator benchmarks: one step with collision checks for N skids; memory over a long run."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np

from swarmpark.apps.bench import register, time_call

# Pillars between the lattice rows and columns (the skids sit at x = 2 + 2c, y = 1.5 + 1.5r).
HANGAR_WALLS = [
    [[12.8, 11.05], [13.2, 11.05], [13.2, 11.45], [12.8, 11.45]],
    [[24.8, 20.05], [25.2, 20.05], [25.2, 20.45], [24.8, 20.45]],
    [[36.8, 29.05], [37.2, 29.05], [37.2, 29.45], [36.8, 29.45]],
]


def hangar_world(n: int, duration_s: float = 600.0):
    """``n`` skids on a 2.0 x 1.5 m lattice in a 50 x 40 m hangar with pillars."""
    from swarmpark.world.scenario import build_world, parse_scenario

    cols = int(np.ceil(np.sqrt(n * 1.5)))
    robots = []
    for k in range(n):
        r, c = divmod(k, cols)
        robots.append({"id": f"s{k}", "pose": [2.0 + 2.0 * c, 1.5 + 1.5 * r, 0.0]})
    data = {
        "name": f"bench-{n}",
        "duration_s": duration_s,
        "map": {"size_m": [50, 40], "resolution_m": 0.05, "walls": HANGAR_WALLS},
        "robots": robots,
        "obstacles": [
            {"radius_m": 0.3, "waypoints": [[1.0, 39.0], [49.0, 39.0]], "loop": True},
        ],
    }
    return build_world(parse_scenario(data))


def jiggle(n: int, k: int) -> np.ndarray:
    """Deterministic commands that make neighbours bump now and then."""
    phase = np.arange(n) * 0.7
    t = k * 0.05
    return np.column_stack([0.5 * np.sin(0.8 * t + phase), 0.8 * np.cos(0.5 * t + phase)])


@register("sim.step", "one simulator step with collision checks", target="< 5 ms at N = 200")
def bench_step(quick: bool) -> list[dict]:
    from swarmpark.sim.simulator import Simulator

    rows = []
    for n in (10, 50, 200):
        sim = Simulator(hangar_world(n))
        counter = iter(range(10**9))
        steps = 40 if quick else 400
        contacts: list[int] = []

        def one(sim=sim, n=n, counter=counter, contacts=contacts) -> None:
            contacts.append(len(sim.step(jiggle(n, next(counter))).new_contacts))

        stats = time_call(one, repeat=steps, warmup=5)
        rows.append(
            {
                "N": n,
                **stats,
                "steps": steps,
                "contacts": sum(contacts),
                "meets_target": (stats["mean_ms"] < 5.0) if n == 200 else None,
            }
        )
    return rows


_MEMORY_CHILD = """
import json, resource, sys
import numpy as np
from swarmpark.apps.bench.sim import hangar_world, jiggle
from swarmpark.sim.simulator import Simulator
from swarmpark.metrics import MetricsRecorder
n, seconds = int(sys.argv[1]), float(sys.argv[2])
world = hangar_world(n, seconds)
sim = Simulator(world)
metrics = MetricsRecorder(world.ids, sim.poses.copy())
goals, has = np.zeros((n, 3)), np.zeros(n, bool)
paused = np.zeros(n, bool)
for k in range(int(round(seconds / sim.dt))):
    step = sim.step(jiggle(n, k))
    metrics.on_step(sim.t, sim.poses, goals, has, paused, step)
# ru_maxrss survives execve on Linux (it would report the parent's peak at fork): read the
# peak of this process's own address space instead.
try:
    with open("/proc/self/status") as f:
        hwm_kb = next(int(line.split()[1]) for line in f if line.startswith("VmHWM:"))
except OSError:
    hwm_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(json.dumps({"max_rss_mb": hwm_kb / 1024}))
"""


@register("sim.memory", "resident memory of a 200-skid run", target="< 300 MB over 10 min")
def bench_memory(quick: bool) -> list[dict]:
    seconds = 30.0 if quick else 600.0
    out = subprocess.run(
        [sys.executable, "-c", _MEMORY_CHILD, "200", str(seconds)],
        capture_output=True,
        text=True,
        check=True,
    )
    rss = json.loads(out.stdout.strip().splitlines()[-1])["max_rss_mb"]
    return [{"N": 200, "simulated_s": seconds, "max_rss_mb": rss, "meets_target": rss < 300}]
