"""Tests of the ORCA kernel: geometry, linear programs, priorities, shapes, unicycle tracking."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from scipy.optimize import linprog
from scipy.spatial import ConvexHull

from swarmpark.control.orca.kernel import (
    HalfPlanes,
    OrcaParams,
    disc_polygons,
    effective_reach,
    holonomic_speed_limit,
    holonomic_to_unicycle,
    inflate_convex,
    minkowski_difference,
    orca_step,
    pair_halfplanes,
    prepare_obstacles,
    responsibility_shares,
    skid_shapes,
    solve_velocity_lp,
    sweep_hits,
    tracking_error_bound,
    unicycle_to_holonomic,
)
from swarmpark.core.geometry import Footprint, convex_gap, rect_disc_gap, rotation

SKID = Footprint(length_m=1.25, width_m=0.75)
FAST = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.filter_too_much])


def rect(length: float, width: float, yaw: float) -> np.ndarray:
    """Centred rectangle, counter-clockwise, turned by ``yaw``."""
    c = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], float) * [length / 2, width / 2]
    return c @ rotation(yaw).T


def skid(yaw: float) -> np.ndarray:
    return rect(SKID.length_m, SKID.width_m, yaw)


def no_filter(**kw) -> OrcaParams:
    return OrcaParams(safety_filter=False, **kw)


def swept_gap(a, pa, va, b, pb, vb, horizon: float, samples: int = 201) -> float:
    """Smallest gap between two polygons moving straight over ``[0, horizon]``."""
    t = np.linspace(0.0, horizon, samples)[:, None, None]
    pa_t = pa + va * t + a[None]
    pb_t = pb + vb * t + b[None]
    return float(convex_gap(pa_t, pb_t).min())


def project_into(v, point, direction):
    """Closest point to ``v`` in the half-plane left of the line."""
    d = direction[0] * (v[1] - point[1]) - direction[1] * (v[0] - point[0])
    if d < 0:
        v = v - d * np.array([-direction[1], direction[0]])
    return v


# --------------------------------------------------------------------------------------------
# geometry


@FAST
@given(
    st.tuples(st.floats(0.2, 2.0), st.floats(0.2, 2.0), st.floats(-4, 4)),
    st.tuples(st.floats(0.2, 2.0), st.floats(0.2, 2.0), st.floats(-4, 4)),
    st.sampled_from([0.0, math.pi / 2, None]),
)
def test_minkowski_difference_equals_hull_of_vertex_differences(ra, rb, snap):
    a = rect(*ra)
    # Parallel edges (equal angles in the merge) are the common case for parked skids.
    b = rect(rb[0], rb[1], ra[2] + snap) if snap is not None else rect(*rb)
    m = minkowski_difference(b[None], a[None])[0]
    hull = ConvexHull((b[:, None] - a[None]).reshape(-1, 2))
    area = 0.5 * np.sum(m[:, 0] * np.roll(m[:, 1], -1) - np.roll(m[:, 0], -1) * m[:, 1])
    assert area == pytest.approx(hull.volume, rel=1e-9, abs=1e-12)
    for v in hull.points[hull.vertices]:
        assert np.min(np.linalg.norm(m - v, axis=1)) < 1e-9


def test_minkowski_difference_of_segment_and_many_sided_polygon():
    seg = np.array([[[0.0, 0.0], [2.0, 0.0], [2.0, 0.0], [2.0, 0.0]]])
    disc = disc_polygons(np.zeros((1, 2)), 0.5, sides=16)
    m = minkowski_difference(seg, disc)[0]
    hull = ConvexHull((seg[0][:, None] - disc[0][None]).reshape(-1, 2))
    area = 0.5 * np.sum(m[:, 0] * np.roll(m[:, 1], -1) - np.roll(m[:, 0], -1) * m[:, 1])
    assert area == pytest.approx(hull.volume, rel=1e-12)


@FAST
@given(
    st.tuples(st.floats(0.3, 1.5), st.floats(0.3, 1.5), st.floats(-4, 4)),
    st.tuples(st.floats(0.3, 1.5), st.floats(0.3, 1.5), st.floats(-4, 4)),
    st.tuples(st.floats(-4, 4), st.floats(-4, 4)),
    st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1)),
    st.floats(0.0, 5.0),
    st.floats(0.0, 5.0),
    st.integers(0, 2**32 - 1),
)
def test_reciprocal_halfplanes_keep_the_pair_apart_over_the_horizon(
    ra, rb, p, vels, prio_a, prio_b, seed
):
    """ORCA's guarantee: any velocities in the two half-planes (shares summing to one)
    avoid collision for the whole horizon."""
    a, b = rect(*ra), rect(*rb)
    p = np.array(p)
    if convex_gap(a[None], (p + b)[None])[0] <= 1e-3:
        return  # overlapping now: the one-step separation case, not covered here
    va, vb = np.array(vels[:2]), np.array(vels[2:])
    tau, dt = 2.0, 0.1
    w_a = responsibility_shares(np.array([prio_a]), np.array([prio_b]))
    region = p + minkowski_difference(b[None], a[None])
    inv_tau = np.array([1 / tau])
    # Shares of avoidance (inside) and of room to approach (outside) as orca_step uses them,
    # with the head-on leg preference on.
    pa, da = pair_halfplanes(
        region, (va - vb)[None], va[None], w_a, inv_tau, 1 / dt, 0.5, slack_share=1 - w_a
    )
    pb, db = pair_halfplanes(
        -region, (vb - va)[None], vb[None], 1 - w_a, inv_tau, 1 / dt, 0.5, slack_share=w_a
    )
    rng = np.random.default_rng(seed)
    for _ in range(5):
        xa = project_into(rng.uniform(-3, 3, 2), pa[0], da[0])
        xb = project_into(rng.uniform(-3, 3, 2), pb[0], db[0])
        assert swept_gap(a, np.zeros(2), xa, b, p, xb, tau) > -1e-6


def test_side_by_side_parked_skids_are_not_in_collision_and_do_not_freeze():
    """Two parked skids 0.2 m apart, same heading: with real (enlarged) rectangles the zero
    velocity is outside their velocity obstacle, and they can drive off as a column."""
    # Pivot on the rear axle, effective centre at the middle of the body, 20 Hz control.
    fp = Footprint(length_m=1.25, width_m=0.75, pivot_from_rear_m=0.25)
    v_max, w_max, offset, dt = 0.5, 1.5, fp.center_offset_m, 0.05
    u_max = holonomic_speed_limit(v_max, w_max, offset)
    reach = effective_reach(fp.corners_body(), offset)[0]
    margin = float(tracking_error_bound(u_max, w_max, reach, dt))
    assert 2 * margin < 0.2  # the enlarged skids still have a gap
    for yaw in (0.0, 0.7, -2.0):
        left = np.array([-math.sin(yaw), math.cos(yaw)])
        pivots = np.array([[0.0, 0.0, yaw], [*((fp.width_m + 0.2) * left), yaw]])
        centres, shapes = skid_shapes(pivots, fp.corners_body(), offset_m=offset, margin_m=margin)
        # A single circumscribed circle would make these skids overlap.
        assert 2 * fp.circumradius_m > np.linalg.norm(centres[1] - centres[0])
        region = (centres[1] - centres[0]) + minkowski_difference(shapes[1:], shapes[:1])
        _, inside = sweep_hits(region, np.zeros((1, 2)))
        assert not inside[0]
        zero = np.zeros((2, 2))
        res = orca_step(centres, zero, zero, u_max, 1.0, shapes, dt_s=dt)
        np.testing.assert_allclose(res.velocities, 0.0, atol=1e-12)
        assert not res.infeasible.any()
        # Driving off together in the heading direction is not hindered at all.
        ahead = 0.4 * np.array([[math.cos(yaw), math.sin(yaw)]] * 2)
        res = orca_step(centres, ahead, ahead, u_max, 1.0, shapes, dt_s=dt)
        np.testing.assert_allclose(res.velocities, ahead, atol=1e-9)


# --------------------------------------------------------------------------------------------
# linear programs


def test_lp_hand_checked_cases():
    # Half-plane x >= 0.5 (line through (0.5, 0) pointing down: allowed side on its left).
    hp = HalfPlanes(
        point=np.array([[[0.5, 0.0]]]),
        direction=np.array([[[0.0, -1.0]]]),
        valid=np.ones((1, 1), bool),
        n_hard=0,
    )
    v, bad = solve_velocity_lp(hp, np.array([[0.0, 0.3]]), np.array([2.0]))
    np.testing.assert_allclose(v, [[0.5, 0.3]], atol=1e-12)
    assert not bad[0]
    # The speed circle: x >= 0.5 and |v| <= 1 with preference (0, 2): (0.5, sqrt(0.75)).
    v, _ = solve_velocity_lp(hp, np.array([[0.0, 2.0]]), np.array([1.0]))
    np.testing.assert_allclose(v, [[0.5, math.sqrt(0.75)]], atol=1e-12)
    # Infeasible: x >= 1 and x <= -1: least violation at x = 0, flagged.
    hp2 = HalfPlanes(
        point=np.array([[[1.0, 0.0], [-1.0, 0.0]]]),
        direction=np.array([[[0.0, -1.0], [0.0, 1.0]]]),
        valid=np.ones((1, 2), bool),
        n_hard=0,
    )
    v, bad = solve_velocity_lp(hp2, np.array([[0.0, 0.0]]), np.array([2.0]))
    assert v[0, 0] == pytest.approx(0.0, abs=1e-12) and bad[0]
    # The same with the first line hard: it must hold exactly.
    hp3 = HalfPlanes(hp2.point, hp2.direction, hp2.valid, n_hard=1)
    v, _ = solve_velocity_lp(hp3, np.array([[0.0, 0.0]]), np.array([2.0]))
    assert v[0, 0] == pytest.approx(1.0, abs=1e-9)


def test_infeasible_programs_minimise_the_largest_soft_violation_and_keep_hard_lines():
    """The 3-D fallback against scipy's linprog (speed circle as a 256-gon)."""
    rng = np.random.default_rng(2)
    b_count, m, hard = 60, 7, 2
    ang = rng.uniform(0, 2 * np.pi, (b_count, m))
    d = np.stack([np.cos(ang), np.sin(ang)], -1)
    left = np.stack([-d[..., 1], d[..., 0]], -1)
    p = rng.uniform(-1.5, 1.5, (b_count, m, 2))
    p[:, :hard] = -0.3 * left[:, :hard]  # hard lines that the zero velocity keeps
    hp = HalfPlanes(p, d, np.ones((b_count, m), bool), hard)
    v, bad = solve_velocity_lp(hp, rng.uniform(-1, 1, (b_count, 2)), np.ones(b_count))
    th = np.linspace(0, 2 * np.pi, 256, endpoint=False)
    assert bad.sum() > 20
    for k in np.flatnonzero(bad):
        slack = -np.einsum("md,md->m", left[k], v[k] - p[k])  # > 0: violated by that much
        assert slack[:hard].max() <= 1e-9
        a_ub = [[-left[k, j, 0], -left[k, j, 1], 0.0 if j < hard else -1.0] for j in range(m)]
        b_ub = [-left[k, j] @ p[k, j] for j in range(m)]
        a_ub += [[math.cos(t), math.sin(t), 0.0] for t in th]
        b_ub += [1.0] * len(th)
        best = linprog([0, 0, 1], A_ub=a_ub, b_ub=b_ub, bounds=[(None, None)] * 3).x[2]
        assert slack[hard:].max() <= best + 1e-3


@st.composite
def scenes(draw):
    n = draw(st.integers(2, 7))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    pos = rng.uniform(-4, 4, (n, 2))
    yaw = rng.uniform(-math.pi, math.pi, n)
    shapes = np.stack([skid(y) for y in yaw])
    corners = pos[:, None] + shapes
    ii, jj = np.triu_indices(n, 1)
    assume(np.all(convex_gap(corners[ii], corners[jj]) >= 0.05))  # no overlapping starts
    vel = rng.uniform(-1, 1, (n, 2))
    pref = rng.uniform(-1.5, 1.5, (n, 2))
    prio = rng.choice([0.0, 1.0, 2.0, 10.0], n)
    return pos, vel, pref, prio, shapes


@FAST
@given(scenes())
def test_every_velocity_satisfies_all_its_halfplanes_when_feasible(scene):
    pos, vel, pref, prio, shapes = scene
    res = orca_step(pos, vel, pref, 1.0, prio, shapes, dt_s=0.1, params=no_filter())
    viol = res.halfplanes.violation(res.velocities)
    ok = ~res.infeasible
    assert np.all(viol[ok] <= 1e-9)
    assert np.all(np.linalg.norm(res.velocities, axis=1) <= 1.0 + 1e-9)
    # Where infeasible, the hard-free fallback still respects the speed limit.
    assert res.halfplanes.valid.shape[0] == len(pos)


@FAST
@given(scenes())
def test_safety_filter_leaves_no_overlap_within_the_step(scene):
    pos, vel, pref, prio, shapes = scene
    dt = 0.25
    res = orca_step(pos, vel, pref * 3, 1.0, prio, shapes, dt_s=dt)
    n = len(pos)
    ii, jj = np.triu_indices(n, 1)
    region = (pos[jj] - pos[ii])[:, None] + minkowski_difference(shapes[jj], shapes[ii])
    v = res.velocities
    hits, inside = sweep_hits(region, (v[ii] - v[jj]) * dt)
    assert not np.any(hits & ~inside)
    # The filter only ever slows down: same direction, not faster.
    raw = orca_step(pos, vel, pref * 3, 1.0, prio, shapes, dt_s=dt, params=no_filter())
    s = np.linalg.norm(v, axis=1) / np.maximum(np.linalg.norm(raw.velocities, axis=1), 1e-300)
    assert np.all(s <= 1 + 1e-12)
    np.testing.assert_allclose(v, raw.velocities * s[:, None], atol=1e-12)


# --------------------------------------------------------------------------------------------
# priorities, people, obstacles, order


def test_shares_follow_priorities():
    p = np.array([10.0, 1.0, 0.0, 0.0, 3.0])
    q = np.array([1.0, 10.0, 1.0, 0.0, 3.0])
    w = responsibility_shares(p, q)
    np.testing.assert_allclose(w + responsibility_shares(q, p), 1.0)
    np.testing.assert_allclose(w, [1 / 11, 10 / 11, 1.0, 0.5, 0.5])
    np.testing.assert_allclose(responsibility_shares(p, q, min_share=0.2)[:3], [0.2, 0.8, 0.8])


def head_on(prio_a: float, prio_b: float, steps: int = 150, dt: float = 0.1):
    """Two skids driving at each other (0.05 m offset); returns their largest lateral
    deviations and the smallest gap."""
    pos = np.array([[0.0, 0.0], [8.0, 0.05]])
    goal = np.array([[8.0, 0.0], [0.0, 0.05]])
    shapes = np.stack([skid(0.0), skid(math.pi)])
    vel = np.zeros((2, 2))
    dev = np.zeros(2)
    gap = math.inf
    for _ in range(steps):
        to = goal - pos
        d = np.linalg.norm(to, axis=1)
        pref = to * (np.minimum(1.0, d / dt) / np.maximum(d, 1e-12))[:, None]
        vel = orca_step(pos, vel, pref, 1.0, [prio_a, prio_b], shapes, dt_s=dt).velocities
        pos = pos + vel * dt
        dev = np.maximum(dev, np.abs(pos[:, 1] - [0.0, 0.05]))
        gap = min(gap, float(convex_gap((pos[0] + shapes[0])[None], (pos[1] + shapes[1])[None])[0]))
    return dev, gap, np.linalg.norm(goal - pos, axis=1)


def test_higher_priority_deviates_less_in_a_head_on_pass():
    dev, gap, left = head_on(10.0, 1.0)
    assert gap > 0 and np.all(left < 0.05)
    assert dev[0] < 0.25 * dev[1]
    dev_b, _, _ = head_on(1.0, 10.0)
    assert dev_b[1] < 0.25 * dev_b[0]
    dev_eq, gap_eq, _ = head_on(1.0, 1.0)
    assert gap_eq > 0 and dev_eq[0] == pytest.approx(dev_eq[1], rel=0.2)


def test_parked_priority_zero_yields_fully_and_returns():
    """A skid crossing a parked one (priority 0, goal = its spot): the mover keeps its line,
    the parked skid moves out of the way and comes back (paper Sect. 3.4.1)."""
    dt = 0.1
    pos = np.array([[0.0, 0.0], [4.0, 0.05]])
    goal = np.array([[8.0, 0.0], [4.0, 0.05]])
    shapes = np.stack([skid(0.0), skid(math.pi / 2)])
    vel = np.zeros((2, 2))
    dev, gap = np.zeros(2), math.inf
    for _ in range(200):
        to = goal - pos
        d = np.linalg.norm(to, axis=1)
        pref = to * (np.minimum(1.0, d / dt) / np.maximum(d, 1e-12))[:, None]
        vel = orca_step(pos, vel, pref, 1.0, [5.0, 0.0], shapes, dt_s=dt).velocities
        pos = pos + vel * dt
        dev = np.maximum(dev, np.abs(pos[:, 1] - goal[:, 1]))
        gap = min(gap, float(convex_gap((pos[0] + shapes[0])[None], (pos[1] + shapes[1])[None])[0]))
    assert gap > 0
    assert dev[0] < 0.02 and dev[1] > 0.5
    assert np.all(np.linalg.norm(goal - pos, axis=1) < 0.05)


def test_person_gets_full_avoidance_from_a_robot():
    """A person takes no share: the robot alone leaves the velocity obstacle."""
    robot, person = np.array([[0.0, 0.0]]), np.array([[4.0, 0.3]])
    v_robot, v_person, radius = np.array([[0.8, 0.0]]), np.array([[-1.0, 0.0]]), 0.3
    shapes = skid(0.0)[None]
    params = no_filter(time_horizon_s=3.0)
    res = orca_step(
        robot,
        v_robot,
        v_robot,
        1.0,
        1.0,
        shapes,
        dt_s=0.1,
        params=params,
        people_positions=person,
        people_velocities=v_person,
        people_radii=radius,
    )
    v_new = res.velocities[0]
    # Moving straight, robot and walking person never meet within the horizon.
    t = np.linspace(0, 3.0, 301)
    corners = robot[0] + v_new * t[:, None, None] + shapes[0][None]
    centres = person[0] + v_person[0] * t[:, None]
    assert rect_disc_gap(corners, centres, np.full(len(t), radius)).min() > -1e-6
    # Treated as a reciprocal robot instead, the robot would do only half and still collide.
    person_poly = disc_polygons(np.zeros((1, 2)), radius, 8)
    skid_8 = shapes[:, [0, 1, 2, 3, 3, 3, 3, 3]]  # padded to the person's vertex count
    half = orca_step(
        np.vstack([robot, person]),
        np.vstack([v_robot, v_person]),
        np.vstack([v_robot, v_person]),
        1.0,
        1.0,
        np.concatenate([skid_8, person_poly]),
        dt_s=0.1,
        params=params,
    ).velocities[0]
    corners = robot[0] + half * t[:, None, None] + shapes[0][None]
    assert rect_disc_gap(corners, centres, np.full(len(t), radius)).min() < 0


def test_person_walking_through_is_avoided_in_closed_loop():
    dt, pos, vel = 0.1, np.array([[0.0, 0.0]]), np.zeros((1, 2))
    person, v_person, radius = np.array([6.0, 0.1]), np.array([-1.0, 0.0]), 0.3
    goal = np.array([6.0, 0.0])
    gaps = []
    for _ in range(120):
        to = goal - pos[0]
        d = np.linalg.norm(to)
        pref = (to * min(1.0, d / dt) / max(d, 1e-12))[None]
        vel = orca_step(
            pos,
            vel,
            pref,
            0.8,
            1.0,
            skid(0.0)[None],
            dt_s=dt,
            people_positions=person[None],
            people_velocities=v_person[None],
            people_radii=radius,
        ).velocities
        pos = pos + vel * dt
        person = person + v_person * dt
        gaps.append(rect_disc_gap((pos[0] + skid(0.0))[None], person[None], np.array([radius]))[0])
    assert min(gaps) > 0
    assert np.linalg.norm(goal - pos[0]) < 0.05


def test_wall_is_a_hard_obstacle_and_is_never_crossed():
    walls = prepare_obstacles(
        [np.array([[3.0, -5.0], [3.0, 5.0]]), np.array([[0.0, 2.0], [1.0, 2.0], [0.5, 3.0]])]
    )
    dt, pos, vel = 0.1, np.array([[0.0, 0.0], [0.0, 4.0]]), np.zeros((2, 2))
    pref = np.array([[1.0, 0.2], [0.0, -1.0]])  # into the wall / into the triangle
    shapes = np.stack([skid(0.0), skid(-math.pi / 2)])
    for _ in range(80):
        res = orca_step(pos, vel, pref, 1.0, 1.0, shapes, dt_s=dt, obstacles=walls)
        assert res.halfplanes.n_hard >= 1
        vel = res.velocities
        pos = pos + vel * dt
        corners = pos[:, None] + shapes
        assert corners[0, :, 0].max() <= 3.0 + 1e-9
        gap_tri = convex_gap(corners[1:], np.array([[[0, 2], [1, 2], [0.5, 3], [0.5, 3]]], float))
        assert gap_tri[0] > -1e-9
    # The first robot ends up sliding along the wall (moving in +y), not stuck.
    assert corners[0, :, 0].max() > 2.8 and vel[0, 1] > 0.1


def test_a_wall_of_many_small_pieces_is_never_entered():
    """A wall of 24 small cells: ORCA sees the nearest few, and even with none of them as
    constraints (``max_obstacles=0``) the safety filter stops the robot at the wall."""
    cells = [
        np.array([[x, 2.0], [x + 0.25, 2.0], [x + 0.25, 2.25], [x, 2.25]])
        for x in np.arange(-3.0, 3.0, 0.25)
    ]
    walls = prepare_obstacles(cells)
    shape = skid(math.pi / 2)[None]
    for max_obstacles in (2, 0):
        dt, pos, vel = 0.25, np.array([[0.0, 0.0]]), np.zeros((1, 2))
        params = OrcaParams(max_obstacles=max_obstacles)
        for _ in range(40):
            pref = np.array([[0.3, 1.0]])  # obliquely into the wall
            vel = orca_step(
                pos, vel, pref, 1.0, 1.0, shape, dt_s=dt, obstacles=walls, params=params
            ).velocities
            pos = pos + vel * dt
            assert (pos[0] + shape[0])[:, 1].max() <= 2.0 + 1e-9
        assert (pos[0] + shape[0])[:, 1].max() > 1.8  # it did come close


def test_immobile_robot_gets_zero_and_the_other_avoids_it_alone():
    pos = np.array([[0.0, 0.0], [2.5, 0.0]])
    vel = np.array([[1.0, 0.0], [0.3, 0.0]])
    pref = np.array([[1.0, 0.0], [0.5, 0.0]])
    shapes = np.stack([skid(0.0), skid(0.0)])
    res = orca_step(pos, vel, pref, 1.0, [1.0, 1.0], shapes, dt_s=0.1, immobile=[False, True])
    np.testing.assert_array_equal(res.velocities[1], [0.0, 0.0])
    # The mover's choice alone keeps it off the stopped skid for the whole horizon.
    assert (
        swept_gap(shapes[0], pos[0], res.velocities[0], shapes[1], pos[1], np.zeros(2), 2.0) > -1e-6
    )


def test_decision_does_not_depend_on_robot_order():
    rng = np.random.default_rng(7)
    n = 30
    pos = rng.uniform(-8, 8, (n, 2))
    shapes = np.stack([skid(y) for y in rng.uniform(-math.pi, math.pi, n)])
    vel, pref = rng.uniform(-1, 1, (n, 2)), rng.uniform(-1, 1, (n, 2))
    prio = rng.choice([0.0, 1.0, 5.0], n)
    walls = prepare_obstacles([np.array([[-10.0, 9.0], [10.0, 9.0]])])
    people = dict(
        people_positions=rng.uniform(-8, 8, (4, 2)),
        people_velocities=rng.uniform(-1, 1, (4, 2)),
        people_radii=0.3,
    )
    kw = dict(dt_s=0.1, obstacles=walls, **people)
    base = orca_step(pos, vel, pref, 1.0, prio, shapes, **kw)
    # Dense enough that the fallback and the filter are exercised too.
    assert base.infeasible.sum() >= 3
    for seed in range(3):
        perm = np.random.default_rng(seed).permutation(n)
        res = orca_step(pos[perm], vel[perm], pref[perm], 1.0, prio[perm], shapes[perm], **kw)
        # Bit for bit: every pair is built from the same side whatever the order.
        np.testing.assert_array_equal(res.velocities, base.velocities[perm])
        np.testing.assert_array_equal(res.slowed, base.slowed[perm])
        np.testing.assert_array_equal(res.infeasible, base.infeasible[perm])


def test_circle_of_eight_skids_all_arrive_without_overlap():
    n, dt, radius = 8, 0.25, 5.0
    ang = 2 * math.pi * np.arange(n) / n
    pos = radius * np.stack([np.cos(ang), np.sin(ang)], -1)
    goal = -pos
    shapes = np.stack([skid(a + math.pi) for a in ang])
    vel = np.zeros_like(pos)
    ii, jj = np.triu_indices(n, 1)
    # The circle is perfectly symmetric and jams at the centre without a tie-break (as in
    # RVO2's examples): keep right a little and add seeded noise to the preference.
    rng = np.random.default_rng(0)
    keep_right = rotation(-0.2)
    arrived_at = None
    for step in range(300):
        to = goal - pos
        d = np.linalg.norm(to, axis=1)
        if np.all(d < 0.05):
            arrived_at = step
            break
        pref = to * (np.minimum(1.0, d / dt) / np.maximum(d, 1e-12))[:, None]
        pref = pref @ keep_right.T + rng.normal(0.0, 0.02, pref.shape)
        vel = orca_step(pos, vel, pref, 1.0, 1.0, shapes, dt_s=dt).velocities
        pos = pos + vel * dt
        corners = pos[:, None] + shapes
        assert convex_gap(corners[ii], corners[jj]).min() > -1e-9
    # All eight arrive (free flight would take 40 steps).
    assert arrived_at is not None and arrived_at < 300


# --------------------------------------------------------------------------------------------
# non-holonomic conversion


def unicycle_arc(pose, v, w, t):
    """Exact pose after driving ``(v, w)`` for time ``t``."""
    x, y, th = pose
    if abs(w) < 1e-12:
        return np.array([x + v * t * math.cos(th), y + v * t * math.sin(th), th])
    return np.array(
        [
            x + v / w * (math.sin(th + w * t) - math.sin(th)),
            y - v / w * (math.cos(th + w * t) - math.cos(th)),
            th + w * t,
        ]
    )


@FAST
@given(
    st.floats(-math.pi, math.pi),
    st.tuples(st.floats(-5, 5), st.floats(-5, 5)),
    st.floats(0.1, 2.0),
    st.floats(0.2, 3.0),
    st.floats(0.1, 1.0),
)
def test_unicycle_conversion_respects_limits_and_inverts_exactly(yaw, u, v_max, w_max, offset):
    pose = np.array([[1.0, -2.0, yaw]])
    v, w = holonomic_to_unicycle(pose, np.array([u]), offset_m=offset, v_max=v_max, omega_max=w_max)
    assert abs(v[0]) <= v_max + 1e-12 and abs(w[0]) <= w_max + 1e-12
    back = unicycle_to_holonomic(pose, v, w, offset_m=offset)[0]
    # Scaled (never turned) when the limits bite; exact below the holonomic speed limit.
    assert back[0] * u[1] - back[1] * u[0] == pytest.approx(0.0, abs=1e-9)
    if np.hypot(*u) <= holonomic_speed_limit(v_max, w_max, offset):
        np.testing.assert_allclose(back, u, atol=1e-12)


def test_tracking_error_stays_within_the_stated_bound_along_a_trajectory():
    v_max, w_max, offset, dt = 1.0, 1.2, 0.4, 0.2
    u_max = float(holonomic_speed_limit(v_max, w_max, offset))
    reach = float(effective_reach(SKID.corners_body(), offset)[0])
    bound = float(tracking_error_bound(u_max, w_max, reach, dt))
    pose = np.array([0.0, 0.0, 0.3])
    corners_local = SKID.corners_body() - [offset, 0.0]
    worst = 0.0
    for k in range(300):
        # A figure-eight for the effective centre at the speed limit: sharp turns included.
        s = 0.35 * k
        u = u_max * np.array([math.cos(s), math.sin(2 * s)])
        u *= min(1.0, u_max / np.linalg.norm(u))
        v, w = holonomic_to_unicycle(
            pose[None], u[None], offset_m=offset, v_max=v_max, omega_max=w_max
        )
        assert abs(v[0]) <= v_max + 1e-12 and abs(w[0]) <= w_max + 1e-12
        centre0 = pose[:2] + offset * np.array([math.cos(pose[2]), math.sin(pose[2])])
        start = centre0 + corners_local @ rotation(pose[2]).T
        for t in np.linspace(0.0, dt, 9)[1:]:
            p = unicycle_arc(pose, v[0], w[0], t)
            centre = p[:2] + offset * np.array([math.cos(p[2]), math.sin(p[2])])
            real = centre + corners_local @ rotation(p[2]).T
            worst = max(worst, float(np.linalg.norm(real - (start + u * t), axis=1).max()))
        pose = unicycle_arc(pose, v[0], w[0], dt)
    assert worst <= bound + 1e-12
    assert worst > 0.5 * bound  # the bound is not vacuous


def test_skid_shapes_and_inflation():
    poses = np.array([[1.0, 2.0, math.pi / 2]])
    centres, shapes = skid_shapes(poses, SKID.corners_body(), offset_m=0.25, margin_m=0.1)
    np.testing.assert_allclose(centres, [[1.0, 2.25]])
    # Facing +y: length along y, enlarged by 0.1 on every side.
    np.testing.assert_allclose(shapes[0].min(0), [-0.475, -0.975], atol=1e-12)
    np.testing.assert_allclose(shapes[0].max(0), [0.475, 0.475], atol=1e-12)
    tri = np.array([[[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]])
    big = inflate_convex(tri, 0.1)[0]
    # Every edge moved out by exactly 0.1.
    for k in range(3):
        e = big[(k + 1) % 3] - big[k]
        n = np.array([e[1], -e[0]]) / np.linalg.norm(e)
        assert float(n @ (big[k] - tri[0, k])) == pytest.approx(0.1)


# --------------------------------------------------------------------------------------------
# bad input


def test_bad_input_is_refused_with_the_field_named():
    pos, vel = np.zeros((2, 2)) + [[0, 0], [3, 0]], np.zeros((2, 2))
    shapes = np.stack([skid(0.0), skid(0.0)])
    with pytest.raises(ValueError, match=r"shapes\[1\]: not a convex polygon"):
        orca_step(pos, vel, vel, 1.0, 1.0, np.stack([skid(0.0), skid(0.0)[::-1]]), dt_s=0.1)
    with pytest.raises(ValueError, match="priorities must be >= 0"):
        orca_step(pos, vel, vel, 1.0, [1.0, -1.0], shapes, dt_s=0.1)
    with pytest.raises(ValueError, match=r"velocities: expected shape \(2, 2\)"):
        orca_step(pos, np.zeros((3, 2)), vel, 1.0, 1.0, shapes, dt_s=0.1)
    with pytest.raises(ValueError, match="dt_s must be"):
        orca_step(pos, vel, vel, 1.0, 1.0, shapes, dt_s=0.0)
    with pytest.raises(ValueError, match="positions: values must be finite"):
        orca_step(pos + np.nan, vel, vel, 1.0, 1.0, shapes, dt_s=0.1)
    with pytest.raises(ValueError, match="people_radii: required"):
        orca_step(pos, vel, vel, 1.0, 1.0, shapes, dt_s=0.1, people_positions=np.zeros((1, 2)))
    with pytest.raises(ValueError, match=r"OrcaParams.time_horizon_s must be"):
        OrcaParams(time_horizon_s=-1.0)
    with pytest.raises(ValueError, match=r"OrcaParams.min_share must lie in \[0, 0.5\]"):
        OrcaParams(min_share=0.7)
    with pytest.raises(ValueError, match=r"obstacles\[0\]: needs at least 2 points"):
        prepare_obstacles([np.array([[0.0, 0.0]])])
    with pytest.raises(ValueError, match=r"obstacles\[1\]: not a convex polygon"):
        prepare_obstacles(
            [np.array([[0, 0], [1, 0]]), np.array([[0, 0], [2, 0], [1, 0.2], [1, 2]])]
        )
    with pytest.raises(ValueError, match="offset_m must be > 0"):
        holonomic_to_unicycle(
            np.zeros((1, 3)), np.zeros((1, 2)), offset_m=0.0, v_max=1, omega_max=1
        )
