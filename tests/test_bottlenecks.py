"""Bottleneck zones of a map (:mod:`swarmpark.plan.bottlenecks`)."""

from __future__ import annotations

import numpy as np
from shapely.geometry import box

from swarmpark.core.gridmap import grid_from_walls
from swarmpark.plan.bottlenecks import find_bottlenecks

KW = {"min_width_m": 0.8, "lane_width_m": 2.8, "pad_m": 0.9}


def _two_rooms(door_m: float):
    """Two 6 m x 6 m rooms side by side, joined by a door of ``door_m`` in a 0.3 m wall."""
    lo, hi = 3.0 - door_m / 2, 3.0 + door_m / 2
    walls = [box(5.85, 0.0, 6.15, lo), box(5.85, hi, 6.15, 6.0)]
    return grid_from_walls((12.0, 6.0), 0.05, walls)


def test_a_door_between_two_rooms_is_one_zone_with_a_region_on_each_side():
    b = find_bottlenecks(_two_rooms(1.6), **KW)
    assert b.count == 1
    assert b.zone_at(np.array([[6.0, 3.0]]))[0] == 1
    assert 1.4 <= b.widths_m[0] <= 1.7
    left, right = b.region_at(np.array([[2.0, 3.0], [10.0, 3.0]]))
    assert left > 0 and right > 0 and left != right
    # The zone reaches past the door on both sides, not across the rooms.
    assert b.zone_at(np.array([[5.0, 3.0], [7.0, 3.0]])).tolist() == [1, 1]
    assert b.zone_at(np.array([[3.0, 3.0], [9.0, 3.0]])).tolist() == [0, 0]


def test_wide_openings_corners_and_pillars_are_not_zones():
    assert find_bottlenecks(_two_rooms(4.0), **KW).count == 0  # two lanes wide
    assert find_bottlenecks(_two_rooms(0.6), **KW).count == 0  # too narrow for a skid
    # A pillar 1.5 m from a wall: narrow, but it can be driven around.
    hall = grid_from_walls((12.0, 6.0), 0.05, [box(5.0, 1.5, 6.0, 2.5)])
    assert find_bottlenecks(hall, **KW).count == 0
