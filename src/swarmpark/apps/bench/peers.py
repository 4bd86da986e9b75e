"""Peer ORCA implementations on the circle benchmark, run in this process for a side-by-side
timing: RVO2 (the C++ reference, through the ``pyrvo`` bindings) and navground's ORCA.

Both are optional (the ``bench`` extra); a missing one gives no row. They are round: each
agent gets the circumscribed radius of the benchmark's skid rectangle, so they are as
conservative as a disc can be. Their overlap is measured on those discs (largest
``2 r - |p_i - p_j|``). Timing is CPU time (``time.process_time``) of the peer's step call
only: ``doStep`` for RVO2 (preferred velocities are set before the clock starts);
``World.update`` for navground, which also includes its neighbour sensing and integration
(navground has no call that runs the behaviours alone for a whole world).

Drivers: RVO2 gets swarmpark's circle driver (straight at the goal, turned
``KEEP_RIGHT_RAD`` clockwise plus seeded jitter, slowing to land on the goal); navground
runs its own waypoint task at the same speed and tolerance.
"""

from __future__ import annotations

import importlib.util
import math
import time

import numpy as np
from scipy.spatial import cKDTree

from swarmpark.apps.bench.rvo import (
    DT_S,
    GOAL_TOLERANCE_M,
    JITTER_MPS,
    KEEP_RIGHT_RAD,
    MAX_SPEED_MPS,
    SKID,
    circle_scenario,
)
from swarmpark.control.orca.kernel import OrcaParams
from swarmpark.core.geometry import rotation

__all__ = ["available", "run_pyrvo", "run_navground", "PEER_RADIUS_M"]

#: Round peers get the circumscribed radius of the skid rectangle.
PEER_RADIUS_M = SKID.circumradius_m


def available(name: str) -> bool:
    """Whether the peer's Python package (``pyrvo`` or ``navground``) is installed."""
    return importlib.util.find_spec(name) is not None


def _neighbour_dist(params: OrcaParams) -> float:
    """The cut-off swarmpark uses with the defaults: horizon x two top speeds + two radii."""
    return params.time_horizon_s * 2.0 * MAX_SPEED_MPS + 2.0 * PEER_RADIUS_M


def _max_overlap(pos: np.ndarray) -> float:
    """Largest overlap of the peers' discs (0 where none overlap)."""
    pairs = cKDTree(pos).query_pairs(2.0 * PEER_RADIUS_M, output_type="ndarray")
    if pairs.size == 0:
        return 0.0
    d = np.linalg.norm(pos[pairs[:, 0]] - pos[pairs[:, 1]], axis=-1)
    return float(max(0.0, (2.0 * PEER_RADIUS_M - d).max()))


def _row(name, n, steps, cpu_ms, overlap, pos, goal) -> dict:
    arrived = np.linalg.norm(goal - pos, axis=-1) <= GOAL_TOLERANCE_M
    return {
        "case": f"{name} circle n={n}",
        "n": n,
        "steps": steps,
        "cpu_ms_per_step": float(np.mean(cpu_ms)),
        "max_overlap_m": overlap,
        "completed": bool(arrived.all()),
        "arrived_fraction": float(arrived.mean()),
    }


def run_pyrvo(n: int, max_steps: int, seed: int = 0, params: OrcaParams | None = None) -> dict:
    """RVO2 on the circle for at most ``max_steps`` steps (stops when all have arrived)."""
    import pyrvo

    params = OrcaParams() if params is None else params
    start, goal, _ = circle_scenario(n)
    sim = pyrvo.RVOSimulator(
        DT_S,
        _neighbour_dist(params),
        params.max_neighbours,
        params.time_horizon_s,
        params.time_horizon_obst_s,
        PEER_RADIUS_M,
        MAX_SPEED_MPS,
    )
    for p in start:
        sim.add_agent((float(p[0]), float(p[1])))
    rng = np.random.default_rng(seed)
    turn = rotation(-KEEP_RIGHT_RAD)
    pos = start.copy()
    cpu_ms, overlap = [], 0.0
    for _ in range(max_steps):
        to_goal = goal - pos
        dist = np.linalg.norm(to_goal, axis=-1)
        speed = np.minimum(MAX_SPEED_MPS, dist / DT_S)
        pref = (to_goal * (speed / np.maximum(dist, 1e-12))[:, None]) @ turn.T
        a = rng.uniform(0.0, 2.0 * math.pi, n)
        pref += (
            JITTER_MPS * rng.uniform(0.0, 1.0, n)[:, None] * np.stack([np.cos(a), np.sin(a)], -1)
        )
        for i, v in enumerate(pref.tolist()):
            sim.set_agent_pref_velocity(i, (v[0], v[1]))
        c0 = time.process_time()
        sim.do_step()
        cpu_ms.append((time.process_time() - c0) * 1e3)
        pos = np.array([(q.x, q.y) for q in map(sim.get_agent_position, range(n))])
        overlap = max(overlap, _max_overlap(pos))
        if np.all(np.linalg.norm(goal - pos, axis=-1) <= GOAL_TOLERANCE_M):
            break
    return _row("pyrvo", n, len(cpu_ms), cpu_ms, overlap, pos, goal)


def _navground_world(start: np.ndarray, goal: np.ndarray, params: OrcaParams):
    import navground.sim as ng_sim

    agents = []
    for p, g in zip(start.tolist(), goal.tolist(), strict=True):
        agents.append(
            f"""  - position: [{p[0]!r}, {p[1]!r}]
    orientation: {math.atan2(g[1] - p[1], g[0] - p[0])!r}
    radius: {PEER_RADIUS_M!r}
    kinematics: {{type: Omni, max_speed: {MAX_SPEED_MPS!r}}}
    behavior:
      type: ORCA
      time_horizon: {params.time_horizon_s!r}
      optimal_speed: {MAX_SPEED_MPS!r}
      max_number_of_neighbors: {params.max_neighbours}
    task: {{type: Waypoints, waypoints: [[{g[0]!r}, {g[1]!r}]], tolerance: {GOAL_TOLERANCE_M!r}}}
    state_estimation: {{type: Bounded, range: {_neighbour_dist(params)!r}}}"""
        )
    return ng_sim.load_world("agents:\n" + "\n".join(agents))


def run_navground(n: int, max_steps: int, params: OrcaParams | None = None) -> dict:
    """navground's ORCA on the circle for at most ``max_steps`` steps."""
    params = OrcaParams() if params is None else params
    start, goal, _ = circle_scenario(n)
    world = _navground_world(start, goal, params)
    agents = world.agents
    cpu_ms, overlap = [], 0.0
    pos = start
    for _ in range(max_steps):
        c0 = time.process_time()
        world.update(DT_S)
        cpu_ms.append((time.process_time() - c0) * 1e3)
        pos = np.array([a.position for a in agents], dtype=float)
        overlap = max(overlap, _max_overlap(pos))
        if np.all(np.linalg.norm(goal - pos, axis=-1) <= GOAL_TOLERANCE_M):
            break
    return _row("navground", n, len(cpu_ms), cpu_ms, overlap, pos, goal)
