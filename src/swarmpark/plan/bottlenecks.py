"""Bottlenecks of a map: doors and narrow corridors where two skids cannot pass each other.

A bottleneck is a stretch of the free space's medial axis (its skeleton,
``skimage.morphology.medial_axis``) narrower than one *lane* (two skids side by side) but
wide enough for one skid all along, that separates the free space: take its zone away and the
space on its two sides is no longer connected (a corner of a room also has a narrow skeleton
branch but separates nothing; a gap between a pillar and a wall can be driven around). Each
bottleneck becomes a *zone*: the free cells within its half width plus a pad of its throat
(where it is narrowest), the part of the floor where skids meet head-on or jam.

The free space outside all zones splits into *regions* (connected components): a skid's
direction through a zone is the region it comes from. The navigation's traffic control
(:mod:`swarmpark.control.nav.traffic`) queues skids at the zones.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely
from scipy import ndimage
from skimage.morphology import medial_axis

from swarmpark.core.gridmap import OccupancyGrid

__all__ = ["THROAT_TOLERANCE_M", "Bottlenecks", "find_bottlenecks"]

#: A zone is centred on its throat: the skeleton within this much of the passage's least width.
THROAT_TOLERANCE_M = 0.3


@dataclass(frozen=True)
class Bottlenecks:
    """The zones of a map on a (coarse) grid: ``zone`` ``(H, W)`` int (0 outside every zone,
    ``k`` in zone ``k``), ``region`` ``(H, W)`` int (the connected free space outside the zones,
    0 elsewhere), each zone's outline as a polygon (``polygons[k - 1]``), its narrowest free
    width (m) and the length of its throat (m, the skeleton within
    :data:`THROAT_TOLERANCE_M` of that width: about 1.5 m for a door in a wall, the length of
    a corridor of even width)."""

    zone: np.ndarray
    region: np.ndarray
    polygons: tuple
    widths_m: tuple
    resolution_m: float
    origin: np.ndarray
    throats_m: tuple = ()

    @property
    def count(self) -> int:
        return len(self.polygons)

    def cells(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Row and column of world points ``(K, 2)`` (clipped to the grid)."""
        h, w = self.zone.shape
        # np.minimum/np.maximum, not np.clip: the same integers, and the traffic control
        # calls this for every skid near a zone every tick, where np.clip's overhead was
        # two thirds of its cost.
        c = np.floor((xy[:, 0] - self.origin[0]) / self.resolution_m).astype(int)
        r = np.floor((xy[:, 1] - self.origin[1]) / self.resolution_m).astype(int)
        return np.minimum(np.maximum(r, 0), h - 1), np.minimum(np.maximum(c, 0), w - 1)

    def zone_at(self, xy: np.ndarray) -> np.ndarray:
        """Zone number at world points ``(K, 2)`` (0: none)."""
        return self.zone[self.cells(xy)]

    def region_at(self, xy: np.ndarray) -> np.ndarray:
        """Region number at world points ``(K, 2)`` (0: in a zone or a wall)."""
        return self.region[self.cells(xy)]


def find_bottlenecks(
    grid: OccupancyGrid,
    *,
    min_width_m: float,
    lane_width_m: float,
    pad_m: float,
    resolution_m: float = 0.1,
) -> Bottlenecks:
    """The bottlenecks of ``grid`` (see the module docstring).

    Parameters
    ----------
    min_width_m
        Narrower passages are walls to a skid (not a zone).
    lane_width_m
        Passages narrower than this are single lanes.
    pad_m
        The zone reaches this far beyond the passage (where skids line up to enter it).
    resolution_m
        The analysis grid (the map is coarsened to it, conservatively).
    """
    g = grid.coarsen(max(int(round(resolution_m / grid.resolution_m)), 1))
    res = g.resolution_m
    free = ~g.occupied
    # medial_axis breaks ties between skeleton pixels at random: a fixed seed makes the zones,
    # and so the runs, the same every time (without it one generated elevator parked in
    # 49.7 s or 76.6 s from run to run).
    skel, dist = medial_axis(np.pad(free, 1), return_distance=True, rng=0)
    skel, dist = skel[1:-1, 1:-1], dist[1:-1, 1:-1]
    width = 2.0 * dist * res
    narrow = skel & (width < lane_width_m)
    comp, n = ndimage.label(narrow, structure=np.ones((3, 3)))
    zone = np.zeros(free.shape, int)
    polygons, widths, throats = [], [], []
    for k in range(1, n + 1):
        pts = comp == k
        w_min = float(width[pts].min())
        if w_min < min_width_m:
            continue  # too narrow for a skid somewhere along it: a wall to the fleet
        # The throat: where the passage is (nearly) at its narrowest.
        throat = pts & (width <= w_min + THROAT_TOLERANCE_M)
        reach = float(width[throat].max() / 2 + pad_m)
        cand = free & (ndimage.distance_transform_edt(~throat) * res <= reach) & (zone == 0)
        if not cand.any() or not _separates(free, cand):
            continue
        zone[cand] = len(polygons) + 1
        polygons.append(_outline(cand, res, g.origin))
        widths.append(w_min)
        throats.append(float(np.count_nonzero(throat)) * res)
    region, _ = ndimage.label(free & (zone == 0), structure=np.ones((3, 3)))
    return Bottlenecks(
        zone, region, tuple(polygons), tuple(widths), res, np.asarray(g.origin), tuple(throats)
    )


def _separates(free: np.ndarray, cand: np.ndarray) -> bool:
    """Whether taking ``cand`` out of the free space splits the free space next to it into at
    least two pieces that are not connected elsewhere (a door between two rooms; not a gap
    between a pillar and a wall, which can be driven around)."""
    rest, _ = ndimage.label(free & ~cand, structure=np.ones((3, 3)))
    ring = ndimage.binary_dilation(cand, structure=np.ones((3, 3))) & ~cand
    return len(np.unique(rest[ring & (rest > 0)])) >= 2


def _outline(mask: np.ndarray, res: float, origin) -> shapely.Geometry:
    """The cells of ``mask`` as one (multi)polygon in world coordinates."""
    rr, cc = np.nonzero(mask)
    x0 = origin[0] + cc * res
    y0 = origin[1] + rr * res
    return shapely.union_all(shapely.box(x0, y0, x0 + res, y0 + res))
