"""Coastal navigation: skids that localize with their LIDAR plan within sight of walls
(Roy et al. 1999; :func:`swarmpark.plan.grid.build_costmap`)."""

from __future__ import annotations

import pytest

from swarmpark.apps.generate import generate
from swarmpark.supervisor.core import COASTAL_SEEN_FRACTION, default_controller
from swarmpark.world.scenario import SensingSpec, build_world, parse_scenario


def _world(**sensing):
    data = generate("open-deck", 2018, robots=6)
    data["sensing"] = {**data["sensing"], **sensing}
    return build_world(parse_scenario(data))


def test_the_planner_is_coastal_only_when_the_skids_localize_with_their_lidar():
    amcl = default_controller(_world(lidar_range_m=6.0)).params.planner
    assert amcl.seen_within_m == pytest.approx(COASTAL_SEEN_FRACTION * 6.0)
    assert amcl.blind_weight == SensingSpec().coastal_weight > 0
    for off in (_world(localization="truth"), _world(coastal_weight=0)):
        assert default_controller(off).params.planner.seen_within_m is None


def test_a_negative_coastal_weight_is_refused_by_name():
    with pytest.raises(ValueError, match="coastal_weight"):
        SensingSpec(localization="amcl", coastal_weight=-1)
