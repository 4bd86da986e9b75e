"""People who stand and then walk (issues 22 and 15): the fleet never drives into a person and
gives people the right of way, so the person does not walk into a skid either."""

import numpy as np
import pytest
import yaml
from helpers import SCENARIOS

from swarmpark.apps.run import run_world
from swarmpark.core.geometry import footprint_corners, rect_disc_gap
from swarmpark.supervisor.core import Supervisor
from swarmpark.world.scenario import build_world, load_scenario, parse_scenario


@pytest.mark.slow
def test_a_person_who_stands_then_walks_is_given_the_right_of_way():
    world = build_world(load_scenario(SCENARIOS / "person-stands-then-walks.yaml"))
    r = run_world(world).result
    # Neither kind of contact: the skids give the person the right of way (issue 15).
    assert r["collisions"] == [], r["collisions"]
    # The person really stood in the way first and then crossed the skids' route.
    assert world.people[0].waits_s[0] == 12
    assert all(s["parked"] for s in r["robots"].values())


# Issue 22 under start perturbations (sweeps/suite-perturbed.yaml: 0.2 m, 10 deg, shuffled).
PERTURB = {"start_m": 0.2, "start_deg": 10, "shuffle": True}


def _perturbed(name: str, seed: int, *, rvo: bool = False, **people):
    data = yaml.safe_load((SCENARIOS / name).read_text())
    data.update(seed=seed, perturb=PERTURB)
    if rvo:
        data["navigation"] = {"avoidance": "rvo"}
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
    # Seed 2 with velocity obstacles: a2, still docking, stands in the walk; a walker who does
    # not react walks into it. That contact is the person's (person-robot), not the fleet's.
    r = run_world(_perturbed("person-through-formation.yaml", 2, reacts=False, rvo=True)).result
    kinds = {c["kind"] for c in r["collisions"]}
    assert kinds == {"person-robot"}, r["collisions"]
    # The default stack (the file as it is) has a2 out of the walk in time: no contact.
    r = run_world(_perturbed("person-through-formation.yaml", 2, reacts=False)).result
    assert r["collisions"] == [], r["collisions"]


@pytest.mark.slow
@pytest.mark.parametrize("rvo", [False, True], ids=["default", "rvo"])
def test_person_walks_through_the_formation_without_contact_and_it_restores(rvo):
    data = yaml.safe_load((SCENARIOS / "person-through-formation.yaml").read_text())
    if rvo:
        data["navigation"] = {"avoidance": "rvo"}
    world = build_world(parse_scenario(data, SCENARIOS))
    sup = Supervisor(world)
    corners = [fp.corners_body() for fp in sup.sim.footprints]
    start = sup.sim.poses.copy()
    gap, moved = np.inf, np.zeros(sup.sim.n)
    while not (sup.settled() and sup.sim.people_done()) and sup.t < world.scenario.duration_s:
        sup.tick()
        c = footprint_corners(sup.sim.poses, np.stack(corners))
        for pos, rad in zip(sup.sim.person_positions(), sup.sim.person_radius, strict=True):
            gap = min(gap, float(rect_disc_gap(c, pos[None], np.full(len(c), rad)).min()))
        moved = np.maximum(moved, np.linalg.norm(sup.sim.poses[:, :2] - start[:, :2], axis=1))
    assert sup.settled() and sup.sim.people_done()
    assert sup.metrics.collisions == []
    assert gap > 0.05  # the person never came within 5 cm of a skid
    assert moved.max() > 0.15  # skids in the walk made room ...
    err = np.linalg.norm(sup.sim.poses[:, :2] - start[:, :2], axis=1)
    assert err.max() <= 0.05  # ... and are back on their spots


def test_a_person_standing_at_a_spot_is_named_as_the_cause_of_the_wait():
    """A person stands on one of two spots for the whole run: the other skid parks, and the
    deadlock report of the one whose spot it is says a person stands there (before, it read
    "a local minimum of the potential field")."""
    walls = [[[0, 0], [14, 0], [14, 0.3], [0, 0.3]], [[0, 7.7], [14, 7.7], [14, 8], [0, 8]]]
    data = {
        "name": "person-on-a-spot",
        "duration_s": 30,
        "map": {"size_m": [14, 8], "walls": walls},
        "robots": [{"id": "a", "pose": [2.0, 2.5, 0]}, {"id": "b", "pose": [2.0, 5.5, 0]}],
        "obstacles": [{"id": "p", "waypoints": [[10.5, 2.5], [10.5, 2.51]], "speed_mps": 0.01}],
        "commands": [
            {"at_s": 0, "goto": {"robot": "a", "pose": [10.5, 2.5, 0]}},
            {"at_s": 0, "goto": {"robot": "b", "pose": [10.5, 5.5, 0]}},
        ],
    }
    r = run_world(build_world(parse_scenario(data))).result
    assert r["robots"]["b"]["parked"] and not r["robots"]["a"]["parked"]
    causes = [d["cause"] for d in r["deadlocks"] if d["robot"] == "a"]
    assert causes and all(c.startswith("a person stands 0.00 m from its spot") for c in causes)
    assert r["collisions"] == []
