"""The whole-fleet forms of the tick (issue 19) give the same numbers as the per-skid and
numpy forms they replace: the compiled polygon tests and rollouts, and the simulator link's
batched reports and commands."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from helpers import make_world

from swarmpark.control.nav.monitor import rollout
from swarmpark.core.geometry import (
    convex_distance,
    convex_distance_numpy,
    convex_overlap,
    convex_overlap_numpy,
    integrate_unicycle,
)
from swarmpark.links.base import (
    Arrivals,
    CommandBatch,
    Inbox,
    Odometry,
    PoseReport,
    ReportBatch,
    Scan,
    VelocityCommand,
)
from swarmpark.sim.link import SimLink
from swarmpark.supervisor.core import Supervisor


def _polygons(rng, m: int, k: int) -> np.ndarray:
    """``m`` random convex polygons of ``k`` vertices (counter-clockwise)."""
    centre = rng.uniform(-3, 3, (m, 1, 2))
    ang = np.sort(rng.uniform(0, 2 * np.pi, (m, k)), axis=1)
    r = rng.uniform(0.2, 1.5, (m, k))
    return centre + np.stack([r * np.cos(ang), r * np.sin(ang)], -1)


@pytest.mark.parametrize("k, l", [(4, 4), (4, 3), (3, 4)])
def test_compiled_polygon_tests_equal_the_numpy_forms_bit_for_bit(k, l):
    rng = np.random.default_rng(k * 10 + l)
    a, b = _polygons(rng, 20000, k), _polygons(rng, 20000, l)
    b[::7, -1] = b[::7, -2]  # padded polygons: a zero-length edge
    a[::11] = np.round(a[::11], 1)  # coordinates on a grid: ties between projections
    depth = convex_overlap(a, b)
    assert np.array_equal(depth, convex_overlap_numpy(a, b))
    assert (depth > 0).any() and (depth <= 0).any()  # both outcomes are exercised
    apart = depth <= 0
    assert np.array_equal(
        convex_distance(a[apart], b[apart]), convex_distance_numpy(a[apart], b[apart])
    )
    # One polygon against many is broadcast.
    one = convex_overlap_numpy(np.repeat(a[:1], 50, axis=0), b[:50])
    assert np.array_equal(convex_overlap(a[:1], b[:50]), one)


def _rollout_numpy(view, rows, v_cmd, w_cmd, times):
    """The monitor's rollout as one numpy call per sub-step (the form before the kernel)."""
    n_sub = max(1, int(round(times[-1] / view.dt)))
    sub_dt = times[-1] / n_sub
    record = np.clip(np.round(times / sub_dt), 1, n_sub).astype(int)
    v, w = view.vel[rows, 0], view.vel[rows, 1]
    dv = view.max_accel[rows] * sub_dt
    dw = np.inf if view.max_yaw_accel is None else view.max_yaw_accel[rows] * sub_dt
    now = view.poses[rows]
    pose = np.empty((len(rows), len(times), 3))
    for step in range(1, n_sub + 1):
        v = v + np.minimum(np.maximum(v_cmd - v, -dv), dv)
        w = w + np.minimum(np.maximum(w_cmd - w, -dw), dw)
        now = integrate_unicycle(now, v, w, sub_dt)
        at = np.flatnonzero(record == step)
        if len(at):
            pose[:, at] = now[:, None]
    return pose


@pytest.mark.parametrize("yaw_accel", [True, False])
def test_compiled_rollout_equals_the_numpy_loop(yaw_accel):
    rng = np.random.default_rng(3)
    n = 400
    poses = np.column_stack([rng.uniform(-50, 50, (n, 2)), rng.uniform(-np.pi, np.pi, n)])
    vel = np.column_stack([rng.uniform(-0.6, 0.6, n), rng.uniform(-1.2, 1.2, n)])
    vel[::5, 1] = 0.0  # straight runs
    # What a rollout reads of the control view.
    view = SimpleNamespace(
        dt=0.05,
        poses=poses,
        vel=vel,
        max_accel=rng.uniform(0.3, 1.0, n),
        max_yaw_accel=rng.uniform(1.0, 3.0, n) if yaw_accel else None,
    )
    rows = rng.integers(0, n, 600)
    v_cmd, w_cmd = rng.uniform(-0.6, 0.6, 600), rng.uniform(-1.2, 1.2, 600)
    w_cmd[::3] = 0.0
    times = np.linspace(0.2, 1.0, 5)
    got = rollout(view, rows, v_cmd, w_cmd, times)
    assert got.shape == (600, 5, 3)
    assert np.array_equal(got, _rollout_numpy(view, rows, v_cmd, w_cmd, times))


def _messages_of(batch: ReportBatch) -> list:
    return batch.messages()


def _inbox_state(box: Inbox) -> tuple:
    return (
        box.odom.tolist(),
        box.vel.tolist(),
        box.odom_stamp.tolist(),
        box.pose.tolist(),
        box.pose_stamp.tolist(),
        box.scan_stamp.tolist(),
        [None if s is None else s.tolist() for s in box.scans],
        box.last_seen.tolist(),
        box.take_scans().tolist(),
        box.ignored,
    )


def test_a_report_batch_is_absorbed_as_its_messages_one_by_one():
    ids = ("a", "b", "c")
    rng = np.random.default_rng(0)

    def batch(t, seq0, who=ids):
        n = len(who)
        return ReportBatch(
            tuple(who),
            t,
            rng.normal(size=(n, 3)),
            rng.normal(size=(n, 2)),
            np.arange(seq0, seq0 + n),
            pose=rng.normal(size=(n, 3)),
            ranges=rng.normal(size=(n, 4)),
        )

    stream = [
        batch(1.0, 10),
        Odometry("b", 1.0, np.ones(3), np.ones(2), 20),  # same stamp, later counter: newer
        batch(0.5, 30),  # late: all stale
        batch(1.0, 5, ("c", "x", "a")),  # an unknown robot; c and a stale by counter
        PoseReport("a", 2.0, np.zeros(3), 1),
        batch(2.0, 40, ("a", "b")),  # newer for a and b (a's pose by the counter)
        Scan("c", 2.5, np.zeros(4), 2),
    ]
    whole, single = Inbox(ids), Inbox(ids)
    whole.absorb(Arrivals(stream))
    for m in stream:
        single.absorb(_messages_of(m) if isinstance(m, ReportBatch) else [m])
    assert _inbox_state(whole) == _inbox_state(single)
    assert whole.ignored == 3 * 3 + 3 * 3  # the late batch; x, c and a in the fourth
    # Read as a sequence, arrivals are the single messages in order.
    arr = Arrivals(stream[:2])
    assert len(arr) == 3 * 3 + 1
    assert [type(m).__name__ for m in arr[:3]] == ["Odometry", "PoseReport", "Scan"]
    assert arr[-1] is stream[1]


def test_a_command_batch_reads_as_velocity_commands():
    cmds = CommandBatch(("a", "b", "c"), np.array([2, 0]), 1.5, np.array([[0.1, -0.2], [0.3, 0]]))
    assert list(cmds) == [
        VelocityCommand("c", 1.5, 0.1, -0.2),
        VelocityCommand("a", 1.5, 0.3, 0.0),
    ]
    assert len(cmds) == 2 and cmds[1] == VelocityCommand("a", 1.5, 0.3, 0.0)


def _three():
    return make_world(
        robots=[
            {"id": "a", "pose": [2.0, 2.0, 0.0]},
            {"id": "b", "pose": [2.0, 4.0, 0.0]},
            {"id": "c", "pose": [5.0, 3.0, 0.5]},
        ]
    )


def test_the_sim_link_takes_a_command_batch_as_the_commands_one_by_one():
    world = _three()
    whole, single = SimLink(world), SimLink(world)
    for link in (whole, single):
        link.connect()
    rows = np.array([0, 2])
    for t, cmd in ((0.0, [[0.3, 0.1], [0.2, -0.4]]), (-1.0, [[0.9, 0.9], [0.9, 0.9]])):
        batch = CommandBatch(whole.ids, rows, t, np.array(cmd))
        whole.send(batch)
        single.send(list(batch))  # the older second batch is ignored by both
    assert np.array_equal(whole._cmd, single._cmd)
    assert np.array_equal(whole._cmd_t, single._cmd_t)
    assert whole._cmd[0].tolist() == [0.3, 0.1] and whole._cmd[1].tolist() == [0.0, 0.0]


def test_the_sim_link_reports_each_robot_once_per_step_in_one_batch():
    world = _three()
    link = SimLink(world)
    link.connect()
    first = link.receive()
    assert isinstance(first, Arrivals)
    kinds = sorted(type(m).__name__ for m in first)
    # Odometry and a pose per robot, their first status, the people tracker.
    assert kinds == ["Odometry"] * 3 + ["PoseReport"] * 3 + ["Status"] * 3 + ["TrackedPeople"]
    sup = Supervisor(world, link=SimLink(world))
    for _ in range(3):
        sup.tick()
    assert np.array_equal(sup.inbox.odom, sup.sim.poses)
    assert np.array_equal(sup.inbox.pose, sup.sim.poses)
    assert np.all(sup.inbox.odom_stamp == sup.t) and sup.inbox.ignored == 0


def test_keep_right_facing_pairs_equal_the_per_skid_products():
    from scipy.spatial import cKDTree

    from swarmpark.control.nav.keep_right import _facing

    rng = np.random.default_rng(5)
    n = 300
    centres = np.round(rng.uniform(0, 30, (n, 2)), 1)  # on a grid: exact zeros happen
    u_pref = rng.normal(size=(n, 2))
    u_pref[::4] = np.round(u_pref[::4])  # axis-aligned velocities, some zero
    u_pref[::9] = 0.0
    cruising = np.arange(0, n, 2)
    others = np.arange(n)
    near = cKDTree(centres[others]).query_ball_point(centres[cruising], 3.0)
    lens = np.array([len(c) for c in near])
    kk = np.repeat(np.arange(len(cruising)), lens)
    j = others[np.concatenate([np.asarray(c, int) for c in near])]
    i = cruising[kk]
    kk, i, j = kk[j != i], i[j != i], j[j != i]
    ahead, oncoming = _facing(centres, u_pref, kk, i, j, cruising, others, near)
    want_a, want_o = [], []
    for ic, cand in zip(cruising, near, strict=True):  # the loop it replaces
        jk = others[cand]
        jk = jk[jk != ic]
        want_a += ((centres[jk] - centres[ic]) @ u_pref[ic] > 0).tolist()
        want_o += (u_pref[jk] @ u_pref[ic] < 0).tolist()
    assert ahead.tolist() == want_a and oncoming.tolist() == want_o
    assert ahead.any() and oncoming.any() and not ahead.all()


def test_envelope_pairs_are_the_search_tree_pairs():
    import shapely

    from swarmpark.core import geometry

    rng = np.random.default_rng(7)
    for n_tree in (5, geometry.BOX_SCAN_MAX + 50):
        t_lo = np.round(rng.uniform(0, 20, (n_tree, 2)), 1)
        t_hi = t_lo + np.round(rng.uniform(0, 3, (n_tree, 2)), 1)
        tree = shapely.STRtree(shapely.box(t_lo[:, 0], t_lo[:, 1], t_hi[:, 0], t_hi[:, 1]))
        lo = np.round(rng.uniform(0, 20, (400, 2)), 1)
        hi = lo + np.round(rng.uniform(0, 2, (400, 2)), 1)
        hi[::10] = lo[::10]  # points; boxes touching at an edge are found too
        want = tree.query(shapely.box(lo[:, 0], lo[:, 1], hi[:, 0], hi[:, 1]))
        got = geometry.envelope_pairs(lo, hi, t_lo, t_hi, tree)
        assert sorted(zip(*got, strict=True)) == sorted(zip(*want, strict=True))
        assert len(got[0]) > 0


def test_compiled_rollout_corners_equal_the_numpy_transform():
    from swarmpark.control.nav.kernels import rollout_corners
    from swarmpark.core.geometry import Footprint, footprint_corners

    rng = np.random.default_rng(11)
    body = np.stack(
        [Footprint(rng.uniform(0.8, 2), rng.uniform(0.5, 1)).corners_body() for _ in range(30)]
    )
    poses = np.column_stack([rng.uniform(-80, 80, (600, 2)), rng.uniform(-7, 7, 600)])
    want = footprint_corners(poses, np.repeat(body, 20, axis=0))
    assert np.array_equal(rollout_corners(poses, body, 20), want)


def test_joint_check_pairs_equal_the_exact_test_at_every_time():
    from swarmpark.control.nav.kernels import pairs_touching
    from swarmpark.core.geometry import Footprint, footprint_corners

    rng = np.random.default_rng(13)
    n, T = 120, 5
    body = Footprint(1.2, 0.8).corners_body()
    poses = np.column_stack([rng.uniform(0, 12, (n * T, 2)), rng.uniform(-np.pi, np.pi, n * T)])
    corners = footprint_corners(poses, np.broadcast_to(body, (n * T, 4, 2))).reshape(n, T, 4, 2)
    corners[0] = body + [3.0, 3.0]  # heading along x
    corners[2] = body + [8.0, 8.0]
    corners[1] = corners[0] + [1.2, 0.0]  # edge to edge: touching, not overlapping
    corners[3] = corners[2] + [1.2 - 1e-7, 0.0]  # overlapping by 0.1 um
    a, b = np.triu_indices(n, 1)
    pairs = np.column_stack([a, b]).astype(np.int64)
    got = pairs_touching(pairs, np.ascontiguousarray(corners), 1e-9)
    depth = convex_overlap_numpy(
        corners[np.repeat(a, T), np.tile(np.arange(T), len(a))],
        corners[np.repeat(b, T), np.tile(np.arange(T), len(a))],
    ).reshape(len(a), T)
    assert got.tolist() == (depth > 1e-9).any(axis=1).tolist()
    assert got.any() and not got.all()
    assert not got[0] and got[np.flatnonzero((a == 2) & (b == 3))[0]]


def test_compiled_outline_and_skid_tests_equal_their_numpy_forms():
    from swarmpark.control.nav.kernels import hits_against_skids, outline_pairs
    from swarmpark.core.geometry import Footprint, footprint_corners

    rng = np.random.default_rng(17)
    # Outline points within reach: per (row, skid) pair, the skid's run of points.
    counts = rng.integers(3, 9, 40)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    pts = rng.uniform(0, 10, (int(counts.sum()), 2))
    here = rng.uniform(0, 10, (25, 2))
    r = rng.uniform(0.5, 3.0, 25)
    rb = np.repeat(np.arange(25), 6)
    sk = rng.integers(0, 40, len(rb))
    rob, pt = outline_pairs(rb, sk, starts, counts, pts, here, r)
    want_rob = np.repeat(rb, counts[sk])
    want_pt = np.concatenate([np.arange(starts[s], starts[s] + counts[s]) for s in sk])
    d = pts[want_pt] - here[want_rob]
    keep = d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] <= r[want_rob] * r[want_rob]
    assert rob.tolist() == want_rob[keep].tolist() and pt.tolist() == want_pt[keep].tolist()
    # Footprints of rollouts (groups of 6) against standing skids.
    body = Footprint(1.2, 0.8).corners_body()
    poses = np.column_stack([rng.uniform(0, 8, (60, 2)), rng.uniform(-np.pi, np.pi, 60)])
    corners = footprint_corners(poses, np.broadcast_to(body, (60, 4, 2)))
    centres = corners.mean(axis=1)
    stand = np.column_stack([rng.uniform(0, 8, (15, 2)), rng.uniform(-np.pi, np.pi, 15)])
    others = footprint_corners(stand, np.broadcast_to(body, (15, 4, 2)))
    other_c = others.mean(axis=1)
    ra, rbs = np.repeat(np.arange(10), 15), np.tile(np.arange(15), 10)
    bad = np.zeros(60, bool)
    q, b = hits_against_skids(ra, rbs, centres, other_c, corners, others, 1.5, 6, 1e-9, bad)
    qa = (ra[:, None] * 6 + np.arange(6)).ravel()
    qb = np.repeat(rbs, 6)
    near = np.linalg.norm(centres[qa] - other_c[qb], axis=1) <= 1.5
    qa, qb = qa[near], qb[near]
    hit = convex_overlap_numpy(corners[qa], others[qb]) > 1e-9
    assert q.tolist() == qa[hit].tolist() and b.tolist() == qb[hit].tolist()
    assert bad.tolist() == np.isin(np.arange(60), qa[hit]).tolist() and hit.any()
