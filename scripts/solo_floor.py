"""Each skid of a park alone: how far above its lower bound one skid parks with nobody in its
way (docs/navigation.md, session 48, "A skid alone is already slow in a car").

    python scripts/solo_floor.py SCENARIO.yaml [--robots g1,g2,...]

The scenario's first park command is run once per skid (all of them, or ``--robots``) with
that skid only: the other skids are removed, and the command lays out one spot for it. Prints,
per skid, its time to park, the lower bound, their ratio, its path length and the time it
lost against top speed by what it was doing (the run result's ``time_lost_s``). A ratio well
above 1 with nobody about is what the approach and the docking cost on that site, a floor
under the fleet's own ratio.
"""

from __future__ import annotations

import argparse
import copy
import sys
from pathlib import Path

import yaml

from swarmpark.apps.run import run_world
from swarmpark.world.scenario import build_world, parse_scenario


def first_park(data: dict) -> dict:
    """The scenario's first park command (the whole entry, ``at_s`` and ``park``)."""
    park = next((c for c in data.get("commands", []) if "park" in c), None)
    if park is None:
        raise ValueError("commands: the scenario has no park command")
    return park


def alone(data: dict, rid: str) -> dict:
    """The scenario with only skid ``rid``, parked by the first park command (its other
    commands dropped)."""
    out = copy.deepcopy(data)
    park = first_park(out)
    if rid not in park["park"]["robots"]:
        raise ValueError(f"robots: {rid!r} is not in the first park command")
    park["park"]["robots"] = [rid]
    out["robots"] = [r for r in out["robots"] if r["id"] == rid]
    out["commands"] = [park]
    out.pop("expect", None)
    return out


def solo_runs(data: dict, base: Path, robots: list[str] | None = None) -> list[dict]:
    """One row per skid: ``robot``, ``time_to_park_s``, ``lower_bound_s``, ``ratio`` (None if
    it did not park), ``path_m`` and ``time_lost_s``."""
    ids = first_park(data)["park"]["robots"] if robots is None else robots
    runs = [alone(data, rid) for rid in ids]  # every id checked before the first run
    rows = []
    for rid, one in zip(ids, runs, strict=True):
        result = run_world(build_world(parse_scenario(one, base))).result
        t, bound = result["time_to_park_s"], result["lower_bound_s"]
        rows.append(
            {
                "robot": rid,
                "time_to_park_s": t,
                "lower_bound_s": bound,
                "ratio": None if t is None or not bound else t / bound,
                "path_m": result["robots"][rid]["path_length_m"],
                "time_lost_s": result["time_lost_s"],
            }
        )
    return rows


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenario", type=Path)
    ap.add_argument("--robots", help="comma-separated skid ids (default: the park's skids)")
    a = ap.parse_args(argv)
    if not a.scenario.is_file():
        ap.error(f"scenario: no such file ({a.scenario})")
    data = yaml.safe_load(a.scenario.read_text())
    robots = a.robots.split(",") if a.robots else None
    try:
        rows = solo_runs(data, a.scenario.parent, robots)
    except ValueError as exc:
        ap.error(str(exc))
    print("robot | time_to_park_s | lower_bound_s | ratio | path_m | time lost (s)")
    for r in rows:
        lost = ", ".join(f"{k} {v:.1f}" for k, v in (r["time_lost_s"] or {}).items() if v >= 0.1)
        t = "-" if r["time_to_park_s"] is None else f"{r['time_to_park_s']:.2f}"
        ratio = "-" if r["ratio"] is None else f"{r['ratio']:.2f}"
        print(
            f"{r['robot']} | {t} | {r['lower_bound_s']:.2f} | {ratio} | {r['path_m']:.2f} | {lost}"
        )


if __name__ == "__main__":
    main(sys.argv[1:])
