"""The fleet layers of each plan and the plan repairs (:mod:`swarmpark.control.nav.fleetmap`)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from navkit import FOOTPRINT, make_view

from swarmpark.control.nav.fleetmap import (
    FleetState,
    fleet_costmap,
    fleet_layers,
    points_in_rects,
)
from swarmpark.control.nav.follower import PathFollower, PathState
from swarmpark.control.nav.params import (
    FleetMapParams,
    FollowerParams,
    PeopleParams,
    PlannerParams,
)
from swarmpark.control.nav.planner import Planner

P = FleetMapParams(spot_cost=6.0)  # the spot layer on, to test it


def _planner():
    return Planner(PlannerParams(), staging_m=0.9, direct_within_m=1.8, fleet_params=P)


def _crosses(path, pose, grow=0.0):
    pts = np.vstack([np.linspace(a, b, 20) for a, b in zip(path[:-1], path[1:], strict=True)])
    return points_in_rects(pts, np.atleast_2d(pose), [FOOTPRINT], grow).any()


def test_parked_skids_are_lethal_and_goal_spots_cost_extra():
    poses = [[1.0, 3.0, 0.0], [5.0, 3.0, np.pi / 2], [7.0, 1.5, 0.0]]
    goals = [[9.0, 3.0, 0.0], [5.0, 3.0, np.pi / 2], [5.0, 4.6, 0.0]]
    view = make_view(poses, goals)
    pl = _planner()
    cm = pl.costmap(view, FOOTPRINT)
    parked = np.array([False, True, False])
    bound = ~parked
    fcm = fleet_costmap(cm, view, 0, parked, bound, P)
    rc = cm.grid.world_to_cell(np.array([[5.0, 3.0], [5.0, 4.6], [1.0, 3.0]]))
    assert np.isinf(fcm.cost[rc[0, 0], rc[0, 1]])  # on the parked skid
    assert fcm.cost[rc[1, 0], rc[1, 1]] >= cm.cost[rc[1, 0], rc[1, 1]] + P.spot_cost  # g2's spot
    assert fcm.cost[rc[2, 0], rc[2, 1]] == cm.cost[rc[2, 0], rc[2, 1]]  # its own place
    # A skid of higher priority is not stopped by the parked one (the block makes room).
    view_hi = make_view(poses, goals, priority=[5, 1, 1])
    fcm_hi = fleet_costmap(cm, view_hi, 0, parked, bound, P)
    assert np.isfinite(fcm_hi.cost[rc[0, 0], rc[0, 1]])


def test_fleet_layers_in_place_are_the_copy_and_are_undone():
    poses = [[1.0, 3.0, 0.0], [5.0, 3.0, np.pi / 2], [7.0, 1.5, 0.0], [5.2, 4.0, 0.3]]
    goals = [[9.0, 3.0, 0.0], [5.0, 3.0, np.pi / 2], [5.0, 4.6, 0.0], [5.2, 4.0, 0.3]]
    view = make_view(poses, goals)
    cm = _planner().costmap(view, FOOTPRINT)
    before = cm.cost.copy()
    parked = np.array([False, True, False, True])  # two parked skids whose bands overlap
    for p in (P, replace(P, spot_cost=3.0)):
        want = fleet_costmap(cm, view, 0, parked, ~parked, p).cost
        with fleet_layers(cm, view, 0, parked, ~parked, p) as fcm:
            assert fcm.cost is cm.cost
            assert np.array_equal(fcm.cost, want)
        assert np.array_equal(cm.cost, before)


def test_first_plan_is_static_and_is_repaired_when_a_skid_parks_on_it():
    poses = [[1.0, 3.0, 0.0], [5.0, 1.0, np.pi / 2]]
    goals = [[9.0, 3.0, 0.0], [5.0, 3.0, np.pi / 2]]
    states = [PathState(), PathState()]
    fol = PathFollower(FollowerParams())
    pl = _planner()
    view = make_view(poses, goals, goal_changed=[True, True])
    moving = FleetState(parked=np.zeros(2, bool), bound=np.ones(2, bool), still=np.zeros(2, bool))
    pl.update(view, states, fol, moving)
    first = states[0].path
    # The first plan is the static map's: straight through skid 1's (empty) goal spot.
    assert _crosses(first, goals[1], grow=0.0)
    # Skid 1 parks there, on skid 0's path: skid 0 is planned again, round it.
    view = make_view([poses[0], goals[1]], goals)
    parked = FleetState(
        parked=np.array([False, True]), bound=np.array([True, False]), still=np.zeros(2, bool)
    )
    pl.update(view, states, fol, parked)
    assert states[0].path is not first
    assert not _crosses(states[0].path, goals[1], grow=0.3)
    # Nothing new parked: no new plan.
    again = states[0].path
    pl.update(replace(view, t=0.1), states, fol, parked)
    assert states[0].path is again


def test_stuck_skid_is_planned_again_with_the_still_skids_as_obstacles():
    poses = [[1.0, 3.0, 0.0], [4.0, 3.0, np.pi / 2]]
    goals = [[9.0, 3.0, 0.0], [4.0, 1.0, np.pi / 2]]
    states = [PathState(), PathState()]
    fol = PathFollower(FollowerParams())
    pl = _planner()
    fleet = FleetState(
        parked=np.zeros(2, bool), bound=np.ones(2, bool), still=np.array([False, True])
    )
    view = make_view(poses, goals, goal_changed=[True, True])
    pl.update(view, states, fol, fleet)
    first = states[0].path
    assert _crosses(first, poses[1], grow=0.3)  # skid 1 is on its way: not an obstacle
    t = 0.0
    while states[0].path is first and t < 2 * P.stuck_s:
        t += 0.5
        pl.update(make_view(poses, goals, t=t), states, fol, fleet)
    assert P.stuck_s <= t < P.stuck_s + 1.0
    assert not _crosses(states[0].path, poses[1], grow=0.3)


PEOPLE = PeopleParams()


def _repair_with_person(vel, people=PEOPLE):
    """Skid 0's plan after a stuck repair with a person in its lane at (4, 3)."""
    poses, goals = [[1.0, 3.0, 0.0]], [[9.0, 3.0, 0.0]]
    states = [PathState()]
    fol = PathFollower(FollowerParams())
    pl = Planner(PlannerParams(), staging_m=0.9, direct_within_m=1.8, fleet_params=P, people=people)
    fleet = FleetState(parked=np.zeros(1, bool), bound=np.ones(1, bool), still=np.zeros(1, bool))
    person = dict(people_xy=[[4.0, 3.0]], people_vel=[vel], people_radius=[0.25])
    pl.update(make_view(poses, goals, goal_changed=[True], **person), states, fol, fleet)
    first, t = states[0].path, 0.0
    while states[0].path is first and t < 2 * P.stuck_s:
        t += 0.5
        pl.update(make_view(poses, goals, t=t, **person), states, fol, fleet)
    return first, states[0].path


def _gap(path, xy):
    """Closest approach of a polyline to a point."""
    pts = np.vstack([np.linspace(a, b, 50) for a, b in zip(path[:-1], path[1:], strict=True)])
    return float(np.hypot(*(pts - xy).T).min())


def test_stuck_skid_plans_round_a_person_standing_in_its_lane():
    first, repaired = _repair_with_person([0.0, 0.0])
    assert _gap(first, [4.0, 3.0]) < 0.1  # the first plan runs straight through them
    pp = PEOPLE
    # The repair keeps the yield's stand-off from the person's rim plus half the skid's width.
    want = 0.25 + pp.clearance_m + pp.standing_berth_m + FOOTPRINT.width_m / 2
    assert _gap(repaired, [4.0, 3.0]) >= want - 0.1  # (within a map cell or two)
    # A person walking will be elsewhere; without the yield people are not planned round.
    for vel, people in (([0.0, 1.0], pp), ([0.0, 0.0], None)):
        first, repaired = _repair_with_person(vel, people)
        assert _gap(repaired, [4.0, 3.0]) < 0.1
