"""Obstacle layer: unexplained scan points become obstacles, and clear when they leave."""

from __future__ import annotations

import numpy as np
import pytest
from shapely.geometry import box

from swarmpark.core.geometry import Footprint, footprint_corners
from swarmpark.core.gridmap import grid_from_walls
from swarmpark.sense.costmap import CostmapConfig, LocalCostmap
from swarmpark.sense.lidar import LidarSpec, prepare_grid, scan

SPEC = LidarSpec()
PERSON_R = 0.25


def room():
    """8 m x 6 m room with 10 cm walls and a pillar at (5.5..6, 4..4.5)."""
    walls = [
        box(0, 0, 8, 0.1),
        box(0, 5.9, 8, 6),
        box(0, 0, 0.1, 6),
        box(7.9, 0, 8, 6),
        box(5.5, 4.0, 6.0, 4.5),
    ]
    return grid_from_walls((8.0, 6.0), 0.05, walls)


def person(x, y):
    return {"discs": np.array([[x, y]]), "disc_radii": np.array([PERSON_R])}


def test_walls_are_explained_and_a_person_is_detected_where_they_stand():
    g = room()
    cm = LocalCostmap(g, 1, SPEC)
    pose = np.array([[2.0, 3.0, 0.0]])
    cm.update(0.0, pose, scan(SPEC, pose, g, **person(4.0, 3.0)))
    obs = cm.obstacles(0, 0.0)
    assert len(obs.cells) > 5
    # Every marked cell is on the person's near side: within a cell of the disc's rim.
    d = np.hypot(obs.points[:, 0] - 4.0, obs.points[:, 1] - 3.0)
    assert np.all(np.abs(d - PERSON_R) < 0.05)
    assert np.all(obs.points[:, 0] < 4.0)
    # Nothing on the walls or the pillar (the map explains them).
    dist = g.distance_field()[obs.cells[:, 0], obs.cells[:, 1]]
    assert np.all(dist > cm.config.map_tolerance_m)
    assert np.all(obs.age_s == 0.0)


def test_a_person_who_walks_away_is_cleared_by_the_beams_that_now_pass():
    g = prepare_grid(room())
    cm = LocalCostmap(room(), 1, SPEC)
    pose = np.array([[2.0, 3.0, 0.0]])
    cm.update(0.0, pose, scan(SPEC, pose, g, **person(4.0, 3.0)))
    assert len(cm.obstacles(0, 0.0).cells) > 0
    cm.update(0.1, pose, scan(SPEC, pose, g, **person(4.0, 1.5)))  # stepped aside
    obs = cm.obstacles(0, 0.1)
    assert len(obs.cells) > 0
    assert np.all(np.hypot(obs.points[:, 0] - 4.0, obs.points[:, 1] - 1.5) < PERSON_R + 0.05)


def test_without_clearing_a_person_out_of_view_decays_after_decay_s():
    g = room()
    cm = LocalCostmap(g, 1, SPEC, CostmapConfig(clear_on_pass=False, decay_s=1.5))
    pose = np.array([[2.0, 3.0, 0.0]])
    cm.update(0.0, pose, scan(SPEC, pose, g, **person(4.0, 3.0)))
    n0 = len(cm.obstacles(0, 0.0).cells)
    for t in (0.5, 1.0, 1.5):
        cm.update(t, pose, scan(SPEC, pose, g))  # gone, but nothing clears by passing
        assert len(cm.obstacles(0, t).cells) == n0
        assert cm.obstacles(0, t).age_s.max() == pytest.approx(t)
    cm.update(1.6, pose, scan(SPEC, pose, g))
    assert len(cm.obstacles(0, 1.6).cells) == 0


def test_a_person_still_there_is_refreshed_not_cleared():
    g = room()
    cm = LocalCostmap(g, 1, SPEC, CostmapConfig(decay_s=0.5))
    pose = np.array([[2.0, 3.0, 0.0]])
    for t in np.arange(0.0, 3.0, 0.1):
        cm.update(t, pose, scan(SPEC, pose, g, **person(4.0, 3.0)))
        obs = cm.obstacles(0, t)
        assert len(obs.cells) > 5
        assert np.all(obs.age_s == 0.0)


def test_a_dropout_does_not_clear_and_noise_does_not_mark_walls():
    g = room()
    cm = LocalCostmap(g, 1, SPEC)
    pose = np.array([[2.0, 3.0, 0.0]])
    cm.update(0.0, pose, scan(SPEC, pose, g, **person(4.0, 3.0)))
    n0 = len(cm.obstacles(0, 0.0).cells)
    blind = np.full((1, SPEC.num_beams), np.nan)  # every beam dropped out
    cm.update(0.1, pose, blind)
    assert len(cm.obstacles(0, 0.1).cells) == n0
    noisy = LidarSpec(range_noise_std_m=0.02, dropout_prob=0.05)
    cm2 = LocalCostmap(g, 1, noisy)
    rng = np.random.default_rng(0)
    for t in np.arange(0.0, 1.0, 0.1):
        cm2.update(t, pose, scan(noisy, pose, g, rng=rng))
    assert len(cm2.obstacles(0, 1.0).cells) == 0  # 2 cm noise is well within the tolerance


def test_other_skids_are_obstacles_for_each_skid_separately():
    g = room()
    fp = Footprint(length_m=1.25, width_m=0.75, pivot_from_rear_m=0.25)
    poses = np.array([[2.0, 3.0, 0.0], [4.0, 3.0, 0.0], [2.0, 1.0, 0.0]])
    polys = footprint_corners(poses, np.broadcast_to(fp.corners_body(), (3, 4, 2)))
    ranges = scan(SPEC, poses, g, polygons=polys, polygon_owner=np.arange(3))
    cm = LocalCostmap(g, 3, SPEC)
    cm.update(0.0, poses, ranges)
    # Skid 0 sees skid 1's rear face (x = 3.75) and skid 2's left side (y = 1.375).
    pts0 = cm.obstacles(0, 0.0).points
    assert np.any(np.abs(pts0[:, 0] - 3.775) < 0.03)
    assert np.any(np.abs(pts0[:, 1] - 1.35) < 0.03)
    # Nobody's own footprint is among its obstacles.
    for i in range(3):
        pts = cm.obstacles(i, 0.0).points
        c, s = np.cos(poses[i, 2]), np.sin(poses[i, 2])
        rel = pts - poses[i, :2]
        bx, by = c * rel[:, 0] + s * rel[:, 1], -s * rel[:, 0] + c * rel[:, 1]
        assert not np.any((bx > -0.25) & (bx < 1.0) & (np.abs(by) < 0.375))
    # A radius query keeps only what is near.
    near = cm.obstacles(0, 0.0, center=poses[0, :2], radius_m=1.7)
    assert len(near.points) > 0
    assert np.all(np.hypot(*(near.points - poses[0, :2]).T) <= 1.7)
    assert len(near.points) < len(pts0)


def test_costmap_grid_adds_detections_to_the_static_map():
    g = room()
    cm = LocalCostmap(g, 1, SPEC)
    pose = np.array([[2.0, 3.0, 0.0]])
    cm.update(0.0, pose, scan(SPEC, pose, g, **person(4.0, 3.0)))
    out = cm.costmap(0, 0.0)
    mask = cm.obstacle_mask(0, 0.0)
    assert mask.sum() == len(cm.obstacles(0, 0.0).cells)
    np.testing.assert_array_equal(out.occupied, g.occupied | mask)
    assert not np.any(g.occupied & mask)
    assert g.occupied.sum() + mask.sum() == out.occupied.sum()


def test_bad_inputs_are_refused():
    g = room()
    cm = LocalCostmap(g, 2, SPEC)
    with pytest.raises(ValueError, match="poses has 1 rows, expected 2"):
        cm.update(0.0, np.zeros((1, 3)), np.zeros((1, SPEC.num_beams)))
    cm.update(1.0, np.array([[2.0, 3.0, 0.0]] * 2), np.full((2, SPEC.num_beams), np.inf))
    with pytest.raises(ValueError, match="time went back"):
        cm.update(0.5, np.array([[2.0, 3.0, 0.0]] * 2), np.full((2, SPEC.num_beams), np.inf))
    with pytest.raises(ValueError, match="robot must be in"):
        cm.obstacles(2, 1.0)
    with pytest.raises(ValueError, match="costmap.decay_s"):
        CostmapConfig(decay_s=0.0)
    with pytest.raises(ValueError, match="costmap.n_robots"):
        LocalCostmap(g, 0, SPEC)


def test_a_kidnapped_skids_false_detections_fade_from_the_fleet_layer():
    """Issue 20 item 4: skid 0 is carried off (it believes it is still where it was), so
    the walls it sees land where the map has none. The fleet's layer keeps them no longer
    than ``unconfirmed_s`` even while skid 0 keeps seeing them; what the well-localized skid
    1 sees stays."""
    from helpers import asymmetric_room

    from swarmpark.sense.costmap import FleetLayer, FleetLayerConfig
    from swarmpark.sense.lidar import LidarSpec, scan

    grid = asymmetric_room()
    spec = LidarSpec(num_beams=360, max_range_m=8.0)
    truth = np.array([[6.0, 2.5, 2.0], [1.0, 2.5, 0.0]])
    believed = np.array([[3.5, 1.2, 0.3], truth[1]])  # skid 0's wrong estimate
    crate = np.array([[[3.0, 2.3], [3.4, 2.3], [3.4, 2.7], [3.0, 2.7]]])  # seen by skid 1
    cm = LocalCostmap(grid, 2, spec)
    fleet = FleetLayer(cm, FleetLayerConfig(unconfirmed_s=1.0))
    rng = np.random.default_rng(0)
    crate_cell = grid.world_to_cell(np.array([[3.0, 2.5]]))[0]
    for k in range(31):  # 3 s of scans at 10 Hz
        t = 0.1 * k
        cm.update(t, believed, scan(spec, truth, grid, polygons=crate, rng=rng))
        cells = fleet.merge(t)
        if k == 0:
            first = len(cells)
    assert cm.explained_share[0] < 0.5 < 0.9 < cm.explained_share[1]
    own = cm.obstacles(0, t).cells
    assert len(own) > 50  # skid 0 still sees its false walls ...
    merged = {tuple(c) for c in cells}
    assert not merged & {tuple(c) for c in own if tuple(c) not in _cells_of(cm, 1, t)}
    assert first >= len(own)  # ... which the fleet had at first, and has dropped since
    # The crate skid 1 sees is in the fleet's layer all along.
    near = np.abs(cells - crate_cell).max(axis=1) <= 1
    assert near.any()


def _cells_of(cm, robot, t):
    return {tuple(c) for c in cm.obstacles(robot, t).cells}


def test_fleet_layer_config_names_the_bad_field():
    from swarmpark.sense.costmap import FleetLayerConfig

    with pytest.raises(ValueError, match="unconfirmed_s"):
        FleetLayerConfig(unconfirmed_s=0.0)
    with pytest.raises(ValueError, match="trust_share"):
        FleetLayerConfig(trust_share=1.5)
