"""The parking region and the skids in the *layout frame*, shared by every layout method.

The layout frame is the world frame rotated by ``-heading`` about the origin, so every skid
(all park with the same heading) is an axis-aligned rectangle there: body x along layout x.
Methods work on rectangle centres in this frame; :func:`centres_to_poses` turns them into
world pivot poses.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import shapely
from shapely import affinity
from shapely.geometry import Polygon
from shapely.geometry.base import BaseGeometry

from swarmpark.core.geometry import Footprint, as_simple_polygon, center_to_pivot, rotation
from swarmpark.core.limits import MAX_BOUNDARY_VERTICES

__all__ = [
    "LayoutError",
    "Region",
    "Skids",
    "make_region",
    "make_skids",
    "non_negative",
    "rect_gaps",
    "centres_to_poses",
    "describe_skids",
    "BOUNDARY_QUAD_SEGS",
    "MARGIN_TOL_M",
]

#: Segments per quarter circle when eroding the free region by the margin (shapely ``buffer``).
BOUNDARY_QUAD_SEGS = 16
#: Eroding by the margin offsets straight edges exactly, but rounds reflex corners with
#: chords that cut inside the true arc. Discs of radius ``margin * factor`` (whose chords lie
#: outside the true circle) around every vertex are cut away too, so the region is
#: conservative while a skid can still sit exactly ``margin`` from a straight edge.
_DISC_FACTOR = 1.0 / np.cos(np.pi / (4 * BOUNDARY_QUAD_SEGS))
#: Slack (metres) allowed when checking spacings against the margin: round-off, solver
#: tolerances. A micrometre is far below anything a skid can feel.
MARGIN_TOL_M = 1e-6
#: Containment tests shrink rectangles by this much (metres) so an exact fit (a skid exactly
#: ``margin`` from an edge) survives float round-off; far inside :data:`MARGIN_TOL_M`.
FIT_TOL_M = 1e-9
#: Grid (metres) the free region is snapped to (see :func:`make_region`).
GRID_SIZE_M = 1e-9
#: Thickness (metres) given to line or point obstacles (a wall drawn as a line) so that
#: subtracting them cuts the region.
_LINE_OBSTACLE_THICKNESS_M = 1e-3


class LayoutError(ValueError):
    """A layout that cannot be made: bad input, or fewer skids fit than asked for.

    Attributes
    ----------
    fits
        How many skids do fit (``None`` when the error is not about room).
    """

    def __init__(self, message: str, fits: int | None = None) -> None:
        super().__init__(message)
        self.fits = fits


@dataclass(frozen=True, eq=False)
class Region:
    """Parking geometry in the layout frame.

    Attributes
    ----------
    heading
        Yaw (radians) of every parked skid in the world; the layout frame is the world
        rotated by ``-heading``.
    boundary
        The operator's boundary (counter-clockwise), layout frame.
    free
        ``boundary`` minus obstacles and walls (Polygon or MultiPolygon), layout frame.
    obstacles
        Obstacles clipped to the boundary, layout frame (possibly empty).
    margin
        Required clearance (metres) between skids and from skids to the edge of ``free``.
    inner
        ``free`` eroded by (slightly more than) ``margin``, prepared: a rectangle that lies
        in ``inner`` keeps at least ``margin`` from every wall and obstacle.
    margin_edge
        Distance of ``inner``'s straight edges from the free region's straight edges
        (equal to ``margin``).
    scan_flip
        Whether stacking scans each layout axis from its high end (``(x, y)``); set to
        start at the corner away from the opening, so the room left over is by the opening.
    """

    heading: float
    boundary: Polygon
    free: BaseGeometry
    obstacles: BaseGeometry
    margin: float
    inner: BaseGeometry
    margin_edge: float
    scan_flip: tuple[bool, bool] = (False, False)

    def to_layout(self, xy: np.ndarray) -> np.ndarray:
        """World points ``(N, 2)`` into the layout frame."""
        return np.asarray(xy, dtype=float).reshape(-1, 2) @ rotation(self.heading)

    def to_world(self, xy: np.ndarray) -> np.ndarray:
        """Layout-frame points ``(N, 2)`` into the world frame."""
        return np.asarray(xy, dtype=float).reshape(-1, 2) @ rotation(self.heading).T

    def boxes(self, centres: np.ndarray, half: np.ndarray) -> np.ndarray:
        """Axis-aligned rectangles (shapely array) with centres ``(N, 2)``, half sizes ``(N, 2)``."""
        lo, hi = centres - half, centres + half
        return shapely.box(lo[:, 0], lo[:, 1], hi[:, 0], hi[:, 1])

    def inside(self, centres: np.ndarray, half: np.ndarray) -> np.ndarray:
        """Bool ``(N,)``: rectangle lies in ``inner`` (inside the free region with margin)."""
        if len(centres) == 0:
            return np.zeros(0, dtype=bool)
        return shapely.covers(self.inner, self.boxes(centres, np.asarray(half) - FIT_TOL_M))


@dataclass(frozen=True, eq=False)
class Skids:
    """The footprints to park, as the layout frame sees them.

    Attributes
    ----------
    footprints
        As given by the caller, in order.
    half
        ``(N, 2)`` half length and half width (layout x, y).
    offsets
        ``(N,)`` body-x offset of each rectangle centre from its pivot.
    """

    footprints: tuple[Footprint, ...]
    half: np.ndarray
    offsets: np.ndarray

    def __len__(self) -> int:
        return len(self.footprints)

    @property
    def uniform(self) -> bool:
        """True if every footprint has the same length and width."""
        return bool(np.all(np.abs(self.half - self.half[0]) < 1e-12))


def make_skids(footprints: Sequence[Footprint], field: str = "park.footprints") -> Skids:
    """Check the footprints and collect their half sizes and centre offsets."""
    if isinstance(footprints, Footprint):
        footprints = [footprints]
    try:
        fps = tuple(footprints)
    except TypeError as exc:
        raise LayoutError(f"{field}: expected a list of Footprint (got {footprints!r})") from exc
    if not fps:
        raise LayoutError(f"{field}: at least one footprint is required (got 0)")
    for i, fp in enumerate(fps):
        if not isinstance(fp, Footprint):
            raise LayoutError(f"{field}[{i}]: expected a Footprint (got {fp!r})")
    half = np.array([[fp.length_m / 2.0, fp.width_m / 2.0] for fp in fps], dtype=float)
    offsets = np.array([fp.center_offset_m for fp in fps], dtype=float)
    return Skids(fps, half, offsets)


def _as_boundary(boundary) -> tuple[Polygon, list[Polygon]]:
    """The boundary as a simple polygon (holes of a shapely polygon become obstacles)."""
    if isinstance(boundary, Polygon):
        if boundary.is_empty:
            raise LayoutError("park.boundary: the polygon is empty")
        shell = as_simple_polygon(
            np.asarray(boundary.exterior.coords)[:-1],
            "park.boundary",
            max_vertices=MAX_BOUNDARY_VERTICES,
        )
        holes = [Polygon(h) for h in boundary.interiors]
        return shell, holes
    if isinstance(boundary, BaseGeometry):
        raise LayoutError(
            f"park.boundary: expected a Polygon or a list of [x, y] (got {boundary.geom_type})"
        )
    return as_simple_polygon(boundary, "park.boundary", max_vertices=MAX_BOUNDARY_VERTICES), []


def _as_obstacles(obstacles) -> BaseGeometry:
    """Union of the obstacle geometry (any shapely geometry or a list of them)."""
    if obstacles is None:
        return shapely.Polygon()
    if isinstance(obstacles, BaseGeometry):
        geoms = [obstacles]
    else:
        try:
            geoms = list(obstacles)
        except TypeError as exc:
            raise LayoutError(
                f"park.obstacles: expected shapely geometry or a list of it (got {obstacles!r})"
            ) from exc
    for i, g in enumerate(geoms):
        if not isinstance(g, BaseGeometry):
            raise LayoutError(f"park.obstacles[{i}]: expected shapely geometry (got {g!r})")
    parts = []
    for g in geoms:
        if g.is_empty:
            continue
        g = shapely.make_valid(g)
        # Walls given as lines or points still block: give them a hair of thickness.
        area = shapely.get_parts(g)
        for p in area:
            parts.append(p if p.area > 0 else p.buffer(_LINE_OBSTACLE_THICKNESS_M / 2.0))
    return shapely.union_all(parts) if parts else shapely.Polygon()


def non_negative(value, field: str) -> float:
    """``value`` as a finite float >= 0; a :class:`LayoutError` naming ``field`` and the value
    otherwise."""
    try:
        x = float(value)
    except (TypeError, ValueError) as exc:
        raise LayoutError(f"{field}: expected a number (got {value!r})") from exc
    if not (np.isfinite(x) and x >= 0.0):
        raise LayoutError(f"{field}: must be a finite number >= 0 (got {value!r})")
    return x


def make_region(boundary, obstacles, heading: float, margin_m: float) -> Region:
    """Validate the boundary and obstacles and build the layout-frame :class:`Region`.

    Raises
    ------
    GeometryError
        The boundary is not a simple polygon.
    LayoutError
        Bad margin or obstacle input, or nothing of the boundary is left free.
    """
    margin = non_negative(margin_m, "park.margin_m")
    shell, holes = _as_boundary(boundary)
    obst = _as_obstacles(obstacles)
    if holes:
        obst = shapely.union_all([obst, *holes])
    free_w = shell.difference(obst) if not obst.is_empty else shell
    # Snap to a nanometre grid: removes zero-width spikes and cracks (a ring that folds back
    # on itself) that shapely accepts as valid but that no skid can use or respect.
    free_w = shapely.set_precision(free_w, GRID_SIZE_M)
    obst_w = obst.intersection(shell) if not obst.is_empty else obst
    if free_w.is_empty or free_w.area <= 0:
        raise LayoutError("park.boundary: obstacles cover the whole boundary", fits=0)
    rot = dict(angle=-heading, origin=(0.0, 0.0), use_radians=True)
    boundary_l = affinity.rotate(shell, **rot)
    free_l = shapely.make_valid(affinity.rotate(free_w, **rot))
    obst_l = affinity.rotate(obst_w, **rot) if not obst_w.is_empty else obst_w
    inner = _erode(free_l, margin)
    shapely.prepare(inner)
    return Region(float(heading), boundary_l, free_l, obst_l, margin, inner, margin)


def _erode(free: BaseGeometry, margin: float) -> BaseGeometry:
    """Points of ``free`` at least ``margin`` from its edge (a polygonal subset of them)."""
    if margin <= 0:
        return free
    inner = free.buffer(-margin, quad_segs=BOUNDARY_QUAD_SEGS)
    if inner.is_empty:
        return inner
    vertices = shapely.points(np.unique(shapely.get_coordinates(free.boundary), axis=0))
    discs = shapely.buffer(vertices, margin * _DISC_FACTOR, quad_segs=BOUNDARY_QUAD_SEGS)
    # Only discs that reach into the eroded region matter (reflex corners).
    discs = discs[shapely.intersects(inner, discs)]
    if len(discs):
        inner = inner.difference(shapely.union_all(discs))
    return inner


def rect_gaps(centres: np.ndarray, half: np.ndarray, rows: np.ndarray | None = None) -> np.ndarray:
    """Signed gaps between axis-aligned rectangles: distance if apart, minus the smaller
    overlap depth along an axis if they overlap.

    Returns ``(R, N)`` gaps of the rectangles ``rows`` (default all, ``(N, N)``) to all;
    a rectangle's gap to itself is ``inf``.
    """
    rows = np.arange(len(centres)) if rows is None else np.asarray(rows)
    d = np.abs(centres[rows, None, :] - centres[None, :, :]) - (
        half[rows, None, :] + half[None, :, :]
    )
    apart = np.hypot(np.maximum(d[..., 0], 0.0), np.maximum(d[..., 1], 0.0))
    depth = np.maximum(d[..., 0], d[..., 1])
    gaps = np.where(depth < 0.0, depth, apart)
    gaps[np.arange(len(rows)), rows] = np.inf
    return gaps


def centres_to_poses(region: Region, skids: Skids, centres: np.ndarray) -> np.ndarray:
    """World pivot poses ``(N, 3)`` for layout-frame rectangle centres ``(N, 2)``."""
    world = region.to_world(centres)
    return center_to_pivot(world, np.full(len(world), region.heading), skids.offsets)


def describe_skids(skids: Skids) -> str:
    """Short text such as ``'1.2 x 0.8 m'`` or ``'mixed sizes: 1.2 x 0.8 m x5, 2 x 1 m x4'``."""
    sizes: dict[tuple[float, float], int] = {}
    for fp in skids.footprints:
        key = (fp.length_m, fp.width_m)
        sizes[key] = sizes.get(key, 0) + 1
    text = [f"{length:g} x {width:g} m" for (length, width) in sizes]
    if len(sizes) == 1:
        return text[0]
    return "mixed sizes: " + ", ".join(
        f"{t} x{n}" for t, n in zip(text, sizes.values(), strict=True)
    )
