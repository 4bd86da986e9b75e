"""Move a group in formation along given paths by velocity optimization (Liu, Sun & Zhu 2010).

Each robot drives along its own arc-length path (:class:`swarmpark.core.paths.SplinePath`); only
the speeds are planned. The planner (Sect. II of the paper) chooses speeds ``v_i(t)`` at
``M + 1`` instants ``t = m dt`` so that the travel distances (trapezoid rule, eq. 7) put the
robots where the desired formation wants them, measured by the formation error ``Q^e`` of
eqs. (9)-(10) with the desired offsets given in the frame of robot ``i`` of each pair (eq. 6)
and changing along the path; subject to speed and acceleration bounds (11)-(12), rest at
both ends (13)-(14) and a safe distance between all pairs (15).

The no-formation baseline uses the same paths and constraints without the formation term (each
robot gets to its goal as early as it can, still respecting (11)-(15)); the leader-follower
baseline is in :mod:`.leader_follower`. The problem and the plan are in :mod:`.problem`, the
formation error in :mod:`.metrics`, reference sampling and tracking in :mod:`.tracking`, the
online modification for a moving obstacle (Sect. II.D) in :mod:`.online`.

Solver choice
-------------
The planning problem is a nonlinear program with ``2 R (M + 1)`` variables, sparse linear
constraints (7), (11)-(14) and ``O(R^2 M)`` nonconvex distance constraints (15). It is solved
with CasADi + IPOPT rather than scipy's SLSQP: CasADi gives exact sparse first and second
derivatives (the path functions are CasADi B-spline interpolants of the arc-length splines),
and IPOPT's interior point with a sparse linear solver scales to 20 robots x 60 steps with
thousands of pair constraints, where SLSQP's dense quasi-Newton QP grows cubically and needs
finite-difference or hand-written Jacobians. Pair constraints that can never bind (the two
paths stay apart over the arc-length ranges reachable at that step) are left out.
"""

from __future__ import annotations

import math
from typing import Literal

import casadi as ca
import numpy as np
from scipy.spatial import cKDTree

from swarmpark.control.formation.leader_follower import _leader_follower
from swarmpark.control.formation.metrics import _smoothstep, formation_metrics
from swarmpark.control.formation.problem import (
    FormationPlan,
    FormationProblem,
    _as_float,
    _speed_caps,
    nominal_profile,
)

__all__ = ["METHODS", "plan_velocities"]

Method = Literal["formation", "no_formation", "leader_follower"]
METHODS: tuple[str, ...] = ("formation", "no_formation", "leader_follower")

#: Spacing (metres) of the arc-length samples behind the CasADi path interpolants; the cubic
#: B-spline through them reproduces the path to ~1e-9 m for curvatures below 10 /m.
_TABLE_SPACING_M = 0.005
_TABLE_MIN_SAMPLES = 32

_IPOPT_DEFAULTS = {
    "ipopt.print_level": 0,
    "print_time": 0,
    "ipopt.sb": "yes",
    "ipopt.max_iter": 3000,
    "ipopt.tol": 1e-8,
}


def _reach_bounds(problem: FormationProblem) -> tuple[np.ndarray, np.ndarray]:
    """Arc-length bounds ``(R, M + 1)`` implied by (11)-(14): how far a robot can be at step m."""
    cap = _speed_caps(problem.M, problem.dt_s, problem.v_max_mps, problem.a_max_mps2)
    step = 0.5 * problem.dt_s * (cap[:-1] + cap[1:])
    fwd = np.concatenate([[0.0], np.cumsum(step)])
    bwd = fwd[-1] - fwd
    length = problem.lengths_m[:, None]
    return np.maximum(0.0, length - bwd[None, :]), np.minimum(length, fwd[None, :])


def _plan_poses(problem: FormationProblem, s: np.ndarray) -> np.ndarray:
    return np.stack([p.pose(s[i]) for i, p in enumerate(problem.paths)])


def _min_pair_distance(poses_tr: np.ndarray) -> float:
    """Smallest distance between two robots, poses ``(T, R, 3)``."""
    n = poses_tr.shape[1]
    if n < 2:
        return math.inf
    iu, ju = np.triu_indices(n, 1)
    d = np.linalg.norm(poses_tr[:, iu, :2] - poses_tr[:, ju, :2], axis=-1)
    return float(d.min())


def _make_plan(problem, method, v, s, success, status, iterations) -> FormationPlan:
    n_steps = v.shape[1] - 1
    t = np.arange(n_steps + 1) * problem.dt_s
    poses = _plan_poses(problem, s)
    fe = formation_metrics(problem, t, np.swapaxes(poses, 0, 1), s.T)
    return FormationPlan(
        problem=problem,
        method=method,
        t_s=t,
        v_mps=v,
        s_m=s,
        poses=poses,
        q_e_m2=fe.q_e_m2,
        max_pair_error_m=fe.max_pair_error_m,
        min_pair_distance_m=_min_pair_distance(np.swapaxes(poses, 0, 1)),
        success=bool(success),
        status=str(status),
        iterations=int(iterations),
    )


# --------------------------------------------------------------------------- optimizer
def _check_endpoints(problem: FormationProblem) -> None:
    if problem.n_robots < 2 or problem.d_safe_m == 0:
        return
    for name, s in (("start", np.zeros(problem.n_robots)), ("goal", problem.lengths_m)):
        xy = np.array([p.position(s[i]) for i, p in enumerate(problem.paths)])
        iu, ju = np.triu_indices(problem.n_robots, 1)
        d = np.linalg.norm(xy[iu] - xy[ju], axis=1)
        bad = np.flatnonzero(d < problem.d_safe_m - 1e-9)
        if bad.size:
            k = bad[0]
            raise ValueError(
                f"paths: robots {iu[k]} and {ju[k]} are {d[k]:.4f} m apart at their {name}, "
                f"closer than d_safe_m={problem.d_safe_m:g}; no plan can satisfy (15)"
            )


def _candidate_pairs(problem: FormationProblem, s_lo: np.ndarray, s_hi: np.ndarray):
    """Robot pairs and steps ``(i, j, m)`` where the safe-distance constraint (15) can bind.

    Paths are sampled every ``h``; a pair at step ``m`` is kept if two samples within
    ``d_safe + h`` of each other both lie within ``h`` of the arc-length ranges the robots can
    reach at step ``m``. Every true point is within ``h / 2`` of a sample, so no pair that can
    come closer than ``d_safe`` is dropped.
    """
    d = problem.d_safe_m
    r, m_steps = problem.n_robots, problem.M
    if r < 2 or d == 0:
        return np.zeros((3, 0), dtype=int)
    h = max(d / 4.0, 1e-4)
    ss, pts, owner = [], [], []
    for i, p in enumerate(problem.paths):
        n = max(2, math.ceil(p.length_m / h) + 1)
        s = np.linspace(0.0, p.length_m, n)
        ss.append(s)
        pts.append(p.position(s))
        owner.append(np.full(n, i))
    s_all, xy, own = np.concatenate(ss), np.concatenate(pts), np.concatenate(owner)
    pairs = cKDTree(xy).query_pairs(d + h, output_type="ndarray")
    if pairs.size == 0:
        return np.zeros((3, 0), dtype=int)
    a, b = pairs[:, 0], pairs[:, 1]
    keep = own[a] != own[b]
    a, b = a[keep], b[keep]
    swap = own[a] > own[b]
    a, b = np.where(swap, b, a), np.where(swap, a, b)
    ra, rb = own[a], own[b]
    inner = slice(1, m_steps)  # the end instants are fixed and checked separately
    in_a = (s_all[a, None] >= s_lo[ra, inner] - h) & (s_all[a, None] <= s_hi[ra, inner] + h)
    in_b = (s_all[b, None] >= s_lo[rb, inner] - h) & (s_all[b, None] <= s_hi[rb, inner] + h)
    hit = in_a & in_b  # (P, M - 1)
    p_idx, m_idx = np.nonzero(hit)
    key = np.unique((ra[p_idx] * r + rb[p_idx]) * (m_steps + 1) + (m_idx + 1))
    m = key % (m_steps + 1)
    pair = key // (m_steps + 1)
    return np.stack([pair // r, pair % r, m])


def _solve_nlp(
    problem: FormationProblem, method: str, ipopt_options: dict | None, smoothing: float
):
    r, m_steps, dt = problem.n_robots, problem.M, problem.dt_s
    lengths = problem.lengths_m
    _check_endpoints(problem)
    # Feasibility of (11)-(14) and the initial guess: every robot on the nominal profile of
    # the longest path, scaled to its own length, so all advance in step.
    v_nom, s_nom = nominal_profile(
        float(lengths.max()), m_steps, dt, problem.v_max_mps, problem.a_max_mps2
    )
    scale = lengths / lengths.max()
    v0, s0 = scale[:, None] * v_nom[None, :], scale[:, None] * s_nom[None, :]
    s_lo, s_hi = _reach_bounds(problem)
    s_lo[:, -1] = s_hi[:, -1] = lengths

    vv = ca.SX.sym("v", r, m_steps + 1)
    ss = ca.SX.sym("s", r, m_steps + 1)
    cols = m_steps + 1

    # Path functions f_i(s) = (x, y, cos theta, sin theta) as smooth CasADi interpolants.
    rows = []
    for i, p in enumerate(problem.paths):
        n = max(_TABLE_MIN_SAMPLES, math.ceil(p.length_m / _TABLE_SPACING_M) + 1)
        grid, table = p.table(n)
        f = ca.interpolant(f"path{i}", "bspline", [grid], table.ravel().tolist())
        rows.append(f.map(cols)(ss[i, :]))
    px = ca.vertcat(*[row[0, :] for row in rows])
    py = ca.vertcat(*[row[1, :] for row in rows])
    pc = ca.vertcat(*[row[2, :] for row in rows])
    ps = ca.vertcat(*[row[3, :] for row in rows])

    def col(values) -> ca.DM:
        return ca.repmat(ca.DM(np.asarray(values, dtype=float)), 1, cols)

    if method == "formation" and problem.edges.shape[0] == 0:
        objective = ca.SX(0.0)  # no formation to hold: any feasible plan is optimal
    elif method == "formation":
        ei, ej = problem.edges[:, 0].tolist(), problem.edges[:, 1].tolist()
        sigma = ss[ei, :] * col(1.0 / lengths[ei])
        off, at = problem.offsets_m, problem.offset_at
        dxp, dyp = col(off[:, 0, 0]), col(off[:, 0, 1])
        for k in range(off.shape[1] - 1):
            w = _smoothstep((sigma - col(at[:, k])) * col(1.0 / (at[:, k + 1] - at[:, k])), ca)
            dxp = dxp + w * col(off[:, k + 1, 0] - off[:, k, 0])
            dyp = dyp + w * col(off[:, k + 1, 1] - off[:, k, 1])
        ci, si = pc[ei, :], ps[ei, :]
        ex = px[ej, :] - px[ei, :] - (ci * dxp - si * dyp)
        ey = py[ej, :] - py[ei, :] - (si * dxp + ci * dyp)
        # Scale by the formation size so IPOPT's tolerances are relative to it.
        ref = float(np.mean(np.linalg.norm(off, axis=-1)))
        ref = ref if ref > 0 else 1.0
        objective = ca.sum1(ca.sum2(ex * ex + ey * ey)) / ref**2
    elif method == "no_formation":
        # Each robot gets as far along its path as early as it can (a smooth stand-in for the
        # minimum completion time of Peng & Akella's path coordination, ref. [12]).
        rest = (col(lengths) - ss) * col(1.0 / lengths)
        objective = ca.sum1(ca.sum2(rest * rest))
    else:  # pragma: no cover - guarded by plan_velocities
        raise ValueError(f"method: unknown {method!r}")

    trap = ss[:, 1:] - ss[:, :-1] - 0.5 * dt * (vv[:, 1:] + vv[:, :-1])
    acc = vv[:, 1:] - vv[:, :-1]
    if smoothing > 0:
        # Optional: trade formation error for gentler speed changes (not in the paper).
        jerk = acc / (problem.a_max_mps2 * dt)
        objective = objective + smoothing * ca.sum1(ca.sum2(jerk * jerk)) / (r * m_steps)
    g = [ca.vec(trap), ca.vec(acc)]
    lbg = [np.zeros(r * m_steps), np.full(r * m_steps, -problem.a_max_mps2 * dt)]
    ubg = [np.zeros(r * m_steps), np.full(r * m_steps, problem.a_max_mps2 * dt)]
    ci_, cj_, cm_ = _candidate_pairs(problem, s_lo, s_hi)
    if ci_.size:
        a = (ci_ + r * cm_).tolist()  # column-major index into vec(px)
        b = (cj_ + r * cm_).tolist()
        vx, vy = ca.vec(px), ca.vec(py)
        dist2 = (vx[a] - vx[b]) ** 2 + (vy[a] - vy[b]) ** 2
        g.append(dist2 / problem.d_safe_m**2 - 1.0)
        lbg.append(np.zeros(ci_.size))
        ubg.append(np.full(ci_.size, np.inf))

    x = ca.vertcat(ca.vec(vv), ca.vec(ss))
    v_lb = np.zeros((r, cols))
    v_ub = np.full((r, cols), problem.v_max_mps)
    v_ub[:, 0] = v_ub[:, -1] = 0.0
    lbx = np.concatenate([v_lb.ravel(order="F"), s_lo.ravel(order="F")])
    ubx = np.concatenate([v_ub.ravel(order="F"), s_hi.ravel(order="F")])
    x0 = np.concatenate([v0.ravel(order="F"), np.clip(s0, s_lo, s_hi).ravel(order="F")])

    opts = dict(_IPOPT_DEFAULTS)
    opts.update(ipopt_options or {})
    solver = ca.nlpsol("formation", "ipopt", {"x": x, "f": objective, "g": ca.vertcat(*g)}, opts)
    sol = solver(x0=x0, lbx=lbx, ubx=ubx, lbg=np.concatenate(lbg), ubg=np.concatenate(ubg))
    stats = solver.stats()
    xs = np.asarray(sol["x"]).ravel()
    v = np.clip(xs[: r * cols].reshape((r, cols), order="F"), 0.0, problem.v_max_mps)
    v[:, 0] = v[:, -1] = 0.0
    # Rebuild the distances from the speeds with (7), then scale both by the (1 +- 1e-8)
    # factor that lands on L_i: (7) then holds exactly, s never decreases and ends at L_i.
    s = np.concatenate([np.zeros((r, 1)), np.cumsum(0.5 * dt * (v[:, 1:] + v[:, :-1]), 1)], 1)
    factor = lengths / np.maximum(s[:, -1], 1e-300)
    v = np.minimum(v * factor[:, None], problem.v_max_mps)
    s = s * factor[:, None]
    s[:, -1] = lengths
    return v, s, bool(stats["success"]), str(stats["return_status"]), int(stats["iter_count"])


# --------------------------------------------------------------------------- public planner
def plan_velocities(
    problem: FormationProblem,
    method: Method = "formation",
    *,
    ipopt_options: dict | None = None,
    smoothing: float = 0.0,
) -> FormationPlan:
    """Plan the robots' velocity profiles along their paths.

    Parameters
    ----------
    problem
        Paths, formation and limits.
    method
        ``"formation"``: minimize ``Q^e`` (10) subject to (7), (11)-(15) (the paper's method).
        ``"no_formation"``: same constraints, each robot reaches its goal as early as it can
        (minimizes ``sum_t sum_i ((L_i - s_i(t)) / L_i)^2``); the formation is ignored.
        ``"leader_follower"``: the leader (``problem.leader``) drives the nominal profile of
        :func:`nominal_profile`; each follower, in tree order, picks its next speed within
        (11)-(12) to reach the point of its path nearest to where its leader's next pose and
        the desired offset put it, braking so that it can stop at its goal. Followers do not
        coordinate, so (15) is not enforced; the plan may run past ``M`` steps until every
        follower has arrived.
    ipopt_options
        Extra CasADi/IPOPT options (e.g. ``{"ipopt.max_iter": 200}``).
    smoothing
        Weight of an optional penalty on the mean squared speed change per step (in units of
        ``a_max dt``) added to the optimizers' objective; 0 (default) is the paper's problem.
        Holding a changing formation genuinely needs large speed changes (the Table 1
        solution swings between 40 and 120 mm/s), so this only matters when the tracking
        layer cannot follow them.

    Returns
    -------
    FormationPlan
        Check ``success``/``status``: an IPOPT failure is reported there, not raised.

    Raises
    ------
    ValueError
        Unknown method; a path too long for ``M dt`` under the bounds; two robots closer than
        ``d_safe_m`` at their start or goal; edges that are not a tree (leader-follower).
    """
    if method not in METHODS:
        raise ValueError(f"method: must be one of {METHODS} (got {method!r})")
    if method == "leader_follower":
        v, s, ok, status, n_used = _leader_follower(problem)
        return _make_plan(problem, method, v, s, ok, status, n_used)
    smoothing = _as_float(smoothing, "smoothing", allow_zero=True)
    v, s, ok, status, iters = _solve_nlp(problem, method, ipopt_options, smoothing)
    return _make_plan(problem, method, v, s, ok, status, iters)
