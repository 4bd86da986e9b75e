"""Compare assignment costs on the scenario suite and write a markdown table.

Every scenario with a park command is run once per cost (``sequential``, ``euclidean``,
``formation``, ``path``) with everything else unchanged; the table reports success,
collisions, time to park against the lower bound, total path length and assignment switches.
Runs are independent processes (the core stays single-threaded and deterministic).
"""

from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from swarmpark.assign import COSTS
from swarmpark.world.scenario import Scenario, build_world, load_scenario

__all__ = ["compare_costs", "markdown_table"]


def with_cost(scn: Scenario, cost: str) -> Scenario:
    """The scenario with every park command using ``cost``."""
    cmds = [
        c.model_copy(update={"park": c.park.model_copy(update={"assignment": cost})})
        if c.park is not None
        else c
        for c in scn.commands
    ]
    return scn.model_copy(update={"commands": cmds})


def _run_one(args: tuple[str, str, float | None]) -> dict:
    from swarmpark.apps.run import run_world

    path, cost, duration_s = args
    scn = with_cost(load_scenario(path), cost)
    if duration_s is not None:
        scn = scn.model_copy(update={"duration_s": min(scn.duration_s, duration_s)})
    r = run_world(build_world(scn)).result
    ratio = None
    if r["time_to_park_s"] is not None and r["lower_bound_s"]:
        ratio = round(r["time_to_park_s"] / r["lower_bound_s"], 2)
    return {
        "scenario": scn.name,
        "cost": cost,
        "success": r["success"],
        "collisions": len(r["collisions"]),
        "time_to_park_s": r["time_to_park_s"],
        "lower_bound_s": r["lower_bound_s"],
        "ratio": ratio,
        "path_length_m": round(sum(r["path_length_m"].values()), 1),
        "switches": r["assignment_switches"],
        "deadlocks": len(r["deadlocks"]),
    }


def compare_costs(
    scenarios: list[Path], costs=COSTS, workers: int = 2, duration_s: float | None = None
) -> list[dict]:
    """Run every (scenario, cost) pair; only scenarios with a park command are used.

    ``duration_s`` cuts every run short (smoke runs); ``workers=1`` runs in this process.
    """
    jobs = [
        (str(p), c, duration_s)
        for p in scenarios
        if any(cmd.park is not None for cmd in load_scenario(p).commands)
        for c in costs
    ]
    if workers <= 1:
        return [_run_one(j) for j in jobs]
    with ProcessPoolExecutor(max_workers=workers) as pool:
        return list(pool.map(_run_one, jobs))


def markdown_table(rows: list[dict]) -> str:
    head = (
        "| scenario | cost | success | collisions | time to park (s) | lower bound (s) | "
        "ratio | total path (m) | switches | deadlocks |"
    )
    lines = [head, "|" + "---|" * 10]
    for r in rows:
        tp = "-" if r["time_to_park_s"] is None else f"{r['time_to_park_s']:.1f}"
        lb = "-" if r["lower_bound_s"] is None else f"{r['lower_bound_s']:.1f}"
        ratio = "-" if r["ratio"] is None else f"{r['ratio']:.2f}"
        lines.append(
            f"| {r['scenario']} | {r['cost']} | {'yes' if r['success'] else 'NO'} | "
            f"{r['collisions']} | {tp} | {lb} | {ratio} | {r['path_length_m']} | "
            f"{r['switches']} | {r['deadlocks']} |"
        )
    return "\n".join(lines) + "\n"
