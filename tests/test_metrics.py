"""Metrics on tiny scripted runs whose numbers can be checked by hand."""

import numpy as np
import pytest
from helpers import SCENARIOS, Scripted, make_world

from swarmpark.apps.cli import _print_table
from swarmpark.apps.run import RunObserver, run_world
from swarmpark.metrics import LOST_TIME, lower_bound_s


def straight_run(**kw):
    # v = 0.5 m/s commanded for 4 s then 0; accel 0.5 m/s^2, dt 0.05.
    # Speeds step by 0.025: 20 steps up (0.025 .. 0.5), 60 at 0.5, then 20 down (0.475 .. 0).
    # Distance = dt * (0.025 * (1 + ... + 20) + 60 * 0.5 + 0.025 * (0 + ... + 19))
    #          = 0.05 * (5.25 + 30 + 4.75) = 2.0 m exactly.
    world = make_world(
        duration_s=8,
        commands=[{"at_s": 0, "goto": {"robot": "a", "pose": [4.0, 3.0, 0.0]}}],
        **kw,
    )
    ctl = Scripted(lambda t: [[0.5, 0.0]] if t < 4.0 - 1e-9 else [[0.0, 0.0]])
    return run_world(world, controller=ctl)


def test_path_length_and_parking_time_by_hand():
    out = straight_run()
    r = out.result
    assert r["path_length_m"]["a"] == pytest.approx(2.0, abs=1e-9)
    assert r["robots"]["a"]["final_position_error_m"] == pytest.approx(0.0, abs=1e-9)
    assert r["success"] is True and r["collisions"] == []
    # Within 0.10 m of x = 4 when x >= 3.9: 0.1 m before the end, during the slow-down
    # (the last 5 steps cover 0.05 * 0.025 * (4+3+2+1+0) = 0.0125 m; the last 9: 0.045;
    # the last 12: 0.0825; the last 13 reach 0.0975, the last 14 0.1135), so it enters
    # tolerance after step 100 - 13 = 87: t = 4.35 s.
    assert r["robots"]["a"]["parked_at_s"] == pytest.approx(4.35)
    assert r["time_to_park_s"] == pytest.approx(4.35)
    # Lower bound: 2 m at 0.5 m/s.
    assert r["lower_bound_s"] is None  # no park command: the bound is for park commands


def test_clearance_to_wall_by_hand():
    # A wall 0.3 m above the robot's left side (y = 3.4): clearance 0.3 all along.
    out = straight_run(
        map={
            "size_m": [10, 6],
            "resolution_m": 0.05,
            "walls": [[[0.5, 3.7], [9.5, 3.7], [9.5, 4.0], [0.5, 4.0]]],
        }
    )
    assert out.result["min_clearance_wall_m"] == pytest.approx(0.3, abs=1e-9)
    assert out.result["min_clearance_m"] == pytest.approx(0.3, abs=1e-9)


def test_deadlock_is_reported_when_pushing_into_a_wall(capsys):
    world = make_world(
        duration_s=25,
        map={
            "size_m": [10, 6],
            "resolution_m": 0.05,
            # A gap at the top, so the goto is taken (a goal no way reaches is refused).
            "walls": [[[4, 0], [4.5, 0], [4.5, 4.8], [4, 4.8]]],
        },
        commands=[{"at_s": 0, "goto": {"robot": "a", "pose": [7.0, 3.0, 0.0]}}],
    )
    out = run_world(world, controller=Scripted(lambda t: [[0.5, 0.0]]))
    r = out.result
    assert r["success"] is False
    assert len(r["collisions"]) == 1 and r["collisions"][0]["kind"] == "robot-wall"
    (dl,) = r["deadlocks"]
    assert dl["robot"] == "a" and dl["end_s"] is None
    # The wall face is at x = 4: the pivot stops at 3.4 after about 2.9 s; the last progress
    # of at least 0.05 m happens shortly before, then 10 s pass.
    assert 2.0 < dl["start_s"] < 3.5
    # A scripted controller cannot say why: the cause says so.
    assert dl["cause"] == "no progress"
    # Where it stood when reported: against the wall, 3.6 m short of its goal.
    assert dl["pose"][0] == pytest.approx(3.4, abs=0.05) and dl["pose"][2] == pytest.approx(0)
    assert dl["goal_distance_m"] == pytest.approx(3.6, abs=0.05)
    # The run's table says so too.
    _print_table(r)
    (line,) = [s for s in capsys.readouterr().out.splitlines() if s.startswith("deadlock a ")]
    assert line.endswith("s to the end at (3.40, 3.00), 3.60 m from its goal: no progress")


def test_deadlock_names_its_cause_from_the_navigator():
    """The default navigator says what held a skid up when its deadlock is reported: here the
    goal is inside a closed box, so there is no path. (A goto there is refused; the goal is
    set past that check, as when the known map closes round a goal taken earlier.)"""
    world = make_world(
        duration_s=25,
        map={
            "size_m": [10, 6],
            "resolution_m": 0.05,
            "walls": [
                [[6, 2], [8, 2], [8, 2.2], [6, 2.2]],
                [[6, 3.8], [8, 3.8], [8, 4], [6, 4]],
                [[6, 2.2], [6.2, 2.2], [6.2, 3.8], [6, 3.8]],
                [[7.8, 2.2], [8, 2.2], [8, 3.8], [7.8, 3.8]],
            ],
        },
    )

    class SetGoal(RunObserver):
        def on_start(self, sup):
            sup._set_goals(np.array([0]), np.array([[7.0, 3.0, 0.0]]))

    (dl,) = run_world(world, observers=[SetGoal()]).result["deadlocks"]
    assert dl["cause"] == "no path to its goal on the known map"


class _Held(Scripted):
    """Stands still; the fill order holds the skid, and ``at_hold`` says whether it stands
    at its stop (as the navigator's attribute does; None: no such attribute)."""

    def __init__(self, at_hold):
        super().__init__(lambda t: [[0.0, 0.0]])
        if at_hold is not None:
            self.at_hold = np.array([at_hold])


@pytest.mark.parametrize(("at_hold", "reported"), [(False, True), (True, False), (None, False)])
def test_a_held_skid_is_waiting_only_at_its_stop(monkeypatch, at_hold, reported):
    """A skid the fill order holds back waits on purpose (no deadlock) once it stands at its
    stop; held but stuck on its way there, it is in deadlock like any other. A controller
    that does not say where its held skids stand has them all waiting."""
    from swarmpark.supervisor import core

    monkeypatch.setattr(
        core.fill_order, "holds", lambda groups, poses: (np.ones(len(poses), bool),) * 2
    )
    world = make_world(
        duration_s=15, commands=[{"at_s": 0, "goto": {"robot": "a", "pose": [7.0, 3.0, 0.0]}}]
    )
    r = run_world(world, controller=_Held(at_hold)).result
    assert r["success"] is False
    assert len(r["deadlocks"]) == (1 if reported else 0)
    if reported:  # the cause says it is held, and not at its stop
        assert (
            r["deadlocks"][0]["cause"]
            == "held back by the fill order, not at its stop: no progress"
        )


class _Queued(Scripted):
    """Both skids stand still; skid b is queued at a door whose grant skid a holds (as the
    navigator's ``queued`` and ``queue_holders`` say; ``holders`` False: no such method)."""

    def __init__(self, holders: bool):
        super().__init__(lambda t: [[0.0, 0.0], [0.0, 0.0]])
        self.queued = np.array([False, True])
        if holders:
            self.queue_holders = lambda i: [0] if i == 1 else []

    def explain(self, i):
        return ("queued", [0]) if i == 1 else ("stuck", [])


@pytest.mark.parametrize("holders", [True, False])
def test_a_queue_behind_a_stuck_holder_is_reported_as_deadlocked(holders):
    """A skid queued at a bottleneck waits on purpose, unless every skid holding the zone is
    in a deadlock episode itself: then it is reported too, from when they were, with the
    controller's cause. A controller that does not name the holders has its queues waiting."""
    world = make_world(
        duration_s=25,
        robots=[{"id": "a", "pose": [2.0, 3.0, 0.0]}, {"id": "b", "pose": [2.0, 1.5, 0.0]}],
        commands=[
            {"at_s": 0, "goto": {"robot": "a", "pose": [7.0, 3.0, 0.0]}},
            {"at_s": 0, "goto": {"robot": "b", "pose": [7.0, 1.5, 0.0]}},
        ],
    )
    dls = run_world(world, controller=_Queued(holders)).result["deadlocks"]
    assert [d["robot"] for d in dls] == (["a", "b"] if holders else ["a"])
    assert dls[0]["cause"] == "stuck"
    if holders:  # b's clock started when a's episode was reported
        assert dls[1]["cause"] == "queued: a"
        assert dls[1]["start_s"] == pytest.approx(dls[0]["start_s"] + 10.0, abs=0.2)


def test_lower_bound_goes_around_a_wall():
    world = make_world(
        map={
            "size_m": [10, 6],
            "resolution_m": 0.05,
            "walls": [[[4, 0], [4.5, 0], [4.5, 4.5], [4, 4.5]]],
        }
    )
    starts = np.array([[2.0, 1.0, 0.0]])
    goals = np.array([[7.0, 1.0, 0.0]])
    lb = lower_bound_s(world.grid, starts, goals, 0.4, np.array([0.5]))
    # The true shortest path for a disc of radius 0.4 goes over the wall's buffered top: the
    # upper part of the convex hull of start, goal and the buffered wall above y = 1.
    from shapely.geometry import MultiPoint, box
    from shapely.ops import unary_union

    wall = box(4, 0, 4.5, 4.5).buffer(0.4, quad_segs=64).intersection(box(0, 1, 10, 6))
    hull = unary_union([wall, MultiPoint([(2, 1), (7, 1)])]).convex_hull
    true_len = hull.exterior.length - 5.0
    assert lb is not None
    assert 0.9 * true_len / 0.5 < lb <= true_len / 0.5  # a bound, and a tight one


def test_lower_bound_is_computed_lazily_from_the_first_park_command_with_one():
    from swarmpark.metrics import MetricsRecorder

    world = make_world(map={"size_m": [10, 6], "resolution_m": 0.05})
    starts = np.array([[2.0, 1.0, 0.0]])
    goals = np.array([[7.0, 1.0, 0.0]])
    rec = MetricsRecorder(["a"], starts)
    assert rec.lower_bound is None  # no park command yet
    # A goal that cannot be reached gives no bound; the next command's inputs are used.
    rec.defer_lower_bound(world.grid, starts, np.array([[20.0, 1.0, 0.0]]), 0.4, [0.5])
    moved = starts.copy()
    rec.defer_lower_bound(world.grid, moved, goals, 0.4, np.array([0.5]))
    moved[0, 0] = 0.5  # the inputs were copied: later changes do not leak in
    expected = lower_bound_s(world.grid, starts, goals, 0.4, np.array([0.5]))
    assert expected is not None and rec.lower_bound == expected
    rec.defer_lower_bound(world.grid, starts, goals, 0.4, np.array([5.0]))
    assert rec.lower_bound == expected  # the first bound found stays


def test_time_lost_against_top_speed_by_hand():
    # The straight run above: 20 steps speeding up (losing dt * (1 - v / 0.5) each:
    # 0.05 * (20 - 0.05 * 210) = 0.475 s), then full speed, then slowing down until it is
    # within tolerance at step 87 (steps 81-86 lose 0.05 * 0.05 * (1 + ... + 6) = 0.0525 s).
    # All of it within 2 m of its goal: parking.
    r = straight_run().result
    assert r["time_lost_s"]["parking"] == pytest.approx(0.5275, abs=1e-3)
    assert sum(r["time_lost_s"].values()) == pytest.approx(0.5275, abs=1e-3)
    assert r["robots"]["a"]["time_lost_s"] == {"parking": pytest.approx(0.5275, abs=1e-3)}


def test_time_lost_adds_up_and_names_the_fill_order():
    # A convoy into a dead end: the skids bound for the spots nearer the mouth wait for the
    # deeper ones. Each skid's time lost is its time to park less its path at top speed.
    from swarmpark.world.scenario import build_world, load_scenario

    world = build_world(load_scenario(SCENARIOS / "dead-end-fig6.yaml"))
    r = run_world(world).result
    assert r["success"]
    vmax = world.scenario.robot_defaults.max_speed_mps
    for rid, s in r["robots"].items():
        expected = s["parked_at_s"] - s["path_length_m"] / vmax
        assert sum(s["time_lost_s"].values()) == pytest.approx(expected, abs=0.3), rid
    assert r["time_lost_s"]["fill_order"] > 2.0
    assert set(r["time_lost_s"]) == set(LOST_TIME)
