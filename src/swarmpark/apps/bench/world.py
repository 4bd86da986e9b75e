"""World-building benchmarks: loading every suite scenario as the server does, and building a
site for hundreds of skids (CPU time, ``time.process_time``)."""

from __future__ import annotations

import time
from pathlib import Path

from swarmpark.apps.bench import register

#: The suite's scenarios (the repository's ``scenarios/`` folder).
SCENARIOS = Path(__file__).resolve().parents[4] / "scenarios"


def _cpu(fn):
    t0 = time.process_time()
    out = fn()
    return out, time.process_time() - t0


def load_times(path: Path) -> dict:
    """CPU seconds of the server's load of ``path`` (read, build the world, start the
    supervisor, the frame encoder and the map image) and of its first tick."""
    from swarmpark.server.frames import FrameEncoder, map_png, world_info
    from swarmpark.supervisor.core import Supervisor
    from swarmpark.world.scenario import build_world, load_scenario

    def load():
        sup = Supervisor(build_world(load_scenario(path)))
        FrameEncoder(sup)
        world_info(sup)
        map_png(sup)
        return sup

    sup, load_s = _cpu(load)
    _, tick_s = _cpu(sup.tick)
    return {"load": load_s, "first_tick": tick_s, "robots": sup.n}


@register(
    "world.build",
    "server load of every suite scenario (read, build, supervisor, frame encoder, map image) "
    "and its first tick; a fleet site built for 500 skids",
    target="load <= 1 s for every suite scenario; a 500-skid site builds in <= 1 s",
)
def bench_world_build(quick: bool) -> list[dict]:
    from swarmpark.apps.bench.nav import fleet_park_world
    from swarmpark.supervisor.core import Supervisor

    files = sorted(SCENARIOS.glob("*.yaml"))
    if quick:
        files = files[:4]
    # Imports and compiled kernels (numba, from its cache) are loaded once, outside the rows.
    fleet_park_world(10)
    for f in files:
        load_times(f)
        break
    rows = []
    for f in files:
        r = load_times(f)
        rows.append(
            {
                "case": f.stem,
                "robots": r["robots"],
                "load_ms": round(r["load"] * 1e3, 1),
                "first_tick_ms": round(r["first_tick"] * 1e3, 1),
                "meets_target": r["load"] <= 1.0,
            }
        )
    for n in (100,) if quick else (100, 500, 1000):
        world, build_s = _cpu(lambda n=n: fleet_park_world(n))
        _, sup_s = _cpu(lambda w=world: Supervisor(w))
        rows.append(
            {
                "case": f"fleet site, {n} skids (nav.fleet's)",
                "robots": n,
                "load_ms": round((build_s + sup_s) * 1e3, 1),
                "first_tick_ms": None,
                "meets_target": build_s + sup_s <= 1.0 if n == 500 else None,
            }
        )
    return rows
