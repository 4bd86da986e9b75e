"""Convex pieces of the free region for the convex layout: a non-convex region (non-convex
boundary, or obstacles inside) is split into convex pieces (strips or constrained Delaunay
triangles, then adjacent pieces merged while their union stays convex), each written as
``normals @ z <= offsets`` with its cuts between pieces marked."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely
from shapely.geometry import Polygon

__all__ = [
    "ConvexPiece",
    "convex_pieces",
    "DECOMPOSITIONS",
    "CUT_WEIGHT",
    "SIMPLIFY_ABOVE_VERTICES",
    "SIMPLIFY_TOL_M",
    "MIN_PIECE_INRADIUS_M",
]

#: Weight of a cut between convex pieces in the boundary-distance rows: a skid keeps
#: ``R_j * weight`` from a cut, the skid on the other side as much. Walls across a cut are
#: not covered by this; the piece program keeps them at ``R_j`` by cutting planes
#: (:func:`swarmpark.layout.convex.columns.wall_cuts`).
CUT_WEIGHT = 0.5
#: Free regions with more vertices than this (map staircases) are simplified first, by
#: eroding by ``SIMPLIFY_TOL_M`` and simplifying with the same tolerance (stays inside).
SIMPLIFY_ABOVE_VERTICES = 120
SIMPLIFY_TOL_M = 0.05
#: Pieces thinner than this (inradius, metres) hold nothing useful and are dropped.
MIN_PIECE_INRADIUS_M = 1e-3


@dataclass(frozen=True, eq=False)
class ConvexPiece:
    """A convex piece of the free region, as ``normals @ z <= offsets``.

    Attributes
    ----------
    polygon
        The piece (counter-clockwise), layout frame.
    normals
        ``(E, 2)`` unit outward edge normals.
    offsets
        ``(E,)`` so that the piece is ``normals @ z <= offsets``.
    weights
        ``(E,)`` 1 for an edge on the free region's edge (boundary, wall, obstacle),
        :data:`CUT_WEIGHT` for a cut between pieces.
    """

    polygon: Polygon
    normals: np.ndarray
    offsets: np.ndarray
    weights: np.ndarray

    @property
    def is_whole(self) -> bool:
        return bool(np.all(self.weights == 1.0))


def _is_convex(poly: Polygon) -> bool:
    return len(poly.interiors) == 0 and poly.area >= poly.convex_hull.area * (1.0 - 1e-9)


def _merge_convex(polys: list[Polygon]) -> list[Polygon]:
    """Merge adjacent convex polygons while their union stays convex, across the longest
    shared edges first (Hertel-Mehlhorn style)."""
    polys = [p for p in polys if p.area > 0]
    tree = shapely.STRtree(polys)
    left, right = tree.query(polys, predicate="touches")
    keep = left < right
    left, right = left[keep], right[keep]
    shared = (
        shapely.length(
            shapely.intersection(
                shapely.boundary(np.take(polys, left)), shapely.boundary(np.take(polys, right))
            )
        )
        if len(left)
        else np.zeros(0)
    )
    order = sorted(range(len(left)), key=lambda k: (-round(float(shared[k]), 9), left[k], right[k]))
    parent = list(range(len(polys)))
    merged: dict[int, Polygon] = dict(enumerate(polys))

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for k in order:
        if shared[k] <= 1e-9:
            continue
        ri, rj = find(int(left[k])), find(int(right[k]))
        if ri == rj:
            continue
        union = shapely.union(merged[ri], merged[rj])
        if union.geom_type == "Polygon" and _is_convex(union):
            merged[ri] = union
            parent[rj] = ri
            del merged[rj]
    return [merged[k] for k in sorted(merged)]


def _triangles(part: Polygon) -> list[Polygon]:
    """Constrained Delaunay triangles of a polygon (holes respected)."""
    return [
        t for t in shapely.get_parts(shapely.constrained_delaunay_triangles(part)) if t.area > 0
    ]


def _strips(part: Polygon, axis: int) -> list[Polygon]:
    """Slabs between consecutive vertex coordinates along ``axis``: every component of the
    polygon in a slab with no vertex strictly inside is a trapezoid (convex)."""
    xs = np.unique(np.round(shapely.get_coordinates(part.boundary)[:, axis], 9))
    x0, y0, x1, y1 = part.bounds
    out = []
    for lo, hi in zip(xs[:-1], xs[1:], strict=True):
        if hi - lo < 1e-9:
            continue
        slab = (
            shapely.box(lo, y0 - 1, hi, y1 + 1)
            if axis == 0
            else shapely.box(x0 - 1, lo, x1 + 1, hi)
        )
        for g in shapely.get_parts(part.intersection(slab)):
            if g.geom_type != "Polygon" or g.area <= 1e-12:
                continue
            out.extend([g] if _is_convex(g) else _triangles(g))
    return out


#: Ways to split a non-convex polygon into convex pieces, tried in turn.
DECOMPOSITIONS = ("vertical strips", "horizontal strips", "triangles")


def _make_piece(poly: Polygon, edge_band) -> ConvexPiece | None:
    """A :class:`ConvexPiece` with cut edges marked (``edge_band``: a thin band around the
    free region's boundary)."""
    pts = np.asarray(poly.simplify(0.0).exterior.coords)
    if _signed_area(pts) < 0:
        pts = pts[::-1]
    d = np.diff(pts, axis=0)
    length = np.hypot(d[:, 0], d[:, 1])
    keep = length > 1e-12
    normals = np.column_stack([d[keep, 1], -d[keep, 0]]) / length[keep, None]
    offsets = np.einsum("ij,ij->i", normals, pts[:-1][keep])
    # An edge is a cut only if no stretch of it lies on the free region's edge: the rows are
    # whole lines, so a line that is partly wall must keep the full distance.
    # Tested with a 0.1 um tolerance band: pieces' vertices are computed, not exact. Errors
    # go the safe way (a cut taken for a wall keeps the full distance).
    segs = shapely.linestrings(np.stack([pts[:-1][keep], pts[1:][keep]], axis=1))
    on_edge = shapely.length(shapely.intersection(segs, edge_band)) > 1e-6
    weights = np.where(on_edge, 1.0, CUT_WEIGHT)
    piece = ConvexPiece(Polygon(pts), normals, offsets, weights)
    return piece if _inradius(piece) > MIN_PIECE_INRADIUS_M else None


def convex_pieces(free, score=None) -> tuple[list[ConvexPiece], str]:
    """Split the free region (layout frame) into convex pieces with marked cuts.

    A convex region is one piece. Otherwise every decomposition in :data:`DECOMPOSITIONS`
    is made and the one with the highest ``score(pieces)`` (default: fewest pieces) is
    kept; ties go to the first. Returns the pieces and the decomposition's name.
    """
    if shapely.get_coordinates(free.boundary).shape[0] > SIMPLIFY_ABOVE_VERTICES:
        free = free.buffer(-SIMPLIFY_TOL_M, join_style="mitre").simplify(SIMPLIFY_TOL_M)
    edge = free.boundary.buffer(1e-7)
    shapely.prepare(edge)
    parts = [p for p in shapely.get_parts(free) if not p.is_empty and p.area > 0]
    if all(_is_convex(p) for p in parts):
        pieces = [_make_piece(p, edge) for p in parts]
        return [p for p in pieces if p is not None], "none"
    best: tuple[float, list[ConvexPiece], str] | None = None
    for name in DECOMPOSITIONS:
        polys: list[Polygon] = []
        for part in parts:
            if _is_convex(part):
                polys.append(part)
            elif name == "triangles":
                polys.extend(_merge_convex(_triangles(part)))
            else:
                polys.extend(_merge_convex(_strips(part, 0 if name.startswith("v") else 1)))
        pieces = [p for p in (_make_piece(q, edge) for q in polys) if p is not None]
        value = score(pieces) if score is not None else -len(pieces)
        if best is None or value > best[0]:
            best = (value, pieces, name)
    assert best is not None
    return best[1], best[2]


def _signed_area(pts: np.ndarray) -> float:
    x, y = pts[:, 0], pts[:, 1]
    return 0.5 * float(np.dot(x[:-1], y[1:]) - np.dot(x[1:], y[:-1]))


def _inradius(piece: ConvexPiece) -> float:
    """Radius of the largest disc in the piece (eq. 7), from its vertices (cheap bound)."""
    c = np.asarray(piece.polygon.representative_point().coords[0])
    return float(np.min(piece.offsets - piece.normals @ c))
