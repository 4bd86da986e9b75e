"""The start-pose check of world building on large fleets: only skids whose boxes meet are
tested exactly, and the first overlap reported is the one checking every pair would report."""

import numpy as np
import pytest

from swarmpark.world.build import _meeting_pairs
from swarmpark.world.scenario import ScenarioError, build_world, parse_scenario


def test_meeting_pairs_are_the_pairs_whose_boxes_meet_in_triu_order():
    rng = np.random.default_rng(0)
    for _ in range(30):
        n = int(rng.integers(2, 150))
        lo = rng.uniform(0, 20, (n, 2))
        hi = lo + rng.uniform(0, 3, (n, 2))
        i, j = _meeting_pairs(lo, hi)
        iu, ju = np.triu_indices(n, 1)
        ok = np.all((lo[iu] <= hi[ju]) & (hi[iu] >= lo[ju]), axis=1)
        assert np.array_equal(i, iu[ok]) and np.array_equal(j, ju[ok])


def _fleet(n, moved=None):
    robots = [
        {"id": f"s{k}", "pose": [2.0 + 2.5 * (k // 10), 2.0 + 1.6 * (k % 10), 0.0]}
        for k in range(n)
    ]
    for k, pose in (moved or {}).items():
        robots[k]["pose"] = pose
    size = [2.0 + 2.5 * (n // 10) + 3.0, 20.0]
    return {"name": "f", "duration_s": 10, "map": {"size_m": size}, "robots": robots}


def test_a_large_fleet_builds_and_its_first_overlap_is_named():
    assert len(build_world(parse_scenario(_fleet(200))).robots) == 200
    # s150 and s37 both placed onto s5: the first pair in index order is s5 / s37.
    bad = _fleet(200, {37: [2.3, 10.0, 0.0], 150: [2.1, 10.1, 0.0]})
    with pytest.raises(ScenarioError, match="robot 's37' overlaps robot 's5'"):
        build_world(parse_scenario(bad))
