"""Formation velocity planning (Liu, Sun & Zhu 2010): constraints, baselines, online
modification for a moving obstacle, reference sampling and unicycle tracking."""

from __future__ import annotations

import math

import numpy as np
import pytest

from swarmpark.control.formation import (
    FormationProblem,
    OnlineAdjuster,
    TrackingGains,
    adjust_for_obstacle,
    blend_offsets,
    formation_error,
    formation_metrics,
    nominal_profile,
    pair_errors,
    plan_velocities,
    predict_obstacle,
    sample_reference,
    track_unicycle,
)
from swarmpark.control.formation.paper import (
    experiment_problem,
    paper_problem,
    run_obstacle_experiment,
)
from swarmpark.control.formation.paper_report import run_paper
from swarmpark.core.paths import SplinePath

TOL_V = 1e-9  # speeds are clipped to their bounds after the solve
TOL_CON = 1e-6  # IPOPT's constraint tolerance is 1e-8 on the scaled problem


@pytest.fixture(scope="module")
def paper():
    return paper_problem()


@pytest.fixture(scope="module")
def paper_plans(paper):
    return {m: plan_velocities(paper, m) for m in ("formation", "no_formation", "leader_follower")}


@pytest.fixture(scope="module")
def experiment():
    return run_obstacle_experiment()


def straight(a, b) -> SplinePath:
    return SplinePath.through([a, b])


def two_abreast(**kw) -> FormationProblem:
    """Two robots 0.5 m apart on parallel 1 m lines; robot 1 is on robot 0's left."""
    return FormationProblem(
        paths=(straight([0, 0], [1, 0]), straight([0, 0.5], [1, 0.5])),
        edges=[[0, 1]],
        offsets_m=[[0.0, 0.5]],
        **{"M": 12, "dt_s": 1.0, "v_max_mps": 0.12, "a_max_mps2": 0.12, "d_safe_m": 0.2, **kw},
    )


def assert_constraints(plan, *, check_safe: bool = True) -> None:
    """Eqs. (7), (11)-(15) on the plan instants, recomputed from the paths."""
    pb = plan.problem
    v, s, dt = plan.v_mps, plan.s_m, pb.dt_s
    assert np.all(v >= -TOL_V) and np.all(v <= pb.v_max_mps + TOL_V)  # (12)
    assert np.all(np.abs(np.diff(v, axis=1)) <= pb.a_max_mps2 * dt + TOL_CON)  # (11)
    assert np.all(v[:, 0] == 0) and np.all(v[:, -1] == 0)  # (13)
    np.testing.assert_allclose(s[:, 0], 0.0, atol=1e-12)  # (14)
    np.testing.assert_allclose(s[:, -1], pb.lengths_m, atol=1e-9)
    trap = s[:, 1:] - s[:, :-1] - 0.5 * dt * (v[:, 1:] + v[:, :-1])  # (7)
    np.testing.assert_allclose(trap, 0.0, atol=TOL_CON)
    assert np.all(np.diff(s, axis=1) >= -1e-9)  # only forward along the paths
    xy = np.stack([p.position(s[i]) for i, p in enumerate(pb.paths)])  # (R, T, 2)
    np.testing.assert_allclose(plan.poses[..., :2], xy, atol=1e-12)
    if check_safe:
        iu, ju = np.triu_indices(pb.n_robots, 1)
        dist = np.linalg.norm(xy[iu] - xy[ju], axis=-1)  # every pair, every instant (15)
        assert dist.min() >= pb.d_safe_m - TOL_CON


# --------------------------------------------------------------------------- building blocks
def test_nominal_profile_is_feasible_and_exact():
    v, s = nominal_profile(1.2, 15, 1.0, 0.12, 0.12)
    assert s[-1] == pytest.approx(1.2, abs=1e-12)
    assert v[0] == v[-1] == 0 and v.max() <= 0.12 + 1e-15
    np.testing.assert_allclose(np.diff(s), 0.5 * (v[1:] + v[:-1]), atol=1e-12)
    # The longest path M = 15 allows: 0.06 + 13 * 0.12 + 0.06 m.
    v, s = nominal_profile(1.68, 15, 1.0, 0.12, 0.12)
    np.testing.assert_allclose(v, [0] + [0.12] * 14 + [0], atol=1e-12)
    with pytest.raises(ValueError, match=r"path length 1.7000 m cannot be covered .*1.6800 m"):
        nominal_profile(1.7, 15, 1.0, 0.12, 0.12)


def test_blend_offsets_hold_and_smoothstep():
    at = np.array([[0.0, 0.2, 0.6, 1.0]])
    off = np.array([[[0, 1], [0, 1], [2, 3], [2, 3]]], dtype=float)
    sig = np.array([[0.0, 0.1, 0.2, 0.4, 0.6, 0.8, 1.0]])
    out = blend_offsets(at, off, sig)[0]
    np.testing.assert_allclose(out, [[0, 1], [0, 1], [0, 1], [1, 2], [2, 3], [2, 3], [2, 3]])


def test_pair_error_uses_robot_i_frame():
    # Robot 0 faces +y; "1 m ahead of robot 0" is world (0, 1). Robot 1 is at (0.1, 1).
    pb = two_abreast()
    pb = FormationProblem(paths=pb.paths, edges=[[0, 1]], offsets_m=[[1.0, 0.0]])
    poses = np.array([[0.0, 0.0, np.pi / 2], [0.1, 1.0, 0.0]])
    err = pair_errors(pb, poses, np.zeros(2))
    np.testing.assert_allclose(err, [[0.1, 0.0]], atol=1e-12)
    fe = formation_metrics(pb, [0.0, 1.0], np.stack([poses, poses]), np.zeros((2, 2)))
    assert fe.q_e_m2 == pytest.approx(2 * 0.01)
    assert fe.integral_m2s == pytest.approx(0.01)
    assert fe.max_pair_error_m == pytest.approx(0.1)


@pytest.mark.parametrize(
    ("kw", "match"),
    [
        ({"edges": [[0, 2]]}, r"edges\[0\]: \(0, 2\) must be two different robots in 0..1"),
        ({"edges": [[1, 1]]}, r"edges\[0\]: \(1, 1\)"),
        ({"offsets_m": [[0.0, 0.5, 1.0]]}, r"offsets_m: expected shape \(1, K, 2\)"),
        ({"offsets_m": [[[0, 0], [1, 1]]], "offset_at": [0.5, 0.5]}, "strictly increasing"),
        ({"offsets_m": [[[0, 0], [1, 1]]], "offset_at": [0.0, 1.5]}, r"lie in \[0, 1\]"),
        ({"M": 1}, r"M: must be an integer >= 2 \(got 1\)"),
        ({"v_max_mps": -0.1}, r"v_max_mps: must be finite and > 0 \(got -0.1\)"),
        ({"d_safe_m": float("nan")}, "d_safe_m: must be finite"),
        ({"leader": 5}, r"leader: must be a robot index in 0..1 \(got 5\)"),
    ],
)
def test_problem_validation_names_field_and_value(kw, match):
    base = {"paths": two_abreast().paths, "edges": [[0, 1]], "offsets_m": [[0.0, 0.5]]}
    with pytest.raises(ValueError, match=match):
        FormationProblem(**{**base, **kw})


def test_infeasible_problems_are_refused_with_reasons():
    with pytest.raises(ValueError, match="method: must be one of"):
        plan_velocities(two_abreast(), "fastest")
    with pytest.raises(ValueError, match=r"cannot be covered in M\*dt = 5 s"):
        plan_velocities(two_abreast(M=5))
    with pytest.raises(ValueError, match=r"robots 0 and 1 are 0.5000 m apart at their start"):
        plan_velocities(two_abreast(d_safe_m=0.6))
    star = FormationProblem(
        paths=(*two_abreast().paths, straight([0, -0.5], [1, -0.5])),
        edges=[[0, 1], [2, 1]],
        offsets_m=[[0.0, 0.5], [0.0, 1.0]],
    )
    with pytest.raises(ValueError, match=r"edges\[1\]: \(2, 1\) gives robot 1 a second leader"):
        plan_velocities(star, "leader_follower")


# --------------------------------------------------------------------------- optimization
def test_parallel_pair_keeps_formation_exactly():
    plan = plan_velocities(two_abreast())
    assert plan.success, plan.status
    assert_constraints(plan)
    np.testing.assert_allclose(plan.v_mps[0], plan.v_mps[1], atol=1e-6)
    assert plan.max_pair_error_m < 1e-5


def test_crossing_paths_are_separated_in_time():
    # An X: both robots would meet at the origin if each rushed to its goal.
    pb = FormationProblem(
        paths=(straight([-1, 0], [1, 0]), straight([0, -1], [0, 1])),
        edges=np.zeros((0, 2), dtype=int),
        offsets_m=np.zeros((0, 2)),
        M=25,
        d_safe_m=0.3,
    )
    for method in ("no_formation", "formation"):
        plan = plan_velocities(pb, method)
        assert plan.success, plan.status
        assert_constraints(plan)
        assert plan.min_pair_distance_m >= 0.3 - TOL_CON


@pytest.mark.parametrize("method", ["formation", "no_formation"])
def test_paper_plans_satisfy_all_constraints(paper_plans, method):
    plan = paper_plans[method]
    assert plan.success, plan.status
    assert plan.t_s.size == 16  # M = 15
    assert_constraints(plan)


def test_leader_follower_obeys_speed_limits_and_arrives(paper_plans):
    plan = paper_plans["leader_follower"]
    assert plan.success, plan.status
    # Followers do not coordinate, so (15) is not guaranteed; everything else holds.
    assert_constraints(plan, check_safe=False)
    np.testing.assert_allclose(
        plan.v_mps[0, :16],
        nominal_profile(plan.problem.lengths_m[0], 15, 1.0, 0.12, 0.12)[0],
        atol=1e-12,
    )


def test_formation_method_has_lowest_error_on_the_paper_problem(paper_plans):
    q = {m: p.q_e_m2 for m, p in paper_plans.items()}
    assert q["formation"] < q["leader_follower"] < q["no_formation"]  # the paper's ranking
    assert q["formation"] < 0.01 * q["leader_follower"]
    dense = {
        m: formation_error(p, np.arange(0.0, p.duration_s + 1e-9, 0.05)).integral_m2s
        for m, p in paper_plans.items()
    }
    assert dense["formation"] < dense["leader_follower"] < dense["no_formation"]


def test_candidate_pairs_never_drop_a_pair_that_can_collide(paper):
    from swarmpark.control.formation.planner import _candidate_pairs, _reach_bounds

    lo, hi = _reach_bounds(paper)
    ci, cj, cm = _candidate_pairs(paper, lo, hi)
    kept = set(zip(ci.tolist(), cj.tolist(), cm.tolist(), strict=True))
    rng = np.random.default_rng(7)
    iu, ju = np.triu_indices(paper.n_robots, 1)
    for _ in range(300):
        m = int(rng.integers(1, paper.M))
        s = lo[:, m] + rng.random(paper.n_robots) * (hi[:, m] - lo[:, m])
        xy = np.array([p.position(s[i]) for i, p in enumerate(paper.paths)])
        close = np.linalg.norm(xy[iu] - xy[ju], axis=1) < paper.d_safe_m
        for i, j in zip(iu[close], ju[close], strict=True):
            assert (int(i), int(j), m) in kept


# --------------------------------------------------------------------------- execution
def test_sample_reference_matches_plan_instants(paper_plans):
    plan = paper_plans["formation"]
    ref = sample_reference(plan, plan.t_s)
    np.testing.assert_allclose(ref.poses, np.swapaxes(plan.poses, 0, 1), atol=1e-12)
    np.testing.assert_allclose(ref.v, plan.v_mps.T, atol=1e-12)
    # Between instants the distance integrates the speed (piecewise-linear speed, eq. 7).
    t = np.linspace(0.0, 15.0, 3001)
    r = sample_reference(plan, t)
    np.testing.assert_allclose(
        np.diff(r.s, axis=0), 0.5 * (r.v[1:] + r.v[:-1]) * (t[1] - t[0]), atol=1e-9
    )
    kappa = np.stack([p.curvature(r.s[:, i]) for i, p in enumerate(plan.problem.paths)], 1)
    np.testing.assert_allclose(r.omega, kappa * r.v, atol=1e-12)  # eq. (4)
    single = sample_reference(plan, 3.3)
    assert single.poses.shape == (6, 3) and single.v.shape == (6,)
    # Before the start and after the end the robots hold their start and goal poses.
    outside = sample_reference(plan, [-2.0, 100.0])
    np.testing.assert_allclose(outside.s, [np.zeros(6), plan.problem.lengths_m], atol=1e-12)
    assert np.all(outside.v == 0) and np.all(outside.omega == 0)


def rollout(reference_fn, pose0, t_end, dt=0.01, gains=None):
    """Unicycles following ``reference_fn(t) -> (poses, v, omega)`` with the commands held
    over each step and integrated exactly (arcs); returns ``(t, poses, reference poses)``."""
    pose = np.array(pose0, dtype=float)
    out = []
    for k in range(int(round(t_end / dt)) + 1):
        ref_pose, ref_v, ref_w = reference_fn(k * dt)
        out.append((k * dt, pose.copy(), ref_pose))
        v, w = track_unicycle(pose, ref_pose, ref_v, ref_w, gains)
        th = pose[..., 2]
        dth = w * dt
        # sin(x)/x form of the exact arc, well defined for straight motion.
        chord = v * dt * np.sinc(dth / (2 * np.pi))
        mid = th + 0.5 * dth
        pose = pose + np.stack([chord * np.cos(mid), chord * np.sin(mid), dth], -1)
    return out


def test_tracking_converges_forward_on_a_circle():
    radius, speed = 1.0, 0.2

    def ref(t):
        a = speed * t / radius
        pose = np.array([[radius * np.sin(a), radius * (1 - np.cos(a)), a]])
        return pose, np.array([speed]), np.array([speed / radius])

    trace = rollout(ref, [[-0.1, 0.1, 0.3]], 40.0)
    err = [np.hypot(*(p[0, :2] - r[0, :2])) for _, p, r in trace]
    assert err[0] > 0.09
    assert max(err[-500:]) < 1e-3


def test_tracking_converges_when_the_reference_drives_backwards():
    def ref(t):
        return np.array([[-0.15 * t, 0.0, 0.0]]), np.array([-0.15]), np.array([0.0])

    trace = rollout(ref, [[0.0, 0.08, 0.2]], 40.0, gains=TrackingGains(1.0, 4.0, 4.0))
    _, pose, r = trace[-1]
    assert np.hypot(*(pose[0, :2] - r[0, :2])) < 1e-3
    assert abs(pose[0, 2]) < 1e-2


def test_skids_tracking_the_paper_plan_keep_the_formation(paper_plans):
    plan = paper_plans["formation"]

    def ref(t):
        r = sample_reference(plan, t)
        return r.poses, r.v, r.omega

    trace = rollout(ref, np.swapaxes(plan.poses, 0, 1)[0], 16.0, dt=0.02)
    times = np.array([t for t, _, _ in trace])
    poses = np.stack([p for _, p, _ in trace])
    actual = formation_metrics(plan.problem, times, poses, sample_reference(plan, times).s)
    planned = formation_error(plan, times)
    assert actual.max_pair_error_m < planned.max_pair_error_m + 0.005
    final = poses[-1, :, :2]
    goals = np.array([p.position(p.length_m) for p in plan.problem.paths])
    assert np.abs(final - goals).max() < 0.01


# --------------------------------------------------------------------------- moving obstacle
def test_predict_obstacle():
    t = np.array([5.0, 5.5, 6.0])
    xy = np.array([[1.0, 2.0], [1.5, 1.5], [2.0, 1.0]])
    np.testing.assert_allclose(predict_obstacle(t, xy, [8.0, 10.0]), [[4, -1], [6, -3]])
    np.testing.assert_allclose(predict_obstacle([5.0], [[1.0, 2.0]], 9.0), [1.0, 2.0])
    with pytest.raises(ValueError, match="2 times, 3 positions"):
        predict_obstacle(t[:2], xy, 8.0)


def crossing_obstacle(x_cross: float, y_at_8: float, vy: float = 0.36):
    """An obstacle moving along x = x_cross (+y), observed every 0.5 s from 5 s to 8 s."""
    t = np.arange(5.0, 8.0 + 1e-9, 0.5)
    xy = np.stack([np.full_like(t, x_cross), y_at_8 + vy * (t - 8.0)], axis=1)
    return t, xy, (lambda tt: np.stack([np.full_like(tt, x_cross), y_at_8 + vy * (tt - 8.0)], -1))


def distances(plan, truth, t0, t1, dt=0.01):
    t = np.arange(t0, t1, dt)
    xy = sample_reference(plan, t).poses[..., :2]
    return np.linalg.norm(xy - truth(t)[:, None, :], axis=-1).min()


def test_far_obstacle_leaves_the_plan_alone(experiment):
    plan = experiment["plan"]
    t, xy, _ = crossing_obstacle(20.0, -9.0)
    adj = adjust_for_obstacle(plan, t, xy, 8.0, d_obs_m=0.6)
    assert adj.decision == "continue" and adj.plan is plan


def test_wait_when_standing_still_is_safe(experiment):
    plan = experiment["plan"]
    t, xy, truth = crossing_obstacle(3.2, -1.3)
    adj = adjust_for_obstacle(plan, t, xy, 8.0, d_obs_m=0.6, horizon_steps=5)
    assert adj.decision == "wait" and adj.wait_s > 0 and adj.reverse_s == 0
    new = adj.plan
    # Eq. (18): hold q(t_obs) for dt_d, then replay the plan dt_d late.
    q_obs = sample_reference(plan, 8.0).poses
    for t_ in np.linspace(8.0, 8.0 + adj.wait_s, 7):
        np.testing.assert_allclose(sample_reference(new, t_).poses, q_obs, atol=1e-12)
    assert np.all(sample_reference(new, np.linspace(8.0, 8.0 + adj.wait_s - 1e-6, 7)).v == 0)
    for t_ in (9.7, 14.0, 20.0):
        np.testing.assert_allclose(
            sample_reference(new, t_ + adj.wait_s).poses,
            sample_reference(plan, t_).poses,
            atol=1e-12,
        )
    assert new.duration_s == pytest.approx(plan.duration_s + adj.wait_s)
    assert distances(plan, truth, 8.0, plan.duration_s) < 0.6  # the original would collide
    assert distances(new, truth, 8.0, new.duration_s) >= 0.6  # the modified plan does not


def test_reverse_when_standing_still_is_not_safe(experiment):
    plan = experiment["plan"]
    t, xy, truth = crossing_obstacle(2.1, -1.3)
    adj = adjust_for_obstacle(plan, t, xy, 8.0, d_obs_m=0.6, horizon_steps=5)
    assert adj.decision == "reverse" and adj.reverse_s > 0
    new, t_obs, back, wait = adj.plan, 8.0, adj.reverse_s, adj.wait_s
    # Eq. (19): retrace, wait at q(t_obs - dt_r), then replay 2 dt_r + dt'_d late.
    for x in np.linspace(0.0, back, 5):
        np.testing.assert_allclose(
            sample_reference(new, t_obs + x).poses,
            sample_reference(plan, t_obs - x).poses,
            atol=1e-12,
        )
    for x in np.linspace(back, back + wait, 4):
        np.testing.assert_allclose(
            sample_reference(new, t_obs + x).poses,
            sample_reference(plan, t_obs - back).poses,
            atol=1e-12,
        )
    for t_ in (9.0, 15.0, 21.0):
        np.testing.assert_allclose(
            sample_reference(new, t_ + 2 * back + wait).poses,
            sample_reference(plan, t_).poses,
            atol=1e-12,
        )
    assert np.all(sample_reference(new, t_obs + 0.5 * back).v <= 0)
    assert distances(new, truth, t_obs, new.duration_s) >= 0.6


@pytest.mark.parametrize("x_cross", [1.9, 2.3, 2.6, 2.9, 3.3])
def test_wait_or_reverse_follows_condition_17(experiment, x_cross):
    plan = experiment["plan"]
    t, xy, truth = crossing_obstacle(x_cross, -1.3)
    h, d_obs = 5, 0.6
    adj = adjust_for_obstacle(plan, t, xy, 8.0, d_obs_m=d_obs, horizon_steps=h)
    # Condition (17) by hand: robots standing at q(t_obs) against the predicted obstacle.
    tt = 8.0 + np.linspace(0.0, h, 10 * h + 1)
    standing = sample_reference(plan, 8.0).poses[:, :2]
    d17 = np.linalg.norm(standing[None] - truth(tt)[:, None, :], axis=-1).min()
    moving = np.linalg.norm(sample_reference(plan, tt).poses[..., :2] - truth(tt)[:, None], axis=-1)
    if moving.min() >= d_obs:
        assert adj.decision == "continue"
    else:
        assert adj.decision == ("wait" if d17 >= d_obs else "reverse")
    assert distances(adj.plan, truth, 8.0, adj.plan.duration_s) >= d_obs
    # The group shares one time warp, so the formation error never exceeds the plan's.
    fe_new = formation_error(adj.plan, np.arange(0.0, adj.plan.duration_s, 0.1))
    fe_old = formation_error(plan, np.arange(0.0, plan.duration_s + 1e-9, 0.01))
    assert fe_new.max_pair_error_m <= fe_old.max_pair_error_m + 1e-9


def test_table2_experiment_reverses_and_stays_clear(experiment):
    adj = experiment["adjustments"]
    assert [a.decision for a in adj] == ["reverse"]
    assert adj[0].t_obs_s == 8.0  # watched from 5 s for 3 s, as in the paper
    assert experiment["min_obstacle_distance_m"] >= experiment["d_obs_m"]
    executed = experiment["executed"]
    assert executed.duration_s == pytest.approx(
        experiment["plan"].duration_s + 2 * adj[0].reverse_s + adj[0].wait_s
    )


def test_online_adjuster_waits_for_watch_time_and_rejects_unknown_options(experiment):
    plan = experiment["plan"]
    with pytest.raises(TypeError, match="unknown keyword"):
        OnlineAdjuster(plan, horizon=5)
    t, xy, _ = crossing_obstacle(2.1, -1.3)
    oa = OnlineAdjuster(plan, min_watch_s=3.0, d_obs_m=0.6)
    for ti, p in zip(t[:-1], xy[:-1], strict=True):
        oa.observe(ti, p)
        assert oa.update(ti) is None  # still watching
    oa.observe(t[-1], xy[-1])
    adj = oa.update(8.0)
    assert adj is not None and adj.decision == "reverse" and oa.plan is adj.plan
    assert oa.update(9.0) is None  # the modified plan already clears the prediction
    with pytest.raises(ValueError, match="observe: non-finite"):
        oa.observe(9.0, [np.nan, 0.0])


def test_experiment_formation_switches_from_step_a_to_b(experiment):
    pb = experiment_problem()
    plan = experiment["plan"]
    start, end = sample_reference(plan, 0.0).poses, sample_reference(plan, plan.duration_s).poses
    np.testing.assert_allclose(start[1, :2] - start[0, :2], [0.0, 1.2], atol=1e-9)
    np.testing.assert_allclose(end[1, :2] - end[0, :2], [-1.2, 0.0], atol=1e-6)
    assert pb.d_safe_m <= plan.min_pair_distance_m


@pytest.mark.slow
def test_run_paper_writes_figures_and_ranks_the_proposed_method_first(tmp_path):
    out = run_paper(tmp_path)
    assert out["best_method"] == "formation"
    t1 = out["table1"]
    assert t1["formation"]["integral_m2s"] < t1["leader_follower"]["integral_m2s"]
    assert t1["leader_follower"]["integral_m2s"] < t1["no_formation"]["integral_m2s"]
    for name in ("formation_errors.png", "formation_velocity.png", "formation_paths.png"):
        assert (tmp_path / name).read_bytes()[:4] == b"\x89PNG"
    assert "| reverse |" in (tmp_path / "formation_table.md").read_text()
    assert math.isfinite(out["experiment"]["min_obstacle_distance_m"])
