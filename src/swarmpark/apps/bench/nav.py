"""Navigation benchmarks: assignment, one grid plan, one control tick, scenario quality."""

from __future__ import annotations

import numpy as np

from swarmpark.apps.bench import register, time_call


def _cpu_median_ms(fn, repeat: int) -> float:
    """Median CPU time (``time.process_time``) of ``fn`` over ``repeat`` calls, in ms."""
    import statistics
    import time

    fn()
    times = []
    for _ in range(repeat):
        c0 = time.process_time()
        fn()
        times.append((time.process_time() - c0) * 1e3)
    return statistics.median(times)


@register(
    "nav.assign",
    "assignment, formation cost: cost matrix (cdist) + solve; dense Hungarian and the sparse "
    "k-nearest matching (total cost against the dense optimum)",
    target="< 100 ms at N = 1000 (cost matrix + solve, CPU)",
)
def bench_assign(quick: bool) -> list[dict]:
    from swarmpark.assign import SPARSE_K, assign, cost_matrix, sparse_assign

    rows = []
    rng = np.random.default_rng(0)
    for n in (100, 1000) if quick else (100, 500, 1000):
        robots = rng.uniform(0, 100, (n, 2))
        goals = rng.uniform(0, 100, (n, 2))
        c = cost_matrix(robots, goals, "formation")
        idx = np.arange(n)
        best = c[idx, assign(c)].sum()
        repeat = 3 if quick else 10
        for name, solve in (("dense", assign), (f"sparse k={SPARSE_K}", sparse_assign)):
            if name != "dense" and n < 1000:
                continue

            def run(s=solve, r=robots, g=goals):
                return s(cost_matrix(r, g, "formation"))

            stats = time_call(run, repeat)
            cpu = _cpu_median_ms(run, repeat)
            rows.append(
                {
                    "N": n,
                    "solver": name,
                    **stats,
                    "cpu_median_ms": cpu,
                    "cost_matrix_cpu_ms": _cpu_median_ms(
                        lambda r=robots, g=goals: cost_matrix(r, g, "formation"), repeat
                    ),
                    "total_cost_vs_optimum": float(c[idx, solve(c)].sum() / best),
                    "meets_target": cpu < 100 if n == 1000 else None,
                }
            )
    return rows


@register("nav.plan", "one path on a 400 x 400 grid (20 x 20 m at 5 cm)", target="< 50 ms")
def bench_plan(quick: bool) -> list[dict]:
    from shapely.geometry import box

    from swarmpark.core.gridmap import grid_from_walls
    from swarmpark.plan.grid import build_costmap, plan_path

    walls = [box(5, 0, 5.5, 14), box(10, 6, 10.5, 20), box(15, 0, 15.5, 14)]
    grid = grid_from_walls((20, 20), 0.05, walls)
    start, goal = np.array([1.0, 1.0]), np.array([19.0, 19.0])
    rows = []
    for label, res in (("5 cm (native, default)", None), ("10 cm (plan_resolution_m)", 0.1)):
        cm = build_costmap(grid, 0.4, 0.72, resolution_m=res)
        stats = time_call(lambda cm=cm: plan_path(cm, start, goal), repeat=3 if quick else 20)
        path = plan_path(cm, start, goal)
        length = float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())
        rows.append(
            {
                "map": "400x400",
                "search": label,
                **stats,
                "path_m": round(length, 2),
                "meets_target": stats["median_ms"] < 50,
            }
        )
    return rows


@register(
    "nav.tick",
    "one control tick (assign + plan/follow + field + monitor)",
    target="< 20 ms for 50 skids",
)
def bench_tick(quick: bool) -> list[dict]:
    from swarmpark.supervisor.core import Supervisor
    from swarmpark.world.scenario import build_world, parse_scenario

    rows = []
    for n in (10, 50):
        robots = [
            {"id": f"s{k}", "pose": [3.0 + 2.5 * (k // 10), 2.0 + 1.6 * (k % 10), 0.0]}
            for k in range(n)
        ]
        cols = int(np.ceil(n / 8))
        boundary = [[22, 2], [22 + 1.6 * cols + 1, 2], [22 + 1.6 * cols + 1, 18.5], [22, 18.5]]
        data = {
            "name": f"tick-{n}",
            "duration_s": 60,
            "map": {"size_m": [40, 20], "resolution_m": 0.05},
            "robots": robots,
            "commands": [
                {
                    "at_s": 0,
                    "park": {
                        "robots": [r["id"] for r in robots],
                        "boundary": boundary,
                        "margin_m": 0.3,
                    },
                }
            ],
        }
        sup = Supervisor(build_world(parse_scenario(data)))
        sup.tick()  # the park command: layout, assignment, first plans
        for _ in range(20):
            sup.tick()
        stats = time_call(sup.tick, repeat=20 if quick else 100, warmup=0)
        rows.append({"N": n, **stats, "meets_target": stats["median_ms"] < 20 if n == 50 else None})
    return rows


def fleet_park_world(n: int, avoidance: str | None = None):
    """``n`` skids in columns of 10 on the left of a hall sized to fit them, parking into one
    boundary on the right (the ``nav.tick`` layout, widened for big fleets); ``avoidance``
    sets ``navigation.avoidance`` (by default the scenario default, the monitor)."""
    from swarmpark.world.scenario import build_world, parse_scenario

    robots = [
        {"id": f"s{k}", "pose": [3.0 + 2.5 * (k // 10), 2.0 + 1.6 * (k % 10), 0.0]}
        for k in range(n)
    ]
    x0 = 3.0 + 2.5 * ((n - 1) // 10) + 4.0
    x1 = x0 + 1.6 * int(np.ceil(n / 8)) + 1.0
    data = {
        "name": f"fleet-{n}",
        "duration_s": 600,
        "map": {"size_m": [x1 + 3.0, 20], "resolution_m": 0.05},
        "robots": robots,
        "commands": [
            {
                "at_s": 0,
                "park": {
                    "robots": [r["id"] for r in robots],
                    "boundary": [[x0, 2], [x1, 2], [x1, 18.5], [x0, 18.5]],
                    "margin_m": 0.3,
                },
            }
        ],
    }
    if avoidance is not None:
        data["navigation"] = {"avoidance": avoidance}
    return build_world(parse_scenario(data))


#: Fleet sizes of the ``nav.fleet`` benchmark (quick: the first two).
FLEET_SIZES = (10, 50, 100, 200, 500, 1000)


def fleet_ticks(n: int, steady: int, avoidance: str | None = None) -> dict:
    """CPU times (``time.process_time``) of a park command for ``n`` skids: the first tick,
    every tick until all skids have their first path, and ``steady`` ticks after 20 more
    (``avoidance``: as :func:`fleet_park_world`)."""
    import time

    from swarmpark.supervisor.core import Supervisor

    sup = Supervisor(fleet_park_world(n, avoidance))
    t0 = time.process_time()
    sup.tick()  # the park command: layout, assignment, the first plans
    first = time.process_time() - t0
    nav = sup.controller
    planning = []
    while any(r.path.path_goal is None for r in nav.robots[:n]) and len(planning) < 10 * n:
        t0 = time.process_time()
        sup.tick()
        planning.append(time.process_time() - t0)
    for _ in range(20):
        sup.tick()
    ticks = []
    for _ in range(steady):
        t0 = time.process_time()
        sup.tick()
        ticks.append(time.process_time() - t0)
    return {
        "first": first,
        "planning": np.asarray(planning),
        "steady": np.asarray(ticks),
        "dt": sup.world.scenario.dt_s,
    }


def _warm_up(avoidance: str | None = None) -> None:
    """One small park first, so no row pays for loading the compiled kernels (numba)."""
    fleet_ticks(10, 1, avoidance)


def _fleet_rows(quick: bool, avoidance: str | None = None) -> list[dict]:
    """The ``nav.fleet`` rows (see :func:`bench_fleet`) with ``avoidance``."""
    _warm_up(avoidance)
    rows = []
    for n in FLEET_SIZES[:2] if quick else FLEET_SIZES:
        r = fleet_ticks(n, 20 if quick else 100, avoidance)
        ms, plan = r["steady"] * 1e3, r["planning"] * 1e3
        mean, p99 = float(ms.mean()), float(np.percentile(ms, 99))
        targets = {100: r["first"] <= 0.2, 200: mean <= 10.0, 1000: mean <= 50.0}
        rows.append(
            {
                "N": n,
                "first_tick_ms": round(r["first"] * 1e3, 1),
                "planning_ticks": len(plan),
                "planning_mean_ms": round(float(plan.mean()), 1) if len(plan) else 0.0,
                "planning_max_ms": round(float(plan.max()), 1) if len(plan) else 0.0,
                "steady_mean_ms": round(mean, 2),
                "steady_p99_ms": round(p99, 2),
                "control_period_ms": round(r["dt"] * 1e3, 1),
                "meets_target": (bool(targets[n]) and p99 <= 3 * mean) if n in targets else None,
            }
        )
    return rows


#: The tick targets of issue 19, with either avoidance.
FLEET_TARGET = (
    "steady tick mean <= 10 ms at 200 skids, <= 50 ms at 1000, p99 <= 3x mean; "
    "first tick <= 200 ms at 100"
)


@register(
    "nav.fleet",
    "full ticks with a park command for the whole fleet, CPU time (time.process_time); "
    "planning: the ticks until every skid has its first path",
    target=FLEET_TARGET,
)
def bench_fleet(quick: bool) -> list[dict]:
    return _fleet_rows(quick)


@register(
    "nav.fleet_rvo",
    "nav.fleet with RVO avoidance (navigation: {avoidance: rvo}: make room, the deadlock "
    "ladder, ORCA, then the monitor jointly), CPU time (time.process_time)",
    target=FLEET_TARGET,
)
def bench_fleet_rvo(quick: bool) -> list[dict]:
    return _fleet_rows(quick, "rvo")


@register(
    "nav.manoeuvre",
    "one manoeuvre on the state lattice (plan/lattice.py): into a spot between a pillar and a "
    "parked neighbour, 6 x 6 m window at 5 cm, 16 headings",
    target="< 200 ms (it runs only for a skid stuck for 12 s)",
)
def bench_manoeuvre(quick: bool) -> list[dict]:
    from swarmpark.core.geometry import Footprint
    from swarmpark.plan.lattice import plan_manoeuvre

    res = 0.05
    occ = np.zeros((120, 120), bool)
    occ[:, :2] = occ[:, -2:] = occ[:2, :] = occ[-2:, :] = True
    for x0, y0, x1, y1 in ((2.4, 1.6, 3.2, 2.4), (1.2, 2.6, 2.0, 3.8), (2.4, 4.0, 3.2, 5.1)):
        occ[int(y0 / res) : int(y1 / res), int(x0 / res) : int(x1 / res)] = True
    fp = Footprint(1.2, 0.8, 0.6)
    start, goal = np.array([5.0, 1.0, np.pi / 2]), np.array([2.8, 3.2, np.pi / 2])

    def run():
        return plan_manoeuvre(
            occ, np.zeros(2), res, fp, start, goal, speed_mps=0.5, yaw_rate_radps=1.0
        )

    m = run()  # compiles the search (numba) on a fresh machine
    repeat = 3 if quick else 10
    return [
        {
            "window_cells": int(occ.size),
            **time_call(run, repeat),
            "cpu_median_ms": _cpu_median_ms(run, repeat),
            "expanded": m.expanded,
            "segments": len(m.segments()),
        }
    ]
