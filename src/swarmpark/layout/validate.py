"""Independent check of a finished layout, in the world frame, from the pivot poses.

Every method's output goes through :func:`check_layout` before it is returned: footprints
are rebuilt from the poses (so the pivot/centre conversion is checked too), then tested
against the free region (boundary minus walls and obstacles) with shapely and against each
other with an STR-tree and the exact convex gap of :mod:`swarmpark.core.geometry`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import shapely
from shapely.geometry.base import BaseGeometry

from swarmpark.core.geometry import Footprint, convex_gap, footprint_corners
from swarmpark.layout.region import MARGIN_TOL_M

__all__ = ["LayoutCheck", "check_layout", "footprint_polygons"]


@dataclass(frozen=True)
class LayoutCheck:
    """Result of :func:`check_layout`.

    Attributes
    ----------
    ok
        True if every footprint is inside the free region with the margin and no two are
        closer than the margin (both within :data:`MARGIN_TOL_M`).
    min_spacing_m
        Smallest gap between two footprints (``None`` for a single skid; 0 if two overlap).
    min_boundary_clearance_m
        Smallest distance from a footprint to the edge of the free region (boundary, walls,
        obstacles); 0 for a footprint that sticks out.
    outside
        Indices of footprints not inside the free region with the margin.
    close_pairs
        Index pairs ``(i, j)``, ``i < j``, closer than the margin.
    """

    ok: bool
    min_spacing_m: float | None
    min_boundary_clearance_m: float
    outside: tuple[int, ...] = field(default=())
    close_pairs: tuple[tuple[int, int], ...] = field(default=())

    def problems(self) -> list[str]:
        """Human-readable list of what is wrong (empty if ``ok``)."""
        out = []
        if self.outside:
            out.append(f"goals {list(self.outside)} are not inside the boundary with the margin")
        if self.close_pairs:
            out.append(
                f"goal pairs {[list(p) for p in self.close_pairs]} are closer than the margin"
            )
        return out


def footprint_polygons(poses: np.ndarray, footprints: Sequence[Footprint]) -> np.ndarray:
    """Shapely polygons (array ``(N,)``) of footprints at pivot poses ``(N, 3)``."""
    corners = np.stack([fp.corners_body() for fp in footprints])
    world = footprint_corners(np.asarray(poses, dtype=float), corners)
    return shapely.polygons(world)


def check_layout(
    poses: np.ndarray,
    footprints: Sequence[Footprint],
    free: BaseGeometry,
    margin_m: float,
    *,
    tol_m: float = MARGIN_TOL_M,
) -> LayoutCheck:
    """Check a layout against the free region (world frame) and the margin.

    Parameters
    ----------
    poses
        ``(N, 3)`` pivot poses.
    footprints
        One per pose.
    free
        Boundary minus obstacles, world frame.
    margin_m
        Required clearance between footprints and to the edge of ``free``.
    tol_m
        Allowed shortfall against the margin (round-off, solver tolerance).

    Examples
    --------
    >>> from shapely.geometry import box
    >>> fp = Footprint(1.0, 1.0)
    >>> poses = np.array([[1.0, 1.0, 0.0], [2.5, 1.0, 0.0]])
    >>> chk = check_layout(poses, [fp, fp], box(0, 0, 4, 2), 0.5)
    >>> chk.ok, chk.min_spacing_m, chk.min_boundary_clearance_m
    (True, 0.5, 0.5)
    """
    poses = np.asarray(poses, dtype=float).reshape(-1, 3)
    n = len(poses)
    if n == 0:
        return LayoutCheck(True, None, float("inf"))
    polys = footprint_polygons(poses, footprints)
    edge = free.boundary
    shapely.prepare(free)
    within = shapely.covers(free, polys)
    # Sticking out by less than the tolerance (an exact fit against a slanted edge, after
    # round-off) is not outside.
    near_within = within.copy()
    near_within[~within] = shapely.covers(free.buffer(tol_m, join_style="mitre"), polys[~within])
    clearance = np.where(within, shapely.distance(polys, edge), 0.0)
    outside = np.flatnonzero(~near_within | (clearance < margin_m - tol_m))

    min_spacing: float | None = None
    close: list[tuple[int, int]] = []
    if n > 1:
        tree = shapely.STRtree(polys)
        # Nearest other footprint of each one gives the smallest spacing.
        _, dist = tree.query_nearest(polys, exclusive=True, return_distance=True, all_matches=False)
        # Footprints equal to each other are left out of ``exclusive`` queries (found below).
        min_spacing = float(dist.min()) if len(dist) else float("inf")
        # Pairs within the margin: exact gap (negative = penetration depth) by SAT.
        near = tree.query(polys, predicate="dwithin", distance=max(margin_m - tol_m, 0.0))
        near = near[:, near[0] < near[1]]
        if near.shape[1]:
            corners = shapely.get_coordinates(polys).reshape(n, 5, 2)[:, :4]
            gaps = convex_gap(corners[near[0]], corners[near[1]])
            bad = gaps < margin_m - tol_m
            close = [(int(i), int(j)) for i, j in near[:, bad].T]
            min_spacing = min(min_spacing, float(max(gaps.min(), 0.0)))
    ok = len(outside) == 0 and not close
    return LayoutCheck(
        ok,
        min_spacing,
        float(clearance.min()),
        tuple(int(i) for i in outside),
        tuple(close),
    )
