"""Spots no manoeuvre reaches (plan/spot_reach.py): a rectangle that cannot turn a corner, a
dead-end slot filled in the wrong order (and the order that fills it), and the layout report
naming the spot."""

import numpy as np
import pytest

from swarmpark.core.geometry import Footprint
from swarmpark.plan.spot_reach import (
    SpotWindow,
    _add_hits,
    _hits,
    _masks,
    manoeuvre_blocks,
    manoeuvre_order,
    spot_reach,
)

RES = 0.05
FP = Footprint(1.2, 0.8, 0.6)


def _carve(occ, x0, x1, y0, y1):
    occ[
        int(round(y0 / RES)) : int(round(y1 / RES)), int(round(x0 / RES)) : int(round(x1 / RES))
    ] = False


def _l_slot():
    """A 10 x 10 m map, a solid block with a 1 m slot going up from its lower edge and, at the
    slot's top, a 1 m pocket going right: a 1.2 x 0.8 m skid cannot turn that corner."""
    occ = np.zeros((200, 200), bool)
    occ[int(2 / RES) : int(9.5 / RES), int(4.5 / RES) : int(9.5 / RES)] = True
    _carve(occ, 5.0, 6.0, 2.0, 6.0)  # the slot
    _carve(occ, 5.0, 8.5, 5.0, 6.0)  # the pocket
    return occ


def test_a_spot_behind_a_corner_too_tight_to_turn_is_flagged():
    occ = _l_slot()
    poses = np.array([[7.2, 5.5, 0.0], [5.5, 3.4, np.pi / 2]])
    flagged = spot_reach(occ, np.zeros(2), RES, poses, [FP, FP], (0,))
    assert [f.spot for f in flagged] == [0]
    assert "no manoeuvre" in flagged[0].reason and "1.2 x 0.8 m" in flagged[0].reason
    # The spot in the straight slot is reached (backing straight out).
    assert spot_reach(occ, np.zeros(2), RES, poses, [FP, FP], (1,)) == []


def _dead_end_slot():
    """A dead-end slot one skid wide going up from the block's lower edge, and two spots in
    it: the deep one, the one near the mouth."""
    occ = np.zeros((200, 200), bool)
    occ[int(2 / RES) : int(9.5 / RES), int(4.5 / RES) : int(9.5 / RES)] = True
    _carve(occ, 5.0, 6.0, 2.0, 6.0)
    return occ, np.array([[5.5, 5.0, np.pi / 2], [5.5, 3.0, np.pi / 2]])


def _slot_window():
    occ, poses = _dead_end_slot()
    return SpotWindow(occ, np.zeros(2), RES, poses, [FP, FP])


def test_the_fill_order_decides_a_dead_end_slot():
    """Two spots in a dead-end slot one skid wide: deepest first both are reached; the other
    way round the deep one is walled in by the first."""
    occ, poses = _dead_end_slot()
    assert spot_reach(occ, np.zeros(2), RES, poses, [FP, FP], (0, 1)) == []
    flagged = spot_reach(occ, np.zeros(2), RES, poses, [FP, FP], (1, 0))
    assert [f.spot for f in flagged] == [0]
    assert "the 1 spot(s) filled before it" in flagged[0].reason


def test_incremental_hits_equal_a_fresh_count():
    rng = np.random.default_rng(0)
    occ = rng.random((120, 150)) < 0.01
    masks = _masks(FP, RES, 0.02)
    hits = _hits(occ, masks)
    for a, b, c, d in [(3, 20, 5, 30), (100, 119, 130, 150), (0, 5, 0, 3), (50, 70, 60, 64)]:
        new = np.zeros_like(occ)
        new[a:b, c:d] = True
        new &= ~occ
        _add_hits(hits, new, masks)
        occ |= new
    fresh = _hits(occ, masks)
    assert np.array_equal(hits < 0.5, fresh < 0.5)
    assert np.abs(hits - fresh).max() == pytest.approx(0.0, abs=1e-9)


def test_park_report_names_a_spot_behind_a_tight_corner():
    """The same corner as a site: the layout's disc check passes (the slot is wider than the
    skid), the manoeuvre check flags the spot in the park report and the accepted command."""
    from helpers import make_world

    from swarmpark.supervisor.core import Supervisor
    from swarmpark.world.scenario import ParkCmd

    walls = [  # the block of _l_slot() minus the slot and the pocket, as polygons
        [[4.5, 2.0], [5.0, 2.0], [5.0, 9.5], [4.5, 9.5]],
        [[6.0, 2.0], [9.5, 2.0], [9.5, 5.0], [6.0, 5.0]],
        [[5.0, 6.0], [9.5, 6.0], [9.5, 9.5], [5.0, 9.5]],
        [[8.5, 5.0], [9.5, 5.0], [9.5, 6.0], [8.5, 6.0]],
    ]
    world = make_world(
        map={"size_m": [10, 10], "resolution_m": 0.05, "walls": walls},
        robots=[{"id": "a", "pose": [2.0, 1.0, 0.0]}],
    )
    sup = Supervisor(world)
    cmd = ParkCmd(
        robots=["a"],
        boundary=[[6.0, 5.0], [8.5, 5.0], [8.5, 6.0], [6.0, 6.0]],
        heading_deg=0,
        margin_m=0.05,
    )
    # The operator's way (a preview or park from the server, prepared off the tick).
    out = sup.apply_park(sup.prepare_park(cmd))
    assert out.accepted, out.reason
    (flag,) = out.detail["unreachable_spots"]
    assert flag["spot"] == 0 and "no manoeuvre" in flag["reason"]
    assert any("no manoeuvre" in n for n in sup.groups[0].report["notices"])
    # A scripted park inside the tick: the check runs with the run's metrics afterwards.
    sup2 = Supervisor(world)
    out = sup2.park(cmd)
    assert out.accepted and "unreachable_spots" not in out.detail
    (late,) = sup2.metrics.unreachable_spots
    assert late["spot"] == 0 and late["t_s"] == 0.0 and late["reason"] == flag["reason"]


def test_a_fill_order_that_walls_in_a_spot_is_turned_round():
    """The layout asks for the mouth first: the order found fills the deep spot first, and
    the mouth spot blocks the deep one for the holds."""
    win = _slot_window()
    order, flags = manoeuvre_order(win, (1, 0))
    assert order == (0, 1) and flags == []
    assert manoeuvre_blocks(win, order) == ((), (0,))
    # An order that works is kept as it is.
    assert manoeuvre_order(win, (0, 1)) == ((0, 1), [])


def test_a_spot_no_order_reaches_is_flagged_by_the_order():
    occ = _l_slot()
    poses = np.array([[5.5, 3.4, np.pi / 2], [7.2, 5.5, 0.0]])
    win = SpotWindow(occ, np.zeros(2), RES, poses, [FP, FP])
    order, flags = manoeuvre_order(win, (0, 1))
    assert [f.spot for f in flags] == [1]
    assert flags == spot_reach(occ, np.zeros(2), RES, poses, [FP, FP], order)


def test_taking_a_spot_away_restores_the_hits():
    win = _slot_window()
    win.reachable(0)  # builds the footprint's hit counts on the walls alone
    ((masks, hits),) = win.tests.values()
    fresh = hits.copy()
    win.add(1)
    assert not np.allclose(hits, fresh)
    win.remove(1)
    assert np.abs(hits - fresh).max() == pytest.approx(0.0, abs=1e-9)
