"""People who stand and then walk (issue 22): the fleet never drives into a person; a person
who walks into a skid is reported as "person-robot" and does not count against the fleet."""

from pathlib import Path

import pytest

from swarmpark.apps.run import run_world
from swarmpark.world.scenario import build_world, load_scenario

SCENARIO = (
    Path(__file__).resolve().parents[1]
    / "scenarios"
    / "experimental"
    / "person-stands-then-walks.yaml"
)


@pytest.mark.slow
def test_a_person_who_stands_then_walks_is_never_driven_into():
    world = build_world(load_scenario(SCENARIO))
    r = run_world(world).result
    kinds = [c["kind"] for c in r["collisions"]]
    assert "robot-person" not in kinds, r["collisions"]
    assert all(k == "person-robot" for k in kinds), r["collisions"]
    # The person really stood in the way first and then crossed the skids' route.
    assert world.people[0].waits_s[0] == 12
    assert sum(s["parked"] for s in r["robots"].values()) >= 5
