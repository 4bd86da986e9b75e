"""The supervisor behind the RobotLink seam: a scripted fake link parks robots without the
simulator; the fill order on a hand-made dead end; the command registry; the inbox and the
simulator link's injected faults."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import make_world
from shapely.geometry import box

from swarmpark import assign as assign_mod
from swarmpark.core.geometry import Footprint, integrate_unicycle
from swarmpark.core.gridmap import grid_from_walls
from swarmpark.links.base import (
    FleetInfo,
    Inbox,
    Odometry,
    PoseReport,
    RobotLink,
    Scan,
    VelocityCommand,
)
from swarmpark.metrics import HEADING_TOL_RAD, POSITION_TOL_M, goal_errors
from swarmpark.sim.link import CMD_TIMEOUT_S, SimLink
from swarmpark.supervisor import fill_order
from swarmpark.supervisor.commands import ParkGroup
from swarmpark.supervisor.core import Supervisor
from swarmpark.supervisor.registry import COMMANDS
from swarmpark.world.scenario import ParkCmd, ScenarioError

THREE = [
    {"id": "a", "pose": [1.5, 1.0, 0.0]},
    {"id": "b", "pose": [1.5, 3.0, 0.0]},
    {"id": "c", "pose": [1.5, 5.0, 0.0]},
]


class FakeLink:
    """A scripted fleet: robots that follow their last command exactly (no simulator, no
    contacts, no limits but the speeds), report their pose every period and nothing else."""

    def __init__(self, ids, starts, dt=0.05):
        self.ids = tuple(ids)
        self.poses = np.asarray(starts, float).copy()
        self.vel = np.zeros((len(ids), 2))
        self.cmd = np.zeros((len(ids), 2))
        self.dt = dt
        self.t = 0.0
        self.out: list = []
        self.stops = 0

    def connect(self) -> FleetInfo:
        n = len(self.ids)
        self._report()
        return FleetInfo(
            ids=self.ids,
            footprints=tuple(Footprint(1.2, 0.8, 0.6) for _ in range(n)),
            max_speed_mps=np.full(n, 0.5),
            max_yaw_rate_radps=np.full(n, 1.0),
            max_accel_mps2=np.full(n, 0.5),
            max_yaw_accel_radps2=np.full(n, 2.0),
            dt_s=self.dt,
            start_poses=self.poses.copy(),
        )

    def now(self) -> float:
        return self.t

    def receive(self):
        out, self.out = self.out, []
        return out

    def send(self, commands):
        for c in commands:
            self.cmd[self.ids.index(c.robot)] = (c.v, c.omega)

    def stop(self, robots):
        self.stops += 1
        for r in robots:
            self.cmd[self.ids.index(r)] = 0.0

    def spin(self):
        v = np.clip(self.cmd[:, 0], -0.5, 0.5)
        w = np.clip(self.cmd[:, 1], -1.0, 1.0)
        self.poses = integrate_unicycle(self.poses, v, w, self.dt)
        self.vel = np.column_stack([v, w])
        self.t = round(self.t + self.dt, 9)
        self._report()
        return None

    def _report(self):
        for i, rid in enumerate(self.ids):
            self.out.append(PoseReport(rid, self.t, self.poses[i].copy()))
            self.out.append(Odometry(rid, self.t, self.poses[i].copy(), self.vel[i].copy()))


def test_the_fake_link_is_a_robot_link_and_the_supervisor_parks_through_it():
    world = make_world(robots=THREE, duration_s=90, map={"size_m": [12, 7], "resolution_m": 0.05})
    link = FakeLink(world.ids, [r.start for r in world.robots], dt=world.scenario.dt_s)
    assert isinstance(link, RobotLink)
    sup = Supervisor(world, link=link)
    assert sup.sim is None  # nothing but the link: no truth handle
    out = sup.park(
        ParkCmd(robots=["a", "b", "c"], boundary=[[7, 0.5], [11, 0.5], [11, 6.5], [7, 6.5]])
    )
    assert out.accepted, out.reason
    for _ in range(int(90 / link.dt)):
        sup.tick()
        if sup.settled():
            break
    pos, head = goal_errors(link.poses, sup.goals)
    assert np.all(pos <= POSITION_TOL_M) and np.all(head <= HEADING_TOL_RAD), (pos, head)
    assert sup.modes() == ["parked"] * 3
    assert sup.t < 90
    # The supervisor read the robots' poses from the link only.
    assert np.allclose(sup.poses_known, link.poses)


def test_estop_reaches_the_link_as_a_stop():
    world = make_world(robots=THREE[:1])
    link = FakeLink(world.ids, [r.start for r in world.robots])
    sup = Supervisor(world, link=link)
    sup.estop()
    sup.tick()
    assert link.stops == 1


@pytest.mark.parametrize("lands", ["before the step", "during the step", "after the step"])
def test_an_estop_that_lands_during_a_tick_counts_from_that_ticks_end(lands):
    """The server applies the e-stop from its event loop, so it can land while the sim
    thread is inside a tick whose commands were already decided. It is stamped with that
    tick's end, and from the next tick on nothing moves."""
    world = make_world(robots=THREE[:1])
    sup = Supervisor(world)
    sup.park(ParkCmd(robots=["a"], boundary=[[7, 0.5], [11, 0.5], [11, 6.5], [7, 6.5]]))
    while sup.sim.vel[0, 0] < 0.2:
        sup.tick()
    spin, step, outs = sup.link.spin, sup.sim.step, []

    def spin_with_estop():
        if lands == "before the step":
            outs.append(sup.estop())
        result = spin()
        if lands == "after the step":
            outs.append(sup.estop())
        return result

    def step_with_estop(*args, **kwargs):
        outs.append(sup.estop())
        return step(*args, **kwargs)

    sup.link.spin = spin_with_estop
    if lands == "during the step":
        sup.sim.step = step_with_estop
    sup.tick()
    sup.link.spin, sup.sim.step = spin, step
    assert outs[0].accepted and outs[0].t_s == pytest.approx(sup.t)
    pose = sup.sim.poses.copy()
    for _ in range(5):
        sup.tick()
        assert np.all(sup.sim.vel == 0.0)
        assert np.array_equal(sup.sim.poses, pose)


# ----------------------------------------------------------------------------- fill order


def _dead_end():
    """A 1.2 m wide corridor open to the west, closed at x = 6 m, with three goals along it."""
    walls = [box(0, 0, 8, 2.0), box(0, 3.2, 8, 5), box(6.0, 2.0, 8, 3.2)]
    grid = grid_from_walls((8.0, 5.0), 0.05, walls)
    fps = [Footprint(1.0, 0.6, 0.5)] * 3
    goals = np.array([[5.3, 2.6, 0.0], [4.1, 2.6, 0.0], [2.9, 2.6, 0.0]])  # deepest first
    boundary = box(2.3, 2.0, 6.0, 3.2)
    return grid, fps, goals, boundary


def _group(goals, boundary, blocks, reach=None):
    """Three skids, skid i bound for goal i, filled in index order."""
    return ParkGroup(
        robots=np.array([0, 1, 2]),
        goals=goals,
        cost="euclidean",
        goal_of=np.array([0, 1, 2]),
        fill_order=(0, 1, 2),
        boundary=boundary,
        method="stacking",
        report={},
        blocks=blocks,
        reach=reach,
    )


def test_blockers_of_a_dead_end_are_the_goals_deeper_in():
    grid, fps, goals, boundary = _dead_end()
    blocks = fill_order.blockers(goals, fps, boundary, (0, 1, 2), grid)
    # The goal at the mouth walls in both deeper ones; the middle one the deepest; the
    # deepest blocks nothing.
    assert blocks == ((), (0,), (0, 1))


def test_fill_order_holds_a_skid_that_would_overtake_the_one_bound_deeper():
    grid, fps, goals, boundary = _dead_end()
    blocks = fill_order.blockers(goals, fps, boundary, (0, 1, 2), grid)
    group = _group(goals, boundary, blocks)
    # Robot 0 (deepest goal) is far behind; robots 1 and 2 are nearer their goals: held.
    poses = np.array([[-3.0, 2.6, 0.0], [1.0, 2.6, 0.0], [2.0, 2.6, 0.0]])
    assert fill_order.held([group], poses).tolist() == [False, True, True]
    # Once robot 0 is ahead of robot 1 (nearer its goal), robot 1 may follow; 2 still waits.
    poses[0] = [4.0, 2.6, 0.0]
    assert fill_order.held([group], poses).tolist() == [False, False, True]
    # Both deeper goals filled: the mouth is free to take.
    poses[:2] = goals[:2]
    assert fill_order.held([group], poses).tolist() == [False, False, False]


def test_a_follower_keeps_off_its_spot_until_the_one_ahead_has_parked():
    grid, fps, goals, boundary = _dead_end()
    blocks = fill_order.blockers(goals, fps, boundary, (0, 1, 2), grid)
    group = _group(goals, boundary, blocks)
    # Robot 0 is ahead, still turning into the deepest goal; robots 1 and 2 follow.
    poses = np.array([[4.8, 2.6, 0.5], [2.0, 2.6, 0.0], [-3.0, 2.6, 0.0]])
    outside, short = fill_order.holds([group], poses)
    assert not outside.any()
    assert short.tolist() == [False, True, True]
    # Robot 0 parked: robot 1 may take its spot; robot 1 runs straight in along its axis,
    # so robot 2 may close up behind it (a convoy into a dead end).
    poses[0] = goals[0]
    outside, short = fill_order.holds([group], poses)
    assert not outside.any() and not short.any()
    # Robot 1 off its axis (turning): robot 2 keeps off its spot again.
    poses[1] = [3.0, 2.3, 0.4]
    assert fill_order.holds([group], poses)[1].tolist() == [False, False, True]
    # Robot 1 coming in along the corridor 2 m out, 0.15 m beside its spot's axis and facing
    # along it: its spot lies within the heading tolerance of straight ahead, so it is on
    # its run in and robot 2 may close up (with only the 0.1 m position tolerance beside
    # the axis, each skid of a file into a dead-end bay waited for the one ahead to park).
    poses[1] = [2.1, 2.75, 0.0]
    assert fill_order.holds([group], poses)[1].tolist() == [False, False, False]
    # The same skid beside its axis by as much but 1 m out: a turn is left, robot 2 waits.
    poses[1] = [3.1, 2.75, 0.0]
    assert fill_order.holds([group], poses)[1].tolist() == [False, False, True]


def test_skids_waiting_at_the_mouth_take_over_the_deeper_goals():
    grid, fps, goals, boundary = _dead_end()
    blocks = fill_order.blockers(goals, fps, boundary, (0, 1, 2), grid)
    group = _group(goals, boundary, blocks)
    # The deepest goal's skid far behind; the other two wait at the mouth, in its way.
    poses = np.array([[-3.0, 2.6, 0.0], [1.0, 2.6, 0.0], [2.0, 2.6, 0.0]])
    assert fill_order.held([group], poses).tolist() == [False, True, True]
    # A skid whose goal does not fit is never handed one.
    assert fill_order.hand_over(group, poses, fits=lambda row, goal: False) is None
    # One swap at a time (the nearest goal first), until the skids are in depth order: the
    # first in line has the deepest goal, and the second follows it in.
    for _ in range(4):
        pair = fill_order.hand_over(group, poses)
        if pair is None:
            break
        a, b = pair
        group.goal_of[[a, b]] = group.goal_of[[b, a]]
    assert group.goal_of.tolist() == [2, 1, 0]
    assert fill_order.hand_over(group, poses) is None
    assert fill_order.held([group], poses).tolist() == [False, True, False]
    poses[2] = [4.0, 2.6, 0.0]  # the first in line has gone ahead: the second may follow
    assert not fill_order.held([group], poses).any()


def test_the_supervisor_hands_the_deepest_goal_to_the_first_in_line():
    """Three skids west of a dead end one skid wide, the last one off to the side: the
    assignment gives it the deepest goal (the detour costs it least there), which would hold
    the two ahead of it at the mouth. Within a few ticks the first in line is bound deepest
    and nobody waits outside."""
    walls = [
        [[4, 0], [12, 0], [12, 2.0], [4, 2.0]],
        [[4, 3.2], [12, 3.2], [12, 5], [4, 5]],
        [[10, 2.0], [12, 2.0], [12, 3.2], [10, 3.2]],
    ]
    world = make_world(
        map={"size_m": [12, 5], "resolution_m": 0.05, "walls": walls},
        robots=[
            {"id": "a", "pose": [1.0, 0.8, 0.0]},
            {"id": "b", "pose": [2.2, 2.6, 0.0]},
            {"id": "c", "pose": [3.6, 2.6, 0.0]},
        ],
    )
    sup = Supervisor(world)
    cmd = ParkCmd(
        robots=["a", "b", "c"],
        boundary=[[6.0, 2.0], [10.0, 2.0], [10.0, 3.2], [6.0, 3.2]],
        heading_deg=0,
        margin_m=0.05,
        assignment="euclidean",
    )
    assert sup.park(cmd).accepted
    assert sup.goals[0, 0] == sup.goals[:, 0].max()  # the last one, deepest
    for _ in range(4):
        sup.tick()
    outside, _ = fill_order.holds(sup.groups, sup.poses_known)
    assert not outside.any()
    x_goal = sup.goals[:, 0]
    assert x_goal[2] > x_goal[1] > x_goal[0]  # c, first in line, deepest


def test_a_hand_over_the_re_assignment_would_keep_is_made():
    """The hand-over's check is the re-assignment itself. Skid a waits at a dead end's
    mouth (goal B) for skid b, bound for the deeper goal A but farther from it: they swap.
    Elsewhere, skid p docks 0.59 m from its goal D, beside goal E, whose skid q stands
    beside D: giving p E and q D would save more than the re-assignment's hysteresis, but
    the re-assignment never takes a spot from under a docking skid, so it keeps the swap
    (a check against the unconstrained optimum refused it: found on a 10-skid training
    car, where a skid waited in the door for one behind it until the end of the run)."""
    poses = [[6.0, 2.6, 0.0], [4.6, 2.6, 0.0], [3.59, 5.0, 0.0], [1.9, 5.0, 90.0]]
    sup = Supervisor(
        make_world(
            map={"size_m": [12, 6], "resolution_m": 0.05},
            robots=[{"id": f"r{k}", "pose": p} for k, p in enumerate(poses)],
        )
    )
    goals = np.array([[9.0, 2.6, 0.0], [7.6, 2.6, 0.0], [3.0, 5.0, 0.0], [3.6, 5.0, 0.0]])
    group = ParkGroup(
        robots=np.arange(4),
        goals=goals,
        cost="euclidean",
        goal_of=np.array([1, 0, 2, 3]),  # a -> B, b -> A, p -> D, q -> E
        fill_order=(0, 1, 2, 3),
        boundary=box(2.0, 2.0, 10.0, 5.5),
        method="stacking",
        report={},
        goal_fps=(Footprint(1.2, 0.8),) * 4,
        blocks=((), (0,), (), ()),  # B walls in A
    )
    sup.groups = [group]
    assert fill_order.held(sup.groups, sup.poses_known).tolist() == [True, False, False, False]
    assert fill_order.hand_over(group, sup.poses_known) == (0, 1)
    swapped = np.array([0, 1, 2, 3])
    cost = sup._cost_matrix(group.robots, goals, "euclidean", None)
    now = cost[np.arange(4), swapped].sum()
    best = cost[np.arange(4), assign_mod.assign(cost)].sum()
    assert now - best > max(assign_mod.HYSTERESIS_FRACTION * now, assign_mod.HYSTERESIS_ABS_M)
    assert sup._reassigned(group, swapped) is None
    sup._hand_over()
    assert group.goal_of.tolist() == [0, 1, 2, 3]
    # a, first in line, goes deepest; b waits for it.
    assert fill_order.held(sup.groups, sup.poses_known).tolist() == [False, True, False, False]
    sup._reassign()  # and the re-assignment keeps it
    assert group.goal_of.tolist() == [0, 1, 2, 3]
    # Without the docking skid's guard (p 0.7 m off D), the re-assignment would undo the
    # swap, and the hand-over is not made.
    sup2 = Supervisor(
        make_world(
            map={"size_m": [12, 6], "resolution_m": 0.05},
            robots=[
                {"id": f"r{k}", "pose": p}
                for k, p in enumerate([*poses[:2], [3.7, 5.0, 0.0], poses[3]])
            ],
        )
    )
    group.goal_of = np.array([1, 0, 2, 3])
    group.goals = goals.copy()
    group.goals[3, 0] = 3.7
    sup2.groups = [group]
    sup2._hand_over()
    assert group.goal_of.tolist() == [1, 0, 2, 3]


def test_two_spots_that_shut_a_bay_together_hold_the_second_skid():
    # A bay open to the west (x = 1); the two goals at its mouth, B and C, each leave a lane
    # to the deep goal A, but not both: the layout's pairwise blocks see nothing, and the
    # goals filled now do.
    walls = [box(1, 0.4, 5.6, 1.0), box(1, 3.4, 5.6, 4.0), box(5.0, 1.0, 5.6, 3.4)]
    grid = grid_from_walls((6.0, 4.0), 0.05, walls)
    fps = [Footprint(1.0, 0.6, 0.5)] * 3
    goals = np.array([[4.0, 2.2, 0.0], [1.7, 1.6, 0.0], [1.7, 2.7, 0.0]])  # A, B, C
    boundary = box(1.0, 1.0, 5.0, 3.4)
    r = fill_order.reach(goals, fps, boundary, grid)
    blocks = fill_order.blockers(goals, fps, boundary, (0, 1, 2), grid, r)
    assert blocks == ((), (), ())
    assert r.cut_off(frozenset({1}), 2).tolist() == [True, False, False]
    assert not r.cut_off(frozenset(), 2).any()
    group = _group(goals, boundary, blocks, r)
    # A's skid far behind, B parked, C's skid at the mouth: C waits.
    poses = np.array([[-3.0, 2.2, 0.0], goals[1], [0.2, 2.7, 0.0]])
    assert fill_order.held([group], poses).tolist() == [False, False, True]
    # B not parked yet: C may take its spot (B is then the one to wait, not C).
    poses[1] = [0.0, 1.6, 0.0]
    assert fill_order.held([group], poses).tolist() == [False, False, False]
    # A's skid ahead of C's (nearer its goal): C may follow it.
    poses[1], poses[0] = goals[1], [3.0, 2.2, 0.0]
    assert fill_order.held([group], poses).tolist() == [False, False, False]


# ----------------------------------------------------------------------------- commands


def test_an_unknown_command_is_refused_with_the_known_ones():
    sup = Supervisor(make_world())
    before = (sup.goals.copy(), sup.stopped.copy(), sup.estopped)
    out = sup.command("dance", {"robots": "all"})
    assert not out.accepted
    assert out.command == "dance"
    assert "unknown command 'dance'" in out.reason
    for name in ("park", "goto", "formation", "stop", "estop", "resume"):
        assert name in out.reason
    assert np.array_equal(sup.goals, before[0]) and sup.estopped == before[2]
    assert sup.outcomes[-1] is out


def test_a_command_given_as_a_mapping_is_checked_against_its_schema():
    sup = Supervisor(make_world())
    out = sup.command("goto", {"robot": "a", "pose": [4.0, 3.0, 90.0]})
    assert out.accepted, out.reason
    assert sup.goals[0] == pytest.approx([4.0, 3.0, np.pi / 2])
    bad = sup.command("goto", {"robot": "a"})
    assert not bad.accepted and bad.reason.startswith("goto.pose: Field required")
    assert sup.goals[0] == pytest.approx([4.0, 3.0, np.pi / 2])  # orders unchanged


def test_a_link_to_other_robots_is_refused():
    world = make_world()
    with pytest.raises(ValueError, match=r"link: robots \['zz'\] differ from the scenario's"):
        Supervisor(world, link=FakeLink(["zz"], [[1.0, 1.0, 0.0]]))


def test_the_registry_runs_every_scenario_command():
    assert COMMANDS.names()[:6] == ("park", "goto", "formation", "stop", "estop", "resume")
    sup = Supervisor(make_world())
    assert sup.command("stop", ["a"]).accepted and sup.stopped[0]
    assert sup.command("resume", "all").accepted and not sup.stopped[0]
    assert sup.command("estop").accepted and sup.estopped


# ----------------------------------------------------------------------------- inbox


def test_inbox_keeps_the_newest_message_whatever_the_arrival_order():
    box_ = Inbox(("a", "b"))
    box_.absorb(
        [
            Odometry("a", 2.0, np.array([2.0, 0, 0]), np.zeros(2)),
            Odometry("a", 1.0, np.array([1.0, 0, 0]), np.zeros(2)),  # late
            Odometry("a", 2.0, np.array([9.0, 0, 0]), np.zeros(2)),  # duplicate stamp
            Odometry("zz", 3.0, np.zeros(3), np.zeros(2)),  # not in this fleet
            Scan("b", 0.5, np.ones(4)),
        ]
    )
    assert box_.odom[0].tolist() == [2.0, 0.0, 0.0]
    assert box_.ignored == 3
    assert box_.last_seen.tolist() == [2.0, 0.5]
    assert box_.take_scans().tolist() == [1] and box_.take_scans().tolist() == []
    assert box_.age(3.0)[0] == pytest.approx(1.0)


# ----------------------------------------------------------------------------- faults


def _faulty(faults, **kw):
    return make_world(
        robots=[{"id": "a", "pose": [2.0, 3.0, 0.0]}, {"id": "b", "pose": [5.0, 3.0, 0.0]}],
        faults=faults,
        **kw,
    )


def _spin(link, until_s, cmd=(0.2, 0.0)):
    """Drive both robots with ``cmd`` until ``until_s``; yields the time and the messages
    received after each step."""
    while link.now() < until_s - 1e-9:
        link.send([VelocityCommand(r, link.now(), *cmd) for r in link.ids])
        link.spin()
        yield link.now(), link.receive()


def test_dropped_messages_leave_no_fresh_odometry_in_the_window():
    link = SimLink(_faulty([{"robot": "a", "from_s": 1.0, "to_s": 2.0, "drop": True}]))
    link.connect()
    box_ = Inbox(link.ids)
    box_.absorb(link.receive())  # the reports at connect
    age_a = {}
    for t, msgs in _spin(link, 3.0):
        box_.absorb(msgs)
        age_a[round(t, 2)] = box_.age(t)[0]
        stamps = {m.stamp for m in msgs if isinstance(m, Odometry) and m.robot == "a"}
        if 1.0 <= t < 2.0 - 1e-9:
            assert not stamps  # robot a is silent
        else:
            assert stamps == {t}
        assert any(isinstance(m, Odometry) and m.robot == "b" for m in msgs)
    # Its last odometry is from just before the window, and it is fresh again after it.
    assert age_a[1.95] == pytest.approx(1.0)
    assert age_a[2.0] == 0.0
    # Commands were lost too: a kept its last one for its dead-man time, then stopped.
    assert link.sim.vel[0, 0] == pytest.approx(0.2)  # moving again after the window
    v_a = {}
    link2 = SimLink(_faulty([{"robot": "a", "from_s": 1.0, "to_s": 2.0, "drop": True}]))
    link2.connect()
    for t, _ in _spin(link2, 1.99):
        v_a[round(t, 2)] = link2.sim.vel[:, 0].copy()
    # The last command that got through was sent at 0.95 s; it holds until 0.95 + 0.5 s.
    assert v_a[0.95 + CMD_TIMEOUT_S][0] == pytest.approx(0.2)
    assert v_a[1.55][0] < 0.2 and v_a[1.95][0] == 0.0  # decelerating, then stopped
    assert v_a[1.95][1] == pytest.approx(0.2)  # the other robot never noticed


def test_delayed_messages_arrive_late_and_stale_ones_are_ignored():
    link = SimLink(_faulty([{"robot": "a", "from_s": 1.0, "to_s": 1.5, "delay_s": 0.3}]))
    link.connect()
    box_ = Inbox(link.ids)
    lags = []
    for t, msgs in _spin(link, 2.5):
        lags += [t - m.stamp for m in msgs if isinstance(m, Odometry) and m.robot == "a"]
        box_.absorb(msgs)
        # The inbox never goes back in time.
        assert box_.odom_stamp[0] <= t
    assert max(lags) == pytest.approx(0.3, abs=1e-6)
    assert box_.ignored > 0  # late messages that arrived after newer ones
    assert box_.odom_stamp[0] == pytest.approx(2.5)


def test_noise_fault_perturbs_reported_poses_only():
    clean = SimLink(_faulty([]))
    noisy = SimLink(_faulty([{"robot": "a", "from_s": 0.0, "to_s": 5.0, "noise_m": 0.1}]))
    for link in (clean, noisy):
        link.connect()
        link.receive()
    a = [m for _, ms in _spin(clean, 1.0) for m in ms if isinstance(m, PoseReport)]
    b = [m for _, ms in _spin(noisy, 1.0) for m in ms if isinstance(m, PoseReport)]
    err = [
        np.hypot(*(x.pose[:2] - y.pose[:2])) for x, y in zip(a, b, strict=True) if x.robot == "a"
    ]
    same = [np.allclose(x.pose, y.pose) for x, y in zip(a, b, strict=True) if x.robot == "b"]
    assert 0.03 < np.mean(err) < 0.3 and all(same)
    assert np.allclose(clean.sim.poses, noisy.sim.poses)  # the robots themselves are untouched


@pytest.mark.parametrize(
    "fault, message",
    [
        ({"robot": "x", "from_s": 1, "to_s": 2, "drop": True}, r"faults\[0\].robot: unknown robot"),
        ({"robot": "a", "from_s": 2, "to_s": 1, "drop": True}, r"faults\[0\]: to_s must be after"),
        ({"robot": "a", "from_s": 1, "to_s": 2}, r"faults\[0\]: a fault needs drop"),
        ({"robot": "a", "from_s": 1, "to_s": 2, "delay_s": -1}, r"faults\[0\].delay_s"),
    ],
)
def test_bad_faults_are_refused_naming_the_field(fault, message):
    with pytest.raises(ScenarioError, match=message):
        _faulty([fault])


def test_amcl_skips_a_silent_robot_and_catches_up_when_it_reports_again():
    """Onboard localization runs per robot on what arrives: a robot whose messages are dropped
    keeps its estimate, then its filter takes the whole odometry increment at once."""
    world = make_world(
        robots=[{"id": "a", "pose": [1.5, 1.5, 0.0]}, {"id": "b", "pose": [8.0, 4.5, 180.0]}],
        sensing={"localization": "amcl", "lidar_beams": 120},
        faults=[{"robot": "a", "from_s": 1.0, "to_s": 2.0, "drop": True}],
        commands=[
            {"goto": {"robot": "a", "pose": [6.0, 1.5, 0.0]}},
            {"goto": {"robot": "b", "pose": [4.0, 4.5, 180.0]}},
        ],
    )
    sup = Supervisor(world)
    est = {}
    while sup.t < 2.5 - 1e-9:
        sup.tick()
        est[round(sup.t, 2)] = sup.estimates.copy()
    frozen = [est[t][0] for t in est if 1.0 <= t < 2.0 - 1e-9]
    assert len(frozen) >= 19 and all(np.array_equal(frozen[0], e) for e in frozen)
    assert est[1.95][1][0] < est[1.05][1][0] - 0.1  # b kept moving and localizing
    # Back after the window: a's estimate jumps forward with the odometry it missed, and is
    # where a really is.
    assert est[2.0][0][0] - frozen[-1][0] > 0.1
    assert np.hypot(*(sup.estimates[0, :2] - sup.sim.poses[0, :2])) < 0.1


def test_the_reassignment_never_takes_a_spot_from_under_a_parked_skid():
    """Three spots in a row; the skids bound for the two outer ones stand on them, the third
    is far off to the west. The formation cost (shapes matched after moving the centroids
    together) would hand the parked western skid the middle spot and the far one its spot:
    the solve prices a parked skid's other goals higher, but not enough. A re-assignment that
    moves a parked (or docking) skid's goal is not taken (a generated people site: a skid just
    parked was sent on to the row's deeper spot past a skid parked in between, and the run
    parked 9 of 10)."""
    cmd = ParkCmd(
        robots=["p", "q", "r"],
        boundary=[[6.0, 2.4], [10.0, 2.4], [10.0, 3.6], [6.0, 3.6]],
        heading_deg=0,
        margin_m=0.05,
        assignment="formation",
    )
    spread = [{"id": k, "pose": [1.0 + 2.0 * n, 1.0, 0.0]} for n, k in enumerate("pqr")]
    _, _, lay, _ = Supervisor(make_world(map={"size_m": [12, 6]}, robots=spread)).plan_layout(cmd)
    goals = lay.poses[np.argsort(lay.poses[:, 0])]  # west to east
    robots = [
        {"id": "p", "pose": [goals[0, 0], goals[0, 1], 0.0]},  # parked on the western spot
        {"id": "q", "pose": [1.5, goals[1, 1], 0.0]},  # far off
        {"id": "r", "pose": [goals[2, 0], goals[2, 1], 0.0]},  # parked on the eastern spot
    ]
    sup = Supervisor(make_world(map={"size_m": [12, 6]}, robots=robots))
    assert sup.park(cmd).accepted
    g = sup.groups[0]
    g.goal_of = np.array(
        [int(np.argmin(np.hypot(*(g.goals[:, :2] - goals[k, :2]).T))) for k in range(3)]
    )
    sup.goals[g.robots] = g.goals[g.goal_of]
    before = sup.goals.copy()
    # The solve alone would free the parked skid p (the case this rule is for).
    cost = assign_mod.cost_matrix(sup.poses_known[:, :2], g.goals[:, :2], "formation")
    pos_err, _ = goal_errors(sup.poses_known, g.goals[g.goal_of])
    new, changed = assign_mod.reassign(cost, g.goal_of, pos_err <= POSITION_TOL_M)
    assert changed and new[0] != g.goal_of[0]
    sup._reassign()
    np.testing.assert_array_equal(sup.goals, before)
