"""Move a group in formation along given paths by velocity optimization (Liu, Sun & Zhu 2010).

Each robot drives along its own arc-length path (:class:`swarmpark.core.paths.SplinePath`); only
the speeds are planned. The planner (Sect. II of the paper) chooses speeds ``v_i(t)`` at
``M + 1`` instants ``t = m dt`` so that the travel distances (trapezoid rule, eq. 7) put the
robots where the desired formation wants them, measured by the formation error ``Q^e`` of
eqs. (9)-(10) with the desired offsets given in the frame of robot ``i`` of each pair (eq. 6)
and changing along the path; subject to speed and acceleration bounds (11)-(12), rest at
both ends (13)-(14) and a safe distance between all pairs (15).

Two baselines use the same paths: velocity optimization without the formation term (each
robot gets to its goal as early as it can, still respecting (11)-(15)), and a leader-follower
scheme (the leader drives a fixed profile, every follower steers its own speed toward the
point its leader's pose and the desired offset ask for).

Online (Sect. II.D), :func:`adjust_for_obstacle` / :class:`OnlineAdjuster` predict a moving
obstacle from observed positions, and when (16) fails make the whole group stop and wait
(17)-(18) or retrace its plan and wait (19); the group shares one time warp, so everyone is
always where the original plan put them at the same plan time and the formation holds.

For execution, :func:`sample_reference` turns a plan into reference poses and velocities at
any time and :func:`track_unicycle` is a tracking law for non-holonomic skids.

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
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Literal, NamedTuple

import casadi as ca
import numpy as np
from scipy.spatial import cKDTree

from swarmpark.core.geometry import wrap_angle
from swarmpark.core.paths import SplinePath

__all__ = [
    "FormationProblem",
    "FormationPlan",
    "FormationMetrics",
    "Reference",
    "TrackingGains",
    "ObstacleAdjustment",
    "OnlineAdjuster",
    "METHODS",
    "plan_velocities",
    "nominal_profile",
    "blend_offsets",
    "desired_offsets",
    "pair_errors",
    "formation_metrics",
    "formation_error",
    "sample_reference",
    "track_unicycle",
    "predict_obstacle",
    "adjust_for_obstacle",
]

Method = Literal["formation", "no_formation", "leader_follower"]
METHODS: tuple[str, ...] = ("formation", "no_formation", "leader_follower")

#: Spacing (metres) of the arc-length samples behind the CasADi path interpolants; the cubic
#: B-spline through them reproduces the path to ~1e-9 m for curvatures below 10 /m.
_TABLE_SPACING_M = 0.005
_TABLE_MIN_SAMPLES = 32
#: Arrival tolerance (metres) of the leader-follower baseline's braking logic.
_ARRIVAL_TOL_M = 1e-7
#: The leader-follower baseline runs at most this many times the planning horizon.
_LF_HORIZON_FACTOR = 4
_IPOPT_DEFAULTS = {
    "ipopt.print_level": 0,
    "print_time": 0,
    "ipopt.sb": "yes",
    "ipopt.max_iter": 3000,
    "ipopt.tol": 1e-8,
}


# --------------------------------------------------------------------------- problem
def _as_float(value, name: str, *, positive: bool = True, allow_zero: bool = False) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: must be a number (got {value!r})") from exc
    if not math.isfinite(x) or (positive and (x < 0 or (x == 0 and not allow_zero))):
        need = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"{name}: must be finite and {need} (got {value!r})")
    return x


@dataclass(frozen=True, eq=False, kw_only=True)
class FormationProblem:
    """Paths, formation and limits of one velocity-planning problem (Sect. II).

    Parameters
    ----------
    paths
        One :class:`SplinePath` per robot; robot ``i`` starts at ``s = 0`` and must stop at
        ``s = L_i`` within ``M dt``.
    edges
        ``(E, 2)`` robot pairs ``(i, j)`` whose relative position is prescribed (the arrows of
        the paper's Fig. 2). For the leader-follower baseline ``i`` is ``j``'s leader and the
        edges must form a tree rooted at ``leader``.
    offsets_m
        ``(E, K, 2)`` desired position of ``j`` relative to ``i`` in robot ``i``'s frame
        (x forward, y left), ``(dx'_ij, dy'_ij)`` of eq. (6), at ``K`` keypoints along
        robot ``i``'s path. ``(E, 2)`` means one formation all the way.
    offset_at
        ``(E, K)`` or ``(K,)`` keypoint positions as fractions of robot ``i``'s path length
        ``L_i``, strictly increasing in ``[0, 1]``. At a keypoint the offset is exactly
        ``offsets_m[:, k]``; between keypoints it blends with a C1 smoothstep, so repeating a
        formation at two keypoints holds it over that stretch (formations a-d of Table 1).
        Before the first and after the last keypoint the offset is held.
    M, dt_s
        Number of time intervals and their length: the plan spans ``M dt_s`` seconds.
    v_max_mps, a_max_mps2
        Speed bound ``V_max`` (2) and acceleration bound ``a_max`` (3).
    d_safe_m
        Minimum distance between any two robots at every step (15); 0 disables it.
    leader
        Root robot of the leader-follower baseline.
    """

    paths: tuple[SplinePath, ...]
    edges: np.ndarray
    offsets_m: np.ndarray
    offset_at: np.ndarray | None = None
    M: int = 15
    dt_s: float = 1.0
    v_max_mps: float = 0.12
    a_max_mps2: float = 0.12
    d_safe_m: float = 0.09
    leader: int = 0

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        paths = tuple(self.paths)
        for i, p in enumerate(paths):
            if not isinstance(p, SplinePath):
                raise ValueError(f"paths[{i}]: expected a SplinePath (got {type(p).__name__})")
        if len(paths) < 1:
            raise ValueError("paths: need at least one robot path (got none)")
        set_(self, "paths", paths)
        n = len(paths)

        edges = np.asarray(self.edges)
        if edges.size == 0:
            edges = np.zeros((0, 2), dtype=int)
        if edges.ndim != 2 or edges.shape[1] != 2 or not np.issubdtype(edges.dtype, np.integer):
            raise ValueError(f"edges: expected (E, 2) integer robot indices (got {self.edges!r})")
        for e, (i, j) in enumerate(edges.tolist()):
            if not (0 <= i < n and 0 <= j < n) or i == j:
                raise ValueError(
                    f"edges[{e}]: ({i}, {j}) must be two different robots in 0..{n - 1}"
                )
        set_(self, "edges", edges.astype(int))
        ne = edges.shape[0]

        off = np.asarray(self.offsets_m, dtype=float)
        if off.ndim == 2:
            off = off[:, None, :]
        if off.ndim != 3 or off.shape[0] != ne or off.shape[2] != 2:
            raise ValueError(
                f"offsets_m: expected shape ({ne}, K, 2) for {ne} edges "
                f"(got {np.shape(self.offsets_m)})"
            )
        if not np.all(np.isfinite(off)):
            raise ValueError(f"offsets_m: must be finite (got {off.tolist()})")
        k = off.shape[1]
        set_(self, "offsets_m", off)

        if self.offset_at is None:
            at = np.linspace(0.0, 1.0, k) if k > 1 else np.zeros(1)
        else:
            at = np.asarray(self.offset_at, dtype=float)
        at = np.broadcast_to(at, (ne, k)).copy() if at.ndim == 1 else at
        if at.shape != (ne, k):
            raise ValueError(f"offset_at: expected shape ({k},) or ({ne}, {k}) (got {at.shape})")
        if not np.all(np.isfinite(at)) or at.min(initial=0.0) < 0 or at.max(initial=0.0) > 1:
            raise ValueError(f"offset_at: fractions must lie in [0, 1] (got {at.tolist()})")
        if k > 1 and np.any(np.diff(at, axis=1) <= 0):
            raise ValueError(
                f"offset_at: keypoints must be strictly increasing (got {at.tolist()})"
            )
        set_(self, "offset_at", at)

        if int(self.M) != self.M or int(self.M) < 2:
            raise ValueError(f"M: must be an integer >= 2 (got {self.M!r})")
        set_(self, "M", int(self.M))
        set_(self, "dt_s", _as_float(self.dt_s, "dt_s"))
        set_(self, "v_max_mps", _as_float(self.v_max_mps, "v_max_mps"))
        set_(self, "a_max_mps2", _as_float(self.a_max_mps2, "a_max_mps2"))
        set_(self, "d_safe_m", _as_float(self.d_safe_m, "d_safe_m", allow_zero=True))
        if int(self.leader) != self.leader or not 0 <= int(self.leader) < n:
            raise ValueError(f"leader: must be a robot index in 0..{n - 1} (got {self.leader!r})")
        set_(self, "leader", int(self.leader))

    @property
    def n_robots(self) -> int:
        return len(self.paths)

    @property
    def lengths_m(self) -> np.ndarray:
        """Path lengths ``L_i`` ``(R,)``."""
        return np.array([p.length_m for p in self.paths])

    @property
    def times_s(self) -> np.ndarray:
        """The planning instants ``m dt``, ``(M + 1,)``."""
        return np.arange(self.M + 1) * self.dt_s


# --------------------------------------------------------------------------- profiles
def _speed_caps(m_steps: int, dt: float, v_max: float, a_max: float) -> np.ndarray:
    """Upper bound on the speed at each instant of a rest-to-rest profile, ``(M + 1,)``."""
    k = np.arange(m_steps + 1)
    return np.minimum(v_max, a_max * dt * np.minimum(k, m_steps - k))


def _reach_bounds(problem: FormationProblem) -> tuple[np.ndarray, np.ndarray]:
    """Arc-length bounds ``(R, M + 1)`` implied by (11)-(14): how far a robot can be at step m."""
    cap = _speed_caps(problem.M, problem.dt_s, problem.v_max_mps, problem.a_max_mps2)
    step = 0.5 * problem.dt_s * (cap[:-1] + cap[1:])
    fwd = np.concatenate([[0.0], np.cumsum(step)])
    bwd = fwd[-1] - fwd
    length = problem.lengths_m[:, None]
    return np.maximum(0.0, length - bwd[None, :]), np.minimum(length, fwd[None, :])


def nominal_profile(length_m: float, M: int, dt_s: float, v_max_mps: float, a_max_mps2: float):
    """Slowest symmetric trapezoidal profile covering ``length_m`` in exactly ``M`` steps.

    Returns speeds and distances, each ``(M + 1,)``, obeying (7) and (11)-(14). Used as the
    initial guess of the optimizer (every robot scaled to its own length, so they advance in
    step) and as the leader's profile in the leader-follower baseline.

    Raises
    ------
    ValueError
        If ``length_m`` cannot be covered in ``M dt_s`` under the bounds.

    Examples
    --------
    >>> v, s = nominal_profile(1.2, 15, 1.0, 0.12, 0.12)
    >>> round(float(s[-1]), 9), float(v[0]), float(v[-1])
    (1.2, 0.0, 0.0)
    """
    caps = _speed_caps(M, dt_s, v_max_mps, a_max_mps2)

    def covered(cruise: float) -> float:
        v = np.minimum(caps, cruise)
        return float(0.5 * dt_s * np.sum(v[:-1] + v[1:]))

    reach = covered(v_max_mps)
    if length_m > reach * (1 + 1e-12):
        raise ValueError(
            f"path length {length_m:.4f} m cannot be covered in M*dt = {M * dt_s:g} s with "
            f"v_max {v_max_mps:g} m/s and a_max {a_max_mps2:g} m/s^2 (at most {reach:.4f} m)"
        )
    lo, hi = 0.0, v_max_mps
    # covered() is continuous and increasing in the cruise speed: bisection to round-off.
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if covered(mid) < length_m else (lo, mid)
    v = np.minimum(caps, hi)
    s = np.concatenate([[0.0], np.cumsum(0.5 * dt_s * (v[:-1] + v[1:]))])
    # Scaling speeds and distances together keeps (7) exact and lands on length_m exactly.
    factor = length_m / s[-1] if s[-1] > 0 else 0.0
    return np.minimum(v * factor, caps), s * factor


# --------------------------------------------------------------------------- formation error
def _smoothstep(x, lib):
    """C1 step 0 -> 1 on [0, 1], flat outside (``lib`` is numpy or casadi)."""
    if lib is np:
        xc = np.clip(x, 0.0, 1.0)
    else:
        xc = ca.fmin(ca.fmax(x, 0.0), 1.0)
    return xc * xc * (3.0 - 2.0 * xc)


def blend_offsets(at, offsets_m, sigma) -> np.ndarray:
    """Desired offsets ``(E, ..., 2)`` at path fractions ``sigma`` ``(E, ...)``.

    ``at`` ``(E, K)`` and ``offsets_m`` ``(E, K, 2)`` are keypoints as in
    :class:`FormationProblem`: exact at a keypoint, a C1 smoothstep blend between keypoints,
    held outside.

    Examples
    --------
    >>> at, off = np.array([[0.0, 1.0]]), np.array([[[0.0, 0.0], [1.0, 2.0]]])
    >>> blend_offsets(at, off, np.array([[0.0, 0.5, 1.0, 2.0]]))[0].tolist()
    [[0.0, 0.0], [0.5, 1.0], [1.0, 2.0], [1.0, 2.0]]
    """
    at = np.asarray(at, dtype=float)
    off = np.asarray(offsets_m, dtype=float)
    sigma = np.asarray(sigma, dtype=float)
    shape = (slice(None),) + (None,) * (sigma.ndim - 1)
    out = np.broadcast_to(off[:, 0][shape + (slice(None),)], (*sigma.shape, 2)).copy()
    for k in range(off.shape[1] - 1):
        w = _smoothstep((sigma - at[:, k][shape]) / (at[:, k + 1] - at[:, k])[shape], np)
        out += w[..., None] * (off[:, k + 1] - off[:, k])[shape + (slice(None),)]
    return out


def desired_offsets(problem: FormationProblem, s_i) -> np.ndarray:
    """Desired offsets ``(E, ..., 2)`` in robot ``i``'s frame for each edge at ``s_i``.

    ``s_i`` has shape ``(E, ...)``: the travel distance of each edge's first robot.
    """
    s_i = np.asarray(s_i, dtype=float)
    shape = (slice(None),) + (None,) * (s_i.ndim - 1)
    length = problem.lengths_m[problem.edges[:, 0]][shape]
    return blend_offsets(problem.offset_at, problem.offsets_m, s_i / length)


def pair_errors(problem: FormationProblem, poses, s) -> np.ndarray:
    """Formation errors ``q^e_ij`` (eq. 9) ``(..., E, 2)`` in the world frame.

    Parameters
    ----------
    poses
        ``(..., R, 3)`` robot poses (planned, or actual ones from a simulation).
    s
        ``(..., R)`` travel distances that select the desired offsets (eq. 6 uses ``s_i``).
    """
    poses = np.asarray(poses, dtype=float)
    s = np.asarray(s, dtype=float)
    i, j = problem.edges[:, 0], problem.edges[:, 1]
    d = desired_offsets(problem, np.moveaxis(s[..., i], -1, 0))  # (E, ..., 2)
    d = np.moveaxis(d, 0, -2)  # (..., E, 2)
    th = poses[..., i, 2]
    c, sn = np.cos(th), np.sin(th)
    d_world = np.stack([c * d[..., 0] - sn * d[..., 1], sn * d[..., 0] + c * d[..., 1]], -1)
    return poses[..., j, :2] - poses[..., i, :2] - d_world


@dataclass(frozen=True, eq=False)
class FormationMetrics:
    """Formation error of a motion sampled at ``times_s``.

    Attributes
    ----------
    times_s : ndarray (T,)
    pair_error_m : ndarray (E, T)
        ``||q^e_ij(t)||`` per edge.
    q_e_m2 : float
        ``Q^e`` of eq. (10): sum over the sample times of ``sum_ij ||q^e_ij||^2`` (the paper's
        value when the samples are the plan instants ``m dt``).
    integral_m2s : float
        Time integral of ``sum_ij ||q^e_ij||^2`` (trapezoid rule), independent of sampling.
    max_pair_error_m : float
    """

    times_s: np.ndarray
    pair_error_m: np.ndarray
    q_e_m2: float
    integral_m2s: float
    max_pair_error_m: float


def formation_metrics(problem: FormationProblem, times_s, poses, s) -> FormationMetrics:
    """Formation error of poses ``(T, R, 3)`` with travel distances ``(T, R)`` at ``times_s``.

    Use it on a simulated run: pass the skids' actual poses and the reference ``s`` of
    :func:`sample_reference` at the same times.
    """
    times = np.asarray(times_s, dtype=float)
    err = pair_errors(problem, poses, s)  # (T, E, 2)
    sq = np.sum(err**2, axis=(-1, -2))  # (T,)
    norms = np.linalg.norm(err, axis=-1).T  # (E, T)
    integral = float(np.sum(0.5 * (sq[1:] + sq[:-1]) * np.diff(times))) if times.size > 1 else 0.0
    return FormationMetrics(
        times_s=times,
        pair_error_m=norms,
        q_e_m2=float(sq.sum()),
        integral_m2s=integral,
        max_pair_error_m=float(norms.max(initial=0.0)),
    )


# --------------------------------------------------------------------------- plans
@dataclass(frozen=True, eq=False)
class FormationPlan:
    """Velocity profiles along the paths, and the time warp of any online modification.

    The base plan is given at instants ``t_s = m dt``: speeds ``v_mps`` and distances ``s_m``
    ``(R, N + 1)`` (``N = M`` for the optimizers; leader-follower may need longer), with
    speed linear between instants so that (7) is exact. ``warp_t_s``/``warp_tau_s`` are the
    knots of a piecewise-linear map from execution time ``t`` to plan time ``tau`` (slope 1
    after the last knot): the identity for a fresh plan, eqs. (18)-(19) after
    :func:`adjust_for_obstacle`. Poses at execution time ``t`` are the base plan's at
    ``tau(t)``.

    Attributes
    ----------
    problem, method
    t_s, v_mps, s_m, poses
        Base plan instants, speeds, distances and poses ``(R, N + 1, 3)``.
    q_e_m2, max_pair_error_m
        ``Q^e`` (eq. 10) and the largest ``||q^e_ij||`` over the base plan instants.
    min_pair_distance_m
        Smallest distance between two robots over the base plan instants.
    success, status, iterations
        Solver outcome (IPOPT return status and iteration count; for leader-follower,
        whether every robot reached its goal).
    """

    problem: FormationProblem
    method: str
    t_s: np.ndarray
    v_mps: np.ndarray
    s_m: np.ndarray
    poses: np.ndarray
    q_e_m2: float
    max_pair_error_m: float
    min_pair_distance_m: float
    success: bool
    status: str
    iterations: int
    warp_t_s: np.ndarray = field(default_factory=lambda: np.zeros(1))
    warp_tau_s: np.ndarray = field(default_factory=lambda: np.zeros(1))

    @property
    def duration_s(self) -> float:
        """Execution time until the last robot stops for good (warp included)."""
        t_end = float(self.t_s[-1])
        wt, wtau = self.warp_t_s, self.warp_tau_s
        return float(max(wt[-1], wt[-1] + t_end - wtau[-1]))

    @property
    def is_warped(self) -> bool:
        return self.warp_t_s.size > 1


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


# --------------------------------------------------------------------------- leader-follower
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


def formation_error(plan: FormationPlan, times_s=None) -> FormationMetrics:
    """Formation error of a plan (warp included) sampled at ``times_s``.

    By default the samples are ``0, dt, 2 dt, ...`` up to the plan's duration, i.e. the
    paper's ``Q^e`` for an unmodified plan.
    """
    if times_s is None:
        dt = plan.problem.dt_s
        times_s = np.arange(0.0, plan.duration_s + 0.5 * dt, dt)
    times = np.atleast_1d(np.asarray(times_s, dtype=float))
    ref = sample_reference(plan, times)
    return formation_metrics(plan.problem, times, ref.poses, ref.s)


# --------------------------------------------------------------------------- execution
class Reference(NamedTuple):
    """Reference state of every robot at one time (or ``(T, ...)`` for T times)."""

    poses: np.ndarray  #: (R, 3) reference poses (x, y, yaw)
    v: np.ndarray  #: (R,) reference speed along the heading (negative when retracing)
    omega: np.ndarray  #: (R,) reference yaw rate, k(s) v (eq. 4)
    s: np.ndarray  #: (R,) travel distance along each path


def _warp(plan: FormationPlan, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Plan time ``tau(t)`` and its slope ``dtau/dt`` (right derivative at knots)."""
    wt, wtau = plan.warp_t_s, plan.warp_tau_s
    slopes = np.append(np.diff(wtau) / np.diff(wt), 1.0)
    k = np.clip(np.searchsorted(wt, t, side="right") - 1, 0, wt.size - 1)
    slope = np.where(t < wt[0], 1.0, slopes[k])
    return wtau[k] + slope * (t - wt[k]), slope


def _base_state(plan: FormationPlan, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distances and speeds ``(..., R)`` of the base plan at plan times ``tau``."""
    dt = plan.problem.dt_s
    n_steps = plan.t_s.size - 1
    m = np.clip(np.floor(tau / dt).astype(int), 0, n_steps - 1)
    rr = np.clip(tau - m * dt, 0.0, dt)[..., None]
    s0, s1 = plan.s_m.T[m], plan.s_m.T[m + 1]
    v0, v1 = plan.v_mps.T[m], plan.v_mps.T[m + 1]
    dv = v1 - v0
    s = s0 + v0 * rr + dv * rr**2 / (2.0 * dt)
    # Pin the knots exactly (the quadratic reproduces them up to round-off).
    s = np.where(rr >= dt, s1, s)
    v = v0 + dv * rr / dt
    return s, v


def sample_reference(plan: FormationPlan, t) -> Reference:
    """Reference poses, speeds and yaw rates of every robot at time(s) ``t`` (seconds).

    Pure and vectorized over times: scalar ``t`` gives ``(R, 3)``/``(R,)`` arrays, an array
    of ``T`` times gives ``(T, R, 3)``/``(T, R)``. Before 0 and after the plan ends the
    robots hold their start and goal poses with zero velocity. Speeds are negative while an
    online modification retraces the plan (eq. 19); the heading stays the path's.
    """
    t_arr = np.asarray(t, dtype=float)
    if not np.all(np.isfinite(t_arr)):
        raise ValueError(f"t: times must be finite (got {t!r})")
    flat = np.atleast_1d(t_arr).ravel()
    tau, slope = _warp(plan, flat)
    s, v = _base_state(plan, tau)
    v = v * slope[:, None]
    poses = np.empty((flat.size, plan.problem.n_robots, 3))
    kappa = np.empty((flat.size, plan.problem.n_robots))
    for i, p in enumerate(plan.problem.paths):
        poses[:, i], kappa[:, i] = p.frame(s[:, i])
    omega = kappa * v
    shape = t_arr.shape
    return Reference(
        poses.reshape(*shape, -1, 3),
        v.reshape(*shape, -1),
        omega.reshape(*shape, -1),
        s.reshape(*shape, -1),
    )


@dataclass(frozen=True)
class TrackingGains:
    """Gains of :func:`track_unicycle`.

    ``k_x`` (1/s) closes along-track error, ``k_y`` (1/m^2) cross-track error and ``k_theta``
    (1/m) heading error; ``k_theta = 2 sqrt(k_y)`` damps the cross-track response critically.
    """

    k_x: float = 1.0
    k_y: float = 4.0
    k_theta: float = 4.0

    def __post_init__(self) -> None:
        for name in ("k_x", "k_y", "k_theta"):
            _as_float(getattr(self, name), f"gains.{name}")


def track_unicycle(poses, ref_poses, ref_v, ref_omega, gains: TrackingGains | None = None):
    """Kanayama tracking law for unicycles, vectorized over robots; returns ``(v, omega)``.

    With the error in the robot frame ``(e_x, e_y, e_theta)``::

        v     = v_r cos(e_theta) + k_x e_x
        omega = omega_r + v_r k_y e_y + k_theta |v_r| sin(e_theta)

    Kanayama et al. (1990) use ``v_r k_theta``; ``|v_r|`` keeps the Lyapunov function
    ``(e_x^2 + e_y^2) / 2 + (1 - cos e_theta) / k_y`` decreasing when the reference drives
    backwards (a retraced plan). Saturating ``v``/``omega`` is the caller's job.

    Parameters
    ----------
    poses, ref_poses
        ``(R, 3)`` actual and reference poses.
    ref_v, ref_omega
        ``(R,)`` reference speeds and yaw rates.
    """
    g = gains or TrackingGains()
    poses = np.asarray(poses, dtype=float)
    ref = np.asarray(ref_poses, dtype=float)
    vr = np.asarray(ref_v, dtype=float)
    wr = np.asarray(ref_omega, dtype=float)
    dx, dy = ref[..., 0] - poses[..., 0], ref[..., 1] - poses[..., 1]
    c, s = np.cos(poses[..., 2]), np.sin(poses[..., 2])
    ex, ey = c * dx + s * dy, -s * dx + c * dy
    eth = wrap_angle(ref[..., 2] - poses[..., 2])
    v = vr * np.cos(eth) + g.k_x * ex
    omega = wr + vr * g.k_y * ey + g.k_theta * np.abs(vr) * np.sin(eth)
    return v, omega


# --------------------------------------------------------------------------- online modification
def predict_obstacle(obs_t_s, obs_xy, t_s, *, degree: int = 1) -> np.ndarray:
    """Predict obstacle positions ``(..., 2)`` at times ``t_s`` from observations.

    A least-squares polynomial in time per axis (degree 1: constant velocity; lower when
    there are too few observations; one observation means a standing obstacle).
    """
    ot = np.asarray(obs_t_s, dtype=float).ravel()
    oxy = np.asarray(obs_xy, dtype=float).reshape(-1, 2)
    if ot.size == 0 or ot.size != oxy.shape[0]:
        raise ValueError(
            f"obs_t_s/obs_xy: need matching, non-empty observations (got {ot.size} times, "
            f"{oxy.shape[0]} positions)"
        )
    if not (np.all(np.isfinite(ot)) and np.all(np.isfinite(oxy))):
        raise ValueError("obs_t_s/obs_xy: observations must be finite")
    deg = min(int(degree), np.unique(ot).size - 1)
    t = np.asarray(t_s, dtype=float)
    if deg <= 0:
        return np.broadcast_to(oxy.mean(axis=0), (*t.shape, 2)).copy()
    t_ref = ot.max()  # centre the fit for conditioning
    coef = np.polynomial.polynomial.polyfit(ot - t_ref, oxy, deg)  # (deg + 1, 2)
    return np.polynomial.polynomial.polyval(t - t_ref, coef).transpose(*range(1, t.ndim + 1), 0)


@dataclass(frozen=True, eq=False)
class ObstacleAdjustment:
    """Outcome of :func:`adjust_for_obstacle`.

    Attributes
    ----------
    plan
        The plan to execute from now on (the input plan when ``decision == "continue"``).
    decision
        ``"continue"`` ((16) holds), ``"wait"`` ((17) holds: eq. 18), ``"reverse"`` (eq. 19) or
        ``"unresolved"`` (no wait or retreat within ``max_delay_steps`` clears the predicted
        obstacle; the returned plan stops and waits that long, and the caller should escalate).
    t_obs_s, wait_s, reverse_s
        Decision time ``t_obs``, waiting time (``dt_d`` or ``dt'_d``) and retreat time ``dt_r``.
    min_distance_m
        Smallest predicted robot-obstacle distance over the checked window with the returned
        plan.
    """

    plan: FormationPlan
    decision: str
    t_obs_s: float
    wait_s: float
    reverse_s: float
    min_distance_m: float


def _knots_wait(wt, wtau, t_obs: float, tau_obs: float, delay: float):
    before = wt < t_obs
    after = wt > t_obs
    t_new = np.concatenate([wt[before], [t_obs, t_obs + delay], wt[after] + delay])
    tau_new = np.concatenate([wtau[before], [tau_obs, tau_obs], wtau[after]])
    return _dedupe(t_new, tau_new)


def _knots_reverse(plan, t_obs: float, back: float, delay: float):
    wt, wtau = plan.warp_t_s, plan.warp_tau_s
    tau_obs = float(_warp(plan, np.array([t_obs]))[0][0])
    tau_back = float(_warp(plan, np.array([t_obs - back]))[0][0])
    mid = (wt > t_obs - back) & (wt < t_obs)
    after = wt > t_obs - back
    shift = 2.0 * back + delay
    t_new = np.concatenate(
        [
            wt[wt < t_obs],
            [t_obs],
            (2.0 * t_obs - wt[mid])[::-1],
            [t_obs + back, t_obs + back + delay],
            wt[after] + shift,
        ]
    )
    tau_new = np.concatenate(
        [wtau[wt < t_obs], [tau_obs], wtau[mid][::-1], [tau_back, tau_back], wtau[after]]
    )
    return _dedupe(t_new, tau_new)


def _dedupe(t, tau):
    keep = np.concatenate([[True], np.diff(t) > 1e-12])
    return t[keep], tau[keep]


def adjust_for_obstacle(
    plan: FormationPlan,
    obs_t_s,
    obs_xy,
    t_obs_s: float,
    *,
    d_obs_m: float | None = None,
    horizon_steps: int = 5,
    max_delay_steps: int | None = None,
    substeps: int = 10,
    degree: int = 1,
) -> ObstacleAdjustment:
    """Online modification of a plan for a moving obstacle (Sect. II.D, eqs. 16-19).

    The obstacle's trajectory is predicted from the observations made up to ``t_obs_s``
    (:func:`predict_obstacle`). If every robot keeps ``d_obs_m`` from it over the next
    ``H = horizon_steps`` steps (16), the plan is kept. Otherwise, if stopping where they are
    keeps that distance (17), the group stops and waits ``dt_d`` (18); if not, it retraces its
    plan for ``dt_r``, waits ``dt'_d`` and resumes (19). The shortest delay (``dt_d``, or
    ``2 dt_r + dt'_d``, in steps of ``dt``) is chosen for which the modified plan keeps
    ``d_obs_m`` from the predicted obstacle from ``t_obs`` until ``H`` steps after the group
    resumes. Distances are checked at ``substeps`` points per step, not only at ``m dt``.

    Parameters
    ----------
    plan
        The plan being executed (possibly already modified).
    obs_t_s, obs_xy
        Observation times ``(K,)`` and obstacle positions ``(K, 2)``; those after ``t_obs_s``
        are ignored.
    t_obs_s
        Decision time.
    d_obs_m
        Safe robot-obstacle distance ``D_obs``; defaults to the problem's ``d_safe_m``.
    horizon_steps
        ``H`` of (16)-(17).
    max_delay_steps
        Longest delay considered; defaults to ``M``.
    """
    problem = plan.problem
    dt = problem.dt_s
    t_obs = _as_float(t_obs_s, "t_obs_s", allow_zero=True)
    d_obs = problem.d_safe_m if d_obs_m is None else _as_float(d_obs_m, "d_obs_m")
    if int(horizon_steps) != horizon_steps or horizon_steps < 1:
        raise ValueError(f"horizon_steps: must be an integer >= 1 (got {horizon_steps!r})")
    if int(substeps) != substeps or substeps < 1:
        raise ValueError(f"substeps: must be an integer >= 1 (got {substeps!r})")
    max_delay = problem.M if max_delay_steps is None else int(max_delay_steps)
    if max_delay < 1:
        raise ValueError(f"max_delay_steps: must be >= 1 (got {max_delay_steps!r})")
    ot = np.asarray(obs_t_s, dtype=float).ravel()
    oxy = np.asarray(obs_xy, dtype=float).reshape(-1, 2)
    if ot.size != oxy.shape[0]:
        raise ValueError(f"obs_t_s/obs_xy: {ot.size} times but {oxy.shape[0]} positions")
    past = ot <= t_obs + 1e-9
    if not past.any():
        raise ValueError(
            f"obs_t_s: no observation at or before t_obs_s={t_obs} (got {ot.tolist()})"
        )
    ot, oxy = ot[past], oxy[past]

    def window(t_end: float) -> np.ndarray:
        n = max(1, math.ceil(round((t_end - t_obs) / dt, 9) * substeps))
        return t_obs + np.linspace(0.0, t_end - t_obs, n + 1)

    def clearance(candidate: FormationPlan, t_end: float) -> float:
        tt = window(t_end)
        xy = sample_reference(candidate, tt).poses[..., :2]  # (T, R, 2)
        obs = predict_obstacle(ot, oxy, tt, degree=degree)  # (T, 2)
        return float(np.linalg.norm(xy - obs[:, None, :], axis=-1).min())

    h_end = t_obs + horizon_steps * dt
    d16 = clearance(plan, h_end)
    if d16 >= d_obs:
        return ObstacleAdjustment(plan, "continue", t_obs, 0.0, 0.0, d16)

    tau_obs = float(_warp(plan, np.array([t_obs]))[0][0])
    wt, wtau = plan.warp_t_s, plan.warp_tau_s

    def waited(k: int) -> FormationPlan:
        t_new, tau_new = _knots_wait(wt, wtau, t_obs, tau_obs, k * dt)
        return replace(plan, warp_t_s=t_new, warp_tau_s=tau_new)

    # (17): the group standing still at its poses of t_obs over the next H steps.
    standing = waited(horizon_steps)
    d17 = clearance(standing, h_end)
    if d17 >= d_obs:
        for k in range(1, max_delay + 1):
            cand = waited(k)
            d = clearance(cand, t_obs + (k + horizon_steps) * dt)
            if d >= d_obs:
                return ObstacleAdjustment(cand, "wait", t_obs, k * dt, 0.0, d)

    # (19): retrace the plan for k_r steps, wait k_d steps, resume; shortest total delay.
    max_back = min(max_delay, math.floor(t_obs / dt + 1e-9))
    options = sorted(
        (
            (2 * kr + kd, kr, kd)
            for kr in range(1, max_back + 1)
            for kd in range(0, max_delay + 1)
            if 2 * kr + kd <= 2 * max_delay
        ),
    )
    for _, kr, kd in options:
        t_new, tau_new = _knots_reverse(plan, t_obs, kr * dt, kd * dt)
        cand = replace(plan, warp_t_s=t_new, warp_tau_s=tau_new)
        d = clearance(cand, t_obs + (kr + kd + horizon_steps) * dt)
        if d >= d_obs:
            return ObstacleAdjustment(cand, "reverse", t_obs, kd * dt, kr * dt, d)

    cand = waited(max_delay)
    d = clearance(cand, t_obs + (max_delay + horizon_steps) * dt)
    return ObstacleAdjustment(cand, "unresolved", t_obs, max_delay * dt, 0.0, d)


class OnlineAdjuster:
    """Stateful wrapper around :func:`adjust_for_obstacle` for a control loop.

    Feed obstacle observations with :meth:`observe`; call :meth:`update` at decision times
    (e.g. every ``dt``). Once the obstacle has been watched for ``min_watch_s`` (the paper's
    robots see it at 5 s and act at 8 s), each update checks (16) on the current plan and
    modifies it when needed; :attr:`plan` is always the plan to track and
    :attr:`adjustments` the modifications made. Deterministic: no clocks, no threads.

    Parameters
    ----------
    plan
        The offline plan.
    min_watch_s
        Observation time needed before predicting the obstacle.
    **kwargs
        Passed to :func:`adjust_for_obstacle` (``d_obs_m``, ``horizon_steps``, ...).
    """

    def __init__(self, plan: FormationPlan, *, min_watch_s: float = 0.0, **kwargs) -> None:
        allowed = {"d_obs_m", "horizon_steps", "max_delay_steps", "substeps", "degree"}
        unknown = set(kwargs) - allowed
        if unknown:
            raise TypeError(f"OnlineAdjuster: unknown keyword(s) {sorted(unknown)}")
        self.plan = plan
        self.min_watch_s = _as_float(min_watch_s, "min_watch_s", allow_zero=True)
        self._kwargs = kwargs
        self._obs_t: list[float] = []
        self._obs_xy: list[tuple[float, float]] = []
        self.adjustments: list[ObstacleAdjustment] = []

    def observe(self, t_s: float, xy: Sequence[float]) -> None:
        """Record the obstacle at ``xy`` (metres) at time ``t_s``."""
        xy_arr = np.asarray(xy, dtype=float).reshape(2)
        if not np.all(np.isfinite(xy_arr)) or not math.isfinite(float(t_s)):
            raise ValueError(f"observe: non-finite observation t={t_s!r}, xy={xy!r}")
        self._obs_t.append(float(t_s))
        self._obs_xy.append((float(xy_arr[0]), float(xy_arr[1])))

    def update(self, t_s: float) -> ObstacleAdjustment | None:
        """Decide at time ``t_s``; returns the modification made, or ``None``.

        Every call re-checks (16) on the current (possibly already modified) plan with all
        observations so far, so a changed prediction leads to a further modification.
        """
        if not self._obs_t or t_s - self._obs_t[0] < self.min_watch_s - 1e-9:
            return None
        adj = adjust_for_obstacle(self.plan, self._obs_t, self._obs_xy, t_s, **self._kwargs)
        if adj.decision == "continue":
            return None
        self.plan = adj.plan
        self.adjustments.append(adj)
        return adj
