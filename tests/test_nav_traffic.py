"""Queues at bottlenecks (:mod:`swarmpark.control.nav.traffic`), on hand-built views."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from navkit import make_view

from swarmpark.control.nav.follower import PathFollower, PathState
from swarmpark.control.nav.params import FollowerParams, TrafficParams
from swarmpark.control.nav.traffic import TrafficControl, TrafficState

#: A wall across the 10 m x 6 m hall at x = 5 with a 1.6 m door in the middle.
WALLS = [(4.85, 0.0, 5.15, 2.2), (4.85, 3.8, 5.15, 6.0)]


def _setup(poses, goals):
    view = make_view(poses, goals, boxes=WALLS)
    paths = []
    for p, g in zip(view.poses, view.goals, strict=True):
        st = PathState()
        st.path = np.array([p[:2], [5.0, 3.0], g[:2]])
        st.path_goal = g.copy()
        paths.append(st)
    return view, paths


def test_skids_from_opposite_sides_take_turns_and_the_waiting_one_stops_short():
    # Skid 0 is nearer the door (2.6 m along its path) than skid 1 (3.2 m).
    view, paths = _setup([[2.4, 3.0, 0.0], [8.2, 3.0, np.pi]], [[9.0, 3.0, 0.0], [1.0, 3.0, np.pi]])
    tc = TrafficControl(TrafficParams())
    states = [TrafficState(), TrafficState()]
    parked = np.zeros(2, bool)
    cmd = np.array([[0.5, 0.0], [0.5, 0.0]])
    waiting = tc.step(
        view, np.arange(2), cmd, paths, PathFollower(FollowerParams()), states, parked
    )
    assert tc.zones.count == 1
    assert states[0].zone == 1 and states[1].zone == 0 and states[1].waiting == 1
    assert waiting.tolist() == [False, True]
    # The waiting skid may drive on until it is gap_m from the zone, then it stops.
    z = tc.zones.polygons[0]
    x = z.bounds[2] + TrafficParams().gap_m + 0.6 + 0.05  # its rear edge just outside the gap
    near = replace(view, poses=np.array([[2.4, 3.0, 0.0], [x, 3.0, np.pi]]))
    cmd = np.array([[0.5, 0.0], [0.5, 0.0]])
    tc.step(near, np.arange(2), cmd, paths, PathFollower(FollowerParams()), states, parked)
    assert cmd[1].tolist() == [0.0, 0.0] and cmd[0].tolist() == [0.5, 0.0]
    # Once skid 0 has gone through and left the zone, skid 1 gets the door.
    past = replace(view, poses=np.array([[9.0, 3.0, 0.0], [x, 3.0, np.pi]]))
    cmd = np.array([[0.0, 0.0], [0.5, 0.0]])
    tc.step(past, np.arange(2), cmd, paths, PathFollower(FollowerParams()), states, parked)
    assert states[0].zone == 0 and states[1].zone == 1 and cmd[1, 0] == 0.5


def test_skids_from_the_same_side_follow_in_a_convoy():
    view, paths = _setup([[2.4, 3.0, 0.0], [1.2, 3.0, 0.0]], [[9.0, 3.0, 0.0], [8.0, 3.5, 0.0]])
    # Without a convoy gap a zone is a one-way lane: both from the same side go at once.
    states = [TrafficState(), TrafficState()]
    fol = PathFollower(FollowerParams())
    TrafficControl(TrafficParams(convoy_gap_s=0.0)).step(
        view, np.arange(2), np.zeros((2, 2)), paths, fol, states, np.zeros(2, bool)
    )
    assert states[0].zone == states[1].zone == 1
    # With a convoy gap the second follows that much later.
    p = TrafficParams(convoy_gap_s=2.0)
    tc = TrafficControl(p)
    states = [TrafficState(), TrafficState()]
    fol = PathFollower(FollowerParams())
    parked = np.zeros(2, bool)
    tc.step(view, np.arange(2), np.zeros((2, 2)), paths, fol, states, parked)
    assert states[0].zone == 1 and states[1].waiting == 1  # the second is queued behind ...
    later = replace(view, t=p.convoy_gap_s, poses=np.array([[4.5, 3.0, 0.0], [2.4, 3.0, 0.0]]))
    tc.step(later, np.arange(2), np.zeros((2, 2)), paths, fol, states, parked)
    assert states[1].zone == 1  # ... and follows convoy_gap_s later, from the same side
    assert states[0].side == states[1].side


def test_a_skid_standing_in_the_zone_comes_from_the_side_its_path_leads_away_from():
    # Skid 1 starts inside the door's zone, at its west end, going east like skid 0 behind
    # it: both are one convoy (counted from no side, it refused skid 0 the door for good).
    view, paths = _setup([[1.2, 3.0, 0.0], [4.3, 3.0, 0.0]], [[9.0, 3.0, 0.0], [8.0, 3.5, 0.0]])
    tc = TrafficControl(TrafficParams(convoy_gap_s=0.0))
    assert tc.bottlenecks(view).zone_at(np.array([[4.3, 3.0]]))[0] == 1
    states = [TrafficState(), TrafficState()]
    fol = PathFollower(FollowerParams())
    tc.step(view, np.arange(2), np.zeros((2, 2)), paths, fol, states, np.zeros(2, bool))
    west = tc.zones.region_at(np.array([[1.2, 3.0]]))[0]
    assert states[0].zone == states[1].zone == 1 and states[0].side == states[1].side == west
    # Going back west from the same place it comes from the east side: skid 0 waits.
    view, paths = _setup([[1.2, 3.0, 0.0], [4.3, 3.0, np.pi]], [[9.0, 3.0, 0.0], [1.0, 1.0, np.pi]])
    paths[1].path = np.array([[4.3, 3.0], [1.0, 1.0]])
    states = [TrafficState(), TrafficState()]
    tc.step(view, np.arange(2), np.zeros((2, 2)), paths, fol, states, np.zeros(2, bool))
    east = tc.zones.region_at(np.array([[9.5, 3.0]]))[0]
    assert states[1].zone == 1 and states[1].side == east > 0
    assert states[0].zone == 0 and states[0].waiting == 1


def test_a_skid_the_fill_order_holds_back_gets_no_grant_and_the_next_one_goes():
    # Skid 0 is first in the queue for the door but held back by the fill order: it would
    # wait in the door. It gets no grant and stops short; skid 1 behind it goes first.
    view, paths = _setup([[1.6, 3.0, 0.0], [0.7, 3.0, 0.0]], [[8.0, 3.5, 0.0], [9.0, 3.0, 0.0]])
    view = replace(view, hold=np.array([True, False]), hold_zones=(None, None))
    tc = TrafficControl(TrafficParams())
    states = [TrafficState(), TrafficState()]

    def step(v):
        fol = PathFollower(FollowerParams())
        return tc.step(v, np.arange(2), np.zeros((2, 2)), paths, fol, states, np.zeros(2, bool))

    waiting = step(view)
    assert states[0].zone == 0 and states[0].waiting == 1 and waiting[0]
    assert states[1].zone == 1 and states[1].waiting == 0 and not waiting[1]
    # Released by the fill order, it gets the door in its turn (behind the convoy's gap).
    step(replace(view, t=10.0, hold=np.array([False, False])))
    assert states[0].zone == 1


def test_a_convoy_goes_on_past_a_skid_waiting_the_other_way_for_convoy_max_s():
    """Skid 1 (coming from the east) is refused the door while skid 0 crosses it from the
    west. Skid 2, following skid 0, still goes (a corridor turning round costs a whole
    crossing), until skid 1 has waited convoy_max_s: then skid 3 from the west waits,
    though it stands nearer the door, and skid 1 goes next."""
    poses = [[2.4, 3.0, 0.0], [7.8, 3.0, np.pi], [1.2, 3.0, 0.0], [0.5, 3.0, 0.0]]
    goals = [[9.0, 3.0, 0.0], [1.0, 3.0, np.pi], [8.0, 2.5, 0.0], [8.0, 4.0, 0.0]]
    view, paths = _setup(poses, goals)
    p = TrafficParams(convoy_gap_s=2.0, convoy_max_s=30.0)
    tc = TrafficControl(p)
    states = [TrafficState() for _ in range(4)]

    def step(t, xy, parked=(False, False, False, True)):
        moved = np.array([[*q, h[2]] for q, h in zip(xy, poses, strict=True)], float)
        fol = PathFollower(FollowerParams())
        v = replace(view, t=t, poses=moved)
        return tc.step(v, np.arange(4), np.zeros((4, 2)), paths, fol, states, np.array(parked))

    step(0.0, [[2.4, 3.0], [7.8, 3.0], [1.2, 3.0], [0.5, 3.0]])
    assert [s.zone for s in states] == [1, 0, 0, 0] and states[1].waiting == 1
    step(2.0, [[4.5, 3.0], [7.8, 3.0], [2.4, 3.0], [0.5, 3.0]])
    assert [s.zone for s in states] == [1, 0, 1, 0]  # skid 2 follows skid 0 past skid 1
    assert states[1].waiting == 1 and states[1].refused_since == 0.0
    # Skid 1 has waited convoy_max_s; skid 3 stands nearer the door than skid 1, and waits.
    step(31.0, [[9.0, 3.0], [7.8, 3.0], [4.5, 3.0], [3.6, 3.0]], parked=(True, False, False, False))
    assert [s.zone for s in states] == [0, 0, 1, 0] and states[3].waiting == 1
    step(35.0, [[9.0, 3.0], [7.8, 3.0], [8.0, 2.5], [3.6, 3.0]], parked=(True, False, True, False))
    assert states[1].zone == 1 and states[3].zone == 0 and states[3].waiting == 1


def test_points_judged_far_from_every_zone_find_no_zone_ahead():
    """The shortcut that skips the walk along a skid's path: from a point it judges far from
    the zones, no path of the lookahead's length reaches one (checked on random paths from
    random points of the hall, some of them through the door)."""
    rng = np.random.default_rng(11)
    view, _ = _setup([[2.0, 3.0, 0.0]], [[9.0, 3.0, 0.0]])
    params = TrafficParams(lookahead_m=2.0)  # the hall is 10 m long
    tc = TrafficControl(params)
    tc.prepare(view)
    z = tc.zones
    starts = rng.uniform([0.3, 0.3], [9.7, 5.7], (400, 2))
    far = tc._far_from_zones(z, starts)
    assert 0 < far.sum() < len(far)
    seen = 0
    for start, is_far in zip(starts, far, strict=True):
        turns = rng.uniform(-np.pi, np.pi, 4)
        legs = np.column_stack([np.cos(turns), np.sin(turns)]) * rng.uniform(0.3, 1.0, (4, 1))
        st = PathState(path=np.vstack([start, start + np.cumsum(legs, axis=0)]))
        got = tc._ahead(view, 0, st, 0.0, z)
        if is_far:
            assert got == (0, 0.0, 0)
        seen += got[0] != 0
    assert seen > 10  # paths from the points near the door do reach it


def test_a_path_that_only_cuts_the_zones_edge_asks_for_no_grant():
    """Skid 1 in the east room backs out past the door's zone and comes back into the east
    room (going round a row): it does not go through the door, so it is not queued behind
    skid 0, which holds the door (queued, it stood in skid 0's way while skid 0 waited for
    it, for the rest of a generated door run). A path into the same zone that goes on west
    through the door still asks."""
    view, paths = _setup([[2.4, 3.0, 0.0], [8.4, 3.0, 0.0]], [[9.0, 3.0, 0.0], [8.8, 0.8, 0.0]])
    tc = TrafficControl(TrafficParams(convoy_gap_s=0.0))
    tc.prepare(view)
    z = tc.zones
    edge = z.polygons[0].bounds[2] - 0.2  # inside the zone's east padding, east of the door
    assert edge > 5.15 and z.zone_at(np.array([[edge, 3.0]]))[0] == 1
    paths[1].path = np.array([[8.4, 3.0], [edge, 3.0], [edge, 0.8], [8.8, 0.8]])
    states = [TrafficState(), TrafficState()]
    fol = PathFollower(FollowerParams())
    waiting = tc.step(view, np.arange(2), np.zeros((2, 2)), paths, fol, states, np.zeros(2, bool))
    assert states[0].zone == 1
    assert states[1].zone == 0 and states[1].waiting == 0 and not waiting[1]
    # Through the door to the west room: it asks, and waits for skid 0 coming the other way.
    paths[1].path = np.array([[8.4, 3.0], [edge, 3.0], [1.0, 3.0]])
    waiting = tc.step(view, np.arange(2), np.zeros((2, 2)), paths, fol, states, np.zeros(2, bool))
    assert states[1].waiting == 1 and waiting[1]
