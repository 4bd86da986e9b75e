"""Formation velocity-planning benchmarks: the paper's Table 1 problem and 20 robots x 60 steps.

Times are wall-clock for ``plan_velocities`` (building the CasADi problem and solving it with
IPOPT), the number that matters to an operator waiting for the group to set off.
"""

from __future__ import annotations

from swarmpark.apps.bench import register, time_call


def _row(case: str, plan, stats: dict, target_ms: float) -> dict:
    return {
        "case": case,
        "method": plan.method,
        "robots": plan.problem.n_robots,
        "M": plan.problem.M,
        **stats,
        "q_e_m2": plan.q_e_m2,
        "max_pair_error_mm": 1e3 * plan.max_pair_error_m,
        "min_pair_distance_mm": 1e3 * plan.min_pair_distance_m,
        "status": plan.status,
        "iterations": plan.iterations,
        "meets_target": bool(plan.success and stats["median_ms"] < target_ms),
    }


@register("formation.table1", "six robots, Table 1, M = 15: plan_velocities", target="< 1 s")
def bench_table1(quick: bool) -> list[dict]:
    from swarmpark.control.formation import METHODS, plan_velocities
    from swarmpark.control.formation.paper import paper_problem

    problem = paper_problem()
    rows = []
    for method in METHODS:
        plan = plan_velocities(problem, method)
        stats = time_call(lambda m=method: plan_velocities(problem, m), repeat=2 if quick else 5)
        rows.append(_row("table1", plan, stats, 1000.0))
    return rows


@register(
    "formation.large",
    "20 robots block -> wedge, M = 60: plan_velocities (quick: 10 robots, M = 30)",
    target="< 30 s at 20 robots, M = 60",
)
def bench_large(quick: bool) -> list[dict]:
    from swarmpark.control.formation import plan_velocities
    from swarmpark.control.formation.paper import grid_problem

    n, m = (10, 30) if quick else (20, 60)
    problem = grid_problem(n, m)
    rows = []
    for method in ("formation", "no_formation"):
        plan = plan_velocities(problem, method)
        stats = time_call(lambda mm=method: plan_velocities(problem, mm), repeat=1, warmup=0)
        rows.append(_row(f"grid{n}xM{m}", plan, stats, 30_000.0))
    return rows
