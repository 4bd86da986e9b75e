"""Shapes for the ORCA kernel: footprints, Minkowski differences, discs, static obstacles and
the effective-centre conversion between unicycles and holonomic points (numpy).

Split from :mod:`.kernel` (which re-exports every public name here).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import shapely

from swarmpark.control.orca import pairs
from swarmpark.control.orca.pairs import MIN_EDGE_M

__all__ = [
    "StaticObstacles",
    "prepare_obstacles",
    "minkowski_difference",
    "disc_polygons",
    "inflate_convex",
    "skid_shapes",
    "holonomic_speed_limit",
    "effective_reach",
    "tracking_error_bound",
    "holonomic_to_unicycle",
    "unicycle_to_holonomic",
]

#: Above this many edge pairs, the Minkowski merge sorts instead of counting ranks.
SMALL_MERGE = 64
#: Sides of the regular polygon that covers a person's disc (circumscribed: conservative).
DEFAULT_DISC_SIDES = 8


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
    i = pairs.first_not_convex_ccw(np.ascontiguousarray(polys, dtype=float))
    if i >= 0:
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
