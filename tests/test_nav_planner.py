"""The planner on hand-built views: paths end with a straight run along the goal's axis, plans
(and repairs asked for) wait for their turn, and a failed plan is tried again only when due."""

import numpy as np
import pytest
import shapely
from navkit import make_view

from swarmpark.control.nav.follower import PathFollower, PathState
from swarmpark.control.nav.params import FollowerParams, PlannerParams, TrafficParams
from swarmpark.control.nav.planner import Planner
from swarmpark.control.nav.traffic import TrafficControl


def _planner(**kw):
    return Planner(PlannerParams(**kw), staging_m=0.9, direct_within_m=1.8)


def test_the_path_ends_with_a_run_along_the_goal_axis():
    view = make_view([[1.5, 3.0, 0.0]], [[8.0, 2.0, np.pi / 2]], boxes=[(4.0, 2.0, 5.0, 4.0)])
    pl = _planner()
    path = pl.plan(pl.costmap(view, view.footprints[0]), view.poses[0], view.goals[0])
    assert path[-1] == pytest.approx([8.0, 2.0])
    run = path[-1] - path[-2]
    # The last leg lies on the goal's axis (x = 8), from a staging point 0.9 m off.
    assert run[0] == pytest.approx(0.0, abs=1e-9)
    assert abs(run[1]) == pytest.approx(0.9)
    # Close to the goal the path goes there directly.
    near = pl.plan(pl.costmap(view, view.footprints[0]), np.array([7.0, 2.0, 0.0]), view.goals[0])
    assert near[-1] == pytest.approx([8.0, 2.0], abs=0.05)
    assert len(near) == 2


def test_close_by_it_goes_round_when_its_own_side_has_no_clear_run_to_the_spot():
    # A pillar beside the spot's west end: a skid 1.75 m west of the spot (close enough to
    # go straight in) cannot sweep its rectangle along the axis from there, so the path goes
    # round to the staging point east of the spot and the skid backs in (traced on a 4-skid
    # hangar training site: the skid stood at the pillar for 120 s).
    goal = [5.0, 3.0, 0.0]
    pillar = (3.6, 2.2, 4.3, 2.8)
    view = make_view([[3.4, 3.7, 0.0]], [goal], boxes=[pillar])
    pl = _planner()
    cm = pl.costmap(view, view.footprints[0])
    path = pl.plan(cm, view.poses[0], view.goals[0], footprint=view.footprints[0])
    assert path[-1] == pytest.approx(goal[:2])
    assert path[-2] == pytest.approx([5.9, 3.0], abs=1e-6)  # staging east: backing in
    # Without the pillar it goes straight in, as before.
    open_view = make_view([[3.4, 3.7, 0.0]], [goal])
    cm = pl.costmap(open_view, open_view.footprints[0])
    near = pl.plan(cm, open_view.poses[0], open_view.goals[0], footprint=open_view.footprints[0])
    assert len(near) == 2 and near[-1] == pytest.approx(goal[:2], abs=0.05)


def test_plans_are_bounded_per_tick_and_made_for_the_current_goal():
    poses = [[1.0, 1.0 + k, 0.0] for k in range(4)]
    goals = [[8.0, 1.0 + k, 0.0] for k in range(4)]
    view = make_view(poses, goals, goal_changed=[True] * 4)
    states = [PathState() for _ in range(4)]
    pl, fol = _planner(max_plans_per_tick=3), PathFollower(FollowerParams())
    pl.update(view, states, fol)
    assert [s.path is not None for s in states] == [True, True, True, False]
    assert all(states[i].is_for(view.goals[i]) for i in range(3))
    pl.update(make_view(poses, goals, t=0.1), states, fol)  # the last one's turn
    assert states[3].path is not None and states[3].planned_t == 0.1
    first = states[0].path
    pl.update(make_view(poses, goals, t=10.0), states, fol)  # nothing changed: no replanning
    assert states[0].path is first


def test_the_search_effort_per_tick_is_bounded():
    poses = [[1.0, 1.0 + k, 0.0] for k in range(4)]
    goals = [[8.0, 1.0 + k, 0.0] for k in range(4)]
    view = make_view(poses, goals, goal_changed=[True] * 4)
    states = [PathState() for _ in range(4)]
    # One cell of budget: the first plan of the tick runs, the others wait for the next ticks.
    pl, fol = _planner(max_plan_cells_per_tick=1), PathFollower(FollowerParams())
    pl.update(view, states, fol)
    assert [s.path is not None for s in states] == [True, False, False, False]
    pl.update(make_view(poses, goals, t=0.1), states, fol)
    assert [s.path is not None for s in states] == [True, True, False, False]
    # The plans are the same as without a budget.
    free = [PathState() for _ in range(4)]
    _planner().update(view, free, fol)
    assert np.array_equal(free[0].path, states[0].path)


def test_an_unreachable_goal_fails_and_is_retried_when_due():
    # The goal is walled in.
    walls = [(6.0, 0.0, 6.2, 6.0)]
    view = make_view([[1.0, 3.0, 0.0]], [[8.0, 3.0, 0.0]], boxes=walls, goal_changed=[True])
    states, pl, fol = [PathState()], _planner(), PathFollower(FollowerParams())
    pl.update(view, states, fol)
    assert states[0].failed and states[0].path is None
    pl.update(make_view([[1.0, 3.0, 0.0]], [[8.0, 3.0, 0.0]], boxes=walls, t=1.0), states, fol)
    assert states[0].planned_t == 0.0  # not due yet
    pl.update(make_view([[1.0, 3.0, 0.0]], [[8.0, 3.0, 0.0]], boxes=walls, t=3.0), states, fol)
    assert states[0].planned_t == 3.0


def test_planner_params_name_the_bad_field():
    with pytest.raises(ValueError, match="PlannerParams.max_plans_per_tick"):
        PlannerParams(max_plans_per_tick=0)
    with pytest.raises(ValueError, match="PlannerParams.max_plan_cells_per_tick"):
        PlannerParams(max_plan_cells_per_tick=0)
    with pytest.raises(ValueError, match="PlannerParams.plan_resolution_m"):
        PlannerParams(plan_resolution_m=-0.1)
    with pytest.raises(ValueError, match=r"PlannerParams.zone_band_m must be .*>= 0 \(got -0.1\)"):
        PlannerParams(zone_band_m=-0.1)
    with pytest.raises(ValueError, match="PlannerParams.door_throat_skids"):
        PlannerParams(door_throat_skids=float("nan"))


def test_a_repair_asked_for_over_the_ticks_budget_waits_for_the_next_update():
    from swarmpark.control.nav.fleetmap import FleetState

    poses = [[1.0, 1.0, 0.0], [1.0, 4.0, 0.0], [5.0, 2.5, np.pi / 2]]
    goals = [[8.0, 1.0, 0.0], [8.0, 4.0, 0.0], [5.0, 2.5, np.pi / 2]]
    fleet = FleetState(
        parked=np.array([False, False, True]),
        bound=np.array([True, True, False]),
        still=np.zeros(3, dtype=bool),
        waiting=np.zeros(3, dtype=bool),
    )
    states = [PathState() for _ in range(3)]
    pl, fol = _planner(max_plans_per_tick=1), PathFollower(FollowerParams())
    for t in (0.0, 0.1, 0.2):  # first plans, one per tick
        pl.update(make_view(poses, goals, t=t, goal_changed=[t == 0.0] * 3), states, fol, fleet)
    assert all(s.path is not None for s in states)
    pl.repair(0)
    pl.repair(1)
    pl.update(make_view(poses, goals, t=1.0), states, fol, fleet)
    assert sorted(s.planned_t for s in states[:2]) == [0.1, 1.0]  # one repair this tick
    pl.update(make_view(poses, goals, t=1.1), states, fol, fleet)
    assert sorted(s.planned_t for s in states[:2]) == [1.0, 1.1]  # the other one the next
    pl.update(make_view(poses, goals, t=1.2), states, fol, fleet)
    assert sorted(s.planned_t for s in states[:2]) == [1.0, 1.1]  # and no more


def test_through_a_door_the_path_keeps_to_the_middle_and_turns_past_it():
    # A wall across the hall at x = 5 with a 1.6 m door (y 2.2-3.8), a bottleneck zone for
    # these skids; the goal lies just past the door and below it, so the shortest way cuts
    # the door's lower jamb. In the zone the band is wider: the path keeps off the jamb.
    walls = [(4.85, 0.0, 5.15, 2.2), (4.85, 3.8, 5.15, 6.0)]
    view = make_view([[2.0, 3.0, 0.0]], [[6.6, 0.9, -np.pi / 2]], boxes=walls)
    jambs = [shapely.box(*w) for w in walls]

    def path(band, zones=True):
        pl = Planner(
            PlannerParams(zone_band_m=band),
            staging_m=0.9,
            direct_within_m=1.8,
            zones=TrafficControl(TrafficParams()).bottlenecks if zones else None,
        )
        return pl.plan(pl.costmap(view, view.footprints[0]), view.poses[0], view.goals[0])

    narrow, wide = path(0.0), path(0.5)
    assert np.array_equal(narrow, path(0.5, zones=False))  # no zones: as with no band
    clear = [min(shapely.LineString(p).distance(j) for j in jambs) for p in (narrow, wide)]
    assert clear[1] > clear[0] + 0.03, clear
    # Through the door (x 4.85-5.15) and on to the zone's end it runs along the middle,
    # where the shortest way has turned for the goal already.
    xs = np.linspace(4.55, 5.9, 10)
    ys = np.interp(xs, wide[:, 0], wide[:, 1])
    assert np.all(np.abs(ys - 3.0) < 0.1), ys
    assert not np.all(np.abs(np.interp(xs, narrow[:, 0], narrow[:, 1]) - 3.0) < 0.1)
    assert wide[-1] == pytest.approx([6.6, 0.9])


def test_through_a_narrow_corridor_the_band_stays_as_elsewhere():
    # A 3 m corridor 1.6 m wide between two rooms: a bottleneck zone, but no door (its
    # throat is the corridor's length, over two skid lengths), so the path is the same with
    # the doors' band or without it.
    walls = [(3.5, 0.0, 6.5, 2.2), (3.5, 3.8, 6.5, 6.0)]
    view = make_view([[1.0, 5.0, 0.0]], [[9.0, 1.0, -np.pi / 2]], boxes=walls)
    zones = TrafficControl(TrafficParams()).bottlenecks
    z = zones(view)
    assert z.count == 1 and z.throats_m[0] > 2.0 * view.footprints[0].length_m, z.throats_m

    def path(band):
        pl = Planner(
            PlannerParams(zone_band_m=band), staging_m=0.9, direct_within_m=1.8, zones=zones
        )
        return pl.plan(pl.costmap(view, view.footprints[0]), view.poses[0], view.goals[0])

    assert np.array_equal(path(0.0), path(0.5))
