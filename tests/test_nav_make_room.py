"""Making room on hand-built views: a parked skid in another's corridor moves aside along its
axis to the nearer free side (not into a wall), keeps that side, and skids out of the way stay;
a skid pushed past a spot filled since is cut off from its own."""

from dataclasses import replace

import numpy as np
from navkit import make_view
from shapely.geometry import box

from swarmpark.control.nav.follower import PathState
from swarmpark.control.nav.make_room import MakeRoom, RoomState, cut_off
from swarmpark.control.nav.params import MakeRoomParams
from swarmpark.control.nav.scene import Scene

MOVER_PATH = np.array([[1.0, 3.0], [9.0, 3.0]])  # skid 1 drives along y = 3


def _room(parked_pose, boxes=(), rooms=None, mover=(1.5, 3.0, 0.0)):
    view = make_view([parked_pose, mover], [parked_pose, [9.0, 3.0, 0.0]], boxes=boxes)
    scene = Scene(0.1, 0.03).update(view)
    paths = [PathState(), PathState(path=MOVER_PATH)]
    rooms = rooms or [RoomState(), RoomState()]
    res = MakeRoom(MakeRoomParams()).step(view, np.array([True, False]), paths, rooms, scene)
    return res, rooms


def test_a_parked_skid_in_the_corridor_moves_aside_along_its_axis():
    res, rooms = _room([5.0, 3.0, np.pi / 2])  # across the way, axis along y
    assert res.aside[0] and res.undock[0]
    assert res.speed[0] > 0 and rooms[0].side == 1  # both sides equal: along its heading
    assert not res.aside[1] and res.speed[1] == 0.0  # the mover itself is not settled


def test_it_keeps_the_side_it_chose():
    rooms = [RoomState(side=-1), RoomState()]
    res, rooms = _room([5.0, 3.3, np.pi / 2], rooms=rooms)  # now nearer the + side
    assert res.speed[0] < 0 and rooms[0].side == -1


def test_it_does_not_move_into_a_wall():
    res, rooms = _room([5.0, 3.0, np.pi / 2], boxes=[(4.0, 4.2, 6.0, 6.0)])
    assert res.speed[0] < 0 and rooms[0].side == -1


def test_a_skid_out_of_the_way_stays_and_forgets_its_side():
    res, rooms = _room([5.0, 5.0, np.pi / 2], rooms=[RoomState(side=1), RoomState()])
    assert not res.aside[0] and res.speed[0] == 0.0 and not res.undock[0]
    assert rooms[0].side == 0


def test_a_skid_that_stood_aside_waits_while_its_spot_is_in_the_way():
    # Its goal is on the mover's way, it stands aside at y = 4.5: it waits there (aside)
    # without moving, and keeps its side.
    view = make_view(
        [[5.0, 4.5, np.pi / 2], [1.5, 3.0, 0.0]], [[5.0, 3.0, np.pi / 2], [9.0, 3.0, 0.0]]
    )
    scene = Scene(0.1, 0.03).update(view)
    rooms = [RoomState(side=1), RoomState()]
    paths = [PathState(), PathState(path=MOVER_PATH)]
    res = MakeRoom(MakeRoomParams()).step(view, np.array([True, False]), paths, rooms, scene)
    assert res.aside[0] and res.speed[0] == 0.0 and rooms[0].side == 1


def test_nothing_moves_without_movers():
    view = make_view([[5.0, 3.0, np.pi / 2]])
    scene = Scene(0.1, 0.03).update(view)
    rooms = [RoomState(side=1)]
    res = MakeRoom(MakeRoomParams()).step(view, np.array([True]), [PathState()], rooms, scene)
    assert not res.aside.any() and rooms[0].side == 0


def _column(pushed_to: float, other_at: float):
    """Two spots in a column along y (heading +y): skid 0's at y = 2, skid 1's at y = 4.
    Skid 0 was pushed along the column to ``pushed_to``; skid 1 stands at ``other_at``."""
    up = np.pi / 2
    view = make_view([[5.0, pushed_to, up], [5.0, other_at, up]], [[5.0, 2.0, up], [5.0, 4.0, up]])
    plain = Scene(0.1, 0.03).update(view).skids.plain
    return [bool(v) for v in cut_off(view, np.array([True, True]), plain, 0.09)]


def test_a_skid_pushed_past_a_spot_that_was_filled_since_is_cut_off():
    assert _column(5.6, 4.0) == [True, False]


def test_a_neighbour_pushed_along_with_it_does_not_cut_it_off():
    # Skid 1 is off its own spot too (pushed on ahead of skid 0): it will return first.
    assert _column(3.4, 5.0) == [False, False]


def test_a_skid_on_its_spot_or_with_a_clear_way_back_is_not_cut_off():
    assert _column(2.0, 4.0) == [False, False]
    assert _column(1.2, 4.0) == [False, False]  # pushed the other way


def _waiting(pose, boundary=None, rooms=None):
    """Skid 0 waits on purpose (held back, outside ``boundary`` if given) at ``pose``, its
    goal far off; skid 1 drives along y = 3 from x = 1.5."""
    view = make_view([pose, [1.5, 3.0, 0.0]], [[8.0, 5.0, 0.0], [9.0, 3.0, 0.0]])
    if boundary is not None:
        view = replace(view, hold=np.array([True, False]), hold_zones=(boundary, None))
    scene = Scene(0.1, 0.03).update(view)
    paths = [PathState(), PathState(path=MOVER_PATH)]
    rooms = rooms or [RoomState(), RoomState()]
    res = MakeRoom(MakeRoomParams()).step_waiting(
        view, np.array([True, False]), np.zeros(2, bool), paths, rooms, scene, hold_gap_m=0.2
    )
    return res, rooms


def test_a_waiting_skid_in_the_way_of_one_on_the_move_drives_out_of_it():
    res, rooms = _waiting([5.0, 3.0, np.pi / 2])
    assert res.aside[0] and res.speed[0] > 0 and rooms[0].side == 1
    assert not res.aside[1]
    # Out of the way, it stays where it stood aside while it waits.
    res, rooms = _waiting([5.0, 4.5, np.pi / 2], rooms=rooms)
    assert res.aside[0] and res.speed[0] == 0.0 and rooms[0].side == 1


def test_a_waiting_skid_does_not_move_towards_the_boundary_it_waits_outside():
    # Its boundary (grown by the hold's gap, 0.2 m) lies on the + side: it backs out the
    # other way.
    res, rooms = _waiting([5.0, 3.0, np.pi / 2], boundary=box(4.2, 4.4, 5.8, 5.8))
    assert res.speed[0] < 0 and rooms[0].side == -1


def test_a_waiting_skid_out_of_every_way_is_left_alone():
    res, rooms = _waiting([5.0, 5.0, np.pi / 2])
    assert not res.aside.any() and rooms[0].side == 0
