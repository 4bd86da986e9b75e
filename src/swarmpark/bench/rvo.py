"""Benchmark of the ORCA kernel: the classic circle (agents on a circle, goals antipodal).

Every agent is a 1.25 m x 0.75 m skid rectangle facing the centre; the chosen velocities are
integrated holonomically (the shapes keep their yaw), so the run tests the kernel alone.
Timing covers :func:`swarmpark.control.rvo.orca_step` only; collisions are checked after every
step with the exact separating-axis test of :mod:`swarmpark.geometry`.
"""

from __future__ import annotations

import math
import time

import numpy as np
from scipy.spatial import cKDTree

from swarmpark.bench import register
from swarmpark.control.rvo import OrcaParams, inflate_convex, orca_step
from swarmpark.geometry import TOUCH_TOLERANCE_M, Footprint, convex_gap, rotation

__all__ = ["circle_scenario", "run_circle"]

#: Skid footprint of the benchmark (the papers' weapon skid, pivot in the middle).
SKID = Footprint(length_m=1.25, width_m=0.75)
#: Arc length per agent on the start circle (tangential width 0.75 m: 0.75 m gaps).
ARC_SPACING_M = 1.5
#: Smallest start radius, so ten skids still fit.
MIN_RADIUS_M = 5.0
MAX_SPEED_MPS = 1.0
DT_S = 0.25
#: An agent has arrived when its centre is this close to its goal.
GOAL_TOLERANCE_M = 0.1


def circle_scenario(
    n: int, spacing_m: float = ARC_SPACING_M
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Start centres ``(n, 2)``, antipodal goals ``(n, 2)`` and shapes ``(n, 4, 2)``."""
    radius = max(n * spacing_m / (2.0 * math.pi), MIN_RADIUS_M)
    ang = 2.0 * math.pi * np.arange(n) / n
    start = radius * np.stack([np.cos(ang), np.sin(ang)], -1)
    # Facing the centre; rectangles centred on the agent position.
    corners = SKID.corners_body() - [SKID.center_offset_m, 0.0]
    shapes = np.einsum("nij,kj->nki", rotation(ang + math.pi), corners)
    return start, -start, shapes


def _overlaps(pos: np.ndarray, shapes: np.ndarray) -> tuple[set, float]:
    """Pairs of overlapping shapes and the smallest gap among near pairs."""
    pairs = cKDTree(pos).query_pairs(2.0 * SKID.circumradius_m, output_type="ndarray")
    if pairs.size == 0:
        return set(), math.inf
    a = pos[pairs[:, 0], None] + shapes[pairs[:, 0]]
    b = pos[pairs[:, 1], None] + shapes[pairs[:, 1]]
    gap = convex_gap(a, b)
    hit = pairs[gap < -TOUCH_TOLERANCE_M]
    return {tuple(p) for p in hit.tolist()}, float(gap.min())


def run_circle(
    n: int,
    *,
    max_steps: int | None = None,
    params: OrcaParams | None = None,
    margin_m: float = 0.0,
    bias_rad: float = 0.0,
    jitter_mps: float = 0.0,
    seed: int = 0,
    spacing_m: float = ARC_SPACING_M,
    parked_priority: float = 1.0,
) -> dict:
    """Run the circle benchmark for ``n`` agents; return one flat row of results.

    ``max_steps`` caps the run (default: three times the free-flight crossing time).
    """
    pos, goal, shapes = circle_scenario(n, spacing_m)
    orca_shapes = inflate_convex(shapes, margin_m) if margin_m > 0 else shapes
    vel = np.zeros_like(pos)
    rng = np.random.default_rng(seed)
    crossing = float(np.linalg.norm(goal[0] - pos[0])) / MAX_SPEED_MPS / DT_S
    steps_cap = int(3 * crossing) + 40 if max_steps is None else max_steps
    times_ms: list[float] = []
    cpu_ms: list[float] = []
    colliding_pairs: set = set()
    collision_events = 0
    min_gap = math.inf
    infeasible_steps = 0
    done_at = None
    step = 0
    for step in range(1, steps_cap + 1):
        to_goal = goal - pos
        dist = np.linalg.norm(to_goal, axis=-1)
        # Head for the goal at full speed, slowing to land on it within one step.
        speed = np.minimum(MAX_SPEED_MPS, dist / DT_S)
        pref = to_goal * (speed / np.maximum(dist, 1e-12))[:, None]
        if bias_rad:
            c, s_ = math.cos(bias_rad), math.sin(bias_rad)
            pref = pref @ np.array([[c, s_], [-s_, c]])
        if jitter_mps:
            a = rng.uniform(0, 2 * math.pi, n)
            pref = pref + jitter_mps * rng.uniform(0, 1, n)[:, None] * np.stack(
                [np.cos(a), np.sin(a)], -1
            )
        t0, c0 = time.perf_counter(), time.process_time()
        prio = np.where(dist <= GOAL_TOLERANCE_M, parked_priority, 1.0)
        res = orca_step(pos, vel, pref, MAX_SPEED_MPS, prio, orca_shapes, dt_s=DT_S, params=params)
        times_ms.append((time.perf_counter() - t0) * 1e3)
        cpu_ms.append((time.process_time() - c0) * 1e3)
        infeasible_steps += int(res.infeasible.any())
        vel = res.velocities
        pos = pos + vel * DT_S
        hits, gap = _overlaps(pos, shapes)
        min_gap = min(min_gap, gap)
        collision_events += len(hits)
        colliding_pairs |= hits
        if np.all(np.linalg.norm(goal - pos, axis=-1) <= GOAL_TOLERANCE_M):
            done_at = step * DT_S
            break
    arrived = float(np.mean(np.linalg.norm(goal - pos, axis=-1) <= GOAL_TOLERANCE_M))
    return {
        "case": f"n={n}",
        "n": n,
        "steps": step,
        "ms_per_step": float(np.mean(times_ms)),
        "p99_ms": float(np.percentile(times_ms, 99)),
        "cpu_ms_per_step": float(np.mean(cpu_ms)),
        "collisions": len(colliding_pairs),
        "collision_events": collision_events,
        "min_gap_m": min_gap,
        "steps_with_infeasible_lp": infeasible_steps,
        "completed": done_at is not None,
        "completion_s": done_at if done_at is not None else float("nan"),
        "arrived_fraction": arrived,
        "free_flight_s": crossing * DT_S,
    }


@register(
    "rvo.circle",
    "ORCA step on the circle benchmark (rectangles, antipodal goals): ms/step, collisions, "
    "completion time",
    target="< 20 ms per step at N = 1000, zero collisions",
)
def bench_circle(quick: bool) -> list[dict]:
    if quick:
        return [run_circle(n, max_steps=40) for n in (10, 100)]
    rows = [run_circle(n) for n in (10, 100, 1000)]
    # A full crossing at N = 5000 (a 1.2 km circle) takes ~10^4 steps: time the first 200.
    rows.append(run_circle(5000, max_steps=200))
    return rows
