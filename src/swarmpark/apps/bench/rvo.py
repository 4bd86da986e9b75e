"""Benchmarks of the ORCA kernel: the classic circle (agents on a circle, goals antipodal)
and a dense snapshot.

Every agent is a 1.25 m x 0.75 m skid rectangle facing the centre; the chosen velocities are
integrated holonomically (the shapes keep their yaw), so the run exercises the kernel alone.
Timing covers :func:`swarmpark.control.orca.kernel.orca_step` only (wall and process CPU time: the
bench machine may be shared); collisions are checked after every step with the exact
separating-axis test of :mod:`swarmpark.core.geometry`.

The driver is deliberately simple and says what it does: preferred velocity straight at the
goal, turned ``KEEP_RIGHT_RAD`` clockwise plus seeded noise of up to ``JITTER_MPS`` (the
circle is perfectly symmetric and ORCA needs a tie-break, as in RVO2's own examples);
agents within ``GOAL_TOLERANCE_M`` of their goal count as parked and get priority 0 (they
make room); an agent that has made no progress for ``STALL_S`` side-steps to its right for
``SIDESTEP_S`` (a stand-in for the supervisor's deadlock handling).
"""

from __future__ import annotations

import math
import time

import numpy as np
from scipy.spatial import cKDTree

from swarmpark.apps.bench import register
from swarmpark.control.orca.kernel import OrcaParams, orca_step
from swarmpark.core.geometry import TOUCH_TOLERANCE_M, Footprint, convex_gap, rotation

__all__ = ["circle_scenario", "run_circle", "time_dense"]

#: Skid footprint of the benchmark (the papers' weapon skid, pivot in the middle).
SKID = Footprint(length_m=1.25, width_m=0.75)
#: Arc length per agent on the start circle (tangential width 0.75 m: 1.25 m gaps).
ARC_SPACING_M = 2.0
#: Smallest start radius, so ten skids still fit.
MIN_RADIUS_M = 5.0
MAX_SPEED_MPS = 1.0
DT_S = 0.25
#: An agent has arrived (and parks, priority 0) within this distance of its goal.
GOAL_TOLERANCE_M = 0.1
#: Symmetry breaking of the preferred velocity: a clockwise turn and seeded noise.
KEEP_RIGHT_RAD = 0.2
JITTER_MPS = 0.05
#: No progress (distance to the goal not down by STALL_PROGRESS_M) for this long: side-step.
STALL_S = 3.0
STALL_PROGRESS_M = 0.1
SIDESTEP_S = 2.0
#: Runs stop at this multiple of the free-flight crossing time.
CAP_FACTOR = 3.0


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
    seed: int = 0,
    spacing_m: float = ARC_SPACING_M,
    keep_right_rad: float = KEEP_RIGHT_RAD,
    jitter_mps: float = JITTER_MPS,
    sidestep: bool = True,
) -> dict:
    """Run the circle benchmark for ``n`` agents; return one flat row of results.

    ``max_steps`` caps the run (default: ``CAP_FACTOR`` times the free-flight crossing).
    """
    pos, goal, shapes = circle_scenario(n, spacing_m)
    vel = np.zeros_like(pos)
    rng = np.random.default_rng(seed)
    crossing = float(np.linalg.norm(goal[0] - pos[0])) / MAX_SPEED_MPS
    steps_cap = int(CAP_FACTOR * crossing / DT_S) + 40 if max_steps is None else max_steps
    turn = rotation(-keep_right_rad)
    to_right = rotation(-math.pi / 2)
    stalled = np.zeros(n)
    stepping = np.zeros(n)
    best = np.full(n, np.inf)
    times_ms: list[float] = []
    cpu_ms: list[float] = []
    colliding_pairs: set = set()
    collision_events = 0
    min_gap = math.inf
    infeasible_steps = 0
    sidesteps = 0
    done_at = None
    step = 0
    for step in range(1, steps_cap + 1):
        to_goal = goal - pos
        dist = np.linalg.norm(to_goal, axis=-1)
        # Head for the goal at full speed, slowing to land on it within one step.
        speed = np.minimum(MAX_SPEED_MPS, dist / DT_S)
        pref = to_goal * (speed / np.maximum(dist, 1e-12))[:, None]
        pref = pref @ turn.T
        a = rng.uniform(0.0, 2.0 * math.pi, n)
        pref += (
            jitter_mps * rng.uniform(0.0, 1.0, n)[:, None] * np.stack([np.cos(a), np.sin(a)], -1)
        )
        if sidestep:
            side = stepping > 0
            pref[side] = (to_goal[side] / np.maximum(dist[side], 1e-12)[:, None]) @ to_right.T
            pref[side] *= MAX_SPEED_MPS
        parked = dist <= GOAL_TOLERANCE_M
        prio = np.where(parked, 0.0, 1.0)
        t0, c0 = time.perf_counter(), time.process_time()
        res = orca_step(pos, vel, pref, MAX_SPEED_MPS, prio, shapes, dt_s=DT_S, params=params)
        times_ms.append((time.perf_counter() - t0) * 1e3)
        cpu_ms.append((time.process_time() - c0) * 1e3)
        infeasible_steps += int(res.infeasible.any())
        vel = res.velocities
        pos = pos + vel * DT_S
        if sidestep:
            left = np.linalg.norm(goal - pos, axis=-1)
            progress = left < best - STALL_PROGRESS_M
            best = np.where(progress, left, best)
            waiting = ~progress & (left > GOAL_TOLERANCE_M) & (stepping <= 0)
            stalled = np.where(waiting, stalled + DT_S, 0.0)
            start = stalled >= STALL_S
            sidesteps += int(start.sum())
            stepping = np.where(start, SIDESTEP_S, np.maximum(stepping - DT_S, 0.0))
            stalled[start] = 0.0
            best[start] = np.inf
        hits, gap = _overlaps(pos, shapes)
        min_gap = min(min_gap, gap)
        collision_events += len(hits)
        colliding_pairs |= hits
        if np.all(np.linalg.norm(goal - pos, axis=-1) <= GOAL_TOLERANCE_M):
            done_at = step * DT_S
            break
    arrived = float(np.mean(np.linalg.norm(goal - pos, axis=-1) <= GOAL_TOLERANCE_M))
    return {
        "case": f"circle n={n}",
        "n": n,
        "steps": step,
        "ms_per_step": float(np.mean(times_ms)),
        "p99_ms": float(np.percentile(times_ms, 99)),
        "cpu_ms_per_step": float(np.mean(cpu_ms)),
        "collisions": len(colliding_pairs),
        "collision_events": collision_events,
        "min_gap_m": min_gap,
        "steps_with_infeasible_lp": infeasible_steps,
        "sidesteps": sidesteps,
        "completed": done_at is not None,
        # Empty (not NaN, which is not JSON) when the cap came first.
        "completion_s": done_at if done_at is not None else "",
        "arrived_fraction": arrived,
        "free_flight_s": crossing,
    }


def time_dense(n: int, repeat: int = 5, seed: int = 0) -> dict:
    """Time one decision for ``n`` skids packed in a grid (0.35 m gaps) moving in random
    directions: every agent has its full set of neighbours and most programs are
    infeasible, the worst case of a step."""
    rng = np.random.default_rng(seed)
    side = math.ceil(math.sqrt(n))
    gx, gy = np.meshgrid(np.arange(side) * (SKID.length_m + 0.35), np.arange(side) * 1.1)
    pos = np.stack([gx.ravel(), gy.ravel()], -1)[:n]
    corners = SKID.corners_body() - [SKID.center_offset_m, 0.0]
    shapes = np.broadcast_to(corners, (n, 4, 2)).copy()
    ang = rng.uniform(0.0, 2.0 * math.pi, n)
    vel = 0.5 * np.stack([np.cos(ang), np.sin(ang)], -1)
    pref = np.stack([np.cos(ang + 0.3), np.sin(ang + 0.3)], -1)
    res = orca_step(pos, vel, pref, MAX_SPEED_MPS, 1.0, shapes, dt_s=DT_S)
    wall, cpu = [], []
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        orca_step(pos, vel, pref, MAX_SPEED_MPS, 1.0, shapes, dt_s=DT_S)
        wall.append((time.perf_counter() - t0) * 1e3)
        cpu.append((time.process_time() - c0) * 1e3)
    return {
        "case": f"dense n={n}",
        "n": n,
        "ms_per_step": float(np.mean(wall)),
        "cpu_ms_per_step": float(np.mean(cpu)),
        "infeasible_fraction": float(res.infeasible.mean()),
        "constraints_per_agent": float(res.halfplanes.valid.sum() / n),
    }


def _with_peers(row: dict, quick: bool) -> list[dict]:
    """``row`` (a swarmpark circle run) and the installed peers on the same circle for the
    same number of steps; ``row`` gets the CPU ratios swarmpark / peer."""
    from swarmpark.apps.bench import peers

    out = [row]
    # The skids' overlap on the same scale as the peers' (rectangles, not discs).
    row["max_overlap_m"] = max(0.0, -row["min_gap_m"])
    for name, run in (("pyrvo", peers.run_pyrvo), ("navground", peers.run_navground)):
        if not peers.available(name):
            row[f"x_{name}"] = "not installed"
            continue
        peer = run(row["n"], max_steps=row["steps"])
        row[f"x_{name}"] = row["cpu_ms_per_step"] / peer["cpu_ms_per_step"]
        out.append(peer)
    return out


@register(
    "rvo.circle",
    "ORCA decision on the circle benchmark (skid rectangles, antipodal goals): CPU ms/step, "
    "whole-run collisions, completion time; side by side with RVO2 (pyrvo) and navground "
    "on the same circle for the same steps (round, circumscribed radius; x_peer = "
    "swarmpark / peer CPU per step); plus a dense worst-case snapshot",
    target="N = 1000: <= 3x pyrvo CPU per step, zero collisions, runs to completion",
)
def bench_circle(quick: bool) -> list[dict]:
    # Load the compiled kernels first (numba's on-disk cache): a one-off start-up cost that
    # would otherwise land in the first timed step.
    run_circle(10, max_steps=3)
    if quick:
        rows = [run_circle(10), *_with_peers(run_circle(100, max_steps=40), quick)]
        return rows + [time_dense(100, repeat=2)]
    rows = [run_circle(10)]
    rows += _with_peers(run_circle(100), quick)
    rows += _with_peers(run_circle(1000), quick)
    # A full crossing at N = 5000 (a 1.6 km circle) takes ~10^4 steps: time the first 400.
    rows += _with_peers(run_circle(5000, max_steps=400), quick)
    rows += [time_dense(n) for n in (10, 100, 1000, 5000)]
    return rows
