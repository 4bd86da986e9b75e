"""The manoeuvre planner on a state lattice (:mod:`swarmpark.plan.lattice`)."""

from __future__ import annotations

import numpy as np
import pytest

from swarmpark.core.geometry import Footprint, footprint_corners, integrate_unicycle
from swarmpark.plan.lattice import (
    HEADING_STEPS,
    HEADINGS,
    free_masks,
    plan_manoeuvre,
    rect_mask,
)

FP = Footprint(1.2, 0.8, 0.6)
RES = 0.05


def _room(boxes, size=(6.0, 6.0)):
    """A walled room ``size`` with axis-aligned ``boxes`` (x0, y0, x1, y1) occupied."""
    h, w = int(size[1] / RES), int(size[0] / RES)
    occ = np.zeros((h, w), bool)
    occ[:, :2] = occ[:, -2:] = occ[:2, :] = occ[-2:, :] = True
    for x0, y0, x1, y1 in boxes:
        occ[int(y0 / RES) : int(np.ceil(y1 / RES)), int(x0 / RES) : int(np.ceil(x1 / RES))] = True
    return occ


def _touches(occ, pose, fp=FP):
    """Whether footprint ``fp`` at ``pose`` covers an occupied cell centre (exact test)."""
    corners = footprint_corners(np.asarray(pose)[None], fp.corners_body()[None])[0]
    rr, cc = np.nonzero(occ)
    xy = np.column_stack([(cc + 0.5) * RES, (rr + 0.5) * RES])
    c, s = np.cos(pose[2]), np.sin(pose[2])
    d = xy - pose[:2]
    along, across = d[:, 0] * c + d[:, 1] * s, -d[:, 0] * s + d[:, 1] * c
    inside = (along >= -fp.pivot) & (along <= fp.length_m - fp.pivot)
    del corners
    return bool(np.any(inside & (np.abs(across) <= fp.width_m / 2)))


def test_grid_headings_are_cell_steps():
    assert len(HEADINGS) == 16
    np.testing.assert_allclose(HEADINGS, np.arctan2(HEADING_STEPS[:, 1], HEADING_STEPS[:, 0]))
    assert np.all(np.diff(np.unwrap(HEADINGS)) > 0)


def test_rect_mask_covers_the_footprint():
    mask = rect_mask(FP, 0.0, 0.1, 0.0)
    r = mask.shape[0] // 2
    rows, cols = np.nonzero(mask)
    # 1.2 m long about a middle pivot and 0.8 m wide: 13 x 9 cell centres at 0.1 m.
    assert (cols.max() - cols.min() + 1, rows.max() - rows.min() + 1) == (13, 9)
    assert mask[r, r]


@pytest.mark.parametrize("fp", [FP, Footprint(1.5, 0.6, 0.3)])
def test_free_masks_match_the_footprint_placed_at_every_cell(fp):
    """Where the pivot may stand, found at once for 16 headings and 16 half-way headings, is
    where the footprint's cell mask, placed on the cell, covers no occupied cell and does not
    leave the window (outside counts as occupied): checked cell by cell on a room open on one
    side, with boxes and scattered single cells."""
    rng = np.random.default_rng(7)
    occ = _room([(1.0, 1.0, 1.6, 2.2), (3.1, 3.0, 3.3, 4.4)], size=(4.5, 5.0))
    occ |= rng.random(occ.shape) < 0.004
    occ[:, -2:] = False  # open on the right: the window's edge is all that bounds it there
    grow = 0.02
    free, turn_free = free_masks(occ, fp, RES, grow)
    full = grow + RES * np.sqrt(0.5)
    mids = np.arctan2(
        np.sin(HEADINGS) + np.sin(np.roll(HEADINGS, -1)),
        np.cos(HEADINGS) + np.cos(np.roll(HEADINGS, -1)),
    )
    h, w = occ.shape
    for got, heading in [(free[k], HEADINGS[k]) for k in (0, 1, 2, 5)] + [
        (turn_free[k], mids[k]) for k in (0, 3, 9)
    ]:
        mask = rect_mask(fp, heading, RES, full)
        r = mask.shape[0] // 2
        padded = np.pad(occ, r, constant_values=True)
        want = np.array(
            [[not np.any(padded[y : y + 2 * r + 1, x : x + 2 * r + 1] & mask) for x in range(w)]
             for y in range(h)]
        )  # fmt: skip
        assert want.any() and not want.all()
        np.testing.assert_array_equal(got, want)


def test_into_a_spot_that_only_a_turn_on_the_spot_reaches():
    """A spot with a pillar just below it and parked neighbours left and above: the only way
    in is sideways, then a turn on the spot; the plan's poses never touch an obstacle."""
    occ = _room([(2.4, 1.6, 3.2, 2.4), (1.2, 2.6, 2.0, 3.8), (2.4, 4.0, 3.2, 5.1)])
    start, goal = np.array([5.0, 1.0, np.pi / 2]), np.array([2.8, 3.2, np.pi / 2])
    m = plan_manoeuvre(occ, np.zeros(2), RES, FP, start, goal, speed_mps=0.5, yaw_rate_radps=1.0)
    assert m is not None
    np.testing.assert_allclose(m.poses[-1, :2], goal[:2], atol=RES)
    assert abs(m.poses[-1, 2] - goal[2]) < 1e-9
    assert not any(_touches(occ, p) for p in m.poses)
    kinds = [s[0] for s in m.segments()]
    assert "turn" in kinds and kinds[-1] in ("forward", "reverse")
    # Deterministic.
    again = plan_manoeuvre(
        occ, np.zeros(2), RES, FP, start, goal, speed_mps=0.5, yaw_rate_radps=1.0
    )
    np.testing.assert_array_equal(again.poses, m.poses)


def test_searches_given_the_windows_masks_plan_as_without_and_leave_them_unchanged():
    """Several searches in one window share its masks (``masks=``): each plans exactly as a
    search that works them out itself, also from a start that is not free (the search marks
    its own start free, on a copy), and the masks it was given are not changed."""
    occ = _room([(2.4, 1.6, 3.2, 2.4), (1.2, 2.6, 2.0, 3.8), (2.4, 4.0, 3.2, 5.1)])
    kw = {"speed_mps": 0.5, "yaw_rate_radps": 1.0, "grow_m": 0.02}
    masks = free_masks(occ, FP, RES, kw["grow_m"])
    kept = (masks[0].copy(), masks[1].copy())
    goal = np.array([2.8, 3.2, np.pi / 2])
    wedged = np.array([3.82, 2.0, np.pi])  # its nose 2 cm from the pillar: not free
    for start in (np.array([5.0, 1.0, np.pi / 2]), wedged):
        alone = plan_manoeuvre(occ, np.zeros(2), RES, FP, start, goal, **kw)
        shared = plan_manoeuvre(occ, np.zeros(2), RES, FP, start, goal, masks=masks, **kw)
        assert alone is not None and shared is not None
        np.testing.assert_array_equal(shared.poses, alone.poses)
        assert shared.start_free == alone.start_free
    assert not alone.start_free  # the wedged start did test the copy
    np.testing.assert_array_equal(masks[0], kept[0])
    np.testing.assert_array_equal(masks[1], kept[1])


def test_backs_in_when_cheaper_and_refuses_a_walled_in_goal():
    occ = _room([(0.0, 0.0, 1.9, 6.0)])  # the left third is solid
    # Facing away from a spot right behind it: a short reverse run beats turning twice.
    start, goal = np.array([4.0, 3.0, 0.0]), np.array([3.0, 3.0, 0.0])
    m = plan_manoeuvre(occ, np.zeros(2), RES, FP, start, goal, speed_mps=0.5, yaw_rate_radps=1.0)
    assert m is not None and set(m.moves[1:].tolist()) == {-1}
    walled = np.array([1.0, 3.0, 0.0])  # inside the solid part
    assert (
        plan_manoeuvre(occ, np.zeros(2), RES, FP, start, walled, speed_mps=0.5, yaw_rate_radps=1.0)
        is None
    )


def test_segments_drive_a_unicycle_to_the_goal():
    """Driving the segments with an ideal unicycle ends at the goal."""
    occ = _room([(2.4, 1.6, 3.2, 2.4)])
    start, goal = np.array([4.5, 1.0, 0.3]), np.array([2.8, 3.2, np.pi / 2 + 0.1])
    m = plan_manoeuvre(occ, np.zeros(2), RES, FP, start, goal, speed_mps=0.5, yaw_rate_radps=1.0)
    pose = m.poses[0].copy()
    for kind, _, b in m.segments():
        if kind == "turn":
            pose[2] = b[2]
        else:
            d = np.dot(b[:2] - pose[:2], [np.cos(pose[2]), np.sin(pose[2])])
            pose = integrate_unicycle(pose[None], np.array([d]), np.zeros(1), 1.0)[0]
    assert np.hypot(*(pose[:2] - goal[:2])) < 0.05
    assert abs(np.angle(np.exp(1j * (pose[2] - goal[2])))) < 1e-6


@pytest.mark.parametrize("budget", [10])
def test_budget_bounds_the_search(budget):
    occ = _room([])
    m = plan_manoeuvre(
        occ,
        np.zeros(2),
        RES,
        FP,
        np.array([1.0, 1.0, 0.0]),
        np.array([5.0, 5.0, np.pi]),
        speed_mps=0.5,
        yaw_rate_radps=1.0,
        budget=budget,
    )
    assert m is None


def test_the_window_edge_counts_as_a_wall():
    """Outside the planning window is unknown, so occupied: no planned pose may hang a corner
    past the window's edge (the window is cut from the map; a wall may lie just beyond it).
    Here the window has no walls at all; the skid must stay a half-width inside its edges."""
    occ = np.zeros((int(3.0 / RES), int(6.0 / RES)), bool)
    start, goal = np.array([1.0, 1.5, 0.0]), np.array([5.0, 1.5, np.pi / 2])
    m = plan_manoeuvre(occ, np.zeros(2), RES, FP, start, goal, speed_mps=0.5, yaw_rate_radps=1.0)
    assert m is not None
    corners = footprint_corners(
        m.poses[1:], np.repeat(FP.corners_body()[None], len(m.poses) - 1, 0)
    )
    assert corners.min() >= 0.0
    assert corners[..., 0].max() <= 6.0 and corners[..., 1].max() <= 3.0
    # A goal whose footprint would reach past the edge is refused.
    edge = np.array([5.9, 1.5, 0.0])
    assert (
        plan_manoeuvre(occ, np.zeros(2), RES, FP, start, edge, speed_mps=0.5, yaw_rate_radps=1.0)
        is None
    )


def test_a_goal_by_a_wall_is_reached_from_a_cell_beside_its_own():
    """A spot by the right wall with a block under it and the ceiling close: the skid cannot
    turn on the spot's own cell, only one cell to the left, and cannot come in along the
    axis. With the goal tolerance the plan ends beside the goal's cell, within the
    tolerance, touching nothing; without it there is no plan."""
    occ = _room([(3.3, 0.0, 6.0, 1.95)], size=(6.0, 3.6))
    start, goal = np.array([1.5, 2.8, 0.0]), np.array([5.17, 2.8, np.pi / 2])
    kw = {"speed_mps": 0.5, "yaw_rate_radps": 1.0}
    assert plan_manoeuvre(occ, np.zeros(2), RES, FP, start, goal, **kw) is None
    m = plan_manoeuvre(occ, np.zeros(2), RES, FP, start, goal, goal_tol_m=0.05, **kw)
    assert m is not None
    end = m.poses[-1]
    assert end[2] == pytest.approx(goal[2])
    assert np.hypot(*(end[:2] - goal[:2])) <= 0.05 + RES * np.sqrt(0.5)
    assert not any(_touches(occ, p) for p in m.poses)
    # The last run goes on to the exact goal.
    kind, _, to = m.segments()[-1]
    assert kind in ("forward", "reverse")
    np.testing.assert_allclose(to, goal)
