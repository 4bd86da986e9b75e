"""The scenario `expect` block: the time ratio guard fails a slower park with the reason."""

import pytest

from swarmpark.apps.run import check_expect
from swarmpark.world.scenario import ExpectSpec, ScenarioError, parse_scenario


def _result(tp, lb):
    return {
        "success": True,
        "collisions": [],
        "min_clearance_m": 0.2,
        "time_to_park_s": tp,
        "lower_bound_s": lb,
    }


def test_time_ratio_passes_at_or_under_the_bound_and_fails_over_it():
    assert check_expect(_result(30.0, 20.0), ExpectSpec(max_time_ratio=1.5)) == (True, [])
    ok, why = check_expect(_result(31.0, 20.0), ExpectSpec(max_time_ratio=1.5))
    assert not ok and why == ["time_to_park_s / lower_bound_s 1.550 > 1.5"]
    ok, why = check_expect(_result(31.0, None), ExpectSpec(max_time_ratio=1.5))
    assert not ok and why == ["time_to_park_s / lower_bound_s none > 1.5"]


def test_a_time_ratio_under_one_is_refused():
    data = {
        "name": "t",
        "map": {"size_m": [10, 10], "resolution_m": 0.1},
        "robots": [{"id": "a", "pose": [2, 2, 0]}],
        "expect": {"max_time_ratio": 0.9},
    }
    with pytest.raises(ScenarioError, match="expect.max_time_ratio"):
        parse_scenario(data)
