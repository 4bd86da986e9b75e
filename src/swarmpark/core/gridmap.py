"""Occupancy grids: ROS map_server YAML + PGM/PNG io, polygon walls, world<->cell, inflation.

Cell ``(row, col)`` covers ``x in origin_x + [col, col + 1) * resolution`` and
``y in origin_y + [row, row + 1) * resolution``: row 0 is the *bottom* of the map (the image's
last line), so array rows grow with world y as in REP-103. Everything outside the grid is
treated as occupied.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import shapely
import yaml
from PIL import Image
from scipy import ndimage
from shapely.geometry import Polygon, box

from swarmpark.core.limits import (
    MIN_RESOLUTION_M,
    check_grid_cells,
    finite_float,
    finite_sequence,
)

__all__ = [
    "OccupancyGrid",
    "MapError",
    "load_map_yaml",
    "save_map_yaml",
    "grid_from_walls",
    "rasterize_pieces",
    "refine_occupancy",
]

# ROS map_server defaults (trinary mode).
DEFAULT_OCCUPIED_THRESH = 0.65
DEFAULT_FREE_THRESH = 0.196
PGM_OCCUPIED, PGM_FREE, PGM_UNKNOWN = 0, 254, 205


class MapError(ValueError):
    """A map file or map description that cannot be used."""


@dataclass
class OccupancyGrid:
    """A 2-D occupancy grid.

    Parameters
    ----------
    occupied
        ``(H, W)`` bool, True where a cell is an obstacle.
    resolution_m
        Cell size in metres.
    origin
        World ``(x, y)`` of the lower-left corner of cell ``(0, 0)``.
    unknown
        ``(H, W)`` bool, True where the cell was never observed (never occupied as well).
    """

    occupied: np.ndarray
    resolution_m: float
    origin: tuple[float, float] = (0.0, 0.0)
    unknown: np.ndarray | None = field(default=None)

    def __post_init__(self) -> None:
        self.occupied = np.asarray(self.occupied, dtype=bool)
        if self.unknown is None:
            self.unknown = np.zeros_like(self.occupied)
        self.unknown = np.asarray(self.unknown, dtype=bool) & ~self.occupied
        if self.occupied.ndim != 2:
            raise MapError(f"map: the grid must be 2-D (got shape {self.occupied.shape})")
        check_grid_cells(self.occupied.shape, "map", error=MapError)
        finite_float(self.resolution_m, "map.resolution_m", lo=MIN_RESOLUTION_M, error=MapError)
        self.origin = tuple(finite_sequence(self.origin, "map.origin", length=2, error=MapError))

    @property
    def shape(self) -> tuple[int, int]:
        return self.occupied.shape  # type: ignore[return-value]

    @property
    def size_m(self) -> tuple[float, float]:
        h, w = self.shape
        return (w * self.resolution_m, h * self.resolution_m)

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """``(xmin, ymin, xmax, ymax)`` in metres."""
        w, h = self.size_m
        return (self.origin[0], self.origin[1], self.origin[0] + w, self.origin[1] + h)

    def world_to_cell(self, xy: np.ndarray) -> np.ndarray:
        """Integer ``(row, col)`` ``(N, 2)`` of world points ``(N, 2)`` (may be out of range)."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        col = np.floor((xy[:, 0] - self.origin[0]) / self.resolution_m).astype(np.int64)
        row = np.floor((xy[:, 1] - self.origin[1]) / self.resolution_m).astype(np.int64)
        return np.column_stack([row, col])

    def cell_to_world(self, rc: np.ndarray) -> np.ndarray:
        """World ``(x, y)`` ``(N, 2)`` of the centres of cells ``(N, 2)`` given as (row, col)."""
        rc = np.asarray(rc).reshape(-1, 2)
        x = self.origin[0] + (rc[:, 1] + 0.5) * self.resolution_m
        y = self.origin[1] + (rc[:, 0] + 0.5) * self.resolution_m
        return np.column_stack([x, y])

    def in_bounds(self, rc: np.ndarray) -> np.ndarray:
        rc = np.asarray(rc).reshape(-1, 2)
        h, w = self.shape
        return (rc[:, 0] >= 0) & (rc[:, 0] < h) & (rc[:, 1] >= 0) & (rc[:, 1] < w)

    def is_occupied(self, xy: np.ndarray) -> np.ndarray:
        """Occupancy ``(N,)`` at world points; outside the grid counts as occupied."""
        rc = self.world_to_cell(xy)
        inside = self.in_bounds(rc)
        out = np.ones(len(rc), dtype=bool)
        out[inside] = self.occupied[rc[inside, 0], rc[inside, 1]]
        return out

    def distance_field(self) -> np.ndarray:
        """Distance ``(H, W)`` in metres from each cell centre to the nearest occupied cell's
        boundary (0 in occupied cells). The map edge counts as occupied."""
        padded = np.pad(~self.occupied, 1, constant_values=False)
        d = ndimage.distance_transform_edt(padded)[1:-1, 1:-1]
        return np.maximum(d - 0.5, 0.0) * self.resolution_m

    def inflate(self, radius_m: float) -> np.ndarray:
        """Cells ``(H, W)`` whose centre lies within ``radius_m`` of an obstacle (or occupied)."""
        return self.distance_field() <= radius_m

    def boundary_cells(self) -> np.ndarray:
        """``(row, col)`` of occupied cells with a free 4-neighbour (the only ones a body can
        reach without first crossing another occupied cell) and of occupied cells on the edge."""
        occ = self.occupied
        free = np.pad(~occ, 1, constant_values=True)
        neigh = free[:-2, 1:-1] | free[2:, 1:-1] | free[1:-1, :-2] | free[1:-1, 2:]
        return np.argwhere(occ & neigh)

    def footprint_hits(self, corners: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
        """Bool ``(N,)``: the convex footprint ``corners`` ``(N, K, 2)`` overlaps an occupied
        cell (the separating-axis test against each cell's square, exact) or reaches outside
        the map. ``mask`` (default: the occupied cells) picks the cells that count.

        >>> g = OccupancyGrid(np.array([[0, 0, 0], [0, 1, 0], [0, 0, 0]], bool), 1.0)
        >>> sq = np.array([[0.2, 0.2], [0.8, 0.2], [0.8, 0.8], [0.2, 0.8]])
        >>> g.footprint_hits(np.stack([sq, sq + 1.0, sq + 5.0])).tolist()
        [False, True, True]
        """
        from swarmpark.core.geometry import TOUCH_TOLERANCE_M, convex_overlap

        corners = np.asarray(corners, float)
        mask = self.occupied if mask is None else mask
        lo, hi = corners.min(axis=1), corners.max(axis=1)
        r0, c0, r1, c1 = self.cell_windows(corners)
        tol = TOUCH_TOLERANCE_M
        xmin, ymin, xmax, ymax = self.bounds
        out = (lo[:, 0] < xmin - tol) | (lo[:, 1] < ymin - tol)
        out |= (hi[:, 0] > xmax + tol) | (hi[:, 1] > ymax + tol)
        for i in np.flatnonzero(~out):
            window = mask[r0[i] : r1[i], c0[i] : c1[i]]
            if not window.any():
                continue
            rc = np.argwhere(window) + [r0[i], c0[i]]
            squares = self.cell_squares(rc)
            depth = convex_overlap(np.repeat(corners[i : i + 1], len(squares), axis=0), squares)
            out[i] = bool(np.any(depth > tol))
        return out

    def cell_windows(self, corners: np.ndarray) -> tuple[np.ndarray, ...]:
        """Cell ranges ``(r0, c0, r1, c1)`` (each ``(N,)``, end exclusive, clipped to the grid)
        covering the bounding boxes of the polygons ``corners`` ``(N, K, 2)``."""
        res, (ox, oy) = self.resolution_m, self.origin
        h, w = self.shape
        lo, hi = corners.min(axis=1), corners.max(axis=1)
        c0 = np.clip(np.floor((lo[:, 0] - ox) / res).astype(int), 0, w)
        r0 = np.clip(np.floor((lo[:, 1] - oy) / res).astype(int), 0, h)
        c1 = np.clip(np.ceil((hi[:, 0] - ox) / res).astype(int), 0, w)
        r1 = np.clip(np.ceil((hi[:, 1] - oy) / res).astype(int), 0, h)
        return r0, c0, r1, c1

    def cell_squares(self, rc: np.ndarray) -> np.ndarray:
        """Counter-clockwise corner squares ``(N, 4, 2)`` of cells ``(N, 2)``."""
        r = self.resolution_m
        lo = np.column_stack([self.origin[0] + rc[:, 1] * r, self.origin[1] + rc[:, 0] * r]).astype(
            float
        )
        offsets = np.array([[0, 0], [r, 0], [r, r], [0, r]], dtype=float)
        return lo[:, None, :] + offsets[None]

    def occupied_geometry(self, region: Polygon | None = None):
        """Occupied cells (optionally only those touching ``region``) as one shapely geometry."""
        rc = np.argwhere(self.occupied)
        if region is not None and len(rc):
            xmin, ymin, xmax, ymax = region.bounds
            lo = self.world_to_cell(np.array([[xmin, ymin]]))[0]
            hi = self.world_to_cell(np.array([[xmax, ymax]]))[0]
            keep = (rc[:, 0] >= lo[0]) & (rc[:, 0] <= hi[0]) & (rc[:, 1] >= lo[1])
            rc = rc[keep & (rc[:, 1] <= hi[1])]
        if len(rc) == 0:
            return shapely.Polygon()
        sq = self.cell_squares(rc)
        cells = shapely.box(sq[:, 0, 0], sq[:, 0, 1], sq[:, 2, 0], sq[:, 2, 1])
        geom = shapely.union_all(cells)
        return geom if region is None else geom.intersection(region.buffer(self.resolution_m))

    def coarsen(self, factor: int) -> OccupancyGrid:
        """A grid with ``factor`` x ``factor`` cells merged: occupied if any is (conservative),
        unknown if all free ones are unknown. Partial blocks at the top and right edges are
        padded as occupied."""
        if factor <= 1:
            return self
        h, w = self.shape
        H, W = -(-h // factor), -(-w // factor)
        occ = np.ones((H * factor, W * factor), dtype=bool)
        occ[:h, :w] = self.occupied
        unk = np.ones_like(occ)
        unk[:h, :w] = self.unknown | self.occupied
        occ = occ.reshape(H, factor, W, factor).any(axis=(1, 3))
        unk = unk.reshape(H, factor, W, factor).all(axis=(1, 3)) & ~occ
        return OccupancyGrid(occ, self.resolution_m * factor, self.origin, unk)

    def copy(self) -> OccupancyGrid:
        return OccupancyGrid(
            self.occupied.copy(), self.resolution_m, self.origin, self.unknown.copy()
        )

    def with_polygons(self, polygons: list[Polygon]) -> OccupancyGrid:
        """A copy with the cells covered by the polygons marked occupied."""
        out = self.copy()
        for poly in polygons:
            out.occupied |= _rasterize(poly, out)
        out.unknown &= ~out.occupied
        return out


def _rasterize(poly: Polygon, grid: OccupancyGrid) -> np.ndarray:
    """Cells whose square overlaps the polygon's interior (conservative: partial cells and thin
    walls are marked; a cell that only touches the polygon's edge is not)."""
    mask = np.zeros(grid.shape, dtype=bool)
    _mark_overlapping(mask, poly, grid.origin, grid.resolution_m)
    return mask


def _mark_overlapping(mask: np.ndarray, poly: Polygon, origin, res: float) -> None:
    """Set the cells of ``mask`` (cell ``(r, c)`` spanning ``origin + (c, r) res`` to
    ``origin + (c + 1, r + 1) res``) whose square overlaps ``poly``'s interior (in place)."""
    xmin, ymin, xmax, ymax = poly.bounds
    h, w = mask.shape
    r0 = max(int(np.floor((ymin - origin[1]) / res)), 0)
    r1 = min(int(np.floor((ymax - origin[1]) / res)), h - 1)
    c0 = max(int(np.floor((xmin - origin[0]) / res)), 0)
    c1 = min(int(np.floor((xmax - origin[0]) / res)), w - 1)
    if r0 > r1 or c0 > c1:
        return
    rr, cc = np.mgrid[r0 : r1 + 1, c0 : c1 + 1]
    rr, cc = rr.ravel(), cc.ravel()
    x0, y0 = origin[0] + cc * res, origin[1] + rr * res
    inset = 1e-6 * res  # so that sharing an edge is not overlapping
    boxes = shapely.box(x0 + inset, y0 + inset, x0 + res - inset, y0 + res - inset)
    shapely.prepare(poly)
    hit = shapely.intersects(poly, boxes)
    mask[rr[hit], cc[hit]] = True


def rasterize_pieces(
    pieces: np.ndarray, origin: np.ndarray, res: float, shape: tuple[int, int]
) -> np.ndarray:
    """``(H, W)`` bool: the cells of a window (as :func:`_mark_overlapping`) whose squares
    overlap one of the convex ``pieces`` ``(S, 4, 2)`` (the static solids as the collision
    monitor knows them), as :func:`_rasterize` marks a polygon."""
    out = np.zeros(shape, dtype=bool)
    pieces = np.asarray(pieces, float).reshape(-1, 4, 2)
    # Only the pieces whose bounding box meets the window (a map image has thousands).
    lo = (pieces.min(axis=1) - origin) / res
    hi = (pieces.max(axis=1) - origin) / res
    meets = (hi[:, 0] >= 0) & (hi[:, 1] >= 0) & (lo[:, 0] < shape[1]) & (lo[:, 1] < shape[0])
    for piece in pieces[meets]:
        _mark_overlapping(out, shapely.Polygon(piece), origin, res)
    return out


def refine_occupancy(
    occ: np.ndarray, origin: np.ndarray, res: float, split: int, pieces: np.ndarray
) -> np.ndarray:
    """A window of an occupancy grid on cells ``split`` times finer, from the solids it was
    made of: within a coarse occupied cell that one of ``pieces`` overlaps, only the fine
    cells that overlap a piece stay occupied; every other coarse occupied cell stays occupied
    whole (something the pieces do not hold: a keep-out drawn on the map, a detection).

    A wall rasterized outwards takes up to a whole cell of the free side (10 cm on a 10 cm
    map), which the manoeuvre search, footprints grown by half a cell on top, could not spare
    in an elevator car whose spots keep 28 cm from the walls."""
    up = np.repeat(np.repeat(np.asarray(occ, bool), split, axis=0), split, axis=1)
    if split <= 1:
        return up
    fine = rasterize_pieces(pieces, origin, res / split, up.shape)
    # A coarse cell a piece overlaps is one with a fine cell a piece overlaps (its square is
    # theirs put together): no second rasterization at the coarse size.
    h, w = occ.shape
    covered = fine.reshape(h, split, w, split).any(axis=(1, 3))
    keep_whole = np.repeat(np.repeat(~covered, split, axis=0), split, axis=1)
    return up & (fine | keep_whole)


def grid_from_walls(
    size_m: tuple[float, float],
    resolution_m: float,
    walls: list[Polygon],
    origin: tuple[float, float] = (0.0, 0.0),
) -> OccupancyGrid:
    """An occupancy grid of the given size with polygon walls rasterized into it."""
    w, h = finite_sequence(list(size_m), "map.size_m", length=2, error=MapError)
    if not (w > 0 and h > 0):
        raise MapError(f"map.size_m must be positive (got {list(size_m)})")
    finite_float(resolution_m, "map.resolution_m", lo=MIN_RESOLUTION_M, error=MapError)
    shape = (int(round(h / resolution_m)), int(round(w / resolution_m)))
    check_grid_cells(shape, "map", error=MapError)
    grid = OccupancyGrid(np.zeros(shape, dtype=bool), resolution_m, origin)
    return grid.with_polygons(walls)


def _read_map_meta(path: Path) -> dict:
    """The map YAML as a mapping, or one :class:`MapError` line (missing, not UTF-8, not YAML,
    nested too deeply, not a mapping)."""
    if not path.is_file():
        raise MapError(f"map.yaml: file not found: {str(path)!r}")
    try:
        meta = yaml.safe_load(path.read_bytes().decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise MapError(f"map.yaml: {str(path)!r} is not UTF-8 text ({exc.reason})") from None
    except yaml.YAMLError as exc:
        reason = " ".join(str(exc).split())  # PyYAML's message spans lines: keep one
        raise MapError(f"map.yaml: {str(path)!r} is not valid YAML: {reason}") from None
    except RecursionError:
        raise MapError(f"map.yaml: {str(path)!r} is nested too deeply") from None
    if not isinstance(meta, dict):
        raise MapError(f"map.yaml: {str(path)!r} must be a mapping of map_server keys")
    return meta


def load_map_yaml(path: str | Path) -> OccupancyGrid:
    """Load a ROS map_server map (YAML + PGM/PNG image), trinary mode.

    Raises :class:`MapError` naming the key and value for a missing file or bad metadata.
    """
    path = Path(path)
    meta = _read_map_meta(path)
    for key in ("image", "resolution", "origin"):
        if key not in meta:
            raise MapError(f"map.yaml: {str(path)!r} has no {key!r} key")
    known = {"image", "resolution", "origin", "negate", "occupied_thresh", "free_thresh", "mode"}
    unknown_keys = sorted(set(meta) - known)
    if unknown_keys:
        raise MapError(f"map.yaml: unknown key(s) {unknown_keys} in {str(path)!r}")
    mode = meta.get("mode", "trinary")
    if mode != "trinary":
        raise MapError(f"map.yaml: mode {mode!r} is not supported (only 'trinary')")
    image_path = (path.parent / str(meta["image"])).resolve()
    if not image_path.is_file():
        raise MapError(f"map.yaml: image file not found: {str(image_path)!r}")
    origin = meta["origin"]
    if not (isinstance(origin, list) and len(origin) == 3):
        raise MapError(f"map.yaml: origin must be [x, y, yaw] (got {origin!r})")
    origin = finite_sequence(origin, "map.yaml: origin", error=MapError)
    if abs(origin[2]) > 1e-9:
        raise MapError(f"map.yaml: origin yaw must be 0 (got {origin[2]!r})")
    res = finite_float(meta["resolution"], "map.yaml: resolution", error=MapError)
    occ_t = finite_float(
        meta.get("occupied_thresh", DEFAULT_OCCUPIED_THRESH),
        "map.yaml: occupied_thresh",
        error=MapError,
    )
    free_t = finite_float(
        meta.get("free_thresh", DEFAULT_FREE_THRESH), "map.yaml: free_thresh", error=MapError
    )
    negate = meta.get("negate", 0)
    if negate not in (0, 1):
        raise MapError(f"map.yaml: negate must be 0 or 1 (got {negate!r})")
    if not res >= MIN_RESOLUTION_M:
        raise MapError(f"map.yaml: resolution must be >= {MIN_RESOLUTION_M} (got {res})")
    if not 0 <= free_t < occ_t <= 1:
        raise MapError(
            f"map.yaml: need 0 <= free_thresh < occupied_thresh <= 1 (got {free_t}, {occ_t})"
        )
    pixels = _read_map_image(image_path)
    p = pixels / 255.0 if negate else (255.0 - pixels) / 255.0
    occupied = np.flipud(p > occ_t)
    unknown = np.flipud((p >= free_t) & (p <= occ_t))
    return OccupancyGrid(occupied, res, (float(origin[0]), float(origin[1])), unknown)


def _read_map_image(image_path: Path) -> np.ndarray:
    """The map image as grey levels, refused (:class:`MapError`) if it is not an image, is
    truncated or empty, or would be over the cell budget (checked from the header, before
    the pixels are decoded: a decompression bomb is never expanded)."""
    name = str(image_path)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", Image.DecompressionBombWarning)
            with Image.open(image_path) as img:
                cols, rows = img.size
                check_grid_cells((rows, cols), f"map image {name!r}", error=MapError)
                pixels = np.asarray(img.convert("L"), dtype=float)
    except MapError:
        raise
    except (
        OSError,
        SyntaxError,
        ValueError,
        Image.DecompressionBombError,
        Image.DecompressionBombWarning,
    ) as exc:
        # PIL: UnidentifiedImageError (an OSError) for what is no image, OSError for a
        # truncated one, SyntaxError for a broken header.
        raise MapError(f"map image {name!r} cannot be read: {exc}") from None
    if pixels.ndim != 2 or pixels.size == 0:
        raise MapError(f"map image {name!r} is empty")
    return pixels


def save_map_yaml(grid: OccupancyGrid, path: str | Path) -> Path:
    """Write ``grid`` as a map_server YAML and a PGM image beside it; returns the YAML path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    img = np.full(grid.shape, PGM_FREE, dtype=np.uint8)
    img[grid.unknown] = PGM_UNKNOWN
    img[grid.occupied] = PGM_OCCUPIED
    pgm = path.with_suffix(".pgm")
    Image.fromarray(np.flipud(img)).save(pgm)
    meta = {
        "image": pgm.name,
        "resolution": float(grid.resolution_m),
        "origin": [float(grid.origin[0]), float(grid.origin[1]), 0.0],
        "negate": 0,
        "occupied_thresh": DEFAULT_OCCUPIED_THRESH,
        "free_thresh": DEFAULT_FREE_THRESH,
    }
    path.write_text(yaml.safe_dump(meta, sort_keys=False))
    return path


def region_box(grid: OccupancyGrid) -> Polygon:
    """The grid's extent as a polygon."""
    return box(*grid.bounds)
