"""Egress check: can every goal be driven to from the opening with earlier goals occupied?

The region is rasterized in the layout frame (where parked skids are axis-aligned
rectangles). A skid driving in is modelled as a disc of radius half the widest skid's
width: the narrowest aisle it can drive along, straight. (Room to turn is not checked;
this is the necessary condition, not a full motion plan.) Outside the boundary only an
*apron* around the opening is drivable, so skids enter through the opening and not across
other boundary edges.

The fill order is found by peeling: the goals reachable from the opening with every other
goal occupied are filled last; remove them and repeat. Reachability only grows as goals
are removed, so if any order works this one does. Each peeled layer is filled deepest
(farthest from the opening) first.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely
from scipy import ndimage
from shapely.geometry import Point, Polygon

from swarmpark.layout.region import Region, Skids

__all__ = ["EgressResult", "default_opening", "egress_order"]

#: Cells across the narrowest skid width in the egress raster.
CELLS_PER_WIDTH = 8
#: Raster resolution limits (metres).
MIN_RES_M, MAX_RES_M = 0.02, 0.1
_EIGHT = np.ones((3, 3), dtype=bool)


@dataclass(frozen=True)
class EgressResult:
    """Outcome of :func:`egress_order`.

    Attributes
    ----------
    fill_order
        Goal indices, deepest first; unreachable goals (if any) come first.
    ok
        True if every goal is reachable in that order.
    unreachable
        Goals left over by the peeling: no order reaches them (walled in, or behind goals
        that are themselves unreachable).
    layers
        Number of peeled layers (depth of the formation seen from the opening).
    opening
        Opening point used, world frame, on the boundary.
    """

    fill_order: tuple[int, ...]
    ok: bool
    unreachable: tuple[int, ...]
    layers: int
    opening: tuple[float, float]


def default_opening(boundary: Polygon) -> np.ndarray:
    """The default opening: the midpoint of the boundary's longest edge (first if tied).

    On an elevator or a bay the long open side is the usual way in; callers that know
    where the skids come from should pass the opening instead.
    """
    pts = np.asarray(boundary.exterior.coords)
    lengths = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    k = int(np.argmax(lengths))
    return 0.5 * (pts[k] + pts[k + 1])


def egress_order(
    region: Region, skids: Skids, centres: np.ndarray, opening_world: np.ndarray
) -> EgressResult:
    """Peel the goals from the opening and return a deepest-first fill order.

    Parameters
    ----------
    region
        Layout-frame region.
    skids
        Footprints, one per centre.
    centres
        ``(N, 2)`` layout-frame rectangle centres of the goals.
    opening_world
        ``(x, y)`` of the entrance, world frame; projected onto the boundary.
    """
    n = len(centres)
    half = skids.half
    radius = float(half[:, 1].max())
    res = float(np.clip(2.0 * half[:, 1].min() / CELLS_PER_WIDTH, MIN_RES_M, MAX_RES_M))
    opening_l = region.to_layout(np.asarray(opening_world, dtype=float))[0]
    ring = region.boundary.exterior
    opening_l = np.asarray(ring.interpolate(ring.project(Point(opening_l))).coords[0])
    apron_r = max(2.0 * float(half[:, 0].max()), 4.0 * radius)

    xmin, ymin, xmax, ymax = region.boundary.bounds
    pad = radius + 2.0 * res
    xmin = min(xmin, opening_l[0] - apron_r) - pad
    ymin = min(ymin, opening_l[1] - apron_r) - pad
    xmax = max(xmax, opening_l[0] + apron_r) + pad
    ymax = max(ymax, opening_l[1] + apron_r) + pad
    xs = xmin + res * (np.arange(int(np.ceil((xmax - xmin) / res))) + 0.5)
    ys = ymin + res * (np.arange(int(np.ceil((ymax - ymin) / res))) + 0.5)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")  # cell (i, j) at (xs[i], ys[j])

    in_free = shapely.contains_xy(region.free, gx, gy)
    in_boundary = shapely.contains_xy(region.boundary, gx, gy)
    apron = (np.hypot(gx - opening_l[0], gy - opening_l[1]) <= apron_r) & ~in_boundary
    drivable = in_free | apron
    # A disc centre must keep `radius` from anything not drivable (walls, obstacles, edges).
    wall_ok = ndimage.distance_transform_edt(drivable) * res >= radius

    # Each goal's blocking region: cells whose centre is closer than `radius` to its rectangle.
    windows = []
    centre_cells = []
    for g in range(n):
        lo = centres[g] - half[g] - radius - res
        hi = centres[g] + half[g] + radius + res
        i0, i1 = np.searchsorted(xs, [lo[0], hi[0]])
        j0, j1 = np.searchsorted(ys, [lo[1], hi[1]])
        dx = np.maximum(np.abs(xs[i0:i1, None] - centres[g, 0]) - half[g, 0], 0.0)
        dy = np.maximum(np.abs(ys[None, j0:j1] - centres[g, 1]) - half[g, 1], 0.0)
        mask = np.hypot(dx, dy) < radius
        windows.append((np.s_[i0:i1, j0:j1], mask))
        # Nearest cell centre to the goal centre, as an index inside the window.
        ci = int(np.clip(np.rint((centres[g, 0] - xs[0]) / res), 0, len(xs) - 1))
        cj = int(np.clip(np.rint((centres[g, 1] - ys[0]) / res), 0, len(ys) - 1))
        centre_cells.append((ci - i0, cj - j0))

    remaining = list(range(n))
    layers: list[list[int]] = []
    while remaining:
        count = np.zeros(gx.shape, dtype=np.int32)
        for g in remaining:
            sl, mask = windows[g]
            count[sl] += mask
        cfree = wall_ok & (count == 0)
        labels, _ = ndimage.label(cfree, structure=_EIGHT)
        is_seed = np.zeros(labels.max() + 1, dtype=bool)
        is_seed[labels[apron & cfree]] = True
        is_seed[0] = False
        reach = ndimage.binary_dilation(is_seed[labels], structure=_EIGHT)
        layer = []
        for g in remaining:
            sl, mask = windows[g]
            own = mask & (count[sl] == 1) & wall_ok[sl]
            ci, cj = centre_cells[g]
            if not (0 <= ci < own.shape[0] and 0 <= cj < own.shape[1]) or not own[ci, cj]:
                continue
            lab, _ = ndimage.label(own, structure=_EIGHT)
            if reach[sl][lab == lab[ci, cj]].any():
                layer.append(g)
        if not layer:
            break
        layers.append(layer)
        remaining = [g for g in remaining if g not in set(layer)]

    dist = np.hypot(centres[:, 0] - opening_l[0], centres[:, 1] - opening_l[1])
    order: list[int] = sorted(remaining, key=lambda g: -dist[g])
    for layer in reversed(layers):
        order.extend(sorted(layer, key=lambda g: -dist[g]))
    opening_w = region.to_world(opening_l)[0]
    return EgressResult(
        tuple(int(g) for g in order),
        not remaining,
        tuple(int(g) for g in sorted(remaining)),
        len(layers),
        (float(opening_w[0]), float(opening_w[1])),
    )
