"""Occupancy-grid mapping: log-odds insertion, ICP, drift correction, agreement, shared frame."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import asymmetric_room, drive
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely.geometry import box

from swarmpark.core.geometry import wrap_angle
from swarmpark.core.gridmap import OccupancyGrid, grid_from_walls, load_map_yaml, save_map_yaml
from swarmpark.sense.agreement import map_agreement
from swarmpark.sense.amcl import LikelihoodField, ParticleFilter
from swarmpark.sense.lidar import LidarSpec, prepare_grid, scan
from swarmpark.sense.mapping import (
    GridMapper,
    MapperConfig,
    compose,
    relative_pose,
)
from swarmpark.sim.odometry import OdometryDrift

LOOP = [[1, 3.5], [4.5, 4.3], [7, 4.2], [7, 2.2], [4, 1.5], [3.2, 3], [1, 2.6], [1, 1], [1, 3.5]]
SPEC = LidarSpec(range_noise_std_m=0.01)


def map_run(match: bool, *, seed: int = 0, frame_pose=None, grid_like=None):
    """Drive the loop with drifting odometry and build a map; returns the mapper, the truth
    and the mapper's pose errors (in the map frame)."""
    g = asymmetric_room()
    gf = prepare_grid(g)
    truth = drive(LOOP)
    rng = np.random.default_rng(seed)
    odo = OdometryDrift(
        truth[:1],
        scale_error_std=0.02,
        yaw_bias_std_rad_per_m=0.03,
        rng=np.random.default_rng(seed + 1),
    )
    mapper = GridMapper.like(grid_like or g, spec=SPEC, config=MapperConfig(match=match))
    start = truth[0] if frame_pose is None else frame_pose
    errors = []
    for pose in truth:
        mapper.update(
            odo.step(pose[None])[0], scan(SPEC, pose[None], gf, rng=rng)[0], initial_pose=start
        )
        expected = pose if frame_pose is None else relative_pose(truth[0], pose)
        errors.append(np.hypot(*(mapper.pose[:2] - expected[:2])))
    return mapper, truth, np.array(errors), odo


@settings(max_examples=50, deadline=None)
@given(
    a=st.tuples(st.floats(-5, 5), st.floats(-5, 5), st.floats(-4, 4)),
    b=st.tuples(st.floats(-5, 5), st.floats(-5, 5), st.floats(-4, 4)),
)
def test_relative_pose_inverts_compose(a, b):
    a, b = np.array(a), np.array(b)
    back = compose(a, relative_pose(a, b))
    np.testing.assert_allclose(back[:2], b[:2], atol=1e-9)
    assert abs(wrap_angle(back[2] - b[2])) < 1e-9


def test_one_scan_marks_the_face_clears_the_way_and_leaves_the_back_unknown():
    # 6 m x 4 m, nothing but a wall whose face is at x = 4 m (from y = 1 to 3 m).
    g = grid_from_walls((6.0, 4.0), 0.05, [box(4.0, 1.0, 4.5, 3.0)])
    spec = LidarSpec()
    mapper = GridMapper.like(g, spec=spec)
    pose = np.array([1.0, 2.0, 0.0])
    mapper.insert(pose, scan(spec, pose[None], g)[0])
    cfg = mapper.config
    rc = lambda x, y: tuple(g.world_to_cell(np.array([[x, y]]))[0])  # noqa: E731
    assert mapper.log_odds[rc(4.02, 2.0)] == pytest.approx(cfg.l_occ)  # the face's cells
    assert mapper.log_odds[rc(4.02, 1.2)] == pytest.approx(cfg.l_occ)
    assert mapper.log_odds[rc(2.5, 2.0)] == pytest.approx(cfg.l_free)  # on the way
    assert mapper.log_odds[rc(3.9, 2.0)] == pytest.approx(cfg.l_free)  # just in front
    assert mapper.log_odds[rc(4.8, 2.0)] == 0.0  # behind the wall: never seen
    assert mapper.log_odds[rc(4.3, 2.0)] == 0.0  # inside the wall
    out = mapper.to_occupancy_grid()
    assert out.unknown[rc(4.8, 2.0)] and not out.occupied[rc(4.8, 2.0)]
    # One scan is not enough to call a cell free at map_server's 0.196 threshold: l_free
    # (-0.4) only brings it to p = 0.4. Three scans do (p = 0.23, then 0.18).
    assert out.unknown[rc(2.5, 2.0)]
    for _ in range(3):
        mapper.insert(pose, scan(spec, pose[None], g)[0])
    out = mapper.to_occupancy_grid()
    assert not out.unknown[rc(2.5, 2.0)] and not out.occupied[rc(2.5, 2.0)]
    assert out.occupied[rc(4.02, 2.0)]
    # Repeated hits saturate at l_max.
    for _ in range(10):
        mapper.insert(pose, scan(spec, pose[None], g)[0])
    assert mapper.log_odds.max() == pytest.approx(cfg.l_max)


def test_icp_recovers_a_known_offset():
    g = asymmetric_room()
    mapper = GridMapper.like(g, spec=SPEC)
    rng = np.random.default_rng(0)
    for pose in drive([[1, 3.5], [3.5, 4.0]])[::4]:  # a few scans at known poses
        mapper.insert(pose, scan(SPEC, pose[None], g, rng=rng)[0])
    true = np.array([3.0, 3.6, 0.3])
    guess = true + np.array([0.15, -0.1, np.radians(4.0)])
    result = mapper.match(guess, scan(SPEC, true[None], g, rng=rng)[0])
    assert result.accepted
    assert np.hypot(*(result.pose[:2] - true[:2])) < 0.01
    assert abs(wrap_angle(result.pose[2] - true[2])) < np.radians(0.3)
    assert result.inlier_share > 0.8


def test_mapping_with_drifting_odometry_needs_scan_matching():
    matched, truth, err_m, odo = map_run(match=True)
    raw, _, err_r, _ = map_run(match=False)
    # The odometry really drifts (tens of centimetres over the loop) ...
    assert np.hypot(*(odo.odom[0, :2] - truth[-1, :2])) > 0.3
    assert err_r.max() > 0.3
    # ... and scan matching holds the pose to a centimetre, so the map is right.
    assert err_m.max() < 0.03
    g = asymmetric_room()
    good = map_agreement(matched.to_occupancy_grid(), g)
    bad = map_agreement(raw.to_occupancy_grid(), g)
    assert good["share_observed"] > 0.98
    assert good["share_correct"] > 0.995
    assert good["wall_precision"] > 0.95 and good["wall_recall"] > 0.95
    assert bad["share_correct"] < good["share_correct"] - 0.03
    assert bad["wall_precision"] < 0.5
    # With one cell of tolerance the drifted map is still far off; the matched one is exact.
    assert map_agreement(raw.to_occupancy_grid(), g, tolerance_cells=1)["wall_precision"] < 0.7
    assert map_agreement(matched.to_occupancy_grid(), g, tolerance_cells=1)[
        "wall_precision"
    ] == pytest.approx(1.0, abs=0.005)


def test_along_a_lone_wall_the_matcher_keeps_to_odometry():
    """Only the south wall is in range: the scan fixes y and heading, not x. The degeneracy
    test keeps x at the odometry guess (its error stays the odometry's); without it, noise in
    the wall's normals walks x away by tens of centimetres."""
    g = grid_from_walls(
        (30.0, 12.0),
        0.05,
        [box(0, 0, 30, 0.2), box(0, 11.8, 30, 12), box(0, 0, 0.2, 12), box(29.8, 0, 30, 12)],
    )
    gf = prepare_grid(g)
    route = drive([[6.0, 2.5], [24.0, 2.5]])
    result = {}
    for ratio in (MapperConfig().match_degenerate_ratio, 0.0):
        rng = np.random.default_rng(1)
        odo = OdometryDrift(route[:1], rng=np.random.default_rng(11))
        mapper = GridMapper.like(g, spec=SPEC, config=MapperConfig(match_degenerate_ratio=ratio))
        err = []
        for p in route:
            odom = odo.step(p[None])[0]
            mapper.update(odom, scan(SPEC, p[None], gf, rng=rng)[0], initial_pose=route[0])
            err.append(mapper.pose - p)
        result[ratio] = np.abs(np.array(err)).max(axis=0)
    odometry_x_error = abs(odom[0] - route[-1, 0])
    aware, naive = result[MapperConfig().match_degenerate_ratio], result[0.0]
    assert aware[0] < odometry_x_error + 0.02
    assert aware[1] < 0.03  # across the wall the scan holds it
    assert naive[0] > 0.2
    assert naive[0] > 5 * aware[0]


def test_second_skid_localizes_in_the_first_skids_frame(tmp_path):
    """Hing 2018, Sect. 3.5.2: skid A maps from scratch in its own frame (its start pose is
    the origin); the map is saved and loaded as map_server YAML; skid B, started somewhere
    unknown, localizes in it and so reports poses in A's frame."""
    a_start = drive(LOOP)[0]
    # A map 20 m square around A's origin holds the room (8 m x 5 m) whatever A's start.
    extent = OccupancyGrid(np.zeros((400, 400), bool), 0.05, (-10.0, -10.0))
    mapper, truth, err, _ = map_run(match=True, frame_pose=np.zeros(3), grid_like=extent)
    assert err.max() < 0.03
    path = save_map_yaml(mapper.to_occupancy_grid(), tmp_path / "a_map.yaml")
    built = load_map_yaml(path)
    np.testing.assert_array_equal(built.occupied, mapper.to_occupancy_grid().occupied)
    np.testing.assert_array_equal(built.unknown, mapper.to_occupancy_grid().unknown)

    g = prepare_grid(asymmetric_room())
    route_b = drive([[6.0, 2.5], [3.0, 2.4], [3.2, 4.0]])
    pf = ParticleFilter(
        LikelihoodField(built, min_clearance_m=0.3), SPEC, rng=np.random.default_rng(9)
    )
    rng = np.random.default_rng(10)
    errors = []
    for prev, pose in zip(route_b[:-1], route_b[1:], strict=True):
        pf.predict(prev, pose)  # B's own odometry frame: any frame works for increments
        pf.update(scan(SPEC, pose[None], g, rng=rng)[0])
        in_a = relative_pose(a_start, pose)  # B's true pose expressed in A's frame
        errors.append(np.hypot(*(pf.estimate().pose[:2] - in_a[:2])))
    errors = np.array(errors)
    assert errors[10:].max() < 0.1
    assert errors[10:].mean() < 0.03


def test_agreement_on_a_hand_checked_grid():
    truth = OccupancyGrid(
        np.array(
            [
                [1, 1, 1, 1, 1],
                [1, 0, 0, 0, 1],
                [1, 0, 0, 0, 1],
                [1, 1, 1, 1, 1],
            ],
            bool,
        ),
        1.0,
    )
    # Observable: 6 free cells and the 14 wall cells that touch them (all 14 here) = 20.
    est_occ = truth.occupied.copy()
    est_unknown = np.zeros_like(est_occ)
    est_occ[1, 1] = True  # one free cell called occupied
    est_occ[0, :] = False
    est_unknown[0, :] = True  # the top row (5 wall cells) never seen
    est = OccupancyGrid(est_occ, 1.0, unknown=est_unknown)
    got = map_agreement(est, truth)
    assert got["cells_observable"] == 20
    assert got["share_observed"] == pytest.approx(15 / 20)
    assert got["share_correct"] == pytest.approx(14 / 15)
    assert got["wall_precision"] == pytest.approx(9 / 10)  # 9 real walls of 10 called walls
    assert got["wall_recall"] == pytest.approx(9 / 14)
    assert map_agreement(truth, truth)["share_correct"] == 1.0


def test_bad_inputs_are_refused():
    g = asymmetric_room()
    with pytest.raises(ValueError, match="estimate shape"):
        map_agreement(OccupancyGrid(np.zeros((3, 3), bool), 0.05), g)
    with pytest.raises(ValueError, match="share resolution and origin"):
        map_agreement(OccupancyGrid(g.occupied, 0.1), g)
    with pytest.raises(ValueError, match="mapper.l_occ"):
        MapperConfig(l_occ=-1.0)
    with pytest.raises(ValueError, match="mapper.match_min_dist_m"):
        MapperConfig(match_min_dist_m=1.0, match_max_dist_m=0.5)
    with pytest.raises(ValueError, match="mapper.insert_min_d_m"):
        MapperConfig(insert_min_d_m=-0.1)
    with pytest.raises(ValueError, match="mapper.resolution_m"):
        GridMapper((10, 10), 0.0, spec=SPEC)
    with pytest.raises(ValueError, match="free_thresh"):
        GridMapper.like(g, spec=SPEC).to_occupancy_grid(occupied_thresh=0.1, free_thresh=0.2)


def test_scans_are_matched_every_step_but_inserted_every_half_metre():
    """Keyframes (GMapping's linearUpdate): 4 m of driving in 5 cm steps is 80 scans matched,
    but only about one inserted per 0.5 m; the pose is still tracked at every step."""
    g = prepare_grid(asymmetric_room())
    route = drive([[1.0, 3.5], [5.0, 3.5]], v=0.5, dt=0.1)
    mapper = GridMapper.like(asymmetric_room(), spec=SPEC)
    rng = np.random.default_rng(0)
    for p in route:
        mapper.update(p, scan(SPEC, p[None], g, rng=rng)[0])
        assert np.hypot(*(mapper.pose[:2] - p[:2])) < 0.02
    assert len(route) >= 79
    assert 8 <= mapper.scans <= 10  # the first scan, then one per 0.5 m
