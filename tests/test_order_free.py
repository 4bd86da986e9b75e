"""Order-free and perturbed starts (issue 22): the robot list's order changes nothing; start
perturbations are seeded, valid and refused with the reason when impossible."""

import numpy as np
import pytest
import yaml
from helpers import SCENARIOS

from swarmpark.apps.run import run_world
from swarmpark.world.scenario import ScenarioError, build_world, parse_scenario


def _data(name):
    return yaml.safe_load((SCENARIOS / name).read_text())


def _world(data):
    return build_world(parse_scenario(data, SCENARIOS))


def test_any_order_of_the_robot_list_builds_the_same_fleet():
    data = _data("hangar-bay-12.yaml")
    ref = _world(data)
    rng = np.random.default_rng(0)
    for _ in range(5):
        shuffled = dict(
            data, robots=[data["robots"][k] for k in rng.permutation(len(data["robots"]))]
        )
        w = _world(shuffled)
        assert w.ids == ref.ids
        np.testing.assert_array_equal(
            np.stack([r.start for r in w.robots]), np.stack([r.start for r in ref.robots])
        )


@pytest.mark.slow
def test_a_permuted_robot_list_parks_the_same_way():
    """Property (issue 22): the same parked set and the same time to park, whatever the order
    the robots and the park command list them in."""
    data = _data("dead-end-fig6.yaml")
    base = run_world(_world(data)).result
    rng = np.random.default_rng(1)
    for _ in range(2):
        perm = rng.permutation(len(data["robots"]))
        d = dict(data, robots=[data["robots"][k] for k in perm])
        d["commands"] = [
            {**c, "park": {**c["park"], "robots": list(reversed(c["park"]["robots"]))}}
            if "park" in c and isinstance(c["park"].get("robots"), list)
            else c
            for c in data["commands"]
        ]
        r = run_world(_world(d)).result
        assert r["time_to_park_s"] == base["time_to_park_s"]
        assert r["robots"] == base["robots"]


def test_perturbed_starts_are_seeded_within_bounds_and_clear():
    data = _data("hangar-park.yaml")
    ref = _world(data)
    p = dict(data, perturb={"start_m": 0.2, "start_deg": 10, "shuffle": True}, seed=3)
    a, b = _world(p), _world(p)
    sa = np.stack([r.start for r in a.robots])
    np.testing.assert_array_equal(sa, np.stack([r.start for r in b.robots]))  # same seed
    s0 = np.stack([r.start for r in ref.robots])
    assert np.all(np.abs(sa[:, :2] - s0[:, :2]) <= 0.2 + 1e-12)
    assert np.all(np.abs(sa[:, 2] - s0[:, 2]) <= np.deg2rad(10) + 1e-12)
    assert np.abs(sa - s0).max() > 0.01  # really moved
    other = _world(dict(p, seed=4))
    assert not np.array_equal(sa, np.stack([r.start for r in other.robots]))
    # Another draw for the same seed (a generated site is made from the seed): other starts,
    # within the same bounds; draw 0 is the seed's own draw.
    drawn = [
        np.stack([r.start for r in _world(dict(p, perturb={**p["perturb"], "draw": k})).robots])
        for k in (0, 1, 2)
    ]
    np.testing.assert_array_equal(drawn[0], sa)
    assert not np.array_equal(drawn[1], sa) and not np.array_equal(drawn[1], drawn[2])
    assert np.all(np.abs(drawn[1][:, :2] - s0[:, :2]) <= 0.2 + 1e-12)


def test_an_impossible_perturbation_is_refused_with_the_reason():
    # A 1.2 x 0.8 m skid in a stall 2 cm longer and wider: almost no move of up to 2 m fits.
    x0, x1, y0, y1 = 1.39, 2.61, 1.59, 2.41
    walls = [
        [[0, 0], [4, 0], [4, y0], [0, y0]],
        [[0, y1], [4, y1], [4, 4], [0, 4]],
        [[0, y0], [x0, y0], [x0, y1], [0, y1]],
        [[x1, y0], [4, y0], [4, y1], [x1, y1]],
    ]
    data = {
        "name": "stall",
        "map": {"size_m": [4, 4], "resolution_m": 0.05, "walls": walls},
        "robots": [{"id": "a", "pose": [2.0, 2.0, 0]}],
        "perturb": {"start_m": 2.0},
    }
    with pytest.raises(
        ScenarioError, match="perturb: no free start within 2.0 m / 0.0 deg of robot 'a'"
    ):
        _world(data)


def test_the_perturb_block_is_validated():
    data = _data("hangar-park.yaml")
    with pytest.raises(ScenarioError, match="perturb.start_m"):
        _world(dict(data, perturb={"start_m": -1}))
    with pytest.raises(ScenarioError, match="perturb.jitter"):
        _world(dict(data, perturb={"jitter": 1}))
    with pytest.raises(ScenarioError, match="perturb.draw"):
        _world(dict(data, perturb={"draw": -1}))
