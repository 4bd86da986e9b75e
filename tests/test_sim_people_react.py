"""Scripted people who react to the skids (sim/people.py): they stop short of a skid in their
way, walk on once it has left, back off from one that cannot leave otherwise, and never step
into a footprint; people who do not react still walk into a skid, which is reported as the
person's contact, not the fleet's."""

import numpy as np
import pytest
from helpers import make_world

from swarmpark.core.geometry import footprint_corners, rect_disc_gap
from swarmpark.sim.link import SimLink
from swarmpark.sim.people import PATIENCE_S, RETREAT_M, STOP_AHEAD_M, STOP_AHEAD_STILL_M
from swarmpark.sim.simulator import Simulator
from swarmpark.world.scenario import ScenarioError


def crossing(reacts=True, start_y=10.5, robots=None):
    """A person walking south at 1 m/s from (5, start_y) across (5, 3), where skid ``a``
    stands facing east (its left side at y = 3.4), in a 10 x 12 m room."""
    person = {"radius_m": 0.3, "waypoints": [[5.0, start_y], [5.0, 0.5]], "speed_mps": 1.0}
    person.update(reacts=reacts)
    return make_world(
        map={"size_m": [10, 12], "resolution_m": 0.05},
        robots=robots or [{"id": "a", "pose": [5.0, 3.0, 0.0]}],
        obstacles=[person],
    )


def gap(sim):
    c = footprint_corners(sim.poses[:1], sim.corners_body[:1])
    return float(rect_disc_gap(c, sim.person_positions()[:1], sim.person_radius[:1])[0])


def run(sim, steps, cmd=None):
    contacts = []
    for _ in range(steps):
        c = np.zeros((sim.n, 2)) if cmd is None else np.asarray(cmd, float)
        contacts += sim.step(c).new_contacts
    return contacts


def test_a_reacting_person_stops_well_short_of_a_standing_skid():
    sim = Simulator(crossing())
    contacts = []
    while not sim.person_held[0] and sim.t < 8.0:  # by 6.8 s they would reach the skid
        contacts += run(sim, 1)
    assert contacts == []
    g = gap(sim)
    # A skid standing in the way: they wait STOP_AHEAD_STILL_M short (one step's rounding).
    assert STOP_AHEAD_STILL_M - 1e-9 <= g <= STOP_AHEAD_STILL_M + 1.0 * sim.dt + 1e-9
    assert sim.person_held[0] and sim.reaction.pace[0] == 0.0
    assert not sim.people_done()


def test_a_reacting_person_walks_on_behind_a_skid_driving_across():
    # Skid a drives east at 0.5 m/s across the route as the person arrives: they stop just
    # short of it (not STOP_AHEAD_STILL_M: it is on its way) and walk on behind it.
    sim = Simulator(crossing(robots=[{"id": "a", "pose": [1.5, 3.0, 0.0]}]))
    gaps, held = [], []
    contacts = []
    for _ in range(240):
        contacts += sim.step(np.array([[0.5, 0.0]])).new_contacts
        gaps.append(gap(sim))
        held.append(bool(sim.person_held[0]))
    assert contacts == []
    assert any(held)  # they did stop for it ...
    assert 0.0 < min(gaps) <= STOP_AHEAD_M + 1.0 * sim.dt + 1e-9  # ... just short of it
    assert run(sim, 100) == []  # the skid stops at x = 7.5, off the route
    assert sim.people_done()


def test_a_reacting_person_walks_on_once_the_skid_has_left():
    sim = Simulator(crossing())
    contacts = run(sim, 160)
    assert sim.person_held[0]
    # The skid drives 2.5 m east, out of the route: the person walks on to the end.
    contacts += run(sim, 100, [[0.5, 0.0]])
    contacts += run(sim, 200)
    assert contacts == []
    assert sim.poses[0, 0] > 7.0
    assert sim.people_done()
    assert sim.person_positions()[0] == pytest.approx([5.0, 0.5])


def test_a_reacting_person_backs_off_from_a_skid_that_stays():
    sim = Simulator(crossing())
    while not sim.person_held[0]:
        run(sim, 1)
    stop_y = float(sim.person_positions()[0, 1])
    run(sim, int(round((PATIENCE_S - 0.2) / sim.dt)))
    assert sim.person_positions()[0, 1] == pytest.approx(stop_y)  # still waiting
    link = SimLink(sim.world, sim)
    contacts = run(sim, 20)
    assert sim.person_positions()[0, 1] > stop_y + 0.1  # backing off north, the way it came
    assert sim.reaction.pace[0] < 0
    # A tracker sees them walk back (north), slower than they walked.
    vel = link._people().vel[0]
    assert vel[1] > 0 and np.linalg.norm(vel) < 1.0
    contacts += run(sim, 200)
    assert contacts == []
    # Never further back than RETREAT_M, and standing there while the skid stays.
    assert sim.person_positions()[0, 1] == pytest.approx(stop_y + RETREAT_M)
    assert link._people().vel[0] == pytest.approx([0.0, 0.0])


def test_a_reacting_person_passes_alongside_a_skid_without_stopping():
    # Walking east past the skid's left side with 0.1 m to spare: nothing in the way.
    world = make_world(
        robots=[{"id": "a", "pose": [5.0, 3.0, 0.0]}],
        obstacles=[{"radius_m": 0.3, "waypoints": [[2.0, 3.8], [8.0, 3.8]], "speed_mps": 1.0}],
    )
    sim = Simulator(world)
    assert run(sim, 140) == []
    assert not sim.person_held.any()
    assert sim.people_done()


def test_a_person_who_does_not_react_walks_into_a_standing_skid_not_the_fleets_contact():
    sim = Simulator(crossing(reacts=False))
    contacts = run(sim, 200)
    assert [(c.a, c.b, c.kind) for c in contacts] == [("a", "person0", "person-robot")]
    assert gap(sim) >= -1e-9  # stopped at the skid by the simulator, never inside it
    assert not sim.reaction.pace[0] == 0.0  # not a reaction: the simulator held them


def test_a_skid_driving_off_is_not_held_by_a_person_walking_after_it():
    # The person (not reacting) walks into the skid's left side as the skid drives east out
    # of the route: the skid gets away; the person waits at most for it to pass.
    sim = Simulator(crossing(reacts=False, start_y=5.5))
    run(sim, 36)  # the person is 0.1 m off the skid's side by now
    x0 = float(sim.poses[0, 0])
    contacts = run(sim, 60, [[0.5, 0.0]])
    assert sim.poses[0, 0] > x0 + 1.0  # the skid drove off
    assert all(c.kind == "person-robot" for c in contacts)
    run(sim, 100, [[0.5, 0.0]])
    assert sim.people_done()


def test_reacts_must_be_true_or_false():
    with pytest.raises(ScenarioError, match=r"obstacles\[0\].*reacts"):
        make_world(obstacles=[{"waypoints": [[1, 1], [3, 1]], "reacts": "sometimes"}])


@pytest.mark.parametrize("reacts", [False, True])
def test_a_run_counts_a_person_walking_into_a_parked_skid_apart_from_the_fleets_contacts(reacts):
    from swarmpark.apps.run import run_world

    # Walls 0.1 m off both ends of the skid: it cannot step aside along its axis.
    ends = [[[4.2, 1.5], [4.3, 1.5], [4.3, 3.0], [4.2, 3.0]]]
    ends += [[[5.7, 1.5], [5.8, 1.5], [5.8, 3.0], [5.7, 3.0]]]
    world = make_world(
        duration_s=12,
        map={"size_m": [10, 12], "resolution_m": 0.05, "walls": ends},
        robots=[{"id": "a", "pose": [5.0, 3.0, 0.0]}],
        obstacles=[
            {
                "radius_m": 0.3,
                "waypoints": [[5.0, 6.5], [5.0, 0.5]],
                "speed_mps": 1.0,
                "reacts": reacts,
            }
        ],
        commands=[{"at_s": 0, "goto": {"robot": "a", "pose": [5.0, 3.0, 0.0]}}],
    )
    r = run_world(world).result
    kinds = [c["kind"] for c in r["collisions"]]
    # Walked into by a person who does not react: reported, and the skid still parked with
    # no contact of the fleet's (success). A reacting person stops short: no contact at all.
    assert kinds == (["person-robot"] if not reacts else [])
    assert r["success"]
