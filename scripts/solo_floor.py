"""Each skid of a park alone: how far above its lower bound one skid parks with nobody in its
way (docs/navigation.md, session 48, "A skid alone is already slow in a car", and session 49,
"A lone skid's floor").

    python scripts/solo_floor.py SCENARIO.yaml [MORE.yaml ...] [--robots g1,g2,...]
                                 [--json ROWS.json]

Each scenario's first park command is run once per skid (all of them, or ``--robots``) with
that skid only: the other skids are removed, and the command lays out one spot for it. Prints,
per skid, its time to park, the lower bound, their ratio, its path length, how long it took
to come within the docking's reach of its spot (``docking.manoeuvre_radius_m``) and from
there to park (the final approach), and the time it lost against top speed by what it was
doing (the run result's ``time_lost_s``); then, over all skids of all scenarios, the ratio's
median, 90th percentile and largest value and the final approach's median. A ratio well
above 1 with nobody about is what the approach and the docking cost on that site, a floor
under the fleet's own ratio. A lone skid's run has no traffic in it, so it is the same on
every run and every machine: a change to the approach or the docking shows here without the
chaos of a fleet.
"""

from __future__ import annotations

import argparse
import copy
import json
import sys
from pathlib import Path

import numpy as np
import yaml

from swarmpark.apps.run import run_world
from swarmpark.control.nav.params import DockingParams
from swarmpark.world.scenario import build_world, parse_scenario

#: A skid this close to its goal is in the docking's reach: its final approach.
NEAR_M = DockingParams().manoeuvre_radius_m


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


def _split(out, at_s: float, parked_at: float | None) -> tuple[float | None, float | None]:
    """``(approach_s, final_s)`` of a lone skid's run ``out``: from its park command to
    within :data:`NEAR_M` of its goal, and from there to parked (None where it never got
    there)."""
    goal = out.supervisor.view().goals[0, :2]
    dist = np.linalg.norm(out.poses[:, 0, :2] - goal, axis=1)
    near = np.flatnonzero((dist < NEAR_M) & (out.times >= at_s))
    if not len(near):
        return None, None
    t_near = float(out.times[near[0]])
    final = None if parked_at is None else round(max(parked_at - t_near, 0.0), 3)
    return round(t_near - at_s, 3), final


def lone_scenarios(data: dict, robots: list[str] | None = None) -> list[tuple[str, dict]]:
    """``(skid, scenario with that skid alone)`` for each skid of the first park command (or
    ``robots``); raises ValueError naming a skid that is not in it, before any run."""
    ids = first_park(data)["park"]["robots"] if robots is None else robots
    return [(rid, alone(data, rid)) for rid in ids]


def solo_runs(data: dict, base: Path, robots: list[str] | None = None, lone=None) -> list[dict]:
    """One row per skid: ``robot``, ``time_to_park_s``, ``lower_bound_s``, ``ratio`` (None if
    it did not park), ``path_m``, ``approach_s`` and ``final_s`` (:func:`_split`) and
    ``time_lost_s``. ``lone``: :func:`lone_scenarios` of ``data`` if made already."""
    at_s = float(first_park(data).get("at_s", 0.0))
    rows = []
    for rid, one in lone_scenarios(data, robots) if lone is None else lone:
        out = run_world(build_world(parse_scenario(one, base)))
        result = out.result
        t, bound = result["time_to_park_s"], result["lower_bound_s"]
        approach, final = _split(out, at_s, result["robots"][rid]["parked_at_s"])
        rows.append(
            {
                "robot": rid,
                "time_to_park_s": t,
                "lower_bound_s": bound,
                "ratio": None if t is None or not bound else t / bound,
                "path_m": result["robots"][rid]["path_length_m"],
                "approach_s": approach,
                "final_s": final,
                "time_lost_s": result["time_lost_s"],
            }
        )
    return rows


def summary(rows: list[dict]) -> dict:
    """Over ``rows`` (of any scenarios): skids, how many parked, the ratio's median, 90th
    percentile and largest value, and the final approach's median (None without a park)."""
    ratios = np.array([r["ratio"] for r in rows if r["ratio"] is not None])
    finals = np.array([r["final_s"] for r in rows if r["final_s"] is not None])
    some = len(ratios) > 0
    return {
        "skids": len(rows),
        "parked": len(ratios),
        "ratio_p50": float(np.median(ratios)) if some else None,
        "ratio_p90": float(np.percentile(ratios, 90)) if some else None,
        "ratio_max": float(ratios.max()) if some else None,
        "final_p50_s": float(np.median(finals)) if len(finals) else None,
    }


def _f(x, fmt: str = ".2f") -> str:
    return "-" if x is None else format(x, fmt)


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenarios", type=Path, nargs="+", metavar="scenario")
    ap.add_argument("--robots", help="comma-separated skid ids (default: the park's skids)")
    ap.add_argument("--json", type=Path, help="write every row, with its scenario, here")
    a = ap.parse_args(argv)
    for path in a.scenarios:
        if not path.is_file():
            ap.error(f"scenario: no such file ({path})")
    robots = a.robots.split(",") if a.robots else None
    # Every scenario read and every skid checked before the first run (a bad id in the last
    # file is refused before the runs of the others).
    sites = []
    for path in a.scenarios:
        data = yaml.safe_load(path.read_text())
        try:
            sites.append((path, data, lone_scenarios(data, robots)))
        except ValueError as exc:
            ap.error(f"{path}: {exc}")
    everything = []
    for path, data, lone in sites:
        rows = solo_runs(data, path.parent, lone=lone)
        print(f"{path}")
        print(
            "robot | time_to_park_s | lower_bound_s | ratio | path_m | approach_s | final_s | time lost (s)"
        )
        for r in rows:
            lost = ", ".join(
                f"{k} {v:.1f}" for k, v in (r["time_lost_s"] or {}).items() if v >= 0.1
            )
            print(
                f"{r['robot']} | {_f(r['time_to_park_s'])} | {r['lower_bound_s']:.2f} | "
                f"{_f(r['ratio'])} | {r['path_m']:.2f} | {_f(r['approach_s'])} | "
                f"{_f(r['final_s'])} | {lost}"
            )
        everything += [{"scenario": str(path), **r} for r in rows]
    s = summary(everything)
    print(
        f"all: {s['parked']} of {s['skids']} skids parked alone; ratio p50 {_f(s['ratio_p50'])}, "
        f"p90 {_f(s['ratio_p90'])}, max {_f(s['ratio_max'])}; final approach p50 "
        f"{_f(s['final_p50_s'], '.1f')} s"
    )
    if a.json:
        a.json.write_text(json.dumps(everything, indent=1))


if __name__ == "__main__":
    main(sys.argv[1:])
