"""Simulated LIDAR: hand-checked ranges, own footprint, noise statistics, exactness."""

from __future__ import annotations

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely.geometry import LineString, Point, box

from swarmpark.core.geometry import Footprint, footprint_corners, wrap_angle
from swarmpark.core.gridmap import OccupancyGrid, grid_from_walls
from swarmpark.sense.lidar import (
    LidarSpec,
    _ray_convex,
    _sector_pairs,
    beam_angles,
    prepare_grid,
    scan,
    scan_points,
)

AHEAD, LEFT, BACK, RIGHT = 500, 750, 0, 250  # beam indices of the default 1000-beam scanner


def room_10m() -> OccupancyGrid:
    """10 m x 10 m at 5 cm, a wall whose face is at x = 6 m from y = 2 m to 8 m."""
    return grid_from_walls((10.0, 10.0), 0.05, [box(6.0, 2.0, 6.5, 8.0)])


def test_default_spec_is_the_2015_scanner():
    spec = LidarSpec()
    assert spec.num_beams == 1000
    assert spec.max_range_m == 5.0
    assert np.degrees(spec.angle_increment_rad) == pytest.approx(0.36)
    ang = beam_angles(spec)
    assert ang[AHEAD] == pytest.approx(0.0)
    assert ang[LEFT] == pytest.approx(np.pi / 2)
    assert ang[BACK] == pytest.approx(-np.pi)


def test_beam_facing_a_wall_sees_its_exact_distance():
    g = room_10m()
    spec = LidarSpec()
    poses = np.array([[2.0, 5.0, 0.0], [3.3, 4.0, 0.0], [6.0 - 1.234, 5.5, 0.0]])
    r = scan(spec, poses, g)
    assert r[:, AHEAD] == pytest.approx([4.0, 2.7, 1.234], abs=1e-9)
    # Beams off the axis hit the same (grid-aligned) face at d / cos(angle).
    ang = beam_angles(spec)
    near = np.arange(AHEAD - 40, AHEAD + 41)
    np.testing.assert_allclose(r[0, near], 4.0 / np.cos(ang[near]), atol=1e-9)


def test_facing_the_wall_from_other_headings_and_mount_offset():
    g = room_10m()
    # Robot facing +y: its left beam looks along -x at the wall's far face (x = 6.5), its
    # right beam along +x at the map's edge (x = 10), its back beam at the edge y = 0.
    r = scan(LidarSpec(), np.array([[7.0, 5.0, np.pi / 2]]), g)
    assert r[0, LEFT] == pytest.approx(0.5, abs=1e-9)
    assert r[0, RIGHT] == pytest.approx(3.0, abs=1e-9)
    assert np.isinf(r[0, BACK])
    # A scanner mounted 0.5 m ahead of the pivot is 0.5 m closer to the wall ahead.
    spec = LidarSpec(mount_x_m=0.5)
    r = scan(spec, np.array([[2.0, 5.0, 0.0]]), g)
    assert r[0, AHEAD] == pytest.approx(3.5, abs=1e-9)


def test_nothing_in_range_is_inf_and_inside_a_wall_is_zero():
    g = room_10m()
    r = scan(LidarSpec(), np.array([[5.0, 9.0, 0.0], [6.2, 5.0, 0.0]]), g)
    assert np.isinf(r[0, AHEAD])  # the wall ends at y = 8: nothing ahead within 5 m
    assert r[0, LEFT] == pytest.approx(1.0)  # the map's edge counts as a wall
    assert np.all(r[1] == 0.0)


def test_rectangle_and_disc_at_known_places():
    spec = LidarSpec()
    square = np.array([[[3.0, -0.5], [4.0, -0.5], [4.0, 0.5], [3.0, 0.5]]])
    disc = np.array([[0.0, 2.0]])
    r = scan(spec, np.zeros((1, 3)), None, polygons=square, discs=disc, disc_radii=np.array([0.5]))
    ang = beam_angles(spec)
    assert r[0, AHEAD] == pytest.approx(3.0, abs=1e-12)
    on_face = np.abs(3.0 * np.tan(ang)) < 0.5
    on_face &= np.abs(ang) < np.pi / 2
    np.testing.assert_allclose(r[0, on_face], 3.0 / np.cos(ang[on_face]), atol=1e-12)
    assert np.isinf(r[0, AHEAD + 30])  # 10.8 deg: passes beside the square (tan * 3 = 0.57)
    assert r[0, LEFT] == pytest.approx(1.5, abs=1e-12)
    # A beam at angle a from the +y axis meets the disc at the smaller root of |t u - c| = 0.5.
    a = ang[LEFT + 20]
    u = np.array([np.cos(a), np.sin(a)])
    b = u @ disc[0]
    expected = b - np.sqrt(b * b - (disc[0] @ disc[0] - 0.25))
    assert r[0, LEFT + 20] == pytest.approx(expected, abs=1e-12)
    # Only the beams that really meet something return.
    meets_disc = np.abs(wrap_angle(ang - np.pi / 2)) <= np.arcsin(0.5 / 2.0)
    np.testing.assert_array_equal(np.isfinite(r[0]), on_face | meets_disc)


def test_own_footprint_is_invisible_but_other_skids_are_seen():
    fp = Footprint(length_m=1.25, width_m=0.75, pivot_from_rear_m=0.25)
    poses = np.array([[0.0, 0.0, 0.0], [3.0, 0.0, 0.0]])  # skid 1 is 3 m ahead of skid 0
    polys = footprint_corners(poses, np.broadcast_to(fp.corners_body(), (2, 4, 2)))
    spec = LidarSpec()
    r = scan(spec, poses, None, polygons=polys, polygon_owner=np.array([0, 1]))
    assert r[0, AHEAD] == pytest.approx(3.0 - 0.25, abs=1e-12)  # skid 1's rear face
    assert r[1, BACK] == pytest.approx(3.0 - 1.0, abs=1e-12)  # skid 0's front face
    assert np.isinf(r[1, AHEAD])  # nothing in front of skid 1 (its own body is not seen)
    # Without the owners each skid would see itself from inside: range 0 everywhere.
    r_all = scan(spec, poses, None, polygons=polys)
    assert np.all(r_all == 0.0)


def test_noise_and_dropouts_have_the_configured_statistics_and_are_seeded():
    g = room_10m()
    rng = np.random.default_rng(0)
    poses = np.column_stack([rng.uniform(1, 5, 50), rng.uniform(1, 9, 50), rng.uniform(-3, 3, 50)])
    clean = scan(LidarSpec(), poses, g)
    spec = LidarSpec(range_noise_std_m=0.02, dropout_prob=0.1)
    a = scan(spec, poses, g, rng=np.random.default_rng(7))
    b = scan(spec, poses, g, rng=np.random.default_rng(7))
    np.testing.assert_array_equal(a, b)
    dropped = np.isnan(a)
    assert dropped.mean() == pytest.approx(0.1, abs=0.005)  # 50 000 beams: sd 0.0013
    both = np.isfinite(clean) & ~dropped & (clean > 0.1) & (clean < 4.9)
    err = a[both] - clean[both]
    assert abs(err.mean()) < 1e-3
    assert err.std() == pytest.approx(0.02, rel=0.03)
    assert np.all(np.isinf(a[np.isinf(clean) & ~dropped]))  # no return stays no return
    with pytest.raises(ValueError, match="rng is required"):
        scan(spec, poses, g)


def test_prepared_grid_and_raw_grid_agree_and_points_lie_on_the_face():
    g = room_10m()
    spec = LidarSpec(num_beams=360)
    poses = np.array([[2.0, 5.0, 0.1], [4.0, 3.0, -0.4]])
    r1 = scan(spec, poses, g)
    r2 = scan(spec, poses, prepare_grid(g))
    np.testing.assert_array_equal(r1, r2)
    pts = scan_points(spec, poses, r1)
    assert pts.shape == (2, 360, 2)
    assert np.all(np.isnan(pts[~np.isfinite(r1)]))
    on_wall = np.isfinite(r1) & (np.abs(pts[..., 0] - 6.0) < 1e-6)
    assert on_wall.sum() > 50
    assert np.all((pts[on_wall][:, 1] >= 2.0 - 1e-9) & (pts[on_wall][:, 1] <= 8.0 + 1e-9))


def test_partial_field_of_view_spreads_beams_over_both_ends():
    spec = LidarSpec(num_beams=181, fov_rad=np.pi)
    ang = beam_angles(spec)
    assert ang[0] == pytest.approx(-np.pi / 2) and ang[-1] == pytest.approx(np.pi / 2)
    square = np.array([[[-2.0, -0.5], [-1.0, -0.5], [-1.0, 0.5], [-2.0, 0.5]]])  # behind
    r = scan(spec, np.zeros((1, 3)), None, polygons=square)
    assert np.all(np.isinf(r))


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"num_beams": 0}, "num_beams"),
        ({"fov_rad": 7.0}, "fov_rad"),
        ({"max_range_m": -1.0}, "max_range_m"),
        ({"range_noise_std_m": -0.1}, "range_noise_std_m"),
        ({"dropout_prob": 1.0}, "dropout_prob"),
    ],
)
def test_bad_spec_names_the_field(kwargs, field):
    with pytest.raises(ValueError, match=f"lidar.{field}"):
        LidarSpec(**kwargs)


def test_bad_inputs_are_refused():
    with pytest.raises(ValueError, match=r"poses must have shape \(N, 3\)"):
        scan(LidarSpec(), np.zeros((2, 2)), None)
    with pytest.raises(ValueError, match="polygon_owner must have shape"):
        scan(LidarSpec(), np.zeros((1, 3)), None, polygons=np.zeros((2, 4, 2)), polygon_owner=[0])
    with pytest.raises(ValueError, match="disc_radii must be > 0"):
        scan(LidarSpec(), np.zeros((1, 3)), None, discs=np.ones((1, 2)), disc_radii=[0.0])


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000))
def test_grid_ranges_equal_exact_first_intersection(seed):
    """Against shapely: the first occupied cell square (or map edge) each ray meets."""
    rng = np.random.default_rng(seed)
    occ = rng.random((24, 30)) < 0.06
    g = OccupancyGrid(occ, 0.1, (-0.7, 0.4))
    spec = LidarSpec(num_beams=48, max_range_m=2.5)
    free = np.argwhere(~occ)
    origin = g.cell_to_world(free[rng.integers(len(free))][None])[0] + rng.uniform(-0.04, 0.04, 2)
    pose = np.array([[*origin, rng.uniform(-np.pi, np.pi)]])
    r = scan(spec, pose, g)[0]
    sq = g.cell_squares(np.argwhere(occ))
    cells = shapely.union_all(shapely.box(sq[:, 0, 0], sq[:, 0, 1], sq[:, 2, 0], sq[:, 2, 1]))
    xmin, ymin, xmax, ymax = g.bounds
    solid = cells.union(box(xmin - 1, ymin - 1, xmax + 1, ymax + 1).difference(box(*g.bounds)))
    o = Point(origin)
    for k, a in enumerate(pose[0, 2] + beam_angles(spec)):
        end = origin + spec.max_range_m * np.array([np.cos(a), np.sin(a)])
        hit = LineString([origin, end]).intersection(solid)
        expected = np.inf if hit.is_empty else o.distance(hit)
        if np.isinf(expected):
            assert np.isinf(r[k])
        else:
            assert r[k] == pytest.approx(expected, abs=1e-7)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000))
def test_sector_broad_phase_misses_nothing(seed):
    """Every polygon a beam meets is found by the angular broad phase (wrap-around included)."""
    rng = np.random.default_rng(seed)
    spec = LidarSpec(num_beams=200)
    sensors = np.column_stack(
        [rng.uniform(-3, 3, 4), rng.uniform(-3, 3, 4), rng.uniform(-np.pi, np.pi, 4)]
    )
    fp = Footprint(length_m=1.2, width_m=0.7)
    poses = np.column_stack(
        [rng.uniform(-4, 4, 6), rng.uniform(-4, 4, 6), rng.uniform(-np.pi, np.pi, 6)]
    )
    polys = footprint_corners(poses, np.broadcast_to(fp.corners_body(), (6, 4, 2)))
    fast = scan(spec, sensors, None, polygons=polys)
    # Brute force: every beam of every sensor against every polygon.
    ang = sensors[:, 2:3] + beam_angles(spec)
    dirs = np.stack([np.cos(ang), np.sin(ang)], -1).reshape(-1, 2)
    orig = np.repeat(sensors[:, :2], spec.num_beams, axis=0)
    t = np.stack([_ray_convex(orig, dirs, np.repeat(p[None], len(dirs), 0)) for p in polys])
    brute = t.min(axis=0).reshape(4, -1)
    brute[brute > spec.max_range_m] = np.inf
    np.testing.assert_allclose(fast, brute, atol=1e-12)
    # The broad phase keeps fewer candidate beams than all sensor x polygon x beam triples.
    _, _, pair, _ = _sector_pairs(
        spec, sensors, polys.mean(1), np.full(6, fp.circumradius_m + 1e-9), None
    )
    assert len(pair) < 4 * 6 * spec.num_beams
