"""The leader-follower baseline (Liu, Sun & Zhu 2010, Sect. III): the leader drives the nominal
profile, every follower in tree order steers its own speed toward the point its leader's pose
and the desired offset ask for, braking so that it can stop at its goal."""

from __future__ import annotations

import math

import numpy as np

from swarmpark.control.formation.metrics import blend_offsets
from swarmpark.control.formation.problem import FormationProblem, nominal_profile

#: Arrival tolerance (metres) of the leader-follower baseline's braking logic.
_ARRIVAL_TOL_M = 1e-7
#: The leader-follower baseline runs at most this many times the planning horizon.
_LF_HORIZON_FACTOR = 4


def _tree_order(problem: FormationProblem) -> list[tuple[int, int, int]]:
    """Edges ``(edge, leader, follower)`` in breadth-first order from ``problem.leader``."""
    parent: dict[int, int] = {}
    for e, (i, j) in enumerate(problem.edges.tolist()):
        if j in parent or j == problem.leader:
            raise ValueError(
                f"edges[{e}]: ({i}, {j}) gives robot {j} a second leader; leader-follower needs "
                f"a tree rooted at leader={problem.leader}"
            )
        parent[j] = i
    order, frontier = [], [problem.leader]
    while frontier:
        nxt = []
        for i in frontier:
            for e, (a, b) in enumerate(problem.edges.tolist()):
                if a == i:
                    order.append((e, a, b))
                    nxt.append(b)
        frontier = nxt
    reached = {problem.leader} | {b for _, _, b in order}
    missing = sorted(set(range(problem.n_robots)) - reached)
    if missing:
        raise ValueError(
            f"edges: robots {missing} are not reachable from leader={problem.leader}; "
            "leader-follower needs a tree that spans all robots"
        )
    return order


def _stop_distance(v: float, a: float, dt: float) -> float:
    """Distance to stop from speed ``v`` decelerating ``a dt`` per step under (7)."""
    if v <= 0:
        return 0.0
    n = math.floor(v / (a * dt))
    f = v - n * a * dt
    return 0.5 * dt * (2 * n * v - n * n * a * dt + f)


def _leader_follower(problem: FormationProblem):
    order = _tree_order(problem)
    r, m_steps, dt = problem.n_robots, problem.M, problem.dt_s
    vmax, amax = problem.v_max_mps, problem.a_max_mps2
    lengths = problem.lengths_m
    n_max = _LF_HORIZON_FACTOR * m_steps
    v = np.zeros((r, n_max + 1))
    s = np.zeros((r, n_max + 1))
    lead = problem.leader
    v_lead, s_lead = nominal_profile(float(lengths[lead]), m_steps, dt, vmax, amax)
    v[lead, : m_steps + 1], s[lead, : m_steps + 1] = v_lead, s_lead
    s[lead, m_steps + 1 :] = lengths[lead]
    arrived = np.zeros(r, dtype=bool)
    arrived[lead] = True
    arrival_step = np.full(r, n_max)
    arrival_step[lead] = m_steps
    poses = np.zeros((r, n_max + 1, 3))
    poses[lead] = problem.paths[lead].pose(s[lead])
    for e, i, j in order:
        path = problem.paths[j]
        big_l = lengths[j]
        poses[j, 0] = path.pose(0.0)
        for m in range(n_max):
            if arrived[j]:
                s[j, m + 1] = big_l
                continue
            if m + 1 >= arrival_step[i]:
                s_star = big_l  # the leader has parked: go to the goal, where the formation ends
            else:
                # Where the leader's next pose and the desired offset put the follower,
                # projected onto the follower's path ahead of it.
                li = poses[i, m + 1]
                sigma = np.array([s[i, m + 1] / lengths[i]])
                d = blend_offsets(
                    problem.offset_at[e : e + 1], problem.offsets_m[e : e + 1], sigma
                )[0]
                c, sn = math.cos(li[2]), math.sin(li[2])
                target = li[:2] + np.array([c * d[0] - sn * d[1], sn * d[0] + c * d[1]])
                window = np.linspace(s[j, m], min(big_l, s[j, m] + 2 * vmax * dt), 65)
                k = int(np.argmin(np.linalg.norm(path.position(window) - target, axis=1)))
                s_star = float(window[k])
                s_star += float(np.dot(target - path.position(s_star), path.tangent(s_star)))
                s_star = float(np.clip(s_star, s[j, m], big_l))
            vj = v[j, m]
            lo, hi = max(0.0, vj - amax * dt), min(vmax, vj + amax * dt)

            def overshoot(vn: float, m=m, vj=vj, big_l=big_l, j=j) -> float:
                return s[j, m] + 0.5 * dt * (vj + vn) + _stop_distance(vn, amax, dt) - big_l

            if overshoot(hi) > 0:  # brake so that the follower can still stop at its goal
                a_, b_ = lo, hi
                for _ in range(100):
                    mid = 0.5 * (a_ + b_)
                    a_, b_ = (mid, b_) if overshoot(mid) <= 0 else (a_, mid)
                hi = max(lo, a_)
            vn = float(np.clip(2.0 * (s_star - s[j, m]) / dt - vj, lo, hi))
            s[j, m + 1] = min(big_l, s[j, m] + 0.5 * dt * (vj + vn))
            v[j, m + 1] = vn
            if big_l - s[j, m + 1] < _ARRIVAL_TOL_M and vn == 0.0:
                s[j, m + 1] = big_l
                arrived[j] = True
                arrival_step[j] = m + 1
            poses[j, m + 1] = path.pose(s[j, m + 1])
        poses[j] = path.pose(s[j])
    n_used = max(m_steps, int(arrival_step.max()))
    success = bool(arrived.all())
    status = "all robots reached their goals" if success else "followers did not reach their goals"
    return v[:, : n_used + 1], s[:, : n_used + 1], success, status, n_used
