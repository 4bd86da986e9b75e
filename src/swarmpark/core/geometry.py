"""Poses, rectangular skid footprints, batched rigid transforms and exact convex collision kernels.

Frames follow ROS REP-103: world x right, y up, yaw counter-clockwise from +x; a skid's body
frame has its origin at the pivot (middle of the rear axle in the papers), x forward, y left.
Batches are numpy arrays: poses ``(N, 3)``, points ``(N, 2)``, convex polygons ``(N, K, 2)``
with counter-clockwise vertices.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import shapely
from shapely.geometry import Polygon

from swarmpark.core.limits import (
    MAX_COORDINATE_M,
    MAX_FOOTPRINT_M,
    MIN_FOOTPRINT_M,
    check_vertices,
)

__all__ = [
    "Footprint",
    "wrap_angle",
    "rotation",
    "transform_points",
    "footprint_corners",
    "footprint_polygon",
    "pivot_to_center",
    "center_to_pivot",
    "convex_overlap",
    "convex_gap",
    "convex_distance",
    "point_segment_distance",
    "rect_disc_gap",
    "integrate_unicycle",
    "triangulate",
    "pad_polygons",
    "as_simple_polygon",
    "GeometryError",
]

#: Penetration below this depth (metres) is treated as touching, not as a collision. Exact
#: touching has measure zero in a simulation, and float round-off must not flip it.
TOUCH_TOLERANCE_M = 1e-9


class GeometryError(ValueError):
    """A geometric input that cannot be used (not a simple polygon, degenerate footprint)."""


@dataclass(frozen=True)
class Footprint:
    """A skid's rectangular outline in its body frame.

    Parameters
    ----------
    length_m, width_m
        Outer dimensions along body x (forward) and y (left).
    pivot_from_rear_m
        Distance from the rear edge to the pivot (the point the skid turns about and the origin
        of its pose). ``None`` puts the pivot at the middle of the body.

    Examples
    --------
    >>> fp = Footprint(length_m=1.25, width_m=0.75, pivot_from_rear_m=0.25)
    >>> fp.corners_body().tolist()
    [[-0.25, -0.375], [1.0, -0.375], [1.0, 0.375], [-0.25, 0.375]]
    >>> fp.center_offset_m
    0.375
    """

    length_m: float
    width_m: float
    pivot_from_rear_m: float | None = None

    def __post_init__(self) -> None:
        if not (self.length_m > 0 and self.width_m > 0):
            raise GeometryError(
                f"footprint: length_m and width_m must be > 0 (got {self.length_m}, {self.width_m})"
            )
        small, big = MIN_FOOTPRINT_M, MAX_FOOTPRINT_M
        if not (small <= self.length_m <= big and small <= self.width_m <= big):
            raise GeometryError(
                f"footprint: length_m and width_m must lie within {small}..{big} m "
                f"(got {self.length_m}, {self.width_m})"
            )
        if self.pivot_from_rear_m is None:
            object.__setattr__(self, "pivot_from_rear_m", self.length_m / 2.0)
        elif not (0.0 <= self.pivot_from_rear_m <= self.length_m):
            raise GeometryError(
                f"footprint.pivot_from_rear_m must lie within the body, 0..{self.length_m} "
                f"(got {self.pivot_from_rear_m})"
            )

    @property
    def pivot(self) -> float:
        """Pivot distance from the rear edge (resolved, never ``None``)."""
        return float(self.pivot_from_rear_m)  # type: ignore[arg-type]

    @property
    def center_offset_m(self) -> float:
        """Body-x offset of the rectangle's centre from the pivot."""
        return self.length_m / 2.0 - self.pivot

    @property
    def circumradius_m(self) -> float:
        """Radius of the smallest disc about the rectangle's centre that covers it."""
        return 0.5 * float(np.hypot(self.length_m, self.width_m))

    @property
    def reach_m(self) -> float:
        """Radius of the smallest disc about the pivot that covers the rectangle."""
        far = max(self.pivot, self.length_m - self.pivot)
        return float(np.hypot(far, self.width_m / 2.0))

    def corners_body(self) -> np.ndarray:
        """Corners ``(4, 2)`` in the body frame, counter-clockwise from rear-right."""
        r, f, h = -self.pivot, self.length_m - self.pivot, self.width_m / 2.0
        return np.array([[r, -h], [f, -h], [f, h], [r, h]], dtype=float)


def wrap_angle(a):
    """Wrap angles to ``[-pi, pi)``."""
    return (np.asarray(a) + np.pi) % (2.0 * np.pi) - np.pi


def rotation(yaw) -> np.ndarray:
    """Rotation matrices ``(..., 2, 2)`` for yaw angles."""
    c, s = np.cos(yaw), np.sin(yaw)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


def transform_points(poses: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Body-frame points ``(N, K, 2)`` (or ``(K, 2)`` shared) to world, for poses ``(N, 3)``."""
    poses = np.asarray(poses, dtype=float).reshape(-1, 3)
    pts = np.asarray(points, dtype=float)
    if pts.ndim == 2:
        pts = np.broadcast_to(pts, (poses.shape[0], *pts.shape))
    c, s = np.cos(poses[:, 2])[:, None], np.sin(poses[:, 2])[:, None]
    x = poses[:, 0:1] + c * pts[..., 0] - s * pts[..., 1]
    y = poses[:, 1:2] + s * pts[..., 0] + c * pts[..., 1]
    return np.stack([x, y], -1)


def body_corners(footprints: Sequence[Footprint]) -> np.ndarray:
    """Stack the body-frame corners of many footprints, ``(N, 4, 2)``."""
    return np.stack([fp.corners_body() for fp in footprints]) if footprints else np.zeros((0, 4, 2))


def footprint_corners(poses: np.ndarray, corners_body: np.ndarray) -> np.ndarray:
    """World corners ``(N, 4, 2)`` of footprints with body corners ``(N, 4, 2)`` at ``poses``."""
    return transform_points(poses, corners_body)


def footprint_polygon(pose: Sequence[float], footprint: Footprint) -> Polygon:
    """The footprint at one pose as a shapely polygon."""
    return Polygon(footprint_corners(np.asarray(pose)[None], footprint.corners_body()[None])[0])


def pivot_to_center(poses: np.ndarray, offsets_m: np.ndarray) -> np.ndarray:
    """Rectangle centres ``(N, 2)`` of skids at pivot ``poses`` with body-x centre offsets."""
    poses = np.asarray(poses, dtype=float).reshape(-1, 3)
    off = np.asarray(offsets_m, dtype=float)
    return poses[:, :2] + off[..., None] * np.stack([np.cos(poses[:, 2]), np.sin(poses[:, 2])], -1)


def center_to_pivot(centers: np.ndarray, yaws: np.ndarray, offsets_m: np.ndarray) -> np.ndarray:
    """Pivot poses ``(N, 3)`` for rectangles centred at ``centers`` with headings ``yaws``."""
    centers = np.asarray(centers, dtype=float).reshape(-1, 2)
    yaws = np.broadcast_to(np.asarray(yaws, dtype=float), centers.shape[:1])
    off = np.asarray(offsets_m, dtype=float)
    xy = centers - off[..., None] * np.stack([np.cos(yaws), np.sin(yaws)], -1)
    return np.column_stack([xy, yaws])


def _edge_normals(polys: np.ndarray) -> np.ndarray:
    """Unit normals ``(M, K, 2)`` of the edges of convex polygons ``(M, K, 2)``."""
    edges = np.roll(polys, -1, axis=1) - polys
    normals = np.stack([edges[..., 1], -edges[..., 0]], -1)
    norm = np.linalg.norm(normals, axis=-1, keepdims=True)
    # Padded polygons repeat a vertex; their zero-length edges give no axis (any unit axis works).
    return np.where(norm > 1e-12, normals / np.maximum(norm, 1e-12), np.array([1.0, 0.0]))


def convex_overlap(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Penetration depth ``(M,)`` of convex polygon pairs by the separating-axis theorem.

    ``a`` is ``(M, K, 2)`` and ``b`` is ``(M, L, 2)``. The result is the smallest overlap of the
    projections over all edge normals: positive when the interiors intersect, zero or negative
    when they are separated or touch.
    """
    from swarmpark.core.kernels import convex_overlap_pairs

    # Compiled: the same numbers as convex_overlap_numpy, without its (M, axes, K) temporaries.
    return convex_overlap_pairs(*_pairs_arrays(a, b))


def _pairs_arrays(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``a`` and ``b`` as C-contiguous float arrays ``(M, K, 2)`` and ``(M, L, 2)`` for the
    compiled kernels (a single polygon, ``M = 1``, broadcast against the other side)."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    m = max(len(a), len(b))
    if len(a) != m:
        a = np.broadcast_to(a, (m, *a.shape[1:]))
    if len(b) != m:
        b = np.broadcast_to(b, (m, *b.shape[1:]))
    return np.ascontiguousarray(a), np.ascontiguousarray(b)


def convex_overlap_numpy(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """:func:`convex_overlap` in numpy (the reference the compiled form is tested against)."""
    axes = np.concatenate([_edge_normals(a), _edge_normals(b)], axis=1)  # (M, K+L, 2)
    ax, ay = axes[:, :, None, 0], axes[:, :, None, 1]
    pa = ax * a[:, None, :, 0] + ay * a[:, None, :, 1]  # (M, axes, K)
    pb = ax * b[:, None, :, 0] + ay * b[:, None, :, 1]
    overlap = np.minimum(pa.max(-1), pb.max(-1)) - np.maximum(pa.min(-1), pb.min(-1))
    return overlap.min(-1)


#: Up to this many boxes are searched by testing every pair (compiled), beyond by the tree.
BOX_SCAN_MAX = 256


def envelope_pairs(
    lo: np.ndarray, hi: np.ndarray, tree_lo: np.ndarray, tree_hi: np.ndarray, tree
) -> tuple[np.ndarray, np.ndarray]:
    """The (query, tree item) pairs whose boxes meet, as ``tree.query`` of the boxes
    ``lo``-``hi`` ``(Q, 2)`` gives them (``tree``: a shapely STRtree of the boxes
    ``tree_lo``-``tree_hi``): the same pairs, possibly in another order. Few boxes are tested
    pair by pair (compiled), which costs less than making the query boxes for the tree."""
    if len(tree_lo) > BOX_SCAN_MAX:
        return tree.query(shapely.box(lo[:, 0], lo[:, 1], hi[:, 0], hi[:, 1]))
    from swarmpark.core.kernels import box_pairs

    f = np.float64
    return box_pairs(
        np.ascontiguousarray(lo, dtype=f),
        np.ascontiguousarray(hi, dtype=f),
        np.ascontiguousarray(tree_lo, dtype=f),
        np.ascontiguousarray(tree_hi, dtype=f),
    )


def point_segment_distance(p: np.ndarray, s0: np.ndarray, s1: np.ndarray) -> np.ndarray:
    """Distances between points ``(..., 2)`` and segments ``s0 -> s1`` (broadcast)."""
    dx, dy = s1[..., 0] - s0[..., 0], s1[..., 1] - s0[..., 1]
    px, py = p[..., 0] - s0[..., 0], p[..., 1] - s0[..., 1]
    t = np.clip((px * dx + py * dy) / np.maximum(dx * dx + dy * dy, 1e-18), 0.0, 1.0)
    ex, ey = px - t * dx, py - t * dy
    return np.sqrt(ex * ex + ey * ey)


def convex_distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance ``(M,)`` between convex polygon pairs known not to overlap (0 if touching)."""
    from swarmpark.core.kernels import convex_distance_pairs

    # Compiled: the same numbers as convex_distance_numpy.
    return convex_distance_pairs(*_pairs_arrays(a, b))


def convex_distance_numpy(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """:func:`convex_distance` in numpy (the reference the compiled form is tested against)."""
    a_next, b_next = np.roll(a, -1, axis=1), np.roll(b, -1, axis=1)
    # Each vertex of one polygon against each edge of the other: (M, K, L).
    d_ab = point_segment_distance(a[:, :, None, :], b[:, None, :, :], b_next[:, None, :, :])
    d_ba = point_segment_distance(b[:, :, None, :], a[:, None, :, :], a_next[:, None, :, :])
    return np.minimum(d_ab.min(axis=(1, 2)), d_ba.min(axis=(1, 2)))


def convex_gap(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Signed gap ``(M,)`` between convex polygon pairs: distance if apart, minus depth if not.

    Examples
    --------
    >>> sq = np.array([[[0, 0], [1, 0], [1, 1], [0, 1]]], float)
    >>> float(convex_gap(sq, sq + [3.0, 0.0])[0])
    2.0
    >>> float(convex_gap(sq, sq + [0.5, 0.0])[0])
    -0.5
    """
    depth = convex_overlap(a, b)
    return np.where(depth > TOUCH_TOLERANCE_M, -depth, convex_distance(a, b))


def rect_disc_gap(corners: np.ndarray, centers: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """Signed gap ``(M,)`` between rectangles ``(M, 4, 2)`` and discs (``(M, 2)``, ``(M,)``).

    Inside a rectangle the gap is minus (depth of the centre + radius), a penetration measure.
    """
    origin = corners[:, 0]
    ex, ey = corners[:, 1] - origin, corners[:, 3] - origin
    lx, ly = np.linalg.norm(ex, axis=-1), np.linalg.norm(ey, axis=-1)
    rel = centers - origin
    u = np.einsum("md,md->m", rel, ex) / lx
    w = np.einsum("md,md->m", rel, ey) / ly
    du = np.maximum(np.maximum(-u, u - lx), 0.0)
    dw = np.maximum(np.maximum(-w, w - ly), 0.0)
    outside = np.hypot(du, dw)
    inside = np.minimum(np.minimum(u, lx - u), np.minimum(w, ly - w))
    return np.where(outside > 0, outside - radii, -inside - radii)


def as_simple_polygon(points, field: str, *, max_vertices: int | None = None) -> Polygon:
    """A shapely polygon from vertices, or a :class:`GeometryError` naming ``field``.

    The polygon must have at least three distinct vertices, non-zero area, no
    self-intersection and at most ``max_vertices`` vertices (default
    :data:`~swarmpark.core.limits.MAX_POLYGON_VERTICES`). Orientation is normalized to
    counter-clockwise.
    """
    try:
        pts = np.asarray(points, dtype=float)
    except (TypeError, ValueError) as exc:
        raise GeometryError(f"{field}: not a list of [x, y] points ({points!r})") from exc
    if pts.ndim != 2 or pts.shape[1] != 2 or pts.shape[0] < 3:
        raise GeometryError(f"{field}: a polygon needs at least 3 [x, y] points (got {points!r})")
    if not np.all(np.isfinite(pts)):
        raise GeometryError(f"{field}: coordinates must be finite (got {points!r})")
    if np.abs(pts).max() > MAX_COORDINATE_M:
        raise GeometryError(
            f"{field}: coordinates must lie within +-{MAX_COORDINATE_M:g} m "
            f"(got {float(np.abs(pts).max()):g})"
        )
    check_vertices(len(pts), field, error=GeometryError, limit=max_vertices)
    poly = Polygon(pts)
    if not poly.is_valid or poly.area <= 0:
        reason = shapely.is_valid_reason(poly)
        raise GeometryError(f"{field}: not a simple polygon ({reason}): {pts.tolist()}")
    return shapely.orient_polygons(poly) if hasattr(shapely, "orient_polygons") else poly


def triangulate(poly: Polygon) -> np.ndarray:
    """Constrained triangulation of a simple polygon into convex pieces ``(T, 3, 2)``."""
    tris = shapely.get_parts(shapely.constrained_delaunay_triangles(poly))
    out = np.array([np.asarray(t.exterior.coords)[:3] for t in tris], dtype=float)
    # Counter-clockwise vertices.
    cross = (out[:, 1, 0] - out[:, 0, 0]) * (out[:, 2, 1] - out[:, 0, 1]) - (
        out[:, 1, 1] - out[:, 0, 1]
    ) * (out[:, 2, 0] - out[:, 0, 0])
    out[cross < 0] = out[cross < 0][:, ::-1]
    return out


def pad_polygons(polys: Sequence[np.ndarray], k: int = 4) -> np.ndarray:
    """Pad convex polygons with fewer than ``k`` vertices by repeating the last one."""
    out = np.empty((len(polys), k, 2))
    for i, p in enumerate(polys):
        p = np.asarray(p, dtype=float)
        out[i, : len(p)] = p
        out[i, len(p) :] = p[-1]
    return out


#: Yaw rates below this are integrated as straight lines.
_STRAIGHT_EPS = 1e-9


def integrate_unicycle(poses: np.ndarray, v: np.ndarray, w: np.ndarray, dt: float) -> np.ndarray:
    """Exact arc integration of pivot poses ``(N, 3)`` under constant ``v, w`` for ``dt``."""
    x, y, th = poses[:, 0], poses[:, 1], poses[:, 2]
    dth = w * dt
    straight = np.abs(w) < _STRAIGHT_EPS
    safe_w = np.where(straight, 1.0, w)
    # Each sine and cosine once (both branches use them; the same values as computing them
    # per branch).
    s0, c0 = np.sin(th), np.cos(th)
    th1 = th + dth
    dx = np.where(straight, v * dt * c0, v / safe_w * (np.sin(th1) - s0))
    dy = np.where(straight, v * dt * s0, -v / safe_w * (np.cos(th1) - c0))
    new_th = (th1 + np.pi) % (2 * np.pi) - np.pi
    return np.column_stack([x + dx, y + dy, new_th])
