"""Recoveries on hand-built views: the deadlock ladder climbs its rungs in order while a skid
makes no progress and is left on progress; back-up, give-way and the stall watch."""

import numpy as np
import pytest
from navkit import make_view

from swarmpark.control.nav.params import (
    BackUpParams,
    DeadlockParams,
    GiveWayParams,
    StallParams,
)
from swarmpark.control.nav.recovery import (
    RUNGS,
    BackOut,
    BackUp,
    BackUpState,
    DeadlockLadder,
    DeadlockState,
    GiveWay,
    GiveWayState,
    SideStep,
    StallWatch,
)

GOAL = [8.0, 3.0, 0.0]


class Ladder:
    """Two skids: 0 is stuck far from its goal, 1 stands 2 m behind it (for the back-out)."""

    def __init__(self) -> None:
        self.ladder = DeadlockLadder(DeadlockParams(), BackUpParams(), stall_s=2.0)
        self.states = [DeadlockState(), DeadlockState()]
        self.stalls = [StallWatch(), StallWatch()]
        self.x = 2.0

    def tick(self, t: float, stalled: bool = False) -> np.ndarray:
        if stalled:
            self.stalls[0].stalled_s = 2.0
        view = make_view(
            [[self.x, 3.0, 0.0], [self.x - 2.0, 3.0, 0.0]],
            [GOAL, [self.x - 2.0, 3.0, 0.0]],
            t=t,
            active=[True, False],
            goal_changed=[t == 0.0, False],
        )
        return self.ladder.step(view, np.zeros(2, bool), self.states, self.stalls)

    @property
    def actions(self) -> list[str]:
        ep = self.states[0].episode
        return [] if ep is None else ep["actions"]


def test_the_rungs_are_in_one_ordered_list():
    assert [r.name for r in RUNGS] == ["priority bump", "back out", "side step"]
    assert [type(r) for r in DeadlockState().rungs] == list(RUNGS)


def test_ladder_escalates_while_there_is_no_progress():
    lad, p = Ladder(), DeadlockParams()
    for t in np.arange(0.0, p.stuck_s - 0.05, 0.1):
        assert lad.tick(round(t, 2))[0] == 0.0
    assert lad.actions == []
    # Stuck for stuck_s: the priority is bumped (more the nearer the goal).
    bump = lad.tick(p.stuck_s)
    remaining = 6.0  # 6 m to go, aligned
    assert bump[0] == pytest.approx(p.bump * (1 + 1 / (1 + remaining)))
    assert bump[1] == 0.0  # idle skids are never bumped
    assert lad.actions == ["priority bump"]
    # Not before twice stuck_s: no side step.
    lad.tick(2 * p.stuck_s - 0.1)
    assert lad.actions == ["priority bump"]
    lad.tick(2 * p.stuck_s)
    assert lad.actions == ["priority bump", "side step"]
    assert lad.states[0].side_step.running(2 * p.stuck_s + 0.1)
    assert not lad.states[0].side_step.running(2 * p.stuck_s + p.sidestep_s)
    # Held still now: it backs out, away from the skid behind it (forwards).
    lad.tick(2 * p.stuck_s + 0.1, stalled=True)
    assert lad.actions[-1] == "back out"
    back = lad.states[0].back_out
    assert back.running() and back.left_m == BackUpParams().distance_m
    assert back.direction == 1.0
    assert lad.stalls[0].stalled_s == 0.0
    # While backing out no other rung starts, even when one would be due.
    lad.tick(5 * p.stuck_s)
    assert lad.actions[-1] == "back out"
    assert len(lad.ladder.episodes) == 1


def test_ladder_is_left_on_progress_and_the_episode_closed():
    lad, p = Ladder(), DeadlockParams()
    lad.tick(0.0)
    lad.tick(p.stuck_s)
    lad.tick(p.stuck_s + 0.1, stalled=True)
    assert lad.actions == ["priority bump", "back out"]
    episode = lad.states[0].episode
    lad.x += 2 * p.progress_m  # progress
    t_clear = p.stuck_s + 0.5
    bump = lad.tick(t_clear)
    assert bump[0] == 0.0
    assert lad.states[0].episode is None
    assert episode["cleared_after_s"] == pytest.approx(t_clear - p.stuck_s)
    assert not any(r.running(t_clear) for r in lad.states[0].rungs)
    # Stuck again later: a new episode starts from the first rung.
    lad.tick(t_clear + p.stuck_s)
    assert lad.actions == ["priority bump"]
    assert len(lad.ladder.episodes) == 2


def test_small_moves_are_not_progress():
    lad, p = Ladder(), DeadlockParams()
    lad.tick(0.0)
    lad.x += 0.5 * p.progress_m
    lad.tick(p.stuck_s)
    assert lad.actions == ["priority bump"]


def test_settled_or_idle_skids_close_their_episode():
    lad, p = Ladder(), DeadlockParams()
    lad.tick(0.0)
    lad.tick(p.stuck_s)
    view = make_view([[lad.x, 3.0, 0.0], [0.0, 3.0, 0.0]], [GOAL, GOAL], t=p.stuck_s + 1)
    lad.ladder.step(view, np.array([True, False]), lad.states, lad.stalls)
    assert lad.states[0].episode is None
    assert "cleared_after_s" in lad.ladder.episodes[0]


def test_back_out_and_side_step_rungs_keep_their_own_state():
    back, side = BackOut(), SideStep()
    assert not back.running() and not side.running(0.0)
    back.left_m, back.direction = 0.5, -1.0
    back.advance(-0.2, 0.5, blocked=False)
    assert back.left_m == pytest.approx(0.4)
    back.advance(0.0, 0.1, blocked=True)  # backing out is blocked too
    assert not back.running()
    side.until_s = 3.0
    side.stop()
    assert not side.running(0.0)


def test_back_up_reverses_against_the_field_and_stops_when_blocked():
    p = BackUpParams()
    bu = BackUp(p, stall_s=2.0)
    st, stall = BackUpState(), StallWatch(stalled_s=0.5)
    assert bu.step(st, stall, 0.3, 0.0, 0.1, 0.5) is None  # not stalled long enough
    stall.stalled_s = 2.0
    cmd = bu.step(st, stall, 0.3, 0.0, 0.1, 0.5)
    assert cmd == (pytest.approx(-p.speed_share * 0.5), 0.0)
    assert st.left_m == p.distance_m and stall.stalled_s == 0.0
    cmd = bu.step(st, stall, 0.3, -0.25, 0.1, 0.5)  # driving back at 0.25 m/s
    assert st.left_m == pytest.approx(p.distance_m - 0.025)
    stall.stalled_s = 2.0  # held still again while backing up: give up
    bu.step(st, stall, 0.3, 0.0, 0.1, 0.5)
    assert st.left_m == 0.0


def test_give_way_backs_away_from_a_higher_rank_and_not_when_docking():
    gw = GiveWay(GiveWayParams())
    # Skid 1 (priority 1) faces skid 0 (priority 2) 1.5 m ahead and was held up by it.
    view = make_view(
        [[5.0, 3.0, np.pi], [3.5, 3.0, 0.0]],
        [[1.0, 3.0, np.pi], [8.0, 3.0, 0.0]],
        priority=[2.0, 1.0],
        t=10.0,
    )
    raw = np.array([[0.3, 0.0], [0.3, 0.0]])
    dist = np.array([4.0, 4.5])
    # While skid 0 drives on unhindered, skid 1 waits for it to pass.
    states = [GiveWayState(), GiveWayState(blockers={0}, blocked_s=1.0)]
    out = gw.step(view, np.array([0, 1]), raw, dist, states, [False, False])
    assert np.array_equal(out, raw) and states[1].until_s == -np.inf
    # Skid 0 held up by skid 1 in turn: skid 1 backs away.
    states = [GiveWayState(blockers={1}), GiveWayState(blockers={0}, blocked_s=1.0)]
    out = gw.step(view, np.array([0, 1]), raw, dist, states, [False, False])
    assert out[1, 0] == pytest.approx(-GiveWayParams().speed_share * 0.5)  # backs away
    assert np.array_equal(out[0], raw[0])
    assert states[1].from_robot == 0 and states[1].until_s == 10.0 + GiveWayParams().duration_s
    # Held up by a lower rank: it keeps going...
    states = [GiveWayState(blockers={1}, blocked_s=1.0, held_s=1.0), GiveWayState()]
    out = gw.step(view, np.array([0, 1]), raw, dist, states, [False, False])
    assert np.array_equal(out, raw)
    # ...until that one has had inherit_after_s to clear and has not: then it gives way too.
    p = GiveWayParams()
    states[0].blocked_s = states[0].held_s = p.inherit_after_s
    out = gw.step(view, np.array([0, 1]), raw, dist, states, [False, False])
    assert out[0, 0] == pytest.approx(-p.speed_share * 0.5) and np.array_equal(out[1], raw[1])
    assert states[0].from_robot == 1 and states[0].blocked_s == 0.0
    # A docked skid never gives way.
    states = [GiveWayState(), GiveWayState(blockers={0}, blocked_s=1.0)]
    out = gw.step(view, np.array([0, 1]), raw, dist, states, [False, True])
    assert np.array_equal(out, raw)


def test_stall_watch_counts_still_commands_only():
    p, w = StallParams(), StallWatch()
    w.update(p, np.array([0.0, 0.0]), False, 0.1)
    w.update(p, np.array([0.01, 0.01]), False, 0.1)
    assert w.stalled_s == pytest.approx(0.2)
    w.update(p, np.array([0.0, 0.0]), True, 0.1)  # docked skids are still on purpose
    assert w.stalled_s == 0.0
    w.update(p, np.array([0.0, 0.0]), False, 0.1)
    w.update(p, np.array([0.1, 0.0]), False, 0.1)
    assert w.stalled_s == 0.0


@pytest.mark.parametrize(
    ("cls", "kw", "name"),
    [
        (DeadlockParams, {"stuck_s": 0.0}, "stuck_s"),
        (BackUpParams, {"speed_share": 2.0}, "speed_share"),
        (GiveWayParams, {"clear_m": float("nan")}, "clear_m"),
        (GiveWayParams, {"inherit_after_s": 0.0}, "inherit_after_s"),
        (StallParams, {"time_s": -1.0}, "time_s"),
    ],
)
def test_recovery_params_name_the_bad_field(cls, kw, name):
    with pytest.raises(ValueError, match=f"{cls.__name__}.{name}"):
        cls(**kw)
