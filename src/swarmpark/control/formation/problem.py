"""The velocity-planning problem of a formation (Liu, Sun & Zhu 2010, Sect. II) and its
solution: :class:`FormationProblem` (paths, formation, bounds), :class:`FormationPlan` (speed
profiles and the time warp of online modifications) and the rest-to-rest
:func:`nominal_profile` that both optimizers and the leader-follower baseline start from."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from swarmpark.core.paths import SplinePath

__all__ = ["FormationProblem", "FormationPlan", "nominal_profile"]


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


def _checked_paths(paths_in) -> tuple[SplinePath, ...]:
    """``FormationProblem.paths`` as a tuple of at least one :class:`SplinePath`."""
    paths = tuple(paths_in)
    for i, p in enumerate(paths):
        if not isinstance(p, SplinePath):
            raise ValueError(f"paths[{i}]: expected a SplinePath (got {type(p).__name__})")
    if len(paths) < 1:
        raise ValueError("paths: need at least one robot path (got none)")
    return paths


def _checked_edges(edges_in, n: int) -> np.ndarray:
    """``FormationProblem.edges`` as ``(E, 2)`` int pairs of different robots in ``0..n-1``."""
    edges = np.asarray(edges_in)
    if edges.size == 0:
        edges = np.zeros((0, 2), dtype=int)
    if edges.ndim != 2 or edges.shape[1] != 2 or not np.issubdtype(edges.dtype, np.integer):
        raise ValueError(f"edges: expected (E, 2) integer robot indices (got {edges_in!r})")
    for e, (i, j) in enumerate(edges.tolist()):
        if not (0 <= i < n and 0 <= j < n) or i == j:
            raise ValueError(f"edges[{e}]: ({i}, {j}) must be two different robots in 0..{n - 1}")
    return edges.astype(int)


def _checked_offsets(offsets_in, ne: int) -> np.ndarray:
    """``FormationProblem.offsets_m`` as finite ``(E, K, 2)`` (``(E, 2)`` means ``K = 1``)."""
    off = np.asarray(offsets_in, dtype=float)
    if off.ndim == 2:
        off = off[:, None, :]
    if off.ndim != 3 or off.shape[0] != ne or off.shape[2] != 2:
        raise ValueError(
            f"offsets_m: expected shape ({ne}, K, 2) for {ne} edges (got {np.shape(offsets_in)})"
        )
    if not np.all(np.isfinite(off)):
        raise ValueError(f"offsets_m: must be finite (got {off.tolist()})")
    return off


def _checked_offset_at(offset_at, ne: int, k: int) -> np.ndarray:
    """``FormationProblem.offset_at`` as ``(E, K)`` strictly increasing fractions in ``[0, 1]``
    (``None``: ``K`` keypoints evenly spread)."""
    if offset_at is None:
        at = np.linspace(0.0, 1.0, k) if k > 1 else np.zeros(1)
    else:
        at = np.asarray(offset_at, dtype=float)
    at = np.broadcast_to(at, (ne, k)).copy() if at.ndim == 1 else at
    if at.shape != (ne, k):
        raise ValueError(f"offset_at: expected shape ({k},) or ({ne}, {k}) (got {at.shape})")
    if not np.all(np.isfinite(at)) or at.min(initial=0.0) < 0 or at.max(initial=0.0) > 1:
        raise ValueError(f"offset_at: fractions must lie in [0, 1] (got {at.tolist()})")
    if k > 1 and np.any(np.diff(at, axis=1) <= 0):
        raise ValueError(f"offset_at: keypoints must be strictly increasing (got {at.tolist()})")
    return at


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
        paths = _checked_paths(self.paths)
        set_(self, "paths", paths)
        n = len(paths)
        edges = _checked_edges(self.edges, n)
        set_(self, "edges", edges)
        ne = edges.shape[0]
        off = _checked_offsets(self.offsets_m, ne)
        set_(self, "offsets_m", off)
        set_(self, "offset_at", _checked_offset_at(self.offset_at, ne, off.shape[1]))

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
