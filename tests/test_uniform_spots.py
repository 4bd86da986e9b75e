"""A park of skids of several sizes lays its spots out at the largest size where they fit
(supervisor/commands.py ``uniform_spots``): any skid then fits any goal, so the fill order's
hand-over and the re-assignment are never refused by size."""

import numpy as np
import pytest

from swarmpark import assign as assign_mod
from swarmpark.core.geometry import Footprint, footprint_polygon
from swarmpark.supervisor.commands import uniform_spots
from swarmpark.supervisor.core import Supervisor
from swarmpark.world.scenario import ParkCmd, build_world, parse_scenario

SIZES = [(1.4, 0.9), (1.4, 0.9), (1.0, 0.7), (1.0, 0.7)]


def _world():
    robots = [
        {"id": f"r{i}", "pose": [1.5, 1.5 + 1.5 * i, 0], "footprint": {"length_m": l, "width_m": w}}
        for i, (l, w) in enumerate(SIZES)
    ]
    data = {
        "name": "sizes",
        "duration_s": 10,
        "map": {"size_m": [14, 8], "resolution_m": 0.05},
        "robots": robots,
    }
    return build_world(parse_scenario(data))


def _park(width_m):
    """Four skids in one row, heading north, in a box ``width_m`` wide."""
    box = [[8, 1], [8 + width_m, 1], [8 + width_m, 3], [8, 3]]
    return ParkCmd(robots=[f"r{i}" for i in range(4)], boundary=box, heading_deg=90)


def test_one_size_or_an_off_centre_pivot_keeps_a_spot_per_skid():
    assert uniform_spots([Footprint(1.2, 0.8)] * 3) is None
    assert uniform_spots([Footprint(1.2, 0.8), Footprint(1.0, 0.7, 0.3)]) is None
    spots = uniform_spots([Footprint(1.2, 0.8), Footprint(1.0, 0.9), Footprint(1.4, 0.7)])
    assert spots == [Footprint(1.4, 0.9, 0.7)] * 3


@pytest.mark.parametrize(("width_m", "sizes"), [(5.6, {(1.4, 0.9)}), (4.8, set(SIZES))])
def test_spots_take_the_largest_size_where_four_of_it_fit(width_m, sizes):
    # 5.6 m holds four spots of 1.4 x 0.9 m with their margins; 4.8 m only two of each size.
    sup = Supervisor(_world())
    assert sup.command("park", _park(width_m)).accepted
    g = sup.groups[0]
    assert set(g.goal_dims) == sizes
    dims = [(f.length_m, f.width_m) for f in (sup.info.footprints[i] for i in g.robots)]
    fit = assign_mod.footprint_fits(dims, g.goal_dims)
    assert fit.all() == (len(sizes) == 1)
    # Every skid's own footprint lies within the boundary at its goal, facing north.
    for row, i in enumerate(g.robots):
        goal = g.goals[g.goal_of[row]]
        assert np.isclose(goal[2], np.pi / 2)
        assert g.boundary.contains(footprint_polygon(goal, sup.info.footprints[i]))
