"""Convex layout (Hing et al. 2015, Sect. 3.1): constraint graphs H and V, the stacking seed
(capacity never below stacking's), the linearized distance constraints (eqs. 3-4), and
the validity of every convex layout."""

from __future__ import annotations

import numpy as np
import pytest
import shapely
from shapely.geometry import Polygon

from swarmpark.core.geometry import Footprint
from swarmpark.layout import LayoutError, capacity, layout
from swarmpark.layout.convex import (
    distance_constraints,
    free_segments,
    from_arrangement,
    from_columns,
    refine,
    seeded,
)
from swarmpark.layout.convex.graph import transitive_reduction
from swarmpark.layout.region import make_region, make_skids
from swarmpark.layout.stacking import stack
from swarmpark.layout.validate import check_layout, footprint_polygons

SKID = Footprint(1.2, 0.8)
MARGIN = 0.3
TRIANGLE = [[0, 0], [8, 0], [4, 6]]
DIAMOND = [[4, 0], [8, 4], [4, 8], [0, 4]]
L_SHAPE = [[0, 0], [12, 0], [12, 4], [4, 4], [4, 10], [0, 10]]
RECTANGLE = [[0, 0], [7, 0], [7, 4], [0, 4]]


def random_convex(seed: int) -> list[list[float]]:
    """Convex hull of 7 random points in a 9 x 7 m box (seeded)."""
    rng = np.random.default_rng(seed)
    pts = rng.uniform([0, 0], [9, 7], size=(7, 2))
    hull = shapely.MultiPoint(pts).convex_hull
    return np.round(np.asarray(hull.exterior.coords)[:-1], 6).tolist()


BOUNDARIES = {
    "triangle": TRIANGLE,
    "diamond": DIAMOND,
    "L": L_SHAPE,
    "rectangle": RECTANGLE,
    **{f"random-{s}": random_convex(s) for s in (1, 2, 3, 4)},
}


def assert_valid(res, boundary, margin=MARGIN):
    """Inside the boundary with the margin, pairwise apart by the margin (validate.py and
    plain shapely), and no fallback to stacking."""
    n = len(res.poses)
    chk = check_layout(res.poses, [SKID] * n, Polygon(boundary), margin)
    assert chk.ok, chk.problems()
    assert res.method == "convex"
    assert not any("used the stacking layout" in m for m in res.report["notices"])
    free = Polygon(boundary)
    boxes = footprint_polygons(res.poses, [SKID] * n)
    assert free.buffer(1e-6).covers(boxes).all()
    assert shapely.distance(boxes, free.boundary).min() >= margin - 1e-6
    d = shapely.distance(boxes[:, None], boxes[None, :])
    np.fill_diagonal(d, np.inf)
    assert d.min() >= margin - 1e-6


@pytest.mark.parametrize("name", list(BOUNDARIES))
def test_convex_capacity_at_least_stacking_and_valid(name):
    boundary = BOUNDARIES[name]
    st = capacity(boundary, SKID, method="stacking", margin_m=MARGIN)
    cv = capacity(boundary, SKID, method="convex", margin_m=MARGIN)
    assert len(st.poses) > 0
    assert len(cv.poses) >= len(st.poses)
    assert_valid(cv, boundary)
    # Same number of skids as stacking, laid out by convex: valid, and the closest pair at
    # least as far apart as stacking's (which packs at the margin).
    n = len(st.poses)
    res = layout(boundary, [SKID] * n, method="convex", margin_m=MARGIN)
    assert_valid(res, boundary)
    assert res.report["min_spacing_m"] >= st.report["min_spacing_m"] - 1e-6


def test_triangle_and_diamond_reach_stacking_capacity():
    """The issue's numbers: triangle 10 and diamond 11 by stacking (convex held 8 and 10)."""
    assert len(capacity(TRIANGLE, SKID, method="convex").poses) >= 10
    assert len(capacity(DIAMOND, SKID, method="convex").poses) >= 11


def test_column_graph_joins_every_pair_with_o_n_edges():
    g = from_columns([[0, 1, 2], [3, 4, 5], [6, 7, 8]], "square")
    assert g.covers_all_pairs()
    assert len(g.h) == 12 and len(g.v) == 6 and g.separators == 2
    # Without the separators' H edges the columns are unrelated.
    g2 = from_columns([[0, 1], [2, 3]], "square")
    broken = type(g2)(g2.n, g2.h[:1], g2.v, g2.separators)
    assert not broken.covers_all_pairs()


def test_transitive_reduction_drops_implied_edges():
    a = np.zeros((4, 4), dtype=bool)
    a[0, 1] = a[1, 2] = a[2, 3] = a[0, 2] = a[0, 3] = a[1, 3] = True
    assert transitive_reduction(a).tolist() == [[0, 1], [1, 2], [2, 3]]


def test_graph_from_overlapping_arrangement_is_refused():
    half = np.array([[0.5, 0.5], [0.5, 0.5]])
    with pytest.raises(ValueError, match="skids 0 and 1 are closer than the margin"):
        from_arrangement(np.array([[0.0, 0.0], [1.1, 0.5]]), half, 0.25)


@pytest.mark.parametrize("name", ["triangle", "diamond", "L"])
def test_stacking_graph_constraints_hold(name):
    """The stacking layout's H and V graphs join every pair; the seeded program keeps every
    edge's gap (eqs. 5-6) at least the margin, and the linearized distance constraints
    (eq. 4) hold at the refined layout, with ||c_i - c_j|| >= D_ij (eq. 3)."""
    region = make_region(BOUNDARIES[name], None, 0.0, MARGIN)
    k = stack(region, make_skids([SKID] * 200)).fits
    skids = make_skids([SKID] * k)
    st = stack(region, skids)
    half = skids.half
    graph = from_arrangement(st.centres, half, MARGIN)
    assert graph.covers_all_pairs()
    # Transitively reduced: far fewer edges than pairs.
    assert len(graph.h) + len(graph.v) < k * (k - 1) / 2
    segs = free_segments(region.free)
    centres, objective, g = seeded(segs, st.centres, half, MARGIN)
    assert objective >= MARGIN - 1e-6
    hi, hj = g.h.T
    gap_h = centres[hj, 0] - centres[hi, 0] - half[hi, 0] - half[hj, 0]
    vi, vj = g.v.T
    gap_v = centres[vj, 1] - centres[vi, 1] - half[vi, 1] - half[vj, 1]
    assert gap_h.min() >= MARGIN - 1e-6 and gap_v.min() >= MARGIN - 1e-6
    # Every pair is apart by the margin along the axis of its path.
    rh, rv = g.reach()
    for i, j in zip(*np.nonzero(rh), strict=True):
        assert centres[j, 0] - centres[i, 0] >= half[i, 0] + half[j, 0] + MARGIN - 1e-6
    for i, j in zip(*np.nonzero(rv), strict=True):
        assert centres[j, 1] - centres[i, 1] >= half[i, 1] + half[j, 1] + MARGIN - 1e-6

    out, info, dc, far = refine(segs, centres, half, MARGIN)
    assert info["distance_constraints"] == len(dc.i) > 0
    # Every pair has a distance constraint (neighbours) or a path in the far pairs' graph.
    fh, fv = far.reach()
    joined = fh | fh.T | fv | fv.T
    joined[dc.i, dc.j] = joined[dc.j, dc.i] = True
    np.fill_diagonal(joined, True)
    assert joined.all()
    for i, j in zip(*np.nonzero(fh), strict=True):
        assert out[j, 0] - out[i, 0] >= half[i, 0] + half[j, 0] + MARGIN - 1e-6
    for i, j in zip(*np.nonzero(fv), strict=True):
        assert out[j, 1] - out[i, 1] >= half[i, 1] + half[j, 1] + MARGIN - 1e-6
    np.testing.assert_allclose(np.hypot(dc.a[:, 0], dc.a[:, 1]), 1.0)
    assert dc.residual(out).min() >= -1e-6
    dist = np.hypot(*(out[dc.j] - out[dc.i]).T)
    assert (dist >= dc.d - 1e-6).all()
    assert info["objective_m"] >= objective - 1e-6


def test_distance_direction_is_the_footprints_closest_points():
    half = np.array([[0.5, 0.5], [0.5, 0.5], [0.5, 0.5]])
    centres = np.array([[0.0, 0.0], [2.0, 0.2], [2.0, 2.0]])
    dc = distance_constraints(centres, half, 0.25)
    # (0, 1): apart on x only -> a = (1, 0), D = 1 + 0.25.
    np.testing.assert_allclose(dc.a[0], [1.0, 0.0])
    assert dc.d[0] == pytest.approx(1.25)
    # (0, 2): apart on both axes by 1 -> diagonal, residual = Euclidean gap - margin.
    np.testing.assert_allclose(dc.a[1], [np.sqrt(0.5), np.sqrt(0.5)])
    assert dc.residual(centres)[1] == pytest.approx(np.sqrt(2) - 0.25)


def test_validator_reports_coincident_footprints():
    fp = Footprint(1.0, 1.0)
    poses = np.array([[1.0, 1.0, 0.0], [1.0, 1.0, 0.0]])
    chk = check_layout(poses, [fp, fp], Polygon([[0, 0], [4, 0], [4, 4], [0, 4]]), 0.25)
    assert not chk.ok and chk.close_pairs == ((0, 1),) and chk.min_spacing_m == 0.0


def test_linearized_distance_constraints_raise_the_spacing_beyond_the_columns():
    """Six skids in the triangle: the best column plan (diamond, columns 2-3-1) has its
    closest pair at 0.435 m; re-linearizing eq. 4 lets the columns interleave into rows of
    3-2-1 and reaches 0.562 m."""
    res = layout(TRIANGLE, [SKID] * 6, method="convex", margin_m=MARGIN)
    assert_valid(res, TRIANGLE)
    assert res.report["start"] == "column plans"
    assert res.report["start_min_gap_m"] == pytest.approx(0.435, abs=2e-3)
    assert res.report["min_spacing_m"] == pytest.approx(0.562, abs=2e-3)
    assert res.report["linearization_rounds"] >= 2
    rows = np.unique(np.round(res.poses[:, 1], 3))
    assert len(rows) == 3


@pytest.mark.parametrize("name", ["triangle", "L", "random-2"])
def test_mixed_sizes_fit_wherever_stacking_fits_them(name):
    boundary = BOUNDARIES[name]
    small = Footprint(0.9, 0.6)
    k = len(capacity(boundary, small, method="stacking", margin_m=MARGIN).poses)
    # As many pairs of both sizes as stacking fits (mixed sizes pack less well).
    for pairs in range(k // 2, 0, -1):
        fps = [SKID, small] * pairs + [small]
        try:
            st = layout(boundary, fps, method="stacking", margin_m=MARGIN)
            break
        except LayoutError:
            continue
    assert pairs >= 2
    res = layout(boundary, fps, method="convex", margin_m=MARGIN)
    assert res.method == "convex"
    chk = check_layout(res.poses, fps, Polygon(boundary), MARGIN)
    assert chk.ok, chk.problems()
    assert res.report["min_spacing_m"] >= st.report["min_spacing_m"] - 1e-6
