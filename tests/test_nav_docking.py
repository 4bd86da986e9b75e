"""The docking manoeuvre on hand-built views: which way it drives, when it runs up again, that
it holds still once parked, and that a skid beside its goal docks."""

import numpy as np
import pytest
from navkit import advance, make_view

from swarmpark.control.nav.docking import Docking, DockState, goal_frame_errors
from swarmpark.control.nav.params import BackUpParams, DockingParams
from swarmpark.control.nav.recovery import BackUp, BackUpState, StallWatch

GOAL = [5.0, 3.0, 0.0]


class Harness:
    """One skid's docking states and the component."""

    def __init__(self, n: int = 1) -> None:
        self.dock = Docking(DockingParams(), BackUp(BackUpParams(), stall_s=2.0), stall_s=2.0)
        self.docks = [DockState() for _ in range(n)]
        self.stalls = [StallWatch() for _ in range(n)]
        self.backups = [BackUpState() for _ in range(n)]

    def step(self, view, raw=None, final=True):
        n = len(view.poses)
        raw = np.zeros((n, 2)) if raw is None else np.asarray(raw, float)
        final = np.full(n, final)
        return self.dock.step(view, np.arange(n), raw, final, self.docks, self.stalls, self.backups)


def test_goal_frame_errors_are_in_the_goal_frame():
    # Goal facing +y: a skid 0.2 m "behind" it (lower y) and 0.1 m to its right (higher x).
    e_long, e_lat, e_yaw, dist = goal_frame_errors(
        np.array([[5.1, 2.8, np.pi / 2]]), np.array([[5.0, 3.0, np.pi / 2]])
    )
    assert e_long[0] == pytest.approx(-0.2)
    assert e_lat[0] == pytest.approx(-0.1)
    assert e_yaw[0] == pytest.approx(0.0)
    assert dist[0] == pytest.approx(np.hypot(0.1, 0.2))


@pytest.mark.parametrize(("x", "sign"), [(4.6, 1.0), (5.4, -1.0)])
def test_drives_along_the_goal_axis_towards_the_goal(x, sign):
    # Aligned on the axis, behind the goal (drives forwards) or past it (reverses).
    h = Harness()
    cmd = h.step(make_view([[x, 3.0, 0.0]], [GOAL]))
    assert np.sign(cmd[0, 0]) == sign
    assert cmd[0, 1] == pytest.approx(0.0, abs=1e-9)
    # On its line: up to the aligned share of the top speed (0.5 m/s in the views).
    p = DockingParams()
    assert 0.5 * p.max_speed_share < abs(cmd[0, 0]) <= p.aligned_speed_share * 0.5 + 1e-12
    assert h.docks[0].phase == "approach"


def test_off_its_line_a_skid_docks_at_the_docking_share():
    # As far off the axis as aligned_lateral_m (and 20 deg off the heading): the precise
    # manoeuvre's cap, half the top speed.
    p = DockingParams()
    h = Harness()
    cmd = h.step(make_view([[4.0, 3.0 + p.aligned_lateral_m, np.deg2rad(-20.0)]], [GOAL]))
    assert 0.0 < cmd[0, 0] <= p.max_speed_share * 0.5 + 1e-12


@pytest.mark.parametrize("brake_share", [0.5, 0.0])
def test_docking_brakes_onto_the_goal(brake_share):
    # From 1 m out on the axis: docked inside the parked band; braking at half the
    # acceleration limit gets there sooner than the proportional law (brake_share 0).
    p = DockingParams(brake_share=brake_share)
    h = Harness()
    h.dock.params = p
    view = make_view([[4.0, 3.0, 0.0]], [GOAL], dt=0.05)
    for _ in range(400):
        cmd = h.step(view)
        if h.docks[0].docked:
            break
        view = advance(view, cmd)
    assert h.docks[0].docked
    assert abs(view.poses[0, 0] - GOAL[0]) < p.parked_pos_m
    # (2.15 s against 3.6 s: the proportional law creeps the last decimetres.)
    assert view.t < 3.0 if brake_share else view.t > 3.0


def test_steers_back_onto_the_axis():
    # Behind the goal, 5 cm to its left (+y): the skid turns right (negative yaw rate).
    h = Harness()
    cmd = h.step(make_view([[4.3, 3.05, 0.0]], [GOAL]))
    assert cmd[0, 0] > 0 and cmd[0, 1] < 0


def test_runs_up_when_too_close_to_fix_the_lateral_error():
    # 10 cm behind the goal but 10 cm off its axis: back out along the axis (away from the
    # goal, i.e. reverse here) and come in again.
    h = Harness()
    cmd = h.step(make_view([[4.9, 3.1, 0.0]], [GOAL]))
    assert h.docks[0].phase == "run-up"
    assert cmd[0, 0] < 0
    # Once the lateral error is small again the run-up ends and it comes in forwards.
    cmd = h.step(make_view([[4.5, 3.02, 0.0]], [GOAL]))
    assert h.docks[0].phase == "approach"
    assert cmd[0, 0] > 0


def test_runs_up_when_the_monitor_holds_it_still():
    h = Harness()
    h.stalls[0].stalled_s = 2.0  # held still by the monitor for stall_s
    # 5 cm off the axis: closable on the way in, but worth a run-up when wedged.
    cmd = h.step(make_view([[4.5, 3.05, 0.0]], [GOAL]))
    assert h.docks[0].phase == "run-up" and cmd[0, 0] < 0
    assert h.stalls[0].stalled_s == 0.0


def test_turns_in_place_first_when_far_off_the_goal_heading():
    h = Harness()
    cmd = h.step(make_view([[4.5, 3.0, np.deg2rad(100.0)]], [GOAL]))
    assert cmd[0, 0] == 0.0
    assert cmd[0, 1] < 0  # towards heading 0, the short way


def test_parked_skid_holds_still_and_resumes_when_pushed_out():
    h = Harness()
    cmd = h.step(make_view([[5.01, 3.0, 0.0]], [GOAL]))
    assert np.array_equal(cmd, np.zeros((1, 2)))
    assert h.docks[0].phase == "docked" and h.docks[0].settled
    # Within the outer band it stays docked (no hunting) ...
    cmd = h.step(make_view([[5.06, 3.0, 0.0]], [GOAL]))
    assert h.docks[0].docked and np.array_equal(cmd, np.zeros((1, 2)))
    # ... beyond it, it docks again (reversing to the goal); settled stays (RVO yields).
    cmd = h.step(make_view([[5.2, 3.0, 0.0]], [GOAL]))
    assert not h.docks[0].docked and h.docks[0].settled
    assert cmd[0, 0] < 0
    # A new goal forgets all of it.
    h.step(make_view([[5.2, 3.0, 0.0]], [[8.0, 3.0, 0.0]], goal_changed=[True]))
    assert not h.docks[0].settled


def test_outside_the_manoeuvre_keeps_the_field_command():
    h = Harness()
    raw = np.array([[0.3, 0.1]])
    cmd = h.step(make_view([[2.0, 3.0, 0.0]], [GOAL]), raw=raw)
    assert np.array_equal(cmd, raw)
    # Held still there for stall_s: the back-up recovery reverses, against the field's pull.
    h.stalls[0].stalled_s = 2.0
    cmd = h.step(make_view([[2.0, 3.0, 0.0]], [GOAL]), raw=raw)
    assert cmd[0, 0] == pytest.approx(-BackUpParams().speed_share * 0.5)
    assert h.backups[0].left_m == BackUpParams().distance_m


def test_a_settled_skid_pushed_far_off_its_spot_drives_back_and_never_backs_up():
    """RVO made room with it: 2 m behind its spot, held still by whoever pushed it there
    (behind it), it keeps the field's command towards its spot instead of backing into them."""
    h = Harness()
    h.step(make_view([[5.0, 3.0, 0.0]], [GOAL]))
    assert h.docks[0].settled
    raw = np.array([[0.5, 0.0]])
    h.stalls[0].stalled_s = 2.0
    cmd = h.step(make_view([[3.0, 3.0, 0.0]], [GOAL]), raw=raw)
    assert np.array_equal(cmd, raw) and h.backups[0].left_m == 0.0


@pytest.mark.parametrize("start", [[4.2, 3.06, 0.05], [5.5, 2.95, -0.08], [4.95, 3.12, 0.0]])
def test_a_skid_beside_its_goal_docks(start):
    h = Harness()
    view = make_view([start], [GOAL])
    for _ in range(400):
        cmd = h.step(view)
        if h.docks[0].docked:
            break
        view = advance(view, cmd)
    p = DockingParams()
    e_long, e_lat, e_yaw, _ = goal_frame_errors(view.poses, np.array([GOAL]))
    assert h.docks[0].docked, view.poses
    assert abs(e_long[0]) < p.parked_pos_m and abs(e_lat[0]) < p.dock_lateral_m
    assert abs(e_yaw[0]) < p.parked_yaw_rad


@pytest.mark.parametrize(
    ("kw", "name"),
    [
        ({"parked_pos_m": 0.2}, "parked_pos_m"),
        ({"runup_m": -1.0}, "runup_m"),
        ({"max_speed_share": 1.5}, "max_speed_share"),
        ({"align_first_rad": 4.0}, "align_first_rad"),
    ],
)
def test_docking_params_name_the_bad_field(kw, name):
    with pytest.raises(ValueError, match=f"DockingParams.{name}"):
        DockingParams(**kw)
