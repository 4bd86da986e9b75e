"""Layout benchmarks: solve time per method and size ("layout.speed"), and spacing quality of
the three methods on the same boundaries ("layout.quality").

Boundaries are sized to fit their skids with room to spare: starting from an area of
``ROOM * N * (L + margin) * (W + margin)`` they are scaled up until stacking fits at least
``SPARE * N`` skids. Timing wraps the public :func:`layout` call (validation and egress
order included), never the core itself.
"""

from __future__ import annotations

import math

import numpy as np
import shapely

from swarmpark.apps.bench import register, time_call
from swarmpark.core.geometry import Footprint
from swarmpark.layout import LAYOUT_METHODS, capacity, layout
from swarmpark.layout.validate import footprint_polygons

SKID = Footprint(1.2, 0.8, pivot_from_rear_m=0.3)
MARGIN_M = 0.3
#: Free area over the area the skids need with their margins (starting point).
ROOM = 1.6
#: Boundaries are grown until stacking fits this many times the skids asked for.
SPARE = 1.25
#: Growth factor (linear) per step while sizing a boundary.
GROWTH = 1.05
#: Targets from the issue, at N = 50 (milliseconds); a method without one is only timed.
TARGET_MS = {"stacking": 100.0, "potential": 1000.0, "convex": 2000.0}


def _need(n: int) -> float:
    return n * (SKID.length_m + MARGIN_M) * (SKID.width_m + MARGIN_M)


def rectangle(n: int, aspect: float = 1.4) -> list[list[float]]:
    """A rectangle ``aspect`` times wider than tall with room for ``n`` skids."""
    area = ROOM * _need(n)
    h = math.sqrt(area / aspect)
    w = aspect * h
    return [[0, 0], [w, 0], [w, h], [0, h]]


def hexagon(n: int) -> list[list[float]]:
    """A regular hexagon (convex, not axis-aligned everywhere) with room for ``n`` skids."""
    r = math.sqrt(ROOM * _need(n) / (1.5 * math.sqrt(3)))
    a = np.arange(6) * np.pi / 3
    return np.round(np.column_stack([r * np.cos(a), r * np.sin(a)]), 6).tolist()


def l_shape(n: int) -> list[list[float]]:
    """An L (three equal squares) with room for ``n`` skids."""
    s = math.sqrt(ROOM * _need(n) / 3)
    return [[0, 0], [2 * s, 0], [2 * s, s], [s, s], [s, 2 * s], [0, 2 * s]]


def u_shape(n: int) -> list[list[float]]:
    """A U (five equal squares: a base of three and two arms) with room for ``n`` skids."""
    s = math.sqrt(ROOM * _need(n) / 5)
    return [
        [0, 0],
        [3 * s, 0],
        [3 * s, 2 * s],
        [2 * s, 2 * s],
        [2 * s, s],
        [s, s],
        [s, 2 * s],
        [0, 2 * s],
    ]


def roomy(shape, n: int) -> list[list[float]]:
    """``shape(n)`` scaled up until stacking fits ``SPARE * n`` skids of :data:`SKID`."""
    pts = np.asarray(shape(n), dtype=float)
    while capacity(pts.tolist(), SKID, margin_m=MARGIN_M).report["capacity"] < SPARE * n:
        pts = pts * GROWTH
    return np.round(pts, 6).tolist()


def _gaps(res) -> np.ndarray:
    """Nearest-neighbour gap of every goal."""
    polys = footprint_polygons(res.poses, [SKID] * len(res.poses))
    tree = shapely.STRtree(polys)
    _, dist = tree.query_nearest(polys, exclusive=True, return_distance=True, all_matches=False)
    return dist


@register(
    "layout.speed",
    "layout() time per method, N skids in a rectangle with room to spare (and an L at N=50)",
    target="N=50: stacking < 100 ms, potential < 1000 ms, convex < 2000 ms",
)
def bench_speed(quick: bool) -> list[dict]:
    cases = [("rectangle", 10, roomy(rectangle, 10))]
    if not quick:
        cases += [
            ("rectangle", 50, roomy(rectangle, 50)),
            ("L", 50, roomy(l_shape, 50)),
            ("rectangle", 100, roomy(rectangle, 100)),
        ]
    rows = []
    for shape, n, boundary in cases:
        for method in LAYOUT_METHODS.names():
            res = layout(boundary, [SKID] * n, method=method, margin_m=MARGIN_M)
            repeat = 1 if quick or (method == "convex" and n >= 100) else 3
            t = time_call(
                lambda b=boundary, n=n, m=method: layout(
                    b, [SKID] * n, method=m, margin_m=MARGIN_M
                ),
                repeat=repeat,
                warmup=0 if quick else 1,
            )
            row = {
                "shape": shape,
                "n": n,
                "method": method,
                **t,
                "iterations": res.report["iterations"],
            }
            if n == 50 and method in TARGET_MS:
                row["target_ms"] = TARGET_MS[method]
                row["meets_target"] = "yes" if t["median_ms"] < TARGET_MS[method] else "NO"
            rows.append(row)
    return rows


def quality_cases(quick: bool) -> list[tuple[str, bool, int, list]]:
    """``(name, convex?, n, boundary)`` for the quality table."""
    sizes = (10,) if quick else (10, 50, 100)
    cases = [(f"rectangle-{n}", True, n, roomy(rectangle, n)) for n in sizes]
    cases += [(f"hexagon-{n}", True, n, roomy(hexagon, n)) for n in sizes[:2]]
    cases += [(f"L-{n}", False, n, roomy(l_shape, n)) for n in sizes[:2]]
    cases += [(f"U-{n}", False, n, roomy(u_shape, n)) for n in sizes[:2]]
    return cases


@register(
    "layout.quality",
    "min spacing and min boundary clearance per method on the same boundaries",
    target="convex has the largest min spacing on convex boundaries",
)
def bench_quality(quick: bool) -> list[dict]:
    rows = []
    for name, is_convex, n, boundary in quality_cases(quick):
        spacing = {}
        for method in LAYOUT_METHODS.names():
            res = layout(boundary, [SKID] * n, method=method, margin_m=MARGIN_M)
            gaps = _gaps(res)
            spacing[method] = res.report["min_spacing_m"]
            rows.append(
                {
                    "boundary": name,
                    "convex": "yes" if is_convex else "no",
                    "n": n,
                    "method": method,
                    "min_spacing_m": res.report["min_spacing_m"],
                    "mean_nn_gap_m": float(gaps.mean()),
                    "min_clearance_m": res.report["min_boundary_clearance_m"],
                }
            )
        best = max(spacing, key=lambda m: spacing[m])
        rows.append(
            {
                "boundary": name,
                "convex": "yes" if is_convex else "no",
                "n": n,
                "method": "(largest min spacing)",
                "min_spacing_m": spacing[best],
                "largest": best,
                "convex_is_largest": "yes" if spacing["convex"] >= spacing[best] - 1e-9 else "NO",
            }
        )
    return rows
