"""Collision and distance kernels on cases checked by hand."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely.geometry import Point

from swarmpark.core.geometry import (
    Footprint,
    GeometryError,
    as_simple_polygon,
    center_to_pivot,
    convex_gap,
    convex_overlap,
    footprint_corners,
    footprint_polygon,
    pivot_to_center,
    rect_disc_gap,
    triangulate,
)

UNIT = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)


def rect(cx, cy, length, width, yaw):
    fp = Footprint(length, width)
    return footprint_corners(np.array([[cx, cy, yaw]]), fp.corners_body()[None])[0]


def test_touching_squares_are_not_a_collision():
    a, b = UNIT[None], (UNIT + [1.0, 0.0])[None]
    assert convex_gap(a, b)[0] == pytest.approx(0.0, abs=1e-12)
    assert convex_overlap(a, b)[0] <= 1e-12


def test_overlapping_squares_report_depth():
    assert convex_gap(UNIT[None], (UNIT + [0.75, 0.5])[None])[0] == pytest.approx(-0.25)


def test_separated_squares_report_distance_corner_to_corner():
    assert convex_gap(UNIT[None], (UNIT + [2.0, 2.0])[None])[0] == pytest.approx(np.sqrt(2))


def test_rotated_rectangles_overlap_only_through_the_corner():
    # A 1 x 1 square rotated 45 deg, centred 1.2 m to the right of a unit square's centre:
    # its left corner reaches x = 1.2 - sqrt(2)/2 = 0.4929 < 0.5, so it pokes in by 7.1 mm.
    a = rect(0, 0, 1, 1, 0)
    b = rect(1.2, 0, 1, 1, np.pi / 4)
    assert convex_gap(a[None], b[None])[0] == pytest.approx(-(0.5 - (1.2 - np.sqrt(0.5))), abs=1e-9)
    c = rect(1.3, 0, 1, 1, np.pi / 4)  # 1.3 - 0.7071 = 0.5929: 92.9 mm apart
    assert convex_gap(a[None], c[None])[0] == pytest.approx(1.3 - np.sqrt(0.5) - 0.5, abs=1e-9)


def test_disc_against_rectangle():
    corners = rect(0, 0, 2, 1, 0)[None]  # x in [-1, 1], y in [-0.5, 0.5]
    assert rect_disc_gap(corners, np.array([[2.0, 0.0]]), np.array([0.5]))[0] == pytest.approx(0.5)
    assert rect_disc_gap(corners, np.array([[1.3, 0.0]]), np.array([0.5]))[0] == pytest.approx(-0.2)
    # Diagonal from the corner (1, 0.5): distance sqrt(0.3^2 + 0.4^2) = 0.5, so exactly touching.
    assert rect_disc_gap(corners, np.array([[1.3, 0.9]]), np.array([0.5]))[0] == pytest.approx(0.0)
    # Centre inside: the penetration is at least the radius.
    assert rect_disc_gap(corners, np.array([[0.0, 0.0]]), np.array([0.2]))[0] == pytest.approx(-0.7)


@settings(max_examples=200, deadline=None)
@given(
    st.floats(-3, 3),
    st.floats(-3, 3),
    st.floats(-np.pi, np.pi),
    st.floats(0.2, 2),
    st.floats(0.2, 2),
    st.floats(-np.pi, np.pi),
)
def test_gap_agrees_with_shapely(x, y, yaw, length, width, yaw_a):
    a = rect(0, 0, 1.2, 0.8, yaw_a)
    b = rect(x, y, length, width, yaw)
    from shapely.geometry import Polygon

    pa, pb = Polygon(a), Polygon(b)
    g = convex_gap(a[None], b[None])[0]
    if pa.intersection(pb).area > 1e-9:
        assert g < 0
    else:
        assert g == pytest.approx(pa.distance(pb), abs=1e-9)


@settings(max_examples=100, deadline=None)
@given(st.floats(-2, 2), st.floats(-2, 2), st.floats(0.05, 1.0), st.floats(-np.pi, np.pi))
def test_disc_gap_agrees_with_shapely(x, y, r, yaw):
    corners = rect(0, 0, 1.2, 0.8, yaw)
    from shapely.geometry import Polygon

    g = rect_disc_gap(corners[None], np.array([[x, y]]), np.array([r]))[0]
    d = Polygon(corners).distance(Point(x, y))
    if d > 0:
        assert g == pytest.approx(d - r, abs=1e-9)
    else:
        assert g < 0


def test_footprint_pivot_and_centre_round_trip():
    fp = Footprint(1.2, 0.8, pivot_from_rear_m=0.2)
    pose = np.array([[3.0, 4.0, np.pi / 2]])
    c = pivot_to_center(pose, np.array([fp.center_offset_m]))
    assert c[0] == pytest.approx([3.0, 4.4])
    assert center_to_pivot(c, pose[:, 2], np.array([fp.center_offset_m]))[0] == pytest.approx(
        pose[0]
    )
    poly = footprint_polygon(pose[0], fp)
    assert poly.bounds == pytest.approx((2.6, 3.8, 3.4, 5.0))


def test_footprint_rejects_bad_dimensions():
    with pytest.raises(GeometryError, match="length_m and width_m must be > 0"):
        Footprint(0.0, 1.0)
    with pytest.raises(GeometryError, match="pivot_from_rear_m must lie within the body"):
        Footprint(1.0, 1.0, pivot_from_rear_m=1.5)


def test_simple_polygon_check_names_the_field():
    with pytest.raises(
        GeometryError, match=r"park.boundary: not a simple polygon \(Self-intersection"
    ):
        as_simple_polygon([[0, 0], [2, 2], [2, 0], [0, 2]], "park.boundary")
    with pytest.raises(GeometryError, match="park.boundary: a polygon needs at least 3"):
        as_simple_polygon([[0, 0], [1, 1]], "park.boundary")


def test_triangulation_covers_a_non_convex_polygon_exactly():
    from shapely.geometry import Polygon

    ell = Polygon([(0, 0), (2, 0), (2, 2), (1, 2), (1, 1), (0, 1)])
    tris = triangulate(ell)
    assert sum(Polygon(t).area for t in tris) == pytest.approx(ell.area)
    # Counter-clockwise, so the SAT normals point outward.
    e1, e2 = tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]
    cross = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    assert np.all(cross > 0)
