"""Reproduce Liu, Sun & Zhu (2010): the six-robot simulation (Table 1, Fig. 6) and the moving
obstacle experiment (Table 2, Fig. 9), with figures and a markdown table.

The paper does not give its path geometry, so it is reconstructed here: the group's formation
reference (robot 1's path) is a gentle lane change ``x = 1.3 u``, ``y = 0.15 (1 - cos(pi u))``
metres; every other robot's path is that curve plus its position in the current formation,
rotated with the curve's heading, so that the formations can be held while the shape changes
a -> b -> c -> d (held over 15-20 % of the way each, blended in between). The resulting paths
are 1.3-1.5 m long, within the 1.68 m that ``M = 15``, ``dt = 1 s``, ``V_max = 120 mm/s``,
``a_max = 120 mm/s^2`` allow. Robot numbers in the text are the paper's (1-6); indices in
code are 0-5. Table 1's offsets are used as given, in robot ``i``'s frame with x forward and y
left, which puts robot 1 at the rear of a group that opens forward.

For the experiment (two robots, a moving obstacle appearing at 5 s) the paper gives only the
formations of Table 2, the obstacle's appearance at 5 s and the timeline of Fig. 9. Here
robot 1 drives a 4 m lane change, robot 2 starts 1.2 m to its left (step a) and falls in
1.2 m behind it (step b); a third robot crosses robot 1's path diagonally. It is watched for
3 s (the paper's robots act at 8 s) and predicted at constant velocity.

:func:`swarmpark.control.formation.paper_report.run_paper` writes ``formation_errors.png``,
``formation_velocity.png``, ``formation_paths.png`` and ``formation_table.md`` and returns the
numbers.
"""

from __future__ import annotations

import numpy as np

from swarmpark.control.formation import (
    FormationProblem,
    OnlineAdjuster,
    blend_offsets,
    plan_velocities,
    sample_reference,
)
from swarmpark.core.paths import SplinePath

__all__ = [
    "TABLE1_EDGES",
    "TABLE1_OFFSETS_M",
    "paper_problem",
    "TABLE2_OFFSETS_M",
    "experiment_problem",
    "obstacle_position",
    "grid_problem",
    "run_obstacle_experiment",
]

#: Robot pairs of the paper's Fig. 4 (0-based): 1->2, 1->3, 2->4, 2->5, 3->6.
TABLE1_EDGES = np.array([[0, 1], [0, 2], [1, 3], [1, 4], [2, 5]])
#: Table 1, metres: ``[edge, formation a-d, (dx', dy')]``.
TABLE1_OFFSETS_M = (
    np.array(
        [
            [[0, -200], [100, -200], [100, -100], [70.7, -70.7]],
            [[0, 200], [100, 200], [100, 100], [70.7, 70.7]],
            [[200, 0], [100, 0], [100, -100], [70.7, -70.7]],
            [[200, 200], [100, 200], [100, 100], [70.7, 70.7]],
            [[200, 0], [100, 0], [100, 100], [70.7, 70.7]],
        ],
        dtype=float,
    )
    / 1000.0
)
#: Where along the reference curve (parameter u in [0, 1]) each formation a, b, c, d is held.
#: b -> c moves robots 2 and 3 sideways and gets the longest stretch: a sideways move turns a
#: robot's heading, which swings every offset given in its frame.
_HOLD_U = np.array([[0.0, 0.10], [0.30, 0.35], [0.70, 0.75], [0.92, 1.0]])
#: Dense curve parameter grid used to build the paths, and the waypoint stride on it.
_DENSE_U = np.linspace(0.0, 1.0, 2001)
_WAYPOINT_STRIDE = 20


def _tree_edges(edges: np.ndarray, root: int) -> list[int]:
    """Edge indices in breadth-first order from ``root``."""
    order, frontier = [], [root]
    while frontier:
        nxt = []
        for r in frontier:
            for e, (i, j) in enumerate(edges.tolist()):
                if i == r:
                    order.append(e)
                    nxt.append(j)
        frontier = nxt
    return order


def _formation_paths(root_curve, root, edges, offsets, hold_u, field="paths"):
    """Paths on which the formations can be held exactly, with the problem's keypoints.

    ``root_curve`` ``(N, 2)`` is the root robot's path sampled on :data:`_DENSE_U`; every
    other robot's path is built in tree order as ``p_j(u) = p_i(u) + R(theta_i(u)) d_ij``
    with ``d_ij`` blended exactly as :func:`blend_offsets` does along robot ``i``'s path, i.e.
    eq. (6) holds whenever all robots are at the same ``u``. Formation ``f`` is held for
    ``u`` in ``hold_u[f]``. Returns ``paths``, ``offsets (E, 2F, 2)`` and ``at (E, 2F)``.
    """
    n = int(edges.max()) + 1
    keys = hold_u.ravel()  # (2F,)
    k_off = np.repeat(offsets, 2, axis=1)  # each formation at both ends of its hold
    at = np.zeros((edges.shape[0], keys.size))
    dense = {root: np.asarray(root_curve, dtype=float)}
    for e in _tree_edges(edges, root):
        i, j = edges[e]
        pi = dense[i]
        arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pi, axis=0), axis=1))])
        sigma = arc / arc[-1]
        at[e] = np.interp(keys, _DENSE_U, sigma)
        d = blend_offsets(at[e : e + 1], k_off[e : e + 1], sigma[None])[0]  # (N, 2)
        tangent = np.gradient(pi, _DENSE_U, axis=0, edge_order=2)
        th = np.arctan2(tangent[:, 1], tangent[:, 0])
        c, s = np.cos(th), np.sin(th)
        dense[j] = pi + np.stack([c * d[:, 0] - s * d[:, 1], s * d[:, 0] + c * d[:, 1]], axis=1)
    paths = []
    for r in range(n):
        pts = dense[r]
        tan = np.gradient(pts, _DENSE_U, axis=0, edge_order=2)
        paths.append(
            SplinePath.through(
                pts[::_WAYPOINT_STRIDE],
                start_heading=float(np.arctan2(tan[0, 1], tan[0, 0])),
                end_heading=float(np.arctan2(tan[-1, 1], tan[-1, 0])),
                field_name=f"{field}[{r}].waypoints",
            )
        )
    return paths, k_off, at


def paper_problem() -> FormationProblem:
    """The six-robot problem of Sect. III.A: Table 1 offsets, ``M = 15``, ``dt = 1 s``,
    ``V_max = 0.12 m/s``, ``a_max = 0.12 m/s^2``, ``D_safe = 0.09 m`` (paths reconstructed,
    see the module docstring)."""
    u = _DENSE_U
    curve = np.stack([1.3 * u, 0.15 * (1.0 - np.cos(np.pi * u))], axis=1)
    paths, k_off, at = _formation_paths(curve, 0, TABLE1_EDGES, TABLE1_OFFSETS_M, _HOLD_U)
    return FormationProblem(
        paths=tuple(paths),
        edges=TABLE1_EDGES,
        offsets_m=k_off,
        offset_at=at,
        M=15,
        dt_s=1.0,
        v_max_mps=0.12,
        a_max_mps2=0.12,
        d_safe_m=0.09,
        leader=0,
    )


def grid_problem(
    n_robots: int = 20, M: int = 60, *, spacing_m: float = 0.25, route_m: float | None = None
) -> FormationProblem:
    """A larger benchmark: ``n_robots`` in rows of five change from a block to a wedge while
    following a lane change 0.8 m to the left, ``route_m`` long (default ``0.105 M`` metres,
    6.3 m for ``M = 60``, about 90 % of what the speed bound allows) (``V_max = a_max`` 0.12, ``D_safe = 0.09 m``, ``dt = 1 s``).

    The leader is the front robot of the middle column; the edges form a two-level tree: the
    middle robot of each row follows the leader, the others their row's middle robot.
    """
    if n_robots < 2:
        raise ValueError(f"n_robots: need at least 2 (got {n_robots})")
    cols = min(5, n_robots)
    mid = cols // 2
    idx = np.arange(n_robots)
    row, col = idx // cols, idx % cols
    block = np.stack([-row * spacing_m, (mid - col) * spacing_m], axis=1)
    wedge = np.stack(
        [-row * spacing_m - np.abs(col - mid) * 0.5 * spacing_m, (mid - col) * 0.8 * spacing_m],
        axis=1,
    )
    leader = mid
    edges = []
    for r in idx[idx != leader]:
        parent = leader if col[r] == mid else row[r] * cols + mid
        edges.append((int(parent), int(r)))
    edges = np.array(edges)
    rel = np.stack([block, wedge])  # (2, n, 2)
    offsets = np.stack([rel[:, j] - rel[:, i] for i, j in edges])  # (E, 2, 2)
    u = _DENSE_U
    length, shift = (0.105 * M if route_m is None else float(route_m)), 0.8
    curve = np.stack([length * u, 0.5 * shift * (1.0 - np.cos(np.pi * u))], axis=1)
    hold = np.array([[0.0, 0.3], [0.7, 1.0]])
    paths, k_off, at = _formation_paths(curve, leader, edges, offsets, hold)
    return FormationProblem(
        paths=tuple(paths),
        edges=edges,
        offsets_m=k_off,
        offset_at=at,
        M=M,
        dt_s=1.0,
        v_max_mps=0.12,
        a_max_mps2=0.12,
        d_safe_m=0.09,
        leader=leader,
    )


# --------------------------------------------------------------------------- Table 2 experiment
#: Table 2, metres: robot 2 relative to robot 1 in robot 1's frame, steps a and b.
TABLE2_OFFSETS_M = np.array([[[0.0, 1.2], [-1.2, 0.0]]])
#: When the obstacle (a third robot) is first seen, as in the paper.
OBSTACLE_APPEARS_S = 5.0
#: How long it is watched before the robots act (the paper's robots act at 8 s).
OBSTACLE_WATCH_S = 3.0
#: The obstacle's reconstructed motion: position at OBSTACLE_APPEARS_S and constant velocity.
OBSTACLE_START_M = np.array([2.6, -2.4])
OBSTACLE_VELOCITY_MPS = np.array([-0.05, 0.36])


def experiment_problem() -> FormationProblem:
    """The two-robot experiment of Sect. III.B (Table 2), reconstructed.

    Robot 1 drives 6 m straight along +x; robot 2 starts 1.2 m to its left (step a, held over
    the first quarter) and falls in 1.2 m behind it (step b, held over the last quarter).
    ``M = 25``, ``dt = 1 s``, ``V_max = 0.3 m/s``, ``a_max = 0.3 m/s^2`` (a Pioneer 3-DX is
    good for more), ``D_safe = 0.6 m`` (two 0.5 m robots and a margin).
    """
    u = _DENSE_U
    curve = np.stack([6.0 * u, np.zeros_like(u)], axis=1)
    edges = np.array([[0, 1]])
    hold = np.array([[0.0, 0.25], [0.75, 1.0]])
    paths, k_off, at = _formation_paths(curve, 0, edges, TABLE2_OFFSETS_M, hold)
    return FormationProblem(
        paths=tuple(paths),
        edges=edges,
        offsets_m=k_off,
        offset_at=at,
        M=25,
        dt_s=1.0,
        v_max_mps=0.3,
        a_max_mps2=0.3,
        d_safe_m=0.6,
        leader=0,
    )


def obstacle_position(t_s) -> np.ndarray:
    """True position ``(..., 2)`` of the experiment's moving obstacle at times ``t_s``."""
    t = np.asarray(t_s, dtype=float)[..., None]
    return OBSTACLE_START_M + (t - OBSTACLE_APPEARS_S) * OBSTACLE_VELOCITY_MPS


def run_obstacle_experiment(
    *, d_obs_m: float = 0.6, horizon_steps: int = 5, observe_every_s: float = 0.5
) -> dict:
    """Plan the Table 2 motion, then execute the online modification against the obstacle.

    The obstacle is observed every ``observe_every_s`` from :data:`OBSTACLE_APPEARS_S`; an
    :class:`OnlineAdjuster` decides every ``dt`` once it has watched for
    :data:`OBSTACLE_WATCH_S`. Returns the offline plan, the executed plan, the adjustments and
    the smallest true robot-obstacle distance (sampled every ``dt / 20``).
    """
    problem = experiment_problem()
    plan = plan_velocities(problem, "formation")
    adjuster = OnlineAdjuster(
        plan, min_watch_s=OBSTACLE_WATCH_S, d_obs_m=d_obs_m, horizon_steps=horizon_steps
    )
    dt = problem.dt_s
    sub = max(1, round(dt / observe_every_s))
    t_end = 3.0 * problem.M * dt
    for k in range(int(round(t_end / dt * sub)) + 1):
        t = k * dt / sub
        if t >= OBSTACLE_APPEARS_S - 1e-9:
            adjuster.observe(t, obstacle_position(t))
        if k % sub == 0:
            adjuster.update(t)
        if t > adjuster.plan.duration_s + horizon_steps * dt:
            break
    executed = adjuster.plan
    times = np.arange(0.0, executed.duration_s + 1e-9, dt / 20.0)
    ref = sample_reference(executed, times)
    seen = times >= OBSTACLE_APPEARS_S
    obs = obstacle_position(times)
    dist = np.linalg.norm(ref.poses[..., :2] - obs[:, None, :], axis=-1)
    return {
        "problem": problem,
        "plan": plan,
        "executed": executed,
        "adjustments": list(adjuster.adjustments),
        "times_s": times,
        "reference": ref,
        "min_obstacle_distance_m": float(dist[seen].min()),
        "d_obs_m": d_obs_m,
    }
