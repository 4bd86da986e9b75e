"""People who stand and then walk (issues 22 and 15): the fleet never drives into a person and
gives people the right of way, so the person does not walk into a skid either."""

from pathlib import Path

import pytest

from swarmpark.apps.run import run_world
from swarmpark.world.scenario import build_world, load_scenario

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
