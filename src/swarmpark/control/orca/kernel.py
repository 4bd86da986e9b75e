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

The half-planes are built vectorized over all neighbour pairs (neighbours from a
``scipy.spatial.cKDTree``, limited to the ``max_neighbours`` nearest within a cut-off), and
the small linear programs (RVO2's ``linearProgram1/2/3``) run vectorized across robots: one
Python iteration per constraint slot, not per robot. Each unordered pair is built once, from
the side of the robot with the smaller ``(x, y)``, so the result is bit-for-bit the same
whatever the order of the robots.

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

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import shapely
from scipy.spatial import cKDTree

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

#: Determinants below this are "parallel lines" in the linear programs (RVO2's RVO_EPSILON).
LP_EPSILON = 1e-9
#: Edges shorter than this (metres) are padding or round-off, not edges.
MIN_EDGE_M = 1e-12
#: Times the safety filter halves a velocity before it stops the robot.
SAFETY_HALVINGS = 4
#: Above this many edge pairs, the Minkowski merge sorts instead of counting ranks.
SMALL_MERGE = 64
#: Pairs per block in the vectorized kernels (``(V, block)`` arrays that fit in cache).
PAIR_CHUNK = 4096
#: Sides of the regular polygon that covers a person's disc (circumscribed: conservative).
DEFAULT_DISC_SIDES = 8
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


@dataclass(frozen=True)
class StaticObstacles:
    """Static convex obstacles (walls as segments, pillars as convex polygons), ready to query.

    Build with :func:`prepare_obstacles` once per map, then pass to every :func:`orca_step`.
    """

    vertices: np.ndarray  # (O, L, 2) counter-clockwise, padded by repeating the last vertex
    tree: shapely.STRtree = field(repr=False)

    def __len__(self) -> int:
        return int(self.vertices.shape[0])


# --------------------------------------------------------------------------------------------
# small vector helpers


def _det(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1]


def _as_array(value, shape: tuple, name: str) -> np.ndarray:
    """A finite float array of ``shape`` (``-1`` = any), or a ValueError naming ``name``."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: not a numeric array ({value!r})") from exc
    if arr.ndim != len(shape) or any(
        s != -1 and s != a for s, a in zip(shape, arr.shape, strict=True)
    ):
        want = "(" + ", ".join("*" if s == -1 else str(s) for s in shape) + ")"
        raise ValueError(f"{name}: expected shape {want}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: values must be finite (got {arr!r})")
    return arr


def _check_convex_ccw(polys: np.ndarray, name: str) -> None:
    """Raise if any polygon ``(N, K, 2)`` is not convex with counter-clockwise vertices."""
    if polys.shape[0] == 0:
        return
    e = np.roll(polys, -1, axis=1) - polys
    real = np.linalg.norm(e, axis=-1) > MIN_EDGE_M
    # Turn between consecutive non-zero edges; padded (repeated) vertices give zero edges.
    e_next = np.roll(e, -1, axis=1)
    cross = _det(e, e_next)
    scale = np.linalg.norm(e, axis=-1) * np.linalg.norm(e_next, axis=-1)
    bad_turn = real & np.roll(real, -1, axis=1) & (cross < -1e-9 * np.maximum(scale, 1e-30))
    area2 = _det(polys, np.roll(polys, -1, axis=1)).sum(axis=1)
    bad = bad_turn.any(axis=1) | (area2 < 0)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(
            f"{name}[{i}]: not a convex polygon with counter-clockwise vertices: "
            f"{polys[i].tolist()}"
        )


# --------------------------------------------------------------------------------------------
# geometry of the velocity obstacle


def _pseudo_angle(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """A strictly increasing function of ``atan2(y, x)`` on ``[0, 2 pi)``, values in ``[0, 4)``,
    without trigonometry (only the order of angles is needed)."""
    s = np.abs(x) + np.abs(y)
    r = x / np.where(s > 0, s, 1.0)
    return np.where(y >= 0, 1.0 - r, 3.0 + r)


def _edges(a: np.ndarray) -> np.ndarray:
    """Edge vectors ``next vertex - vertex`` along axis 0 (vertex-major layout ``(V, P)``)."""
    e = np.empty_like(a)
    np.subtract(a[1:], a[:-1], out=e[:-1])
    np.subtract(a[0], a[-1], out=e[-1])
    return e


def _arg_extreme(a: np.ndarray, largest: bool) -> np.ndarray:
    """``argmax``/``argmin`` over the short axis 0 of ``(V, P)``: a loop over ``V`` rows is
    much faster in numpy than a per-column reduction; ties go to the first index."""
    best = a[0].copy()
    idx = np.zeros(a.shape[1], dtype=np.intp)
    for k in range(1, a.shape[0]):
        better = a[k] > best if largest else a[k] < best
        best = np.where(better, a[k], best)
        idx = np.where(better, k, idx)
    return idx


def _minkowski_xy(bx, by, ax, ay):
    """``B ⊕ (-A)`` in vertex-major layout: ``(K, P)`` and ``(L, P)`` in, ``(K + L, P)`` out.

    Edges of both polygons are merged by angle; each edge's place in the merged walk is its
    rank within its own polygon plus the number of the other polygon's edges before it.
    """
    nax, nay = -ax, -ay  # a point reflection keeps counter-clockwise order
    ebx, eby = _edges(bx), _edges(by)
    eax, eay = _edges(nax), _edges(nay)
    # Zero-length edges (padding) go last and add nothing to the walk.
    ang_b = np.where(np.abs(ebx) + np.abs(eby) > MIN_EDGE_M, _pseudo_angle(ebx, eby), np.inf)
    ang_a = np.where(np.abs(eax) + np.abs(eay) > MIN_EDGE_M, _pseudo_angle(eax, eay), np.inf)
    k_b, k_a = ang_b.shape[0], ang_a.shape[0]
    cols = np.arange(bx.shape[1])
    if k_b * k_a > SMALL_MERGE:
        return _minkowski_sorted(bx, by, nax, nay, ebx, eby, eax, eay, ang_b, ang_a)

    def own_rank(ang):
        first = _arg_extreme(ang, False)
        if np.all(np.isfinite(ang)):
            # No padding: edges of a convex polygon are already in cyclic angle order.
            return (np.arange(ang.shape[0])[:, None] - first) % ang.shape[0], first
        rank = np.zeros(ang.shape, dtype=np.intp)
        for k in range(ang.shape[0]):
            for m in range(ang.shape[0]):
                if m != k:
                    rank[k] += (ang[m] < ang[k]) | ((ang[m] == ang[k]) & (m < k))
        return rank, first

    (rank_b, first_b), (rank_a, first_a) = own_rank(ang_b), own_rank(ang_a)
    pos_b, pos_a = rank_b.copy(), rank_a.copy()
    for k in range(k_b):
        for m in range(k_a):
            # On equal angles the edge of B goes first.
            less = ang_a[m] < ang_b[k]
            pos_b[k] += less
            pos_a[m] += ~less
    n_cols = bx.shape[1]
    flat = np.concatenate([pos_b, pos_a], axis=0) * n_cols + cols
    ex = np.empty((k_b + k_a) * n_cols)
    ey = np.empty_like(ex)
    ex[flat.ravel()] = np.concatenate([ebx, eax], axis=0).ravel()
    ey[flat.ravel()] = np.concatenate([eby, eay], axis=0).ravel()
    ex, ey = ex.reshape(-1, n_cols), ey.reshape(-1, n_cols)
    # The walk starts at the sum of the tails of both polygons' first edges.
    sx = bx[first_b, cols] + nax[first_a, cols]
    sy = by[first_b, cols] + nay[first_a, cols]
    out_x = np.empty_like(ex)
    out_y = np.empty_like(ey)
    out_x[0], out_y[0] = sx, sy
    out_x[1:] = sx + np.cumsum(ex[:-1], axis=0)
    out_y[1:] = sy + np.cumsum(ey[:-1], axis=0)
    return out_x, out_y


def _minkowski_sorted(bx, by, nax, nay, ebx, eby, eax, eay, ang_b, ang_a):
    """The edge merge of :func:`_minkowski_xy` by a sort, for polygons with many vertices."""
    cols = np.arange(bx.shape[1])
    kb, ka = np.argmin(ang_b, axis=0), np.argmin(ang_a, axis=0)
    sx = bx[kb, cols] + nax[ka, cols]
    sy = by[kb, cols] + nay[ka, cols]
    ang = np.concatenate([ang_b, ang_a], axis=0)
    order = np.argsort(ang, axis=0, kind="stable")
    ex = np.take_along_axis(np.concatenate([ebx, eax], axis=0), order, axis=0)
    ey = np.take_along_axis(np.concatenate([eby, eay], axis=0), order, axis=0)
    out_x, out_y = np.empty_like(ex), np.empty_like(ey)
    out_x[0], out_y[0] = sx, sy
    out_x[1:] = sx + np.cumsum(ex[:-1], axis=0)
    out_y[1:] = sy + np.cumsum(ey[:-1], axis=0)
    return out_x, out_y


def minkowski_difference(b: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Vertices of ``B ⊕ (-A)`` for batches of convex polygons, by merging edges by angle.

    Parameters
    ----------
    b, a
        ``(P, K, 2)`` and ``(P, L, 2)`` convex polygons with counter-clockwise vertices;
        padding by repeated vertices (and segments as two-vertex polygons) is allowed.

    Returns
    -------
    ``(P, K + L, 2)`` counter-clockwise vertices (collinear and repeated ones may occur).

    Examples
    --------
    >>> sq = np.array([[[0, 0], [1, 0], [1, 1], [0, 1]]], float)
    >>> m = minkowski_difference(sq, sq)
    >>> float(m[0, :, 0].min()), float(m[0, :, 0].max())
    (-1.0, 1.0)
    """
    b = np.asarray(b, dtype=float)
    a = np.asarray(a, dtype=float)
    mx, my = _minkowski_xy(b[..., 0].T, b[..., 1].T, a[..., 0].T, a[..., 1].T)
    return np.stack([mx.T, my.T], -1)


def _vo_projection(rx, ry, wx, wy, inv_horizon, inv_dt, leg_preference=0.0, keep_right=0.0):
    """Shortest move ``u`` from the relative velocity to the boundary of the velocity
    obstacle, and the obstacle's outward normal ``n`` there (see :func:`pair_halfplanes`).

    Vertex-major layout: ``rx, ry`` ``(V, P)`` region vertices, ``wx, wy`` ``(P,)``.
    Returns ``ux, uy, nx, ny`` ``(P,)``.
    """
    cols = np.arange(rx.shape[1])
    ex, ey = _edges(rx), _edges(ry)
    elen = np.sqrt(ex * ex + ey * ey)
    real = elen > MIN_EDGE_M
    inv_len = 1.0 / np.maximum(elen, MIN_EDGE_M)
    # Outward normal of a counter-clockwise polygon: the right-hand perpendicular of the edge.
    nx, ny = ey * inv_len, -ex * inv_len
    front = real & (nx * rx + ny * ry < 0.0)  # the origin lies outside this edge's line
    colliding = ~np.any(front, axis=0)

    inv = np.where(colliding, inv_dt, inv_horizon)
    # The cut-off polygon: region / tau, or region / dt when the shapes overlap now.
    qx, qy = rx * inv, ry * inv
    esx, esy = ex * inv, ey * inv

    # Legs of the cone: rays from the origin through the extreme vertices seen from it.
    cx, cy = rx.sum(axis=0), ry.sum(axis=0)  # a multiple of the centroid: same directions
    key = _pseudo_angle(cx * rx + cy * ry, cx * ry - cy * rx)
    # Angles relative to the centroid lie in (-pi, pi): shift so that the order is monotone.
    key = np.where(key >= 2.0, key - 4.0, key)
    kl, kr = _arg_extreme(key, True), _arg_extreme(key, False)
    lx, ly, gx, gy = rx[kl, cols], ry[kl, cols], rx[kr, cols], ry[kr, cols]
    ll = 1.0 / np.maximum(np.sqrt(lx * lx + ly * ly), MIN_EDGE_M)
    gl = 1.0 / np.maximum(np.sqrt(gx * gx + gy * gy), MIN_EDGE_M)
    lux, luy, gux, guy = lx * ll, ly * ll, gx * gl, gy * gl

    # Facets: edges facing the origin and both legs (no collision) or all edges (collision).
    # The largest signed distance tells inside from outside.
    dxw, dyw = wx - qx, wy - qy
    s_edge = np.where(real & (colliding | front), nx * dxw + ny * dyw, -np.inf)
    k_edge = _arg_extreme(s_edge, True)
    s_in = s_edge[k_edge, cols]
    nix, niy = nx[k_edge, cols], ny[k_edge, cols]
    s_left = np.where(colliding, -np.inf, -luy * wx + lux * wy)
    s_right = np.where(colliding, -np.inf, guy * wx - gux * wy)
    # Near-ties go to the right leg: both robots keep right (the pair's obstacles are point
    # reflections of each other, which keeps handedness). Without the margin a nearly
    # symmetric encounter flips sides with every small turn (the reciprocal dance).
    speed = np.sqrt(wx * wx + wy * wy)
    right = s_right + keep_right * speed >= s_left
    s_leg = np.where(right, s_right, s_left)
    lnx, lny = np.where(right, guy, -luy), np.where(right, -gux, lux)
    inside = np.maximum(s_in, s_leg) <= 0.0
    # Inside, any facet line supports the obstacle, so any of them keeps the reciprocal
    # guarantee. ORCA takes the nearest; a flat cut-off face (rectangles) then only ever
    # brakes two robots meeting head-on. A leg within leg_preference * |w| of the face is
    # taken instead, so that they start passing each other (as discs do by curvature).
    take_leg = ~colliding & (s_leg + leg_preference * speed >= s_in)
    s_in = np.where(take_leg, s_leg, s_in)
    nix, niy = np.where(take_leg, lnx, nix), np.where(take_leg, lny, niy)

    # Outside: project on the boundary pieces. Edges facing away lie inside the obstacle and
    # are never closer than the boundary, so all edges can be tried.
    t = np.clip((dxw * esx + dyw * esy) / np.maximum(esx * esx + esy * esy, 1e-300), 0.0, 1.0)
    px, py = qx + t * esx, qy + t * esy
    d2 = (wx - px) ** 2 + (wy - py) ** 2
    k_out = _arg_extreme(d2, False)
    best = d2[k_out, cols]
    bx, by = px[k_out, cols], py[k_out, cols]
    for ux_, uy_, sx_, sy_ in ((lux, luy, lx, ly), (gux, guy, gx, gy)):
        ox, oy = sx_ * inv, sy_ * inv
        tr = np.maximum((wx - ox) * ux_ + (wy - oy) * uy_, 0.0)
        cxr, cyr = ox + tr * ux_, oy + tr * uy_
        dr = (wx - cxr) ** 2 + (wy - cyr) ** 2
        take = ~colliding & (dr < best)
        best = np.where(take, dr, best)
        bx, by = np.where(take, cxr, bx), np.where(take, cyr, by)
    awx, awy = wx - bx, wy - by
    dist = np.sqrt(awx * awx + awy * awy)
    # A tangent-point normal is ill-defined for a relative velocity on the boundary itself:
    # then the facet normal found above is the outward normal.
    far = dist > 1e-12
    inv_d = 1.0 / np.maximum(dist, 1e-12)
    nox, noy = np.where(far, awx * inv_d, nix), np.where(far, awy * inv_d, niy)

    ux = np.where(inside, -s_in * nix, bx - wx)
    uy = np.where(inside, -s_in * niy, by - wy)
    return ux, uy, np.where(inside, nix, nox), np.where(inside, niy, noy), inside


def _in_chunks(fn, n_out: int, size: int, vertex_major: tuple, per_pair: tuple, *extra):
    """Call ``fn`` on blocks of pairs so the ``(V, block)`` temporaries stay in cache."""
    if size <= PAIR_CHUNK:
        return fn(*vertex_major, *per_pair, *extra)
    outs = [[] for _ in range(n_out)]
    for lo in range(0, size, PAIR_CHUNK):
        sl = slice(lo, lo + PAIR_CHUNK)
        res = fn(*(a[:, sl] for a in vertex_major), *(a[sl] for a in per_pair), *extra)
        for k in range(n_out):
            outs[k].append(res[k])
    return tuple(np.concatenate(o, axis=-1) for o in outs)


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
    ux, uy, nx, ny, inside = _vo_projection(
        np.ascontiguousarray(q[..., 0].T),
        np.ascontiguousarray(q[..., 1].T),
        w[:, 0].copy(),
        w[:, 1].copy(),
        np.broadcast_to(np.asarray(inv_horizon, dtype=float), w.shape[:1]),
        inv_dt,
        leg_preference,
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
# linear programs (RVO2's linearProgram1/2/3), vectorized across robots


def _lp1(point, direction, valid, i, rows, radius, opt, direction_opt):
    """Best point on line ``i`` within the speed circle and lines ``< i``, for ``rows``."""
    pi, di = point[rows, i], direction[rows, i]
    dotp = _dot(pi, di)
    disc = dotp * dotp + radius[rows] ** 2 - _dot(pi, pi)
    ok = disc >= 0.0
    sq = np.sqrt(np.maximum(disc, 0.0))
    t_left, t_right = -dotp - sq, -dotp + sq
    if i > 0:
        pj, dj, vj = point[rows, :i], direction[rows, :i], valid[rows, :i]
        denom = _det(di[:, None], dj)
        numer = _det(dj, pi[:, None] - pj)
        parallel = np.abs(denom) <= LP_EPSILON
        # A parallel line that excludes all of line i makes it infeasible.
        ok &= ~np.any(vj & parallel & (numer < 0.0), axis=1)
        t = numer / np.where(parallel, 1.0, denom)
        cut = vj & ~parallel
        t_right = np.minimum(t_right, np.min(np.where(cut & (denom > 0), t, np.inf), axis=1))
        t_left = np.maximum(t_left, np.max(np.where(cut & (denom < 0), t, -np.inf), axis=1))
        ok &= t_left <= t_right
    if direction_opt:
        t = np.where(_dot(opt, di) > 0.0, t_right, t_left)
    else:
        t = np.clip(_dot(di, opt - pi), t_left, t_right)
    return ok, pi + t[:, None] * di


def _lp2(point, direction, valid, radius, opt, direction_opt):
    """Velocity closest to ``opt`` (or farthest along it) in all lines and the speed circle.

    Returns the result ``(n, 2)`` and the index of the first line that could not be met
    (``M`` where all were met).
    """
    n, m = valid.shape
    if direction_opt:
        result = opt * radius[:, None]
    else:
        speed = np.linalg.norm(opt, axis=-1)
        scale = np.where(speed > radius, radius / np.maximum(speed, 1e-300), 1.0)
        result = opt * scale[:, None]
    fail = np.full(n, m)
    active = np.ones(n, dtype=bool)
    for i in range(m):
        viol = active & valid[:, i] & (_det(direction[:, i], point[:, i] - result) > 0.0)
        rows = np.flatnonzero(viol)
        if rows.size == 0:
            continue
        ok, res = _lp1(point, direction, valid, i, rows, radius, opt[rows], direction_opt)
        result[rows[ok]] = res[ok]
        bad = rows[~ok]
        fail[bad] = i
        active[bad] = False
    return result, fail


def _lp3(point, direction, valid, n_hard, fail, radius, result):
    """Where the half-planes are infeasible, minimise the largest violation of the soft ones
    (the 3-D program of RVO2), keeping the hard ones. Updates ``result`` in place."""
    m = valid.shape[1]
    rows_all = np.flatnonzero(fail < m)
    if rows_all.size == 0:
        return
    res = result[rows_all].copy()
    distance = np.zeros(rows_all.size)
    for i in range(int(fail[rows_all].min()), m):
        pi_all, di_all = point[rows_all, i], direction[rows_all, i]
        need = (fail[rows_all] <= i) & valid[rows_all, i] & (_det(di_all, pi_all - res) > distance)
        sel = np.flatnonzero(need)
        if sel.size == 0:
            continue
        r = rows_all[sel]
        pi, di = point[r, i], direction[r, i]
        lo = n_hard  # the hard lines always hold, as in RVO2
        pj, dj = point[r, n_hard:i], direction[r, n_hard:i]
        d_ij = _det(di[:, None], dj)
        parallel = np.abs(d_ij) <= LP_EPSILON
        same_way = parallel & (_dot(di[:, None], dj) > 0.0)
        # Lines equidistant to line i and line j: where violating both is balanced.
        cross_pt = (
            pi[:, None]
            + (_det(dj, pi[:, None] - pj) / np.where(parallel, 1.0, d_ij))[..., None] * di[:, None]
        )
        proj_p = np.where(parallel[..., None], 0.5 * (pi[:, None] + pj), cross_pt)
        proj_d = dj - di[:, None]
        proj_d = proj_d / np.maximum(np.linalg.norm(proj_d, axis=-1), 1e-300)[..., None]
        pp = np.concatenate([point[r, :lo], proj_p], axis=1)
        dd = np.concatenate([direction[r, :lo], proj_d], axis=1)
        vv = np.concatenate([valid[r, :lo], valid[r, n_hard:i] & ~same_way], axis=1)
        opt = np.stack([-di[:, 1], di[:, 0]], -1)
        new, f2 = _lp2(pp, dd, vv, radius[r], opt, True)
        # Failure here is float round-off only (the old result is feasible): keep the old one.
        ok = f2 >= pp.shape[1]
        res[sel] = np.where(ok[:, None], new, res[sel])
        distance[sel] = _det(di, pi - res[sel])
    result[rows_all] = res


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
    pref = np.asarray(pref_velocities, dtype=float)
    radius = np.asarray(max_speeds, dtype=float)
    result, fail = _lp2(
        halfplanes.point, halfplanes.direction, halfplanes.valid, radius, pref.copy(), False
    )
    infeasible = fail < halfplanes.valid.shape[1]
    _lp3(
        halfplanes.point,
        halfplanes.direction,
        halfplanes.valid,
        halfplanes.n_hard,
        fail,
        radius,
        result,
    )
    if slowest_fallback and infeasible.any():
        _slowest_least_violation(halfplanes, np.flatnonzero(infeasible), radius, result)
    return result, infeasible


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
    new, fail = _lp2(relaxed, d, v, radius[rows], np.zeros((rows.size, 2)), False)
    ok = fail >= v.shape[1]
    result[rows[ok]] = new[ok]


# --------------------------------------------------------------------------------------------
# shapes


def disc_polygons(centres: np.ndarray, radii, sides: int = DEFAULT_DISC_SIDES) -> np.ndarray:
    """Regular polygons ``(P, sides, 2)`` circumscribed about discs (a conservative cover).

    Examples
    --------
    >>> sq = disc_polygons(np.zeros((1, 2)), 1.0, sides=4)
    >>> np.round(np.abs(sq[0]), 9).tolist()
    [[1.0, 1.0], [1.0, 1.0], [1.0, 1.0], [1.0, 1.0]]
    """
    c = np.asarray(centres, dtype=float).reshape(-1, 2)
    r = np.broadcast_to(np.asarray(radii, dtype=float), c.shape[:1])
    ang = (2.0 * np.arange(sides) + 1.0) * np.pi / sides
    unit = np.stack([np.cos(ang), np.sin(ang)], -1) / np.cos(np.pi / sides)
    return c[:, None, :] + r[:, None, None] * unit[None]


def inflate_convex(polys: np.ndarray, margin_m) -> np.ndarray:
    """Move every edge of convex counter-clockwise polygons ``(N, K, 2)`` outward by
    ``margin_m`` (scalar or ``(N,)``), mitred, so the result covers the rounded offset.

    Examples
    --------
    >>> sq = np.array([[[0, 0], [1, 0], [1, 1], [0, 1]]], float)
    >>> inflate_convex(sq, 0.5)[0].tolist()
    [[-0.5, -0.5], [1.5, -0.5], [1.5, 1.5], [-0.5, 1.5]]
    """
    p = np.asarray(polys, dtype=float)
    m = np.broadcast_to(np.asarray(margin_m, dtype=float), p.shape[:1])
    e = np.roll(p, -1, axis=1) - p
    elen = np.linalg.norm(e, axis=-1)
    if np.any(elen <= MIN_EDGE_M):
        raise ValueError("inflate_convex: polygons must not repeat vertices")
    n = np.stack([e[..., 1], -e[..., 0]], -1) / elen[..., None]
    n_prev = np.roll(n, 1, axis=1)
    miter = (n + n_prev) / (1.0 + _dot(n, n_prev))[..., None]
    return p + m[:, None, None] * miter


def skid_shapes(
    poses: np.ndarray, corners_body: np.ndarray, *, offset_m, margin_m=0.0
) -> tuple[np.ndarray, np.ndarray]:
    """Effective centres and world-frame footprints relative to them, for :func:`orca_step`.

    Parameters
    ----------
    poses
        ``(N, 3)`` pivot poses ``(x, y, yaw)``.
    corners_body
        ``(N, K, 2)`` or shared ``(K, 2)`` convex footprint in the body frame (pivot origin),
        e.g. ``Footprint.corners_body()``.
    offset_m
        Distance ``D`` of the effective centre ahead of the pivot (scalar or ``(N,)``).
    margin_m
        Enlargement of the footprint, normally :func:`tracking_error_bound`.

    Returns
    -------
    centres ``(N, 2)`` and shapes ``(N, K, 2)`` (footprint minus centre, world axes).
    """
    poses = _as_array(poses, (-1, 3), "poses")
    n = poses.shape[0]
    body = np.asarray(corners_body, dtype=float)
    body = np.broadcast_to(body, (n, *body.shape)) if body.ndim == 2 else body
    d = np.broadcast_to(np.asarray(offset_m, dtype=float), (n,))
    heading = np.stack([np.cos(poses[:, 2]), np.sin(poses[:, 2])], -1)
    centres = poses[:, :2] + d[:, None] * heading
    local = inflate_convex(body - np.stack([d, np.zeros(n)], -1)[:, None], margin_m)
    c, s = heading[:, 0:1], heading[:, 1:2]
    shapes = np.stack(
        [c * local[..., 0] - s * local[..., 1], s * local[..., 0] + c * local[..., 1]], -1
    )
    return centres, shapes


# --------------------------------------------------------------------------------------------
# non-holonomic conversion: the effective-centre method


def holonomic_speed_limit(v_max, omega_max, offset_m):
    """Largest speed of the effective centre that a unicycle tracks exactly:
    ``min(v_max, offset_m * omega_max)``."""
    return np.minimum(np.asarray(v_max, dtype=float), np.asarray(offset_m) * np.asarray(omega_max))


def effective_reach(corners_body: np.ndarray, offset_m) -> np.ndarray:
    """Distance from the effective centre to the farthest footprint corner, ``(N,)``."""
    body = np.asarray(corners_body, dtype=float)
    body = body[None] if body.ndim == 2 else body
    d = np.asarray(offset_m, dtype=float).reshape(-1, 1)
    return np.hypot(body[..., 0] - d, body[..., 1]).max(axis=-1)


def tracking_error_bound(speed_limit, omega_max, reach_m, dt_s):
    """Bound on how far any footprint point strays from the footprint translated by ``u dt``
    while a unicycle holds ``holonomic_to_unicycle(u)`` for one step ``dt_s``.

    ``speed_limit * omega_max * dt**2 / 2`` (the effective centre runs on an arc, not a chord)
    plus ``2 * reach * sin(omega_max * dt / 2)`` (the body turns about the effective centre),
    valid for ``|u| <= speed_limit <= holonomic_speed_limit(...)``.

    Examples
    --------
    >>> round(float(tracking_error_bound(1.0, 1.0, 0.8, 0.1)), 6)
    0.084967
    """
    w_dt = np.minimum(np.asarray(omega_max, dtype=float) * dt_s, np.pi)
    return np.asarray(speed_limit, dtype=float) * np.asarray(
        omega_max
    ) * dt_s**2 / 2.0 + 2.0 * np.asarray(reach_m, dtype=float) * np.sin(w_dt / 2.0)


def holonomic_to_unicycle(
    poses: np.ndarray, vel_xy: np.ndarray, *, offset_m, v_max, omega_max
) -> tuple[np.ndarray, np.ndarray]:
    """Forward speed and yaw rate that move the effective centre with ``vel_xy``.

    ``v = u·h`` and ``omega = u·n / offset_m``; where that breaks a limit, ``u`` is scaled
    down (direction kept) until ``|v| <= v_max`` and ``|omega| <= omega_max``. Exact (no
    scaling) for ``|u| <= holonomic_speed_limit(v_max, omega_max, offset_m)``.

    Examples
    --------
    >>> v, w = holonomic_to_unicycle(np.array([[0.0, 0.0, 0.0]]), np.array([[0.3, 0.4]]),
    ...                              offset_m=0.5, v_max=1.0, omega_max=1.0)
    >>> float(v[0]), float(w[0])
    (0.3, 0.8)
    """
    poses = _as_array(poses, (-1, 3), "poses")
    u = _as_array(vel_xy, (poses.shape[0], 2), "vel_xy")
    d = np.asarray(offset_m, dtype=float)
    if np.any(d <= 0):
        raise ValueError(f"offset_m must be > 0 (got {offset_m!r})")
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    v = u[:, 0] * c + u[:, 1] * s
    omega = (-u[:, 0] * s + u[:, 1] * c) / d
    vm = np.broadcast_to(np.asarray(v_max, dtype=float), v.shape)
    wm = np.broadcast_to(np.asarray(omega_max, dtype=float), v.shape)
    if np.any(vm <= 0) or np.any(wm <= 0):
        raise ValueError(f"v_max and omega_max must be > 0 (got {v_max!r}, {omega_max!r})")
    # One factor for both, so the effective centre keeps its direction.
    scale = np.minimum(vm / np.maximum(np.abs(v), vm), wm / np.maximum(np.abs(omega), wm))
    return v * scale, omega * scale


def unicycle_to_holonomic(poses: np.ndarray, v, omega, *, offset_m) -> np.ndarray:
    """Velocity ``(N, 2)`` of the effective centre of unicycles driving with ``(v, omega)``."""
    poses = _as_array(poses, (-1, 3), "poses")
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    v = np.asarray(v, dtype=float)
    lat = np.asarray(offset_m, dtype=float) * np.asarray(omega, dtype=float)
    return np.stack([v * c - lat * s, v * s + lat * c], -1)


# --------------------------------------------------------------------------------------------
# static obstacles


def prepare_obstacles(polygons: Sequence) -> StaticObstacles:
    """Static obstacles from convex polygons (``(k, 2)``, ``k >= 3``) and segments (``(2, 2)``).

    Raises a ValueError naming ``obstacles[i]`` for anything else.
    """
    verts, geoms = [], []
    for i, poly in enumerate(polygons):
        p = _as_array(poly, (-1, 2), f"obstacles[{i}]")
        if p.shape[0] < 2:
            raise ValueError(f"obstacles[{i}]: needs at least 2 points (got {p.tolist()})")
        if p.shape[0] == 2:
            if np.linalg.norm(p[1] - p[0]) <= MIN_EDGE_M:
                raise ValueError(f"obstacles[{i}]: segment of zero length: {p.tolist()}")
            geoms.append(shapely.LineString(p))
        else:
            if _det(p, np.roll(p, -1, axis=0)).sum() < 0:
                p = p[::-1].copy()
            try:
                _check_convex_ccw(p[None], "obstacle")
            except ValueError:
                raise ValueError(f"obstacles[{i}]: not a convex polygon: {p.tolist()}") from None
            if _det(p, np.roll(p, -1, axis=0)).sum() <= 0:
                raise ValueError(f"obstacles[{i}]: polygon of zero area: {p.tolist()}")
            geoms.append(shapely.Polygon(p))
        verts.append(p)
    k = max((len(v) for v in verts), default=2)
    padded = np.empty((len(verts), k, 2))
    for i, v in enumerate(verts):
        padded[i, : len(v)] = v
        padded[i, len(v) :] = v[-1]
    return StaticObstacles(vertices=padded, tree=shapely.STRtree(geoms))


# --------------------------------------------------------------------------------------------
# the step


def _rank_in_group(group: np.ndarray, key: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Order by (group, key) and the rank of each item within its group."""
    order = np.lexsort((key, group))
    g = group[order]
    rank = np.arange(g.size) - np.searchsorted(g, g, side="left")
    return order, rank


def _scatter(n: int, m: int, rows, slots, point, direction):
    """Pack pair constraints into per-robot slots ``(n, m)``."""
    p = np.zeros((n, m, 2))
    d = np.zeros((n, m, 2))
    d[..., 0] = 1.0
    v = np.zeros((n, m), dtype=bool)
    p[rows, slots] = point
    d[rows, slots] = direction
    v[rows, slots] = True
    return p, d, v


def _edge_planes(rx: np.ndarray, ry: np.ndarray):
    """Edge lines of convex regions ``(V, P)``: unit outward normals ``n`` and offsets ``c``
    (interior: ``n · x < c`` for every real edge), and the mask of real edges."""
    ex, ey = _edges(rx), _edges(ry)
    elen = np.sqrt(ex * ex + ey * ey)
    real = elen > MIN_EDGE_M
    inv_len = 1.0 / np.maximum(elen, MIN_EDGE_M)
    nx, ny = ey * inv_len, -ex * inv_len
    return nx, ny, nx * rx + ny * ry, real


def _sweep(planes, dx: np.ndarray, dy: np.ndarray) -> np.ndarray:
    """Whether ``t * (dx, dy)``, ``0 <= t <= 1``, enters the interior of the regions."""
    nx, ny, c, real = planes
    # Inside edge e at time t: t * (n_e . d) < c_e - tol (touching is not a hit).
    a = nx * dx + ny * dy
    b = c - TOUCH_TOLERANCE_M
    flat = np.abs(a) <= 1e-15
    blocked = np.any(real & flat & (b <= 0.0), axis=0)
    ratio = b / np.where(flat, 1.0, a)
    cut = real & ~flat
    t_hi = np.minimum(1.0, np.min(np.where(cut & (a > 0), ratio, np.inf), axis=0))
    t_lo = np.maximum(0.0, np.max(np.where(cut & (a < 0), ratio, -np.inf), axis=0))
    return ~blocked & (t_lo < t_hi)


def _inside_now(planes) -> np.ndarray:
    nx, ny, c, real = planes
    return ~np.any(real & (c - TOUCH_TOLERANCE_M <= 0.0), axis=0)


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
    planes = _edge_planes(np.ascontiguousarray(q[..., 0].T), np.ascontiguousarray(q[..., 1].T))
    return _sweep(planes, disp[:, 0], disp[:, 1]), _inside_now(planes)


def _safety_filter(vel, dt, robot_pairs, obstacle_pairs):
    """Slow robots whose straight one-step motions overlap (see ``OrcaParams.safety_filter``).

    ``robot_pairs`` is ``(i, j, rx, ry)`` for every pair that can meet within one step
    (regions in vertex-major layout) and ``obstacle_pairs`` ``(i, rx, ry)``. Scales only go
    down and a stopped pair that does not overlap now is safe, so the loop ends; pairs that
    overlap already are left to ORCA's separating constraints.
    """
    n = vel.shape[0]
    i, j, rx, ry = robot_pairs
    io, ox, oy = obstacle_pairs
    planes, o_planes = _edge_planes(rx, ry), _edge_planes(ox, oy)
    free, o_free = ~_inside_now(planes), ~_inside_now(o_planes)
    scale = np.ones(n)
    halvings = 0
    while True:
        v = vel * scale[:, None]
        d = (v[i] - v[j]) * dt
        hit = _sweep(planes, d[:, 0], d[:, 1]) & free
        o_hit = _sweep(o_planes, v[io, 0] * dt, v[io, 1] * dt) & o_free
        bad = np.zeros(n, dtype=bool)
        bad[i[hit]] = True
        bad[j[hit]] = True
        bad[io[o_hit]] = True
        bad &= scale > 0
        if not bad.any():
            break
        halvings += 1
        scale[bad] = 0.5 * scale[bad] if halvings <= SAFETY_HALVINGS else 0.0
    return vel * scale[:, None], scale < 1.0


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
    # Robots held on a line: velocity ``v`` with ``|n . v| <= AXIS_SLACK`` (``n`` its normal).
    if axes is not None and n:
        raw_axes = _as_array(np.nan_to_num(np.asarray(axes, dtype=float), nan=0.0), (n, 2), "axes")
        on = ~np.isnan(np.asarray(axes, dtype=float)).any(axis=1)
        ax = np.where(on[:, None], raw_axes, [1.0, 0.0])
        nrm = np.stack([-ax[:, 1], ax[:, 0]], -1) * AXIS_SLACK
        pt = np.stack([-nrm, nrm], 1)
        dr = np.stack([ax, -ax], 1)
        valid = np.repeat(on[:, None], 2, axis=1)
        blocks.append((pt, dr, valid))
        n_hard = 2
    # Static obstacles: hard constraints, full share, their own horizon.
    obstacle_pairs = None
    if obstacles is not None and len(obstacles) and n:
        step_reach = reach + vmax * dt_s
        rng = np.maximum(params.time_horizon_obst_s * speed + reach, step_reach)
        ia, io = obstacles.tree.query(shapely.points(pos), predicate="dwithin", distance=rng)
        if ia.size:
            dist = shapely.distance(shapely.points(pos[ia]), obstacles.tree.geometries[io])
            order, rank = _rank_in_group(ia, dist)
            ia, io, dist = ia[order], io[order], dist[order]
            region = minkowski_difference(obstacles.vertices[io] - pos[ia, None], shp[ia])
            # The nearest few constrain ORCA; the safety filter checks all within one step.
            keep = rank < params.max_obstacles
            if keep.any():
                pt, dr = pair_halfplanes(
                    region[keep],
                    vel[ia[keep]],
                    vel[ia[keep]],
                    np.ones(int(keep.sum())),
                    np.full(int(keep.sum()), 1.0 / params.time_horizon_obst_s),
                    inv_dt,
                )
                m_obst = int(rank[keep].max()) + 1
                n_hard += m_obst
                blocks.append(_scatter(n, m_obst, ia[keep], rank[keep], pt, dr))
            near = dist <= step_reach[ia]
            obstacle_pairs = (
                ia[near],
                np.ascontiguousarray(region[near, :, 0].T),
                np.ascontiguousarray(region[near, :, 1].T),
            )

    # People: moving discs, full share.
    if people_positions is not None and params.max_people and n:
        ppos = _as_array(people_positions, (-1, 2), "people_positions")
        n_p = ppos.shape[0]
        pvel = _as_array(
            np.zeros((n_p, 2)) if people_velocities is None else people_velocities,
            (n_p, 2),
            "people_velocities",
        )
        if people_radii is None:
            raise ValueError("people_radii: required with people_positions")
        prad = _as_array(
            np.broadcast_to(np.asarray(people_radii, dtype=float), (n_p,)), (n_p,), "people_radii"
        )
        if np.any(prad <= 0):
            raise ValueError(f"people_radii must be > 0 (got {prad.min()!r})")
        if n_p:
            k = min(params.max_people, n_p)
            cut = params.time_horizon_s * (speed.max() + np.linalg.norm(pvel, axis=-1).max()) + (
                reach.max() + prad.max() / np.cos(np.pi / params.disc_sides)
            )
            dist, idx = cKDTree(ppos).query(pos, k=k, distance_upper_bound=cut)
            dist, idx = dist.reshape(n, k), idx.reshape(n, k)
            rows, slots = np.nonzero(idx < n_p)
            if rows.size:
                j = idx[rows, slots]
                disc = disc_polygons(ppos[j] - pos[rows], prad[j], params.disc_sides)
                region = minkowski_difference(disc, shp[rows])
                # A person does not react, so any tangent of the velocity obstacle is safe;
                # the one nearest the preferred velocity steps aside instead of only braking
                # in front of a flat face (the nearest tangent to the current velocity).
                pt, dr = pair_halfplanes(
                    region,
                    pref[rows] - pvel[j],
                    pref[rows],
                    np.ones(rows.size),
                    np.full(rows.size, 1.0 / params.time_horizon_s),
                    inv_dt,
                    params.leg_preference,
                )
                blocks.append(_scatter(n, k, rows, slots, pt, dr))

    # Other robots: reciprocal, shares by priority. Each unordered pair is built once: the
    # obstacle of j seen from i is the point reflection of that of i seen from j.
    robot_pairs = (np.zeros(0, int), np.zeros(0, int), np.zeros((3, 0)), np.zeros((3, 0)))
    if n > 1:
        keys = []
        rows = nb = slots = np.zeros(0, int)
        m_agents = 0
        if params.max_neighbours:
            cut = params.neighbour_dist_m
            if cut is None:
                top = np.sort(speed)[-2:].sum()
                cut = params.time_horizon_s * top + np.sort(reach)[-2:].sum()
            k = min(params.max_neighbours + 1, n)
            dist, idx = cKDTree(pos).query(pos, k=k, distance_upper_bound=cut)
            ok = (idx < n) & (idx != np.arange(n)[:, None])
            safe = np.where(ok, idx, 0)
            rel = pos[safe] - pos[:, None]
            # Nearest first; exact distance ties broken by geometry, not by robot index.
            key_d = np.where(ok, dist, np.inf)
            order = np.lexsort((rel[..., 1], rel[..., 0], key_d), axis=-1)
            order = order[:, : params.max_neighbours]
            ok = np.take_along_axis(ok, order, axis=1)
            safe = np.take_along_axis(safe, order, axis=1)
            m_agents = order.shape[1]
            rows, slots = np.nonzero(ok)
            nb = safe[rows, slots]
            keys.append(np.minimum(rows, nb) * n + np.maximum(rows, nb))
        n_orca = sum(len(x) for x in keys)
        if params.safety_filter:
            # Pairs that can touch within one step at the speed limits.
            near = 2.0 * reach.max() + 2.0 * vmax.max() * dt_s
            fp = cKDTree(pos).query_pairs(near, output_type="ndarray")
            keys.append(fp[:, 0].astype(np.int64) * n + fp[:, 1])
        if keys and sum(len(x) for x in keys):
            uniq, inverse = np.unique(np.concatenate(keys), return_inverse=True)
            lo, hi = uniq // n, uniq % n
            # Build each pair from the side of the robot with the smaller (x, y), not the
            # smaller index, so that the floats do not depend on the robots' order.
            swap = (pos[hi, 0] < pos[lo, 0]) | (
                (pos[hi, 0] == pos[lo, 0]) & (pos[hi, 1] < pos[lo, 1])
            )
            lo, hi = np.where(swap, hi, lo), np.where(swap, lo, hi)
            # Vertex-major shapes (K, N): the kernels loop over a few vertices, not pairs.
            sx, sy = np.ascontiguousarray(shp[..., 0].T), np.ascontiguousarray(shp[..., 1].T)
            rx, ry = _in_chunks(
                _minkowski_xy, 2, lo.size, (sx[:, hi], sy[:, hi], sx[:, lo], sy[:, lo]), ()
            )
            rx += pos[hi, 0] - pos[lo, 0]
            ry += pos[hi, 1] - pos[lo, 1]
            if params.safety_filter:
                f_idx = np.unique(inverse[n_orca:])
                robot_pairs = (lo[f_idx], hi[f_idx], rx[:, f_idx], ry[:, f_idx])
            if rows.size:
                used, pair_of = np.unique(inverse[:n_orca], return_inverse=True)
                a, b = lo[used], hi[used]
                rel_opt = vel[a] - vel[b]
                ux, uy, nx, ny, inside = _in_chunks(
                    _vo_projection,
                    5,
                    used.size,
                    (rx[:, used], ry[:, used]),
                    (
                        rel_opt[:, 0],
                        rel_opt[:, 1],
                        np.full(used.size, 1.0 / params.time_horizon_s),
                    ),
                    inv_dt,
                    params.leg_preference,
                    params.keep_right,
                )
                sign = np.where(rows == a[pair_of], 1.0, -1.0)
                share = responsibility_shares(prio[rows], prio[nb], params.min_share)
                # Outside the obstacle u is room to approach: the higher priority gets the
                # larger part of it (the complement still sums to one over the pair).
                share = np.where(inside[pair_of], share, 1.0 - share)
                # Against a robot that will not move, all of it is ours, either way.
                share = np.where(still[nb], 1.0, share)
                pt, dr = _lines(
                    vel[rows],
                    share,
                    sign * ux[pair_of],
                    sign * uy[pair_of],
                    sign * nx[pair_of],
                    sign * ny[pair_of],
                )
                blocks.append(_scatter(n, m_agents, rows, slots, pt, dr))

    if blocks:
        point = np.concatenate([b[0] for b in blocks], axis=1)
        direction = np.concatenate([b[1] for b in blocks], axis=1)
        valid = np.concatenate([b[2] for b in blocks], axis=1)
    else:
        point, direction = np.zeros((n, 0, 2)), np.zeros((n, 0, 2))
        valid = np.zeros((n, 0), dtype=bool)
    halfplanes = HalfPlanes(point=point, direction=direction, valid=valid, n_hard=n_hard)

    out = np.zeros((n, 2))
    infeasible = np.zeros(n, dtype=bool)
    move = np.flatnonzero(~still)
    if move.size:
        sub = HalfPlanes(point[move], direction[move], valid[move], n_hard)
        out[move], infeasible[move] = solve_velocity_lp(
            sub, pref[move], vmax[move], slowest_fallback=params.slowest_fallback
        )
    slowed = np.zeros(n, dtype=bool)
    if params.safety_filter and n:
        if obstacle_pairs is None:
            obstacle_pairs = (np.zeros(0, int), np.zeros((3, 0)), np.zeros((3, 0)))
        out, slowed = _safety_filter(out, dt_s, robot_pairs, obstacle_pairs)
    return OrcaResult(velocities=out, infeasible=infeasible, halfplanes=halfplanes, slowed=slowed)
