"""Arc-length spline paths: lengths, headings and curvatures against hand-checked geometry."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from swarmpark.core.paths import PathError, SplinePath


def test_straight_segment_is_exact():
    p = SplinePath.through([[1.0, 1.0], [4.0, 5.0]])  # a 3-4-5 triangle
    assert p.length_m == pytest.approx(5.0, abs=1e-12)
    s = np.array([0.0, 1.0, 2.5, 5.0])
    np.testing.assert_allclose(p.position(s), [[1, 1], [1.6, 1.8], [2.5, 3.0], [4, 5]], atol=1e-12)
    np.testing.assert_allclose(p.heading(s), math.atan2(4, 3), atol=1e-12)
    np.testing.assert_allclose(p.curvature(s), 0.0, atol=1e-12)


def test_collinear_uneven_waypoints_are_a_straight_line_in_arc_length():
    p = SplinePath.through([[0.0, 0.0], [0.5, 0.0], [3.0, 0.0], [3.2, 0.0]])
    assert p.length_m == pytest.approx(3.2, abs=1e-12)
    s = np.linspace(0.0, 3.2, 17)
    np.testing.assert_allclose(p.position(s)[:, 0], s, atol=1e-10)
    np.testing.assert_allclose(p.knot_s, [0.0, 0.5, 3.0, 3.2], atol=1e-12)


def test_circle_arc_length_heading_and_curvature():
    radius = 2.0
    th = np.linspace(0.0, np.pi / 2, 13)
    pts = radius * np.column_stack([np.cos(th), np.sin(th)])
    p = SplinePath.through(pts, start_heading=np.pi / 2, end_heading=np.pi)
    assert p.length_m == pytest.approx(radius * np.pi / 2, rel=1e-5)
    s = np.linspace(0.0, p.length_m, 101)
    np.testing.assert_allclose(np.linalg.norm(p.position(s), axis=1), radius, atol=2e-5)
    np.testing.assert_allclose(p.curvature(s), 1.0 / radius, rtol=5e-3)
    # The heading of a CCW circle is the polar angle + 90 degrees, and s = R * angle.
    np.testing.assert_allclose(np.unwrap(p.heading(s)), s / radius + np.pi / 2, atol=1e-4)
    assert p.pose(0.0)[2] == pytest.approx(np.pi / 2, abs=1e-12)


def test_clockwise_turn_has_negative_curvature():
    th = np.linspace(np.pi / 2, 0.0, 9)
    p = SplinePath.through(np.column_stack([np.cos(th), np.sin(th)]))
    assert np.all(p.curvature(np.linspace(0.2, p.length_m - 0.2, 10)) < 0)


def test_vectorized_shapes_and_clamping():
    p = SplinePath.through([[0.0, 0.0], [1.0, 1.0], [2.0, 0.0]])
    s = np.linspace(-1.0, p.length_m + 1.0, 12).reshape(3, 4)
    assert p.pose(s).shape == (3, 4, 3)
    assert p.position(s).shape == (3, 4, 2)
    assert p.curvature(s).shape == (3, 4)
    np.testing.assert_allclose(p.position(-1.0), [0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(p.position(p.length_m + 5.0), [2.0, 0.0], atol=1e-12)
    grid, table = p.table(50)
    assert grid.shape == (50,) and table.shape == (50, 4)
    np.testing.assert_allclose(np.hypot(table[:, 2], table[:, 3]), 1.0, atol=1e-12)


coord = st.floats(-5.0, 5.0, allow_nan=False)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(coord, coord), min_size=2, max_size=7))
def test_arc_length_parameterization_property(points):
    _check_arc_length(points)


@pytest.mark.parametrize(
    "points",
    [
        # Tight turns (radius 1.4 cm, 15 cm, 1.8 cm) that pass the cusp check, found by the
        # property above: with 16 table intervals per waypoint gap the inverse arc length
        # was off there and |dp/ds| by up to 7e-3.
        [(0.0, 0.0), (0.0, 1.0), (2.0, -0.5), (1.0, 3.0), (-0.625, -0.75), (-0.625, 0.0)],
        [(4.0, 0.0), (-2.5, 0.0), (-2.75, 0.0), (0.0, 0.5), (0.0, 0.0)],
        [(0.0, 1.0), (0.0, 0.0), (-0.75, 4.0), (-0.28125, 5.0), (0.0, 4.5625), (0.5, 0.0)],
    ],
)
def test_arc_length_parameterization_in_tight_turns(points):
    p = SplinePath.through(np.array(points))  # passes the cusp check
    assert np.abs(p.curvature(np.linspace(0.0, p.length_m, 4001))).max() > 6.0
    _check_arc_length(points)


def _check_arc_length(points):
    pts = np.array(points)
    if np.any(np.linalg.norm(np.diff(pts, axis=0), axis=1) < 0.05):
        return  # too close to a duplicate for a meaningful spline
    try:
        p = SplinePath.through(pts)
    except PathError as exc:
        assert "cusp" in str(exc)
        return
    # Passes through the waypoints at knot_s, in order.
    np.testing.assert_allclose(p.position(p.knot_s), pts, atol=1e-7 * (1 + p.length_m))
    assert np.all(np.diff(p.knot_s) > 0)
    # The chord length of a fine sampling approaches the arc length from below.
    s = np.linspace(0.0, p.length_m, 4001)
    chords = np.linalg.norm(np.diff(p.position(s), axis=0), axis=1)
    assert chords.sum() <= p.length_m * (1 + 1e-9)
    assert chords.sum() == pytest.approx(p.length_m, rel=1e-3)
    # Unit speed everywhere: |dp/ds| = 1 by central differences (h balances round-off in
    # the positions against the chord's curvature deficit, kappa^2 h^2 / 6).
    h = 1e-5
    inner = s[(s > 2 * h) & (s < p.length_m - 2 * h)]
    speed = np.linalg.norm(p.position(inner + h) - p.position(inner - h), axis=1) / (2 * h)
    np.testing.assert_allclose(speed, 1.0, atol=1e-4)


@pytest.mark.parametrize(
    ("waypoints", "match"),
    [
        ([[0.0, 0.0]], r"waypoints: a path needs at least 2 waypoints \(got \[\[0.0, 0.0\]\]\)"),
        ([], "waypoints"),
        ([[0.0, 0.0], [1.0, 1.0], [1.0, 1.0]], r"waypoints\[2\]: duplicate .*\[1.0, 1.0\]"),
        ([[0.0, 0.0], [np.nan, 1.0]], r"waypoints\[1\]: coordinates must be finite .*nan"),
        ([[0.0, 0.0], [np.inf, 1.0]], r"waypoints\[1\]: coordinates must be finite .*inf"),
        ([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]], r"waypoints: expected shape \(K, 2\)"),
        ("abc", "waypoints: not a list"),
    ],
)
def test_bad_waypoints_name_field_and_value(waypoints, match):
    with pytest.raises(PathError, match=match):
        SplinePath.through(waypoints)


def test_bad_headings_and_field_name():
    with pytest.raises(PathError, match=r"robots\[3\].waypoints.start_heading: must be finite"):
        SplinePath.through([[0, 0], [1, 0]], start_heading=np.nan, field_name="robots[3].waypoints")
    with pytest.raises(PathError, match="end_heading: must be a number"):
        SplinePath.through([[0, 0], [1, 0]], end_heading="north")
    p = SplinePath.through([[0, 0], [1, 0]])
    with pytest.raises(PathError, match="s: arc lengths must be finite"):
        p.position(np.nan)
