"""Tests for swarmpark.layout: hand-checked layouts, errors, validation and properties."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely
from hypothesis import HealthCheck, given, reject, settings
from hypothesis import strategies as st
from shapely.geometry import Polygon, box

from swarmpark.core.geometry import Footprint, GeometryError, footprint_polygon
from swarmpark.layout import METHODS, LayoutError, candidate_headings, capacity, layout
from swarmpark.layout.validate import check_layout

SQUARE4 = [[0, 0], [4, 0], [4, 4], [0, 4]]
L_SHAPE = [[0, 0], [12, 0], [12, 4], [4, 4], [4, 10], [0, 10]]
U_SHAPE = [[0, 0], [12, 0], [12, 9], [8, 9], [8, 4], [4, 4], [4, 9], [0, 9]]
SKID = Footprint(1.2, 0.8, pivot_from_rear_m=0.3)


def independent_check(res, footprints, boundary, margin, obstacles=None, tol=1e-6):
    """Re-check a layout with plain shapely, without the package's validator."""
    free = Polygon(boundary) if not isinstance(boundary, Polygon) else boundary
    if obstacles is not None:
        free = free.difference(obstacles)
    polys = [footprint_polygon(p, fp) for p, fp in zip(res.poses, footprints, strict=True)]
    for i, poly in enumerate(polys):
        assert free.buffer(tol).covers(poly), f"goal {i} outside the free region"
        assert poly.distance(free.boundary) >= margin - tol, f"goal {i} too close to the edge"
        assert abs(res.poses[i, 2] - res.heading) < 1e-9
    for i in range(len(polys)):
        for j in range(i + 1, len(polys)):
            assert polys[i].distance(polys[j]) >= margin - tol, f"goals {i},{j} too close"
    assert sorted(res.fill_order) == list(range(len(polys)))


# --- hand-checked stacking -------------------------------------------------------------------


def test_nine_in_square_form_3x3_grid():
    fp = Footprint(1.0, 1.0)
    res = layout(SQUARE4, [fp] * 9, margin_m=0.25)
    xs = sorted({round(float(x), 9) for x in res.poses[:, 0]})
    ys = sorted({round(float(y), 9) for y in res.poses[:, 1]})
    assert xs == [0.75, 2.0, 3.25] and ys == [0.75, 2.0, 3.25]
    # Column scan from the left-most point: first column bottom to top.
    np.testing.assert_allclose(res.poses[:3, :2], [[0.75, 0.75], [0.75, 2.0], [0.75, 3.25]])
    assert res.report["min_spacing_m"] == pytest.approx(0.25)
    assert res.report["min_boundary_clearance_m"] == pytest.approx(0.25)
    assert res.report["method"] == "stacking" and res.method == "stacking"
    independent_check(res, [fp] * 9, SQUARE4, 0.25)


def test_poses_are_pivots_not_centres():
    fp = Footprint(1.0, 1.0, pivot_from_rear_m=0.2)  # centre 0.3 m ahead of the pivot
    res = layout(SQUARE4, [fp], margin_m=0.25)
    np.testing.assert_allclose(res.poses[0], [0.45, 0.75, 0.0], atol=1e-12)
    res = layout(SQUARE4, [fp], margin_m=0.25, heading=math.pi / 2)
    # Facing +y: the centre is 0.3 m ahead (in +y) of the pivot.
    np.testing.assert_allclose(res.poses[0], [3.25, 0.45, math.pi / 2], atol=1e-9)


def test_does_not_fit_error_says_how_many():
    fp = Footprint(1.0, 1.0)
    with pytest.raises(LayoutError) as info:
        layout(SQUARE4, [fp] * 10, margin_m=0.25)
    assert info.value.fits == 9
    msg = str(info.value)
    assert msg.startswith("park.boundary: only 9 of 10 skids (1 x 1 m, margin 0.25 m) fit")
    assert "'stacking'" in msg


def test_bad_inputs_name_the_field():
    with pytest.raises(GeometryError, match="park.boundary"):
        layout([[0, 0], [4, 4], [4, 0], [0, 4]], [SKID])  # bow tie
    with pytest.raises(LayoutError, match=r"park.method: .*'best'"):
        layout(SQUARE4, [SKID], method="best")
    with pytest.raises(LayoutError, match=r"park.margin_m: .*-1"):
        layout(SQUARE4, [SKID], margin_m=-1)
    with pytest.raises(LayoutError, match=r"park.heading: .*'north'"):
        layout(SQUARE4, [SKID], heading="north")
    with pytest.raises(LayoutError, match=r"park.footprints: at least one"):
        layout(SQUARE4, [])
    with pytest.raises(LayoutError, match=r"park.footprints\[1\]"):
        layout(SQUARE4, [SKID, (1.0, 2.0)])
    with pytest.raises(LayoutError, match=r"park.opening"):
        layout(SQUARE4, [SKID], opening=(1.0, "x"))
    with pytest.raises(LayoutError) as info:
        layout(SQUARE4, [SKID], obstacles=box(-1, -1, 5, 5))
    assert info.value.fits == 0


def test_heading_rotates_the_grid():
    fp = Footprint(1.0, 0.5)
    res0 = layout([[0, 0], [10, 0], [10, 3], [0, 3]], [fp] * 6, margin_m=0.2)
    independent_check(res0, [fp] * 6, [[0, 0], [10, 0], [10, 3], [0, 3]], 0.2)
    rot = [[0, 0], [3, 0], [3, 10], [0, 10]]
    res90 = layout(rot, [fp] * 6, margin_m=0.2, heading=math.pi / 2)
    independent_check(res90, [fp] * 6, rot, 0.2)
    assert res90.heading == pytest.approx(math.pi / 2)


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("shape", [L_SHAPE, U_SHAPE], ids=["L", "U"])
def test_non_convex_boundaries(shape, method):
    res = layout(shape, [SKID] * 20, method=method)
    independent_check(res, [SKID] * 20, shape, 0.3)
    assert res.report["egress_ok"] and res.method == method


@pytest.mark.parametrize("method", METHODS)
def test_obstacle_inside_boundary_is_avoided(method):
    outer = [[0, 0], [8, 0], [8, 6], [0, 6]]
    pillar = box(3.0, 2.0, 5.0, 4.0)
    res = layout(outer, [SKID] * 12, obstacles=pillar, method=method)
    independent_check(res, [SKID] * 12, outer, 0.3, obstacles=pillar)
    # Fewer fit than without the pillar.
    assert (
        capacity(outer, SKID, obstacles=pillar).report["capacity"]
        < (capacity(outer, SKID).report["capacity"])
    )


def test_polygon_holes_are_obstacles():
    shell = [(0, 0), (8, 0), (8, 6), (0, 6)]
    hole = [(3, 2), (5, 2), (5, 4), (3, 4)]
    res = layout(Polygon(shell, [hole]), [SKID] * 12)
    independent_check(res, [SKID] * 12, shell, 0.3, obstacles=Polygon(hole))


def test_line_obstacle_splits_region():
    rect = [[0, 0], [6, 0], [6, 2], [0, 2]]
    wall = shapely.LineString([(3, -1), (3, 3)])
    fp = Footprint(1.0, 0.8)
    res = layout(rect, [fp] * 4, obstacles=wall, margin_m=0.2)
    for p in res.poses:
        poly = footprint_polygon(p, fp)
        assert poly.distance(wall) >= 0.2 - 1e-6
    # Two each side of the wall; a fifth would need to straddle it.
    assert sorted(res.poses[:, 0] < 3.0) == [False, False, True, True]
    with pytest.raises(LayoutError) as info:
        layout(rect, [fp] * 5, obstacles=wall, margin_m=0.2)
    assert info.value.fits == 4


@pytest.mark.parametrize("method", METHODS)
def test_mixed_footprints(method):
    fps = [Footprint(1.2, 0.8), Footprint(2.0, 1.0), Footprint(0.8, 0.6), Footprint(2.0, 1.0)] * 3
    res = layout(L_SHAPE, fps, method=method)
    independent_check(res, fps, L_SHAPE, 0.3)
    assert res.poses.shape == (12, 3)


def test_capacity_matches_grid_count():
    fp = Footprint(1.0, 1.0)
    cap = capacity(SQUARE4, fp, margin_m=0.25)
    assert cap.report["capacity"] == 9 and cap.poses.shape == (9, 3)
    assert capacity(SQUARE4, Footprint(5.0, 1.0)).report["capacity"] == 0


def test_capacity_elevator_question():
    # "Will 12 fit on this elevator?" 7 x 4 m platform, 1.2 x 0.8 skids, 0.3 m margin:
    # columns of pitch 1.5 m: floor((7 - 0.3) / 1.5) = 4; rows of 1.1 m: floor(3.7/1.1) = 3.
    elevator = [[0, 0], [7, 0], [7, 4], [0, 4]]
    cap = capacity(elevator, SKID)
    assert cap.report["capacity"] == 12
    independent_check(cap, [SKID] * 12, elevator, 0.3)
    with pytest.raises(LayoutError) as info:
        layout(elevator, [SKID] * 13)
    assert info.value.fits == 12


def test_heading_auto_picks_the_roomier_heading():
    # A 1.9 m wide corridor: 1.6 x 0.6 skids (+ 2 x 0.2 m margin) fit only along it, two
    # abreast (0.2 + 0.6 + 0.2 + 0.6 + 0.2 = 1.8 m).
    corridor = [[0, 0], [1.9, 0], [1.9, 12], [0, 12]]
    fp = Footprint(1.6, 0.6)
    res = layout(corridor, [fp] * 6, heading="auto", margin_m=0.2)
    assert abs(math.cos(res.heading)) < 1e-9  # 90 degrees
    assert res.report["heading_deg"] == pytest.approx(90.0)
    assert "auto_heading" in res.report
    cap = capacity(corridor, fp, heading="auto", margin_m=0.2)
    assert cap.report["capacity"] == 2 * 6  # rows of pitch 1.8 m: floor(11.8 / 1.8) = 6
    assert capacity(corridor, fp, margin_m=0.2).report["capacity"] == 0


def test_candidate_headings():
    hs = candidate_headings([[0, 0], [4, 0], [0, 3]])
    np.testing.assert_allclose(np.degrees(hs), [0, 90, -36.8698976, 53.1301024], atol=1e-6)


def test_fill_order_deepest_first():
    fp = Footprint(1.0, 1.0)
    # Opening in the middle of the bottom edge: the top row is deepest and filled first.
    res = layout(SQUARE4, [fp] * 9, margin_m=0.25, opening=(2.0, -1.0))
    ys = res.poses[list(res.fill_order), 1]
    assert np.all(np.diff(ys) <= 1e-9)
    assert res.report["egress_ok"] and res.report["egress_layers"] == 3
    assert res.report["opening"] == pytest.approx([2.0, 0.0])


def test_egress_unreachable_goal_is_reported():
    # Two rooms joined by a slot narrower than the skid: goals in the far room are unreachable.
    shape = [[0, 0], [9, 0], [9, 4], [0, 4]]
    wall = box(4.0, 0.0, 4.5, 3.5)  # leaves a 0.5 m gap at the top, skids are 0.8 m wide
    res = layout(shape, [SKID] * 9, obstacles=wall, opening=(0.0, 2.0))
    assert not res.report["egress_ok"]
    assert any("egress" in n for n in res.report["notices"])
    far = [i for i in range(9) if res.poses[i, 0] > 4.5]
    assert far  # stacking reached the far room
    # Unreachable goals come first in the fill order.
    assert set(res.fill_order[: len(far)]) == set(far)


def test_check_layout_flags_problems():
    fp = Footprint(1.0, 1.0)
    free = box(0, 0, 4, 2)
    good = np.array([[1.0, 1.0, 0.0], [2.5, 1.0, 0.0]])
    assert check_layout(good, [fp, fp], free, 0.5).ok
    close = np.array([[1.0, 1.0, 0.0], [2.2, 1.0, 0.0]])
    chk = check_layout(close, [fp, fp], free, 0.5)
    assert not chk.ok and chk.close_pairs == ((0, 1),)
    assert chk.min_spacing_m == pytest.approx(0.2)
    out = np.array([[0.3, 1.0, 0.0]])
    chk = check_layout(out, [fp], free, 0.5)
    assert not chk.ok and chk.outside == (0,) and chk.min_boundary_clearance_m == 0.0
    overlap = np.array([[1.0, 1.0, 0.0], [1.5, 1.0, 0.3]])
    chk = check_layout(overlap, [fp, fp], box(-5, -5, 5, 5), 0.1)
    assert chk.close_pairs == ((0, 1),) and chk.min_spacing_m == 0.0


def test_deterministic():
    a = layout(U_SHAPE, [SKID] * 15, heading="auto")
    b = layout(U_SHAPE, [SKID] * 15, heading="auto")
    np.testing.assert_array_equal(a.poses, b.poses)
    assert a.fill_order == b.fill_order


# --- properties ------------------------------------------------------------------------------


@st.composite
def star_polygons(draw):
    """Random simple polygons: star-shaped about the origin (sorted angles, random radii)."""
    k = draw(st.integers(4, 10))
    # Operators do not draw zero-width spikes: the angles between neighbouring vertices are
    # drawn as shares (1 to 10) of the full turn, so no two are closer than 2 pi / (10 k),
    # over 3 degrees (rejecting angles drawn too close threw away half the examples, and
    # Hypothesis's health check failed the test now and then).
    shares = np.array(draw(st.lists(st.floats(1.0, 10.0), min_size=k, max_size=k)))
    start = draw(st.floats(0, 2 * np.pi, exclude_max=True))
    angles = start + 2 * np.pi * np.concatenate([[0.0], np.cumsum(shares)[:-1]]) / shares.sum()
    radii = draw(st.lists(st.floats(2.0, 8.0), min_size=k, max_size=k))
    pts = np.column_stack([radii * np.cos(angles), radii * np.sin(angles)])
    poly = Polygon(pts)
    if not poly.is_valid or poly.area < 1.0:
        reject()
    return pts.tolist()


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    boundary=star_polygons(),
    n=st.integers(1, 12),
    length=st.floats(0.5, 2.0),
    width=st.floats(0.4, 1.2),
    heading=st.floats(-np.pi, np.pi),
    margin=st.floats(0.0, 0.5),
)
def test_property_stacking_valid_or_clear_error(boundary, n, length, width, heading, margin):
    fp = Footprint(length, width)
    try:
        res = layout(boundary, [fp] * n, heading=heading, margin_m=margin)
    except LayoutError as exc:
        assert exc.fits is not None and exc.fits < n
        assert f"only {exc.fits} of {n} skids" in str(exc)
        return
    independent_check(res, [fp] * n, boundary, margin)


def test_methods_are_the_three_of_the_papers():
    assert METHODS == ("stacking", "potential", "convex")


# --- potential field -------------------------------------------------------------------------


def nearest_gaps(res, fp):
    """Nearest-neighbour gap of each goal (plain shapely)."""
    polys = [footprint_polygon(p, fp) for p in res.poses]
    return np.array(
        [min(a.distance(b) for j, b in enumerate(polys) if j != i) for i, a in enumerate(polys)]
    )


def test_potential_spreads_the_stacking_goals():
    room = [[0, 0], [12, 0], [12, 9], [0, 9]]
    st = layout(room, [SKID] * 30)
    pf = layout(room, [SKID] * 30, method="potential")
    independent_check(pf, [SKID] * 30, room, 0.3)
    # Stacking packs every goal against a neighbour; the field opens the formation up.
    np.testing.assert_allclose(nearest_gaps(st, SKID), 0.3, atol=1e-9)
    assert nearest_gaps(pf, SKID).mean() > 0.35
    rep = pf.report
    assert rep["variant"] == "footprint" and rep["converged"]
    assert rep["energy_final"] < rep["energy_initial"]
    assert 0 < rep["iterations"] <= 300
    # The spread reaches the far side of the room, which stacking leaves empty.
    assert pf.poses[:, 0].max() > 10.0 > st.poses[:, 0].max()


def test_potential_footprint_variant_for_mixed_sizes():
    fps = [Footprint(1.2, 0.8), Footprint(2.0, 1.0), Footprint(0.8, 0.6)] * 4
    room = [[0, 0], [12, 0], [12, 9], [0, 9]]
    res = layout(room, fps, method="potential")
    assert res.report["variant"] == "footprint"
    assert res.report["energy_final"] < res.report["energy_initial"]
    independent_check(res, fps, room, 0.3)
    assert check_layout(res.poses, fps, Polygon(room), margin_m=0.3).ok


def test_potential_spreads_nine_skids_to_fill_the_box():
    """Issue 21: 9 skids of 1.2 x 0.8 m in 8 x 6 m. Stacking packs them at the margin (0.30
    m); the paper's centroid field stops in a 4-2-3 arrangement (0.54 m); the footprint field
    fills the box as a 3 x 3 grid, near convex's max-min spacing (0.90 m)."""
    from swarmpark.layout import potential
    from swarmpark.layout.methods import stack_best
    from swarmpark.layout.region import make_region, make_skids, rect_gaps

    box8x6 = [[0, 0], [8, 0], [8, 6], [0, 6]]
    fps = [Footprint(1.2, 0.8)] * 9
    st = layout(box8x6, fps, method="stacking")
    pf = layout(box8x6, fps, method="potential")
    assert st.report["min_spacing_m"] == pytest.approx(0.3)
    assert pf.report["min_spacing_m"] >= 0.8
    assert pf.report["min_boundary_clearance_m"] >= 0.8
    for res in (st, pf):
        assert check_layout(res.poses, fps, Polygon(box8x6), margin_m=0.3).ok
        independent_check(res, fps, box8x6, 0.3)
    # Three columns of three: the grid the box's shape calls for.
    assert sorted(np.bincount(np.digitize(pf.poses[:, 0], [8 / 3, 16 / 3]))) == [3, 3, 3]
    # The paper's own centroid variant, from the same start, spreads less (the gap to close).
    region = make_region(box8x6, None, 0.0, 0.3)
    skids = make_skids(fps)
    start = stack_best(region, skids, 9).centres
    centroid, _ = potential.spread(region, skids, start, variant="centroid")
    assert rect_gaps(centroid, skids.half).min() < 0.7


def test_potential_footprint_terms_by_hand():
    from swarmpark.layout.potential import local_terms

    # Two 1 x 1 squares 3 m apart along x (gap 2 m), a boundary point 0.5 m below the first.
    centres = np.array([[0.0, 0.0], [3.0, 0.0]])
    half = np.full((2, 2), 0.5)
    bpts = np.array([[0.0, -1.0]])
    pair, bnd, force = local_terms(
        centres, centres, half, bpts, variant="footprint", threshold_m=1.0, boundary_weight=2.0
    )
    np.testing.assert_allclose(pair, [0.5, 0.5])  # 1 / gap
    # Point 0.5 m from the first square (2 * (1/0.5 - 1/1)); beyond the threshold of the other.
    np.testing.assert_allclose(bnd, [2.0, 0.0])
    # Force on the first: away from the second, 1/2^2, plus 2 * 1/0.5^2 up from the point.
    np.testing.assert_allclose(force[0], [-0.25, 8.0])
    np.testing.assert_allclose(force[1], [0.25, 0.0])


def test_potential_iteration_cap_is_reported():
    from swarmpark.layout import potential, stacking
    from swarmpark.layout.region import make_region, make_skids

    region = make_region([[0, 0], [12, 0], [12, 9], [0, 9]], None, 0.0, 0.3)
    skids = make_skids([SKID] * 20)
    start = stacking.stack(region, skids).centres
    centres, info = potential.spread(region, skids, start, max_iterations=3, relocations=0)
    assert info["iterations"] == 3 and not info["converged"]
    assert "iteration cap 3" in info["notices"][0]
    _, info_v = potential.spread(region, skids, start, variant="vertex", max_iterations=5)
    assert info_v["variant"] == "vertex" and info_v["energy_final"] < info_v["energy_initial"]
    with pytest.raises(ValueError, match="variant"):
        potential.spread(region, skids, start, variant="edges")


def test_potential_energy_terms_by_hand():
    from swarmpark.layout.potential import local_terms, total_energy

    centres = np.array([[0.0, 0.0], [3.0, 4.0]])
    half = np.array([[0.5, 0.5], [0.5, 0.5]])
    bpts = np.array([[0.0, -1.0], [0.0, -10.0]])  # the second is beyond the threshold
    pair, bnd, force = local_terms(
        centres, centres, half, bpts, variant="centroid", threshold_m=2.0, boundary_weight=1.0
    )
    np.testing.assert_allclose(pair, [0.2, 0.2])  # 1 / 5
    np.testing.assert_allclose(bnd, [1.0 - 0.5, 0.0])  # 1/d - 1/threshold, d = 1
    assert total_energy(pair, bnd) == pytest.approx(0.2 + 0.5)
    # Force on goal 0: away from goal 1, (-3, -4) / 125, plus (0, 1) / 1 from the point.
    np.testing.assert_allclose(force[0], [-3 / 125, -4 / 125 + 1.0])


def test_potential_footprint_terms_match_a_dense_reference():
    """The footprint field looks boundary points up in a KD-tree: same values as all pairs."""
    from swarmpark.layout.potential import local_terms

    rng = np.random.default_rng(3)
    centres = rng.uniform(0, 10, (12, 2))
    half = rng.uniform(0.2, 0.8, (12, 2))
    bpts = rng.uniform(-1, 11, (300, 2))
    thr, w = 1.5, 0.3
    pair, bnd, force = local_terms(
        centres, centres, half, bpts, variant="footprint", threshold_m=thr, boundary_weight=w
    )

    def gap(dc, reach):
        ax = np.maximum(np.abs(dc) - reach, 0.0)
        d = max(float(np.hypot(*ax)), 1e-3)
        return d, np.sign(dc) * ax / d

    for i in range(12):
        e_pair, e_bnd, f = 0.0, 0.0, np.zeros(2)
        for j in range(12):
            if j != i:
                d, g = gap(centres[i] - centres[j], half[i] + half[j])
                e_pair, f = e_pair + 1 / d, f + g / d**2
        for b in bpts:
            d, g = gap(centres[i] - b, half[i])
            if d < thr:
                e_bnd, f = e_bnd + w * (1 / d - 1 / thr), f + w * g / d**2
        assert pair[i] == pytest.approx(e_pair, rel=1e-9)
        assert bnd[i] == pytest.approx(e_bnd, rel=1e-9, abs=1e-12)
        np.testing.assert_allclose(force[i], f, rtol=1e-9, atol=1e-12)
    # Rows only: the same values for the skids asked about.
    rows = np.array([4, 7])
    p2, b2, f2 = local_terms(
        centres[rows],
        centres,
        half,
        bpts,
        variant="footprint",
        threshold_m=thr,
        boundary_weight=w,
        rows=rows,
    )
    np.testing.assert_allclose(p2, pair[rows])
    np.testing.assert_allclose(b2, bnd[rows])
    np.testing.assert_allclose(f2, force[rows])


@settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    boundary=star_polygons(),
    n=st.integers(1, 10),
    length=st.floats(0.5, 2.0),
    width=st.floats(0.4, 1.2),
    heading=st.floats(-np.pi, np.pi),
    margin=st.floats(0.0, 0.5),
)
def test_property_potential_valid_or_clear_error(boundary, n, length, width, heading, margin):
    fp = Footprint(length, width)
    try:
        res = layout(boundary, [fp] * n, heading=heading, margin_m=margin, method="potential")
    except LayoutError as exc:
        assert exc.fits is not None and exc.fits < n
        return
    independent_check(res, [fp] * n, boundary, margin)


# --- convex optimization ---------------------------------------------------------------------


def test_convex_nine_in_square_3x3():
    fp = Footprint(1.0, 1.0)
    res = layout(SQUARE4, [fp] * 9, margin_m=0.25, method="convex")
    xs = sorted({round(float(x), 6) for x in res.poses[:, 0]})
    ys = sorted({round(float(y), 6) for y in res.poses[:, 1]})
    assert xs == [0.75, 2.0, 3.25] and ys == [0.75, 2.0, 3.25]
    assert res.report["pieces"][0]["columns"] == [3, 3, 3]


def test_convex_maximizes_the_min_spacing_by_hand():
    # Four 1 x 1 skids in a 6 x 6 square: a 2 x 2 grid with equal gaps t, 3 t + 2 = 6.
    fp = Footprint(1.0, 1.0)
    room = [[0, 0], [6, 0], [6, 6], [0, 6]]
    res = layout(room, [fp] * 4, margin_m=0.25, method="convex")
    t = 4.0 / 3.0
    assert res.report["objective_m"] == pytest.approx(t, abs=1e-6)
    assert res.report["min_spacing_m"] == pytest.approx(t, abs=1e-6)
    assert res.report["min_boundary_clearance_m"] == pytest.approx(t, abs=1e-6)
    np.testing.assert_allclose(
        np.sort(res.poses[:, 0]), [t + 0.5] * 2 + [2 * t + 1.5] * 2, atol=1e-5
    )


def test_convex_structured_optimization_spreads_beyond_the_bottleneck():
    # Three 1 x 1 skids in an 8 x 3 bay: the bottleneck is the height (1 m above and below,
    # t = 1). Held there, the horizontal gaps grow: 8 = 1 + 3 + 2 alpha + 1, alpha = 1.5.
    fp = Footprint(1.0, 1.0)
    bay = [[0, 0], [8, 0], [8, 3], [0, 3]]
    res = layout(bay, [fp] * 3, margin_m=0.25, method="convex")
    assert res.report["objective_m"] == pytest.approx(1.0, abs=1e-6)
    assert res.report["iterations"] >= 2
    np.testing.assert_allclose(np.sort(res.poses[:, 0]), [1.5, 4.0, 6.5], atol=1e-5)
    np.testing.assert_allclose(res.poses[:, 1], 1.5, atol=1e-5)
    assert res.report["min_spacing_m"] == pytest.approx(1.5, abs=1e-5)


def test_convex_diamond_scheme_in_a_diamond():
    # Nine 1 x 1 skids in a diamond: column sizes that follow its width (here 2-3-3-1 in
    # four columns) beat the square 3 x 3 grid.
    diamond = [[0, -6], [6, 0], [0, 6], [-6, 0]]
    fp = Footprint(1.0, 1.0)
    res = layout(diamond, [fp] * 9, margin_m=0.25, method="convex")
    independent_check(res, [fp] * 9, diamond, 0.25)
    piece = res.report["pieces"][0]
    assert piece["scheme"] == "diamond" and piece["columns"] == [2, 3, 3, 1]
    # It beats the square 3 x 3 grid in the same diamond.
    from swarmpark.layout import convex
    from swarmpark.layout.region import make_region, make_skids

    region = make_region(diamond, None, 0.0, 0.25)
    (piece0,), _ = convex.convex_pieces(region.free)
    square = convex.solve_piece(
        piece0, make_skids([fp] * 9).half, 0.25, structured=False, plan=("square", (3, 3, 3))
    )
    assert square is not None and square.objective < res.report["objective_m"] - 0.05


def test_convex_beats_stacking_and_potential_on_a_convex_boundary():
    room = [[0, 0], [12, 0], [12, 9], [0, 9]]
    spacing = {m: layout(room, [SKID] * 30, method=m).report["min_spacing_m"] for m in METHODS}
    assert spacing["convex"] > max(spacing["stacking"], spacing["potential"]) + 0.2


def test_convex_non_convex_boundary_is_split_with_notice():
    res = layout(U_SHAPE, [SKID] * 20, method="convex")
    assert len(res.report["pieces"]) == 3
    assert res.report["decomposition"] in ("vertical strips", "horizontal strips", "triangles")
    assert any("split into 3 convex pieces" in n for n in res.report["notices"])
    independent_check(res, [SKID] * 20, U_SHAPE, 0.3)


def test_convex_pieces_marks_cuts():
    from swarmpark.layout.convex import CUT_WEIGHT, convex_pieces
    from swarmpark.layout.region import make_region

    region = make_region(L_SHAPE, None, 0.0, 0.3)
    pieces, how = convex_pieces(region.free)
    assert len(pieces) == 2 and how == "vertical strips"
    assert sum(p.polygon.area for p in pieces) == pytest.approx(Polygon(L_SHAPE).area)
    # The cut at x = 4 is a pure cut only for the arm on the right; for the left arm that
    # line is partly wall (x = 4, y > 4), so it keeps the full margin.
    cuts = [p.normals[p.weights == CUT_WEIGHT] for p in pieces]
    assert sorted(len(c) for c in cuts) == [0, 1]
    (cut,) = [c for c in cuts if len(c)]
    np.testing.assert_allclose(cut[0], [-1.0, 0.0], atol=1e-12)


def test_convex_does_not_fit_error_and_capacity():
    elevator = [[0, 0], [7, 0], [7, 4], [0, 4]]
    cap = capacity(elevator, SKID, method="convex")
    assert cap.report["capacity"] == 12
    independent_check(cap, [SKID] * 12, elevator, 0.3)
    with pytest.raises(LayoutError) as info:
        layout(elevator, [SKID] * 13, method="convex")
    assert info.value.fits == 12
    assert "only 12 of 13 skids" in str(info.value) and "'convex'" in str(info.value)


@settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    boundary=star_polygons(),
    n=st.integers(1, 8),
    length=st.floats(0.5, 2.0),
    width=st.floats(0.4, 1.2),
    heading=st.floats(-np.pi, np.pi),
    margin=st.floats(0.0, 0.5),
)
def test_property_convex_valid_or_clear_error(boundary, n, length, width, heading, margin):
    fp = Footprint(length, width)
    try:
        res = layout(boundary, [fp] * n, heading=heading, margin_m=margin, method="convex")
    except LayoutError as exc:
        assert exc.fits is not None and exc.fits < n
        assert f"only {exc.fits} of {n} skids" in str(exc)
        return
    independent_check(res, [fp] * n, boundary, margin)


def test_potential_spreads_the_skids_beyond_the_packed_stacking_layout():
    """2018 Sect. 3.2.2: the field pushes the goals apart to fill the boundary. The plain
    descent from stacking stops packed (a column of five held by equal pushes: closest pair
    at the 0.3 m margin); the relocation moves reach a spread layout."""
    from swarmpark.layout import potential, stacking
    from swarmpark.layout.region import make_region, make_skids

    room = [[0, 0], [8, 0], [8, 6], [0, 6]]
    fps = [SKID] * 9
    stack = layout(room, fps, method="stacking", heading=0.0)
    spread = layout(room, fps, method="potential", heading=0.0)
    assert stack.report["min_spacing_m"] < 0.31
    assert spread.report["min_spacing_m"] > 0.5
    assert spread.report["relocations"] >= 1
    assert spread.report["energy_final"] < spread.report["energy_initial"]
    independent_check(spread, fps, room, 0.3)
    region = make_region(room, None, 0.0, 0.3)
    skids = make_skids(fps)
    start = stacking.stack(region, skids).centres
    plain, info = potential.spread(region, skids, start, relocations=0)
    full, info_full = potential.spread(region, skids, start)
    assert info_full["energy_final"] < info["energy_final"]


def test_an_apron_by_the_opening_is_kept_free_when_the_skids_fit_so():
    """Room by the opening (the supervisor asks for it): no spot within ``apron_m`` of the
    opening while the skids fit; the paper's stacking puts the first skid right there."""
    boundary = [[0, 0], [8, 0], [8, 6], [0, 6]]
    opening = (0.0, 3.0)
    plain = layout(boundary, [SKID] * 6, opening=opening)
    assert "room_by_opening" not in plain.report
    disc = shapely.Point(opening).buffer(2.0)
    assert any(footprint_polygon(p, SKID).intersects(disc) for p in plain.poses)
    res = layout(boundary, [SKID] * 6, opening=opening, apron_m=2.0)
    assert res.report["room_by_opening"] == "apron"
    independent_check(res, [SKID] * 6, boundary, 0.3)
    assert not any(footprint_polygon(p, SKID).intersects(disc) for p in res.poses)


def test_without_room_for_the_apron_the_room_left_over_lies_by_the_opening():
    """One row of four slots for three skids: the apron does not fit, so the skids are
    stacked from the far end and the free slot is the one by the opening (the paper's scan
    leaves it at the far end); a full row stays as it was."""
    row = [[0, 0], [6.3, 0], [6.3, 1.4], [0, 1.4]]  # 4 slots of 1.2 m + 0.3 m margins
    near = layout(row, [SKID] * 3, opening=(0.0, 0.7))
    far = layout(row, [SKID] * 3, opening=(0.0, 0.7), apron_m=2.0)
    assert far.report["room_by_opening"] == "far corner"
    independent_check(far, [SKID] * 3, row, 0.3)
    assert min(far.poses[:, 0]) > min(near.poses[:, 0]) + 1.4  # one slot further in
    assert max(far.poses[:, 0]) > max(near.poses[:, 0])
    full = layout(row, [SKID] * 4, opening=(0.0, 0.7), apron_m=2.0)
    np.testing.assert_allclose(
        np.sort(full.poses[:, 0]), np.sort(layout(row, [SKID] * 4).poses[:, 0]), atol=1e-9
    )


@pytest.mark.parametrize("bad", [-1.0, float("nan"), "wide"])
def test_a_bad_apron_is_refused_with_its_value(bad):
    with pytest.raises(LayoutError, match="park.apron_m"):
        layout(SQUARE4, [SKID], opening=(0.0, 2.0), apron_m=bad)
