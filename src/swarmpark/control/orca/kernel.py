"""Optimal reciprocal collision avoidance (ORCA) with priorities for rectangular skids.

One decision for all robots from one snapshot: every robot gets the velocity closest to its
preferred velocity that lies in all its ORCA half-planes (van den Berg et al., "Reciprocal
n-body collision avoidance", ISRR 2011), with these changes for swarmpark (hing2018 Sect. 3.4.1):

* **Real shapes.** The velocity obstacle of a pair is the truncated cone of the Minkowski
  sum ``B ⊕ -A`` of the two convex footprints (rectangles turned by each skid's yaw), not of
  one circumscribed circle, so skids parked side by side 0.2 m apart are not "in collision".
* **Priorities.** Robot ``i`` takes the share ``w_ij = p_j / (p_i + p_j)`` of the avoidance
  against robot ``j`` (clipped to ``[min_share, 1 - min_share]``), so the higher priority takes
  the smaller share and ``w_ij + w_ji = 1`` keeps the reciprocal guarantee. When the pair is
  not on a collision course, ORCA's ``u`` is room to approach rather than avoidance to do,
  and the shares swap (``1 - w_ij``): the higher priority gets most of the room. Policy:
  priority ``0`` is allowed and means "yield fully" (a parked skid against a passing one);
  two priority-0 robots split evenly. A robot flagged ``immobile`` (e-stopped, broken) is
  given velocity zero and every other robot takes the full share against it.
* **Head-on with flat faces.** The nearest boundary point of a polygonal velocity obstacle
  is often on its flat cut-off face, which only brakes: two rectangles meeting head-on would
  push each other back instead of passing. Any boundary point keeps ORCA's guarantee, so a
  leg of the cone is used when it is nearly as close (``OrcaParams.leg_preference``); exact
  ties keep right.
* **Non-reciprocal obstacles.** People are moving discs (approximated by circumscribed
  regular polygons, a conservative cover); the robot takes the full share, on the tangent of
  their velocity obstacle nearest its preferred velocity (a person does not react, so any
  tangent is safe, and this one steps aside instead of backing off in front of them). Walls
  and static obstacles are convex polygons or segments with their own time horizon; their
  constraints are hard (never relaxed by the 3-D fallback), as the obstacle lines of RVO2.
* **A one-step safety filter.** Where the half-planes are infeasible (a squeeze), the 3-D
  fallback violates some of them and ORCA guarantees nothing. After the decision every pair
  of robots, and robot and static obstacle, that could touch within the step is checked
  exactly for overlap along the straight moves; robots in such a pair are slowed (halved,
  finally stopped) until none is left (``OrcaParams.safety_filter``).
* **Non-holonomic skids: the effective-centre method** (Snape et al., "Smooth and
  collision-free navigation for multiple robots under differential-drive constraints",
  IROS 2010; a feedback linearization). The point ``E`` at distance ``D`` ahead of the pivot
  on the body x axis moves holonomically: a wanted velocity ``u`` of ``E`` is tracked exactly
  by ``v = u·h``, ``omega = u·n / D`` (``h`` heading, ``n`` its left normal) as long as
  ``|u| <= min(v_max, D * omega_max)`` (:func:`holonomic_speed_limit`). ORCA therefore runs
  on the effective centres with that speed limit. Holding ``(v, omega)`` for one step
  ``dt`` moves every point of the footprint at most
  ``e = u_max * omega_max * dt**2 / 2 + 2 * rho * sin(omega_max * dt / 2)`` away from the
  footprint translated by ``u * dt`` (``rho`` = farthest footprint point from ``E``): the
  first term is the arc of ``E``, the second the turn of the body about ``E``
  (:func:`tracking_error_bound`). The footprints passed to ORCA are enlarged by ``e``
  (:func:`skid_shapes`), so the per-step ORCA guarantee holds for the real skids. The bound
  grows with ``rho * omega_max * dt``: put ``E`` at the middle of the footprint and run the
  decision at 10-20 Hz (at 20 Hz a 1.25 m x 0.75 m skid turning at 1.5 rad/s needs 5.6 cm).

The hot loops are compiled (``numba``, cached on disk): the neighbour search over a bucket
grid (:mod:`.neighbours`: the ``max_neighbours`` nearest within a cut-off, and the pairs the
safety filter checks), the pair geometry and the robots' lines (:mod:`.pairs`), the small
linear programs, RVO2's ``linearProgram1/2/3`` one robot at a time (:mod:`.lp`), and the
safety filter (:mod:`.safety`). Each unordered pair is built once, from the side of the
robot with the smaller ``(x, y)``, and neighbour ties are broken by geometry, so the
result is bit-for-bit the same whatever the order of the robots. People and static
obstacles (a few per robot) stay in numpy and shapely.

Typical call, once per tick (see :func:`orca_step` for all arguments)::

    centres, shapes = skid_shapes(poses, corners_body, offset_m=D, margin_m=e)
    u_now = unicycle_to_holonomic(poses, v_now, omega_now, offset_m=D)
    u_pref = ...  # preferred velocity of E from the path follower
    res = orca_step(centres, u_now, u_pref, holonomic_speed_limit(v_max, w_max, D),
                    priorities, shapes, dt_s=dt, obstacles=walls)
    v_cmd, omega_cmd = holonomic_to_unicycle(poses, res.velocities, offset_m=D,
                                             v_max=v_max, omega_max=w_max)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely
from scipy.spatial import cKDTree

from swarmpark.control.orca import lp, neighbours, pairs, safety
from swarmpark.control.orca.shapes import (
    DEFAULT_DISC_SIDES,
    StaticObstacles,
    _as_array,
    _check_convex_ccw,
    _det,
    disc_polygons,
    effective_reach,
    holonomic_speed_limit,
    holonomic_to_unicycle,
    inflate_convex,
    minkowski_difference,
    prepare_obstacles,
    skid_shapes,
    tracking_error_bound,
    unicycle_to_holonomic,
)
from swarmpark.core.geometry import TOUCH_TOLERANCE_M

__all__ = [
    "OrcaParams",
    "HalfPlanes",
    "OrcaResult",
    "StaticObstacles",
    "prepare_obstacles",
    "orca_step",
    "pair_halfplanes",
    "sweep_hits",
    "minkowski_difference",
    "responsibility_shares",
    "solve_velocity_lp",
    "disc_polygons",
    "inflate_convex",
    "skid_shapes",
    "holonomic_speed_limit",
    "effective_reach",
    "tracking_error_bound",
    "holonomic_to_unicycle",
    "unicycle_to_holonomic",
]

#: Half-width (m/s) of the band a robot held on its axis may leave it by (round-off room).
AXIS_SLACK = 1e-6


@dataclass(frozen=True, kw_only=True)
class OrcaParams:
    """Tuning of :func:`orca_step` (keyword-only, validated).

    Parameters
    ----------
    time_horizon_s
        Horizon of the velocity obstacles against robots and people: velocities that stay
        collision-free for this long are safe.
    time_horizon_obst_s
        Horizon against static obstacles (shorter, so robots may approach walls closely).
    max_neighbours
        At most this many nearest robots give constraints to a robot.
    max_people, max_obstacles
        At most this many nearest people / static obstacles give constraints to a robot.
    neighbour_dist_m
        Cut-off of the neighbour search; ``None`` uses the farthest distance at which a
        collision within the horizon is possible (horizon times the two fastest speeds plus
        the two largest shape radii).
    min_share
        Floor on a robot's share of the avoidance against another robot, in ``[0, 0.5]``.
        ``0`` makes priority 0 yield fully; a positive floor keeps a little avoidance on the
        higher-priority robot in case the yielding one is boxed in.
    disc_sides
        Sides of the circumscribed polygon used for people's discs.
    slowest_fallback
        Where the half-planes are infeasible, take the slowest of the velocities that violate
        them least (``False``, the default: RVO2's choice, an extreme point of that set). It
        brakes harder in a squeeze but deadlocks crowds more often (circle benchmark).
    leg_preference
        Robots with flat faces meeting head-on: ORCA's nearest boundary point of the
        velocity obstacle is on the flat cut-off face, which only brakes (discs pass each
        other thanks to curvature). A leg of the cone at most ``leg_preference`` times the
        relative speed farther than that face is used instead, so they start passing; ties
        keep right. Any boundary point keeps ORCA's guarantee; ``0`` is plain ORCA.
    keep_right
        Between two robots, the right leg of the cone is taken unless the left one is
        nearer by more than ``keep_right`` times the relative speed: both keep right, and a
        nearly symmetric head-on encounter does not flip sides from one step to the next.
    safety_filter
        After the decision, check every pair of robots (and robot and static obstacle) for
        overlap while moving straight with the chosen velocities for one step; robots in such
        a pair are slowed (halved, finally stopped) until no pair overlaps. ORCA guarantees
        this only where its programs are feasible; in a squeeze the 3-D fallback violates
        constraints, and this check keeps the step collision-free anyway.
    """

    time_horizon_s: float = 2.0
    time_horizon_obst_s: float = 1.0
    max_neighbours: int = 10
    max_people: int = 4
    max_obstacles: int = 8
    neighbour_dist_m: float | None = None
    min_share: float = 0.0
    disc_sides: int = DEFAULT_DISC_SIDES
    slowest_fallback: bool = False
    safety_filter: bool = True
    leg_preference: float = 0.5
    keep_right: float = 0.3

    def __post_init__(self) -> None:
        for name in ("time_horizon_s", "time_horizon_obst_s"):
            val = getattr(self, name)
            if not (np.isfinite(val) and val > 0):
                raise ValueError(f"OrcaParams.{name} must be a finite number > 0 (got {val!r})")
        for name in ("max_neighbours", "max_people", "max_obstacles"):
            val = getattr(self, name)
            if not (isinstance(val, int | np.integer) and val >= 0):
                raise ValueError(f"OrcaParams.{name} must be an integer >= 0 (got {val!r})")
        if self.neighbour_dist_m is not None and not (
            np.isfinite(self.neighbour_dist_m) and self.neighbour_dist_m > 0
        ):
            raise ValueError(
                f"OrcaParams.neighbour_dist_m must be None or > 0 (got {self.neighbour_dist_m!r})"
            )
        if not (np.isfinite(self.keep_right) and self.keep_right >= 0):
            raise ValueError(f"OrcaParams.keep_right must be >= 0 (got {self.keep_right!r})")
        if not (np.isfinite(self.leg_preference) and self.leg_preference >= 0):
            raise ValueError(
                f"OrcaParams.leg_preference must be >= 0 (got {self.leg_preference!r})"
            )
        if not (0.0 <= self.min_share <= 0.5):
            raise ValueError(f"OrcaParams.min_share must lie in [0, 0.5] (got {self.min_share!r})")
        if not (isinstance(self.disc_sides, int | np.integer) and self.disc_sides >= 3):
            raise ValueError(
                f"OrcaParams.disc_sides must be an integer >= 3 (got {self.disc_sides!r})"
            )


@dataclass(frozen=True)
class HalfPlanes:
    """Per-robot ORCA constraints in RVO2's form: a velocity ``v`` is allowed by slot ``k`` of
    robot ``i`` iff ``det(direction[i, k], v - point[i, k]) >= 0`` (left of the line).

    Slots ``[0, n_hard)`` are static obstacles (hard), the rest people and robots (soft).
    ``valid`` marks the slots that hold a constraint.
    """

    point: np.ndarray  # (N, M, 2)
    direction: np.ndarray  # (N, M, 2) unit
    valid: np.ndarray  # (N, M) bool
    n_hard: int

    def violation(self, velocities: np.ndarray) -> np.ndarray:
        """Signed violation ``(N, M)`` of each constraint by ``velocities`` (``<= 0``: kept;
        invalid slots give ``-inf``)."""
        v = np.asarray(velocities, dtype=float)[:, None, :]
        d = _det(self.direction, self.point - v)
        return np.where(self.valid, d, -np.inf)


@dataclass(frozen=True)
class OrcaResult:
    """Output of :func:`orca_step`.

    Attributes
    ----------
    velocities
        ``(N, 2)`` chosen holonomic velocities of the robots' centres.
    infeasible
        ``(N,)`` True where the half-planes had no common point within the speed limit and
        the 3-D fallback chose the velocity that violates the soft ones least.
    halfplanes
        The constraints that were solved (for tests, logging and drawing).
    slowed
        ``(N,)`` True where the one-step safety filter reduced the ORCA velocity.
    """

    velocities: np.ndarray
    infeasible: np.ndarray
    halfplanes: HalfPlanes
    slowed: np.ndarray


def pair_halfplanes(
    region: np.ndarray,
    rel_velocity: np.ndarray,
    own_velocity: np.ndarray,
    share: np.ndarray,
    inv_horizon: np.ndarray,
    inv_dt: float,
    leg_preference: float = 0.0,
    slack_share: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """ORCA half-planes for pairs, from the collision region in relative-position space.

    A pair collides at time ``t`` iff ``rel_velocity * t`` lies in ``region``
    (``p_other - p_self + B ⊕ -A``). The velocity obstacle for horizon ``tau`` is the
    truncated cone ``region / tau ⊕ cone(region)``; when the shapes overlap already it is
    ``region / dt`` (leave the overlap within one step), as in RVO2. ``u`` is the shortest
    vector from the relative velocity to the obstacle's boundary and ``n`` the outward normal
    there; the robot's half-plane is ``{v : (v - (own_velocity + share * u)) · n >= 0}``.

    Parameters
    ----------
    region
        ``(P, V, 2)`` counter-clockwise convex polygons (repeated vertices allowed).
    rel_velocity, own_velocity
        ``(P, 2)``: velocity of the robot minus that of the other; the robot's velocity.
    share
        ``(P,)`` the robot's share of the avoidance (1: full, non-reciprocal).
    inv_horizon
        ``(P,)`` ``1 / tau``.
    inv_dt
        ``1 / dt``, used when the shapes overlap now.
    leg_preference
        Inside the obstacle, take a leg of the cone instead of the nearer cut-off face when
        it is at most ``leg_preference * |rel_velocity|`` farther (see ``OrcaParams``).
    slack_share
        ``(P,)`` share used instead of ``share`` when the relative velocity is outside the
        obstacle: ``u`` then is room to approach, not avoidance to do. ``None``: ``share``.

    Returns
    -------
    point, direction
        ``(P, 2)`` each, in RVO2's line form (allowed side on the left of ``direction``).
    """
    q = np.asarray(region, dtype=float)
    w = np.asarray(rel_velocity, dtype=float)
    ux, uy, nx, ny, inside = pairs.vo_projection(
        np.ascontiguousarray(q[..., 0].T),
        np.ascontiguousarray(q[..., 1].T),
        np.ascontiguousarray(w[:, 0]),
        np.ascontiguousarray(w[:, 1]),
        np.ascontiguousarray(np.broadcast_to(np.asarray(inv_horizon, dtype=float), w.shape[:1])),
        float(inv_dt),
        float(leg_preference),
        0.0,
    )
    share = np.broadcast_to(np.asarray(share, dtype=float), inside.shape)
    if slack_share is not None:
        share = np.where(inside, share, slack_share)
    return _lines(own_velocity, share, ux, uy, nx, ny)


def _lines(own_velocity, share, ux, uy, nx, ny):
    """RVO2 line form of ``{v : (v - (own + share * u)) · n >= 0}``."""
    own = np.asarray(own_velocity, dtype=float)
    sh = np.asarray(share, dtype=float)
    point = np.stack([own[:, 0] + sh * ux, own[:, 1] + sh * uy], -1)
    direction = np.stack([ny, -nx], -1)
    return point, direction


def responsibility_shares(
    p_self: np.ndarray, p_other: np.ndarray, min_share: float = 0.0
) -> np.ndarray:
    """Share of the avoidance robot ``self`` takes against ``other``: ``p_o / (p_s + p_o)``.

    The higher priority takes the smaller share; the two shares of a pair sum to one;
    two priority-0 robots share evenly. The result is clipped to ``[min_share, 1 - min_share]``.

    Examples
    --------
    >>> responsibility_shares(np.array([3.0, 0.0, 0.0]), np.array([1.0, 2.0, 0.0])).tolist()
    [0.25, 1.0, 0.5]
    """
    ps, po = np.asarray(p_self, dtype=float), np.asarray(p_other, dtype=float)
    tot = ps + po
    w = np.where(tot > 0, po / np.where(tot > 0, tot, 1.0), 0.5)
    return np.clip(w, min_share, 1.0 - min_share)


# --------------------------------------------------------------------------------------------
# linear programs (RVO2's linearProgram1/2/3), compiled in :mod:`.lp`


def _split_lines(point, direction):
    """Contiguous ``x``/``y`` planes of ``(N, M, 2)`` line arrays, for the compiled programs."""
    return (
        np.ascontiguousarray(point[..., 0]),
        np.ascontiguousarray(point[..., 1]),
        np.ascontiguousarray(direction[..., 0]),
        np.ascontiguousarray(direction[..., 1]),
    )


def _lp2(point, direction, valid, radius, opt):
    """Velocities closest to ``opt`` in all lines and the speed circles, and the first
    line each robot could not meet (``M`` where all were met)."""
    result = np.empty((valid.shape[0], 2))
    opt = np.asarray(opt, dtype=float)
    fail = lp.solve_lp2(
        *_split_lines(point, direction),
        np.ascontiguousarray(valid),
        np.ascontiguousarray(radius, dtype=float),
        np.ascontiguousarray(opt[:, 0]),
        np.ascontiguousarray(opt[:, 1]),
        result,
    )
    return result, fail


def solve_velocity_lp(
    halfplanes: HalfPlanes,
    pref_velocities: np.ndarray,
    max_speeds: np.ndarray,
    *,
    slowest_fallback: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """The velocity closest to the preferred one in all half-planes and the speed circle.

    Where that set is empty, the velocity that violates the soft half-planes least (largest
    violation minimised) while keeping the hard ones. Vectorized across robots.

    Returns
    -------
    velocities ``(N, 2)`` and ``infeasible`` ``(N,)`` bool.

    Examples
    --------
    Two half-planes ``x >= 1`` and ``x <= -1`` cannot both hold; the least violation is at
    ``x = 0``:

    >>> hp = HalfPlanes(point=np.array([[[1.0, 0.0], [-1.0, 0.0]]]),
    ...                 direction=np.array([[[0.0, -1.0], [0.0, 1.0]]]),
    ...                 valid=np.ones((1, 2), bool), n_hard=0)
    >>> v, bad = solve_velocity_lp(hp, np.array([[0.0, 0.5]]), np.array([2.0]))
    >>> float(v[0, 0]), bool(bad[0])
    (0.0, True)
    """
    pref = np.asarray(pref_velocities, dtype=float).reshape(-1, 2)
    radius = np.broadcast_to(np.asarray(max_speeds, dtype=float), pref.shape[:1])
    return _solve(
        *_split_lines(halfplanes.point, halfplanes.direction),
        halfplanes.valid,
        halfplanes.n_hard,
        pref,
        radius,
        slowest_fallback,
    )


def _solve(px, py, dx, dy, valid, n_hard, pref, radius, slowest_fallback):
    """:func:`solve_velocity_lp` on lines given as ``(N, M)`` coordinate planes."""
    px, py, dx, dy = (np.ascontiguousarray(a, dtype=float) for a in (px, py, dx, dy))
    valid = np.ascontiguousarray(valid, dtype=bool)
    radius = np.ascontiguousarray(radius, dtype=float)
    result = np.empty((valid.shape[0], 2))
    fail = lp.solve_lp2(
        px,
        py,
        dx,
        dy,
        valid,
        radius,
        np.ascontiguousarray(pref[:, 0]),
        np.ascontiguousarray(pref[:, 1]),
        result,
    )
    infeasible = fail < valid.shape[1]
    if infeasible.any():
        lp.solve_lp3(px, py, dx, dy, valid, int(n_hard), fail, radius, result)
    if slowest_fallback and infeasible.any():
        hp = HalfPlanes(np.stack([px, py], -1), np.stack([dx, dy], -1), valid, n_hard)
        _slowest_least_violation(hp, np.flatnonzero(infeasible), radius, result)
    return result, infeasible


def _solve_moving(lines, n_hard, still, pref, vmax, slowest_fallback):
    """:func:`_solve` for the robots that move; the others get zero."""
    n = still.shape[0]
    move = np.flatnonzero(~still)
    if move.size == n:
        return _solve(*lines, n_hard, pref, vmax, slowest_fallback)
    out = np.zeros((n, 2))
    infeasible = np.zeros(n, dtype=bool)
    if move.size:
        out[move], infeasible[move] = _solve(
            *(a[move] for a in lines), n_hard, pref[move], vmax[move], slowest_fallback
        )
    return out, infeasible


def _slowest_least_violation(hp: HalfPlanes, rows, radius, result) -> None:
    """Among the velocities whose largest soft violation equals the one found by the 3-D
    program, take the slowest. RVO2 keeps an extreme point of that set, which in a symmetric
    squeeze can be full speed into the squeeze."""
    p, d, v = hp.point[rows], hp.direction[rows], hp.valid[rows]
    viol = np.where(v, _det(d, p - result[rows][:, None]), -np.inf)
    soft = np.arange(v.shape[1]) >= hp.n_hard
    worst = np.max(np.where(soft, viol, -np.inf), axis=1)
    slack = np.maximum(worst, 0.0) * (1.0 + 1e-9) + 1e-12
    left = np.stack([-d[..., 1], d[..., 0]], -1)
    relaxed = p - np.where(soft[None, :, None], slack[:, None, None] * left, 0.0)
    new, fail = _lp2(relaxed, d, v, radius[rows], np.zeros((rows.size, 2)))
    ok = fail >= v.shape[1]
    result[rows[ok]] = new[ok]


# --------------------------------------------------------------------------------------------
# the step


def _rank_in_group(group: np.ndarray, key: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Order by (group, key) and the rank of each item within its group."""
    order = np.lexsort((key, group))
    g = group[order]
    rank = np.arange(g.size) - np.searchsorted(g, g, side="left")
    return order, rank


def _scatter(n: int, m: int, rows, slots, point, direction):
    """Pack pair constraints into per-robot slots: ``px, py, dx, dy, valid``, ``(n, m)``."""
    px, py, dx, dy = np.zeros((n, m)), np.zeros((n, m)), np.ones((n, m)), np.zeros((n, m))
    v = np.zeros((n, m), dtype=bool)
    px[rows, slots], py[rows, slots] = point[:, 0], point[:, 1]
    dx[rows, slots], dy[rows, slots] = direction[:, 0], direction[:, 1]
    v[rows, slots] = True
    return px, py, dx, dy, v


def sweep_hits(region: np.ndarray, displacement: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Whether the straight path ``t * displacement`` (``0 <= t <= 1``) enters the interior
    of convex ``region`` ``(P, V, 2)``, and whether it starts inside.

    Used with ``region = p_other - p_self + B ⊕ -A`` and the relative displacement of one
    step: a hit means the two shapes overlap at some time during the step.

    Examples
    --------
    >>> sq = np.array([[[1, -1], [3, -1], [3, 1], [1, 1]]], float)
    >>> [bool(x[0]) for x in sweep_hits(sq, np.array([[2.0, 0.0]]))]
    [True, False]
    >>> [bool(x[0]) for x in sweep_hits(sq, np.array([[0.9, 0.0]]))]
    [False, False]
    """
    q = np.asarray(region, dtype=float)
    disp = np.asarray(displacement, dtype=float)
    nx, ny, c, real = safety.edge_planes(
        np.ascontiguousarray(q[..., 0].T), np.ascontiguousarray(q[..., 1].T)
    )
    hit = safety.sweep(
        nx,
        ny,
        c,
        real,
        np.ascontiguousarray(disp[:, 0]),
        np.ascontiguousarray(disp[:, 1]),
        TOUCH_TOLERANCE_M,
    )
    return hit, safety.inside_now(c, real, TOUCH_TOLERANCE_M)


def _axis_lines(axes, n: int):
    """Robots held on a line: velocity ``v`` with ``|n . v| <= AXIS_SLACK`` (``n`` its
    normal), as two opposite hard lines per robot (invalid where the axis is NaN)."""
    raw_axes = _as_array(np.nan_to_num(np.asarray(axes, dtype=float), nan=0.0), (n, 2), "axes")
    on = ~np.isnan(np.asarray(axes, dtype=float)).any(axis=1)
    ax = np.where(on[:, None], raw_axes, [1.0, 0.0])
    nrm = np.stack([-ax[:, 1], ax[:, 0]], -1) * AXIS_SLACK
    pt = np.stack([-nrm, nrm], 1)
    dr = np.stack([ax, -ax], 1)
    valid = np.repeat(on[:, None], 2, axis=1)
    return pt[..., 0], pt[..., 1], dr[..., 0], dr[..., 1], valid


def _obstacle_lines(obstacles, pos, vel, shp, reach, vmax, speed, dt_s, params):
    """Static obstacles: hard lines (full share, their own horizon) for the nearest few, and
    the pairs ``(i, rx, ry)`` the safety filter checks (all within one step)."""
    n = pos.shape[0]
    none = (np.zeros(0, np.int64), np.zeros((3, 0)), np.zeros((3, 0)))
    step_reach = reach + vmax * dt_s
    rng = np.maximum(params.time_horizon_obst_s * speed + reach, step_reach)
    ia, io = obstacles.tree.query(shapely.points(pos), predicate="dwithin", distance=rng)
    if not ia.size:
        return None, none
    dist = shapely.distance(shapely.points(pos[ia]), obstacles.tree.geometries[io])
    order, rank = _rank_in_group(ia, dist)
    ia, io, dist = ia[order], io[order], dist[order]
    region = minkowski_difference(obstacles.vertices[io] - pos[ia, None], shp[ia])
    block = None
    keep = rank < params.max_obstacles
    if keep.any():
        pt, dr = pair_halfplanes(
            region[keep],
            vel[ia[keep]],
            vel[ia[keep]],
            np.ones(int(keep.sum())),
            np.full(int(keep.sum()), 1.0 / params.time_horizon_obst_s),
            1.0 / dt_s,
        )
        block = _scatter(n, int(rank[keep].max()) + 1, ia[keep], rank[keep], pt, dr)
    near = dist <= step_reach[ia]
    pairs_near = (
        ia[near].astype(np.int64),
        np.ascontiguousarray(region[near, :, 0].T),
        np.ascontiguousarray(region[near, :, 1].T),
    )
    return block, pairs_near


def _people_lines(ppos, pvel, prad, pos, pref, shp, reach, speed, inv_dt, params):
    """People: moving discs that do not react; the robot takes the full share."""
    n = pos.shape[0]
    ppos = _as_array(ppos, (-1, 2), "people_positions")
    n_p = ppos.shape[0]
    pvel = _as_array(np.zeros((n_p, 2)) if pvel is None else pvel, (n_p, 2), "people_velocities")
    if prad is None:
        raise ValueError("people_radii: required with people_positions")
    prad = _as_array(np.broadcast_to(np.asarray(prad, dtype=float), (n_p,)), (n_p,), "people_radii")
    if np.any(prad <= 0):
        raise ValueError(f"people_radii must be > 0 (got {prad.min()!r})")
    if not n_p:
        return None
    k = min(params.max_people, n_p)
    cut = params.time_horizon_s * (speed.max() + np.linalg.norm(pvel, axis=-1).max()) + (
        reach.max() + prad.max() / np.cos(np.pi / params.disc_sides)
    )
    dist, idx = cKDTree(ppos).query(pos, k=k, distance_upper_bound=cut)
    dist, idx = dist.reshape(n, k), idx.reshape(n, k)
    rows, slots = np.nonzero(idx < n_p)
    if not rows.size:
        return None
    j = idx[rows, slots]
    disc = disc_polygons(ppos[j] - pos[rows], prad[j], params.disc_sides)
    region = minkowski_difference(disc, shp[rows])
    # A person does not react, so any tangent of the velocity obstacle is safe; the one
    # nearest the preferred velocity steps aside instead of only braking in front of a flat
    # face (the nearest tangent to the current velocity).
    pt, dr = pair_halfplanes(
        region,
        pref[rows] - pvel[j],
        pref[rows],
        np.ones(rows.size),
        np.full(rows.size, 1.0 / params.time_horizon_s),
        inv_dt,
        params.leg_preference,
    )
    return _scatter(n, k, rows, slots, pt, dr)


def _robot_lines(pos, vel, prio, still, shp, reach, vmax, speed, dt_s, params):
    """Other robots: reciprocal lines, shares by priority (compiled:
    :func:`.pairs.robot_lines`), and the pairs ``(lo, hi, rx, ry)`` the safety filter
    checks."""
    n = pos.shape[0]
    cut = params.neighbour_dist_m
    if cut is None:
        top = np.sort(speed)[-2:].sum()
        cut = params.time_horizon_s * top + np.sort(reach)[-2:].sum()
    # Pairs that can touch within one step at the speed limits.
    near = 2.0 * reach.max() + 2.0 * vmax.max() * dt_s if params.safety_filter else -1.0
    slots = min(params.max_neighbours + 1, n, params.max_neighbours)
    nbr, fp = neighbours.grid_neighbours(
        pos, float(cut) if params.max_neighbours else -1.0, slots, slots, float(near)
    )
    # Vertex-major shapes (K, N): the kernels loop over a few vertices, not pairs.
    sx, sy = np.ascontiguousarray(shp[..., 0].T), np.ascontiguousarray(shp[..., 1].T)
    block = None
    if params.max_neighbours:
        block = pairs.robot_lines(
            pos,
            vel,
            prio,
            still,
            nbr,
            sx,
            sy,
            1.0 / params.time_horizon_s,
            1.0 / dt_s,
            float(params.leg_preference),
            float(params.keep_right),
            float(params.min_share),
        )
        if not block[4].any():
            block = None
    robot_pairs = (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((3, 0)), np.zeros((3, 0)))
    if params.safety_filter:
        lo, hi = pairs.canonical_pairs(pos, fp[:, 0].copy(), fp[:, 1].copy())
        rx, ry = pairs.minkowski_pairs(
            sx, sy, hi, lo, pos[hi, 0] - pos[lo, 0], pos[hi, 1] - pos[lo, 1]
        )
        robot_pairs = (lo, hi, rx, ry)
    return block, robot_pairs


def orca_step(
    positions: np.ndarray,
    velocities: np.ndarray,
    pref_velocities: np.ndarray,
    max_speeds,
    priorities,
    shapes: np.ndarray,
    *,
    dt_s: float,
    params: OrcaParams | None = None,
    immobile: np.ndarray | None = None,
    people_positions: np.ndarray | None = None,
    people_velocities: np.ndarray | None = None,
    people_radii=None,
    obstacles: StaticObstacles | None = None,
    axes: np.ndarray | None = None,
) -> OrcaResult:
    """New velocities for all robots from one snapshot (no dependence on robot order).

    Above mccabe complexity 15 on purpose: its branches are the optional constraint families
    (axes, static obstacles, people, neighbours, safety filter) assembled in one vectorized pass
    over shared arrays, the hot path of every tick, which helpers would only split apart.

    Parameters
    ----------
    positions
        ``(N, 2)`` centres the velocity obstacles are built around (effective centres of the
        skids, see :func:`skid_shapes`).
    velocities
        ``(N, 2)`` current velocities of those centres.
    pref_velocities
        ``(N, 2)`` preferred velocities (from the path follower).
    max_speeds
        ``(N,)`` or scalar speed limits of the centres (:func:`holonomic_speed_limit`).
    priorities
        ``(N,)`` or scalar, ``>= 0``; see :func:`responsibility_shares`.
    shapes
        ``(N, K, 2)`` convex footprints relative to ``positions``, world axes,
        counter-clockwise, enlarged by the tracking error bound.
    dt_s
        Control step; robots that overlap already get velocities that separate them within it.
    params
        :class:`OrcaParams` (defaults if ``None``).
    immobile
        ``(N,)`` bool: robots that will not move (e-stop, fault). They get velocity zero and
        others take the full share of avoiding them.
    people_positions, people_velocities, people_radii
        ``(P, 2)``, ``(P, 2)``, ``(P,)`` or scalar: moving discs that do not avoid robots.
    obstacles
        Static obstacles from :func:`prepare_obstacles`.
    axes
        ``(N, 2)`` unit vectors, NaN where free: these robots may only move along that line
        (a parked skid making room by driving along its own axis, so that it does not turn
        its corners into its neighbours). Two opposite hard half-planes hold the velocity on
        the line; the other robots still count on the robot's full share, so where the line
        cannot provide it, the safety filter keeps the step collision-free.
    Returns
    -------
    OrcaResult
    """
    params = OrcaParams() if params is None else params
    pos = _as_array(positions, (-1, 2), "positions")
    n = pos.shape[0]
    vel = _as_array(velocities, (n, 2), "velocities")
    pref = _as_array(pref_velocities, (n, 2), "pref_velocities")
    vmax = _as_array(np.broadcast_to(np.asarray(max_speeds, dtype=float), (n,)), (n,), "max_speeds")
    if np.any(vmax < 0):
        raise ValueError(f"max_speeds must be >= 0 (got {vmax.min()!r})")
    prio = _as_array(np.broadcast_to(np.asarray(priorities, dtype=float), (n,)), (n,), "priorities")
    if np.any(prio < 0):
        raise ValueError(f"priorities must be >= 0 (got {prio.min()!r})")
    shp = _as_array(shapes, (n, -1, 2), "shapes")
    _check_convex_ccw(shp, "shapes")
    if not (np.isfinite(dt_s) and dt_s > 0):
        raise ValueError(f"dt_s must be a finite number > 0 (got {dt_s!r})")
    still = np.zeros(n, bool) if immobile is None else np.asarray(immobile, dtype=bool)
    if still.shape != (n,):
        raise ValueError(f"immobile: expected shape ({n},), got {still.shape}")
    vel = np.where(still[:, None], 0.0, vel)
    inv_dt = 1.0 / dt_s
    reach = np.linalg.norm(shp, axis=-1).max(axis=1) if n else np.zeros(0)
    speed = np.maximum(vmax, np.linalg.norm(vel, axis=-1))

    blocks = []
    n_hard = 0
    if axes is not None and n:
        blocks.append(_axis_lines(axes, n))
        n_hard = 2
    obstacle_pairs = (np.zeros(0, np.int64), np.zeros((3, 0)), np.zeros((3, 0)))
    if obstacles is not None and len(obstacles) and n:
        block, obstacle_pairs = _obstacle_lines(
            obstacles, pos, vel, shp, reach, vmax, speed, dt_s, params
        )
        if block is not None:
            blocks.append(block)
            n_hard += block[0].shape[1]
    if people_positions is not None and params.max_people and n:
        block = _people_lines(
            people_positions,
            people_velocities,
            people_radii,
            pos,
            pref,
            shp,
            reach,
            speed,
            inv_dt,
            params,
        )
        if block is not None:
            blocks.append(block)
    robot_pairs = (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((3, 0)), np.zeros((3, 0)))
    if n > 1:
        block, robot_pairs = _robot_lines(
            pos, vel, prio, still, shp, reach, vmax, speed, dt_s, params
        )
        if block is not None:
            blocks.append(block)

    if blocks:
        px, py, dx, dy, valid = (np.concatenate([b[f] for b in blocks], axis=1) for f in range(5))
    else:
        px, py, dx, dy = np.zeros((n, 0)), np.zeros((n, 0)), np.ones((n, 0)), np.zeros((n, 0))
        valid = np.zeros((n, 0), dtype=bool)
    halfplanes = HalfPlanes(
        point=np.stack([px, py], -1), direction=np.stack([dx, dy], -1), valid=valid, n_hard=n_hard
    )
    out, infeasible = _solve_moving(
        (px, py, dx, dy, valid), n_hard, still, pref, vmax, params.slowest_fallback
    )
    slowed = np.zeros(n, dtype=bool)
    if params.safety_filter and n:
        out, slowed = safety.safety_filter(
            out, float(dt_s), *robot_pairs, *obstacle_pairs, TOUCH_TOLERANCE_M
        )
    return OrcaResult(velocities=out, infeasible=infeasible, halfplanes=halfplanes, slowed=slowed)
