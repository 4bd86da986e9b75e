"""People who stand and then walk (issues 22 and 15): the fleet never drives into a person and
gives people the right of way, so the person does not walk into a skid either."""

from pathlib import Path

import pytest
import yaml

from swarmpark.apps.run import run_world
from swarmpark.world.scenario import build_world, load_scenario, parse_scenario

SCENARIO = Path(__file__).resolve().parents[1] / "scenarios" / "person-stands-then-walks.yaml"


@pytest.mark.slow
def test_a_person_who_stands_then_walks_is_given_the_right_of_way():
    world = build_world(load_scenario(SCENARIO))
    r = run_world(world).result
    # Neither kind of contact: the skids give the person the right of way (issue 15).
    assert r["collisions"] == [], r["collisions"]
    # The person really stood in the way first and then crossed the skids' route.
    assert world.people[0].waits_s[0] == 12
    assert all(s["parked"] for s in r["robots"].values())


# Issue 22 under start perturbations (sweeps/suite-perturbed.yaml: 0.2 m, 10 deg, shuffled).
PERTURB = {"start_m": 0.2, "start_deg": 10, "shuffle": True}
ROOT = SCENARIO.parent


def _perturbed(name: str, seed: int, **people):
    data = yaml.safe_load((ROOT / name).read_text())
    data.update(seed=seed, perturb=PERTURB)
    for o in data.get("obstacles", []):
        if "waypoints" in o:
            o.update(people)
    return build_world(parse_scenario(data))


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2, 3, 4, 5])
def test_the_sailor_who_sets_off_late_never_meets_a_skid_from_perturbed_starts(seed):
    # Seeds 2-4 had the sailor set off into p2 as it crossed their line; the sailor now stops
    # short and walks on behind it (sim/people.py), and p2 is not held by them.
    r = run_world(_perturbed("person-stands-then-walks.yaml", seed)).result
    assert r["collisions"] == [], r["collisions"]
    assert r["success"] and r["expect_met"], r["expect_failures"]


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2, 3, 4, 5])
def test_a_walker_through_the_formation_from_perturbed_starts_parks_without_contact(seed):
    # Seeds 2 and 4 had the walker walk into a skid still docking from its start; the walker
    # now waits for a skid busy in the aisle before reaching it (sim/people.py).
    r = run_world(_perturbed("person-through-formation.yaml", seed)).result
    assert r["collisions"] == [], r["collisions"]
    assert r["success"], {k: v["final_pose"] for k, v in r["robots"].items() if not v["parked"]}


@pytest.mark.slow
def test_a_walker_who_does_not_react_is_reported_as_walking_into_the_formation():
    # Seed 2: a2, still docking, stands in the walk; a walker who does not react walks into
    # it. That contact is the person's (person-robot), not the fleet's.
    r = run_world(_perturbed("person-through-formation.yaml", 2, reacts=False)).result
    kinds = {c["kind"] for c in r["collisions"]}
    assert kinds == {"person-robot"}, r["collisions"]
