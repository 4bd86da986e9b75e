"""Geometry the navigation components share, built once per map and per fleet.

:class:`Scene` holds the sampled outlines of the static solids (for the field), their search
trees (for the monitor and make-room), the ORCA obstacles and the skids' outlines. It is
brought up to date explicitly at the start of each tick (:meth:`Scene.update`): a cache is
rebuilt when its input changes by value (the pieces' coordinates, the footprints), never keyed
by the ``id()`` of an array that may be freed and its id reused.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import shapely
from scipy.spatial import cKDTree

from swarmpark.control.base import ControlView
from swarmpark.core.geometry import Footprint, footprint_corners

__all__ = ["Scene", "SkidOutlines", "StaticSolids", "sample_polygon"]


def sample_polygon(corners: np.ndarray, step_m: float) -> tuple[list[np.ndarray], list[int]]:
    """Points along the closed outline ``corners`` at most ``step_m`` apart, per edge, and
    how many on each edge."""
    pts, counts = [], []
    for a, b in zip(corners, np.roll(corners, -1, axis=0), strict=True):
        n = max(int(np.ceil(np.linalg.norm(b - a) / step_m)), 1)
        pts.append(a + np.linspace(0, 1, n, endpoint=False)[:, None] * (b - a))
        counts.append(n)
    return pts, counts


@dataclass
class StaticSolids:
    """The known static solids ``(S, 4, 2)``: outline samples, a k-d tree of them, the pieces'
    boxes (``lo``, ``hi``) and an STR-tree of them; the ORCA obstacles are made on first use."""

    pieces: np.ndarray
    step_m: float
    points: np.ndarray = field(init=False)
    kd: cKDTree | None = field(init=False)
    tree: shapely.STRtree = field(init=False)
    lo: np.ndarray = field(init=False)
    hi: np.ndarray = field(init=False)
    _orca: list | None = field(init=False, default=None)

    def __post_init__(self) -> None:
        self.pieces = np.array(self.pieces, dtype=float)  # our own copy, to compare against
        pts = []
        for piece in self.pieces:
            pts += sample_polygon(piece, self.step_m)[0]
        self.points = np.vstack(pts) if pts else np.zeros((0, 2))
        self.kd = cKDTree(self.points) if len(self.points) else None
        self.lo, self.hi = lo, hi = self.pieces.min(axis=1), self.pieces.max(axis=1)
        self.tree = shapely.STRtree(shapely.box(lo[:, 0], lo[:, 1], hi[:, 0], hi[:, 1]))

    def same(self, pieces: np.ndarray) -> bool:
        """Whether ``pieces`` have these solids' coordinates (compared by value: the array
        may have been changed in place, or be a new one at a reused address)."""
        return pieces.shape == self.pieces.shape and np.array_equal(pieces, self.pieces)

    @property
    def orca_obstacles(self) -> list:
        """The pieces as ORCA obstacles (:func:`~swarmpark.control.orca.kernel.prepare_obstacles`)."""
        if self._orca is None:
            from swarmpark.control.orca.kernel import prepare_obstacles

            # Static pieces are convex (triangles and squares padded to 4 corners).
            polys = []
            for pc in (np.unique(pc, axis=0) for pc in self.pieces):
                c = pc.mean(axis=0)
                polys.append(pc[np.argsort(np.arctan2(pc[:, 1] - c[1], pc[:, 0] - c[0]))])
            self._orca = prepare_obstacles(polys)
        return self._orca


@dataclass
class SkidOutlines:
    """The skids' footprints: outline samples in the body frame with their owners, the plain
    corners ``(N, 4, 2)``, the corners grown by the monitor's margin, and each footprint's
    reach about its pivot ``(N,)`` and the largest circumradius (computed once per fleet)."""

    footprints: tuple[Footprint, ...]
    step_m: float
    grow_m: float
    points: np.ndarray = field(init=False)
    owner: np.ndarray = field(init=False)
    plain: np.ndarray = field(init=False)
    grown: np.ndarray = field(init=False)
    reach: np.ndarray = field(init=False)
    max_circumradius: float = field(init=False)

    def __post_init__(self) -> None:
        self.reach = np.array([f.reach_m for f in self.footprints])
        self.max_circumradius = max(f.circumradius_m for f in self.footprints)
        pts, owner = [], []
        for j, fp in enumerate(self.footprints):
            edge_pts, counts = sample_polygon(fp.corners_body(), self.step_m)
            pts += edge_pts
            owner += [np.full(m, j) for m in counts]
        self.points = np.vstack(pts)
        self.owner = np.concatenate(owner)
        self.plain = np.stack([f.corners_body() for f in self.footprints])
        g = self.grow_m
        self.grown = np.stack(
            [
                Footprint(f.length_m + 2 * g, f.width_m + 2 * g, f.pivot + g).corners_body()
                for f in self.footprints
            ]
        )


@dataclass
class Scene:
    """The shared geometry of one tick (see the module docstring)."""

    outline_step_m: float
    monitor_margin_m: float
    static: StaticSolids | None = None
    skids: SkidOutlines | None = None

    def update(self, view: ControlView) -> Scene:
        """Rebuild what changed since the last tick (new detected obstacles, a new fleet)."""
        if self.static is None or not self.static.same(view.static_pieces):
            self.static = StaticSolids(view.static_pieces, self.outline_step_m)
        fps = tuple(view.footprints)
        if self.skids is None or self.skids.footprints != fps:
            self.skids = SkidOutlines(fps, self.outline_step_m, self.monitor_margin_m)
        return self

    def corners_now(self, view: ControlView, i: int) -> np.ndarray:
        """Skid ``i``'s footprint corners ``(4, 2)`` where it stands."""
        return footprint_corners(view.poses[i][None], self.skids.plain[i][None])[0]
