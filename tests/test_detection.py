"""Obstacle detection in the loop (issue 6, Hing 2018 Sect. 3.5.1): with onboard sensing the
planner and the avoidance layer use what the scans detected, not the scenario's obstacles."""

import numpy as np
import pytest
from helpers import SCENARIOS

from swarmpark.apps.run import run_world
from swarmpark.supervisor.core import Supervisor
from swarmpark.world.scenario import build_world, load_scenario

CRATE = (6.5, 5.0, 7.5, 6.8)  # x0, y0, x1, y1 of the crate in room-detect.yaml
PERSON_START = np.array([7.6, 3.4])  # where the person stands until 12 s


def _cells_in(grid, x0, y0, x1, y1):
    r0, c0 = grid.world_to_cell(np.array([[x0, y0]]))[0]
    r1, c1 = grid.world_to_cell(np.array([[x1, y1]]))[0]
    return grid.occupied[r0 : r1 + 1, c0 : c1 + 1]


def test_with_sensing_the_planner_starts_without_the_scenarios_obstacles():
    world = build_world(load_scenario(SCENARIOS / "room-detect.yaml"))
    assert world.static_obstacles  # the simulator has the crate ...
    sup = Supervisor(world)
    assert not _cells_in(sup.known_grid, *CRATE).any()  # ... the planner does not, yet
    assert len(sup.view().people_xy) == 0  # nor the person
    sup.tick()
    assert _cells_in(sup.known_grid, *CRATE).any()  # the first scan shows the crate


@pytest.mark.slow
def test_skids_park_past_a_detected_crate_and_a_person_who_walks_away():
    world = build_world(load_scenario(SCENARIOS / "room-detect.yaml"))
    out = run_world(world)
    r, sup = out.result, out.supervisor
    assert r["expect_met"], r["expect_failures"]
    assert r["collisions"] == []
    for rid, s in r["robots"].items():
        assert s["final_position_error_m"] <= 0.10, rid
        assert s["final_heading_error_deg"] <= 5.0, rid
    assert r["localization"]["mean_error_m"] < 0.05
    # The crate is still in the planner's map (seen all along); the person's spot has cleared.
    assert _cells_in(sup.known_grid, *CRATE).any()
    t = sup.t
    for i in range(sup.sim.n):
        near = sup.costmap.obstacles(i, t, center=PERSON_START, radius_m=0.5)
        assert len(near.cells) == 0


@pytest.mark.slow
def test_the_onboard_tracker_gives_navigation_the_walking_person_with_velocity():
    """Issue 20 item 3: with sensing on, the person is tracked from the scans (not read from
    the scenario) and navigation gets the track with its velocity; the crate and the person
    standing are detections only (tracks that never moved are not people)."""
    world = build_world(load_scenario(SCENARIOS / "room-detect.yaml"))
    sup = Supervisor(world)
    errors = []
    while sup.t < 17.0:
        sup.tick()
        view = sup.view()
        if sup.t < 12.0:  # the person stands until 12 s
            assert len(view.people_xy) == 0
        elif sup.t >= 15.0:  # walking east at 1 m/s since 14.1 s (the second leg)
            truth = sup.sim.person_positions()[0]
            d = np.linalg.norm(view.people_xy - truth, axis=1)
            assert d.min() < 0.4, (sup.t, view.people_xy, truth)
            k = int(np.argmin(d))
            errors.append(np.linalg.norm(view.people_vel[k] - [1.0, 0.0]))
    assert errors and max(errors) <= 0.2, max(errors)


def test_the_browser_frame_carries_the_onboard_trackers_people():
    """With sensing on, the frame's ``tracked`` layer is the onboard tracker's people (it was
    never sent before: people were detections only)."""
    from swarmpark.links.base import TrackedPeople
    from swarmpark.server.frames import FrameEncoder

    world = build_world(load_scenario(SCENARIOS / "room-detect.yaml"))
    sup = Supervisor(world)
    enc = FrameEncoder(sup)
    assert "tracked" not in enc.frame({})[0]
    sup.sensing.people = TrackedPeople(0.0, np.array([[8.0, 5.0]]), np.array([[1.0, 0.0]]), [0.25])
    assert enc.frame({})[0]["tracked"] == [[8.0, 5.0, 1.0, 0.0]]
