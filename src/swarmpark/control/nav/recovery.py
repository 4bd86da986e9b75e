"""Recoveries: what a skid does when it is held still or makes no progress.

As Navigation2's recovery behaviours, each is a small named step with its own per-robot state:

- :class:`StallWatch`: how long a skid has been held (nearly) still; the trigger of the others.
- :class:`BackUp`: reverse straight along the axis (Navigation2's back-up), without RVO.
- :class:`GiveWay`: right of way at bottlenecks without RVO: back away from a skid of higher
  rank that has been holding this one up.
- :class:`DeadlockLadder`: with RVO, an ordered ladder of rungs (:data:`RUNGS`) climbed while a
  skid makes no progress (:mod:`swarmpark.core.progress`) and left as soon as it does:
  :class:`PriorityBump`, then :class:`BackOut` when held still, else :class:`SideStep`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from swarmpark.control.base import ControlView
from swarmpark.control.nav.params import (
    BackUpParams,
    DeadlockParams,
    GiveWayParams,
    StallParams,
)
from swarmpark.core.geometry import wrap_angle
from swarmpark.core.progress import made_progress, remaining_m

__all__ = [
    "RUNGS",
    "BackOut",
    "BackUp",
    "BackUpState",
    "DeadlockLadder",
    "DeadlockState",
    "GiveWay",
    "GiveWayState",
    "PriorityBump",
    "SideStep",
    "StallWatch",
    "axis_away",
    "away_from_nearest",
]

#: Below this measured speed a skid backing up is not moving (odometry noise floor).
_MOVING_MPS = 1e-3


def axis_away(view: ControlView, i: int, j: int) -> float:
    """+1 or -1: the direction along skid ``i``'s axis away from skid ``j``."""
    away = view.poses[i, :2] - view.poses[j, :2]
    th = view.poses[i, 2]
    return float(np.sign(away[0] * np.cos(th) + away[1] * np.sin(th) + 1e-9))


def away_from_nearest(view: ControlView, i: int) -> float:
    """+1 or -1: the direction along skid ``i``'s axis away from the nearest other skid."""
    others = np.delete(np.arange(len(view.poses)), i)
    if not len(others):
        return -1.0
    d = np.linalg.norm(view.poses[others, :2] - view.poses[i, :2], axis=1)
    return axis_away(view, i, int(others[np.argmin(d)]))


@dataclass
class StallWatch:
    """How long (s) a skid's command has kept it (nearly) still, docked skids excepted."""

    stalled_s: float = 0.0

    def update(self, p: StallParams, cmd: np.ndarray, docked: bool, dt: float) -> None:
        still = abs(cmd[0]) < p.speed_mps and abs(cmd[1]) < p.yaw_rate_radps and not docked
        self.stalled_s = self.stalled_s + dt if still else 0.0

    @staticmethod
    def update_all(p: StallParams, watches: list, cmd: np.ndarray, docked: list, dt: float):
        """:meth:`update` for many skids: ``watches``, their commands ``(n, 2)`` and whether
        each is docked (the comparisons made for all at once)."""
        slow = (np.abs(cmd[:, 0]) < p.speed_mps) & (np.abs(cmd[:, 1]) < p.yaw_rate_radps)
        for w, s, d in zip(watches, slow.tolist(), docked, strict=True):
            w.stalled_s = w.stalled_s + dt if s and not d else 0.0


# ---------------------------------------------------------------------- back up


@dataclass
class BackUpState:
    """Metres still to back up (0: not backing up)."""

    left_m: float = 0.0


class BackUp:
    """Navigation2's back-up: held still for ``stall_s``, reverse straight for
    ``distance_m`` (away from the way the field pulls), then let the field try again."""

    def __init__(self, params: BackUpParams, *, stall_s: float) -> None:
        self.params = params
        self.stall_s = stall_s

    def step(self, st: BackUpState, stall: StallWatch, raw_v, v_now, dt, v_max):
        """The back-up command ``(v, 0)`` while backing up (started here when stalled), or
        None. ``raw_v``: the field's speed; ``v_now``: the measured one."""
        if stall.stalled_s >= self.stall_s and st.left_m <= 0:
            st.left_m, stall.stalled_s = self.params.distance_m, 0.0
        if st.left_m <= 0:
            return None
        st.left_m -= max(abs(v_now) * dt, 0.0) if abs(v_now) > _MOVING_MPS else 0.0
        if stall.stalled_s >= self.stall_s:  # backing is blocked too
            st.left_m = 0.0
        return (-np.sign(raw_v + 1e-9) * self.params.speed_share * v_max, 0.0)


# ---------------------------------------------------------------------- give way


@dataclass
class GiveWayState:
    """Who held the skid up at full speed last tick and for how long, and whether (until
    when, from whom) it is giving way."""

    blockers: set = field(default_factory=set)
    blocked_s: float = 0.0
    until_s: float = -np.inf
    from_robot: int = -1
    #: Held up without a break, giving way or not (``blocked_s`` restarts when it gives way).
    held_s: float = 0.0

    def observe(self, blockers: set, dt: float) -> None:
        """The monitor's verdict this tick: the skids that slowed this one (or none)."""
        self.blockers = blockers
        self.blocked_s = self.blocked_s + dt if blockers else 0.0
        self.held_s = self.held_s + dt if blockers else 0.0


class GiveWay:
    """Right of way at bottlenecks: a skid held up by a skid of higher rank (priority, then
    nearer its goal, then lower index) for ``after_s`` backs away from it for up to
    ``duration_s``, so the other can pass, if the other is held up in turn (by this skid, or
    by anything for ``after_s``): one that drives on unhindered needs no room (a skid backed
    2.4 m away from a neighbour docking beside it, and drove back). Docking skids never give
    way.

    A skid of lower rank may be unable to clear (boxed in, turning on the spot between parked
    skids and the ones waiting for it): held up by it for ``inherit_after_s``, the skid of
    higher rank gives way to it as well. This is the step of priority inheritance with
    backtracking (Okumura et al., "Priority inheritance with backtracking for iterative
    multi-agent path finding", AIJ 2022) that a local rule can take: an agent whose way is
    held by one that cannot move gives up its own move instead of waiting for ever."""

    def __init__(self, params: GiveWayParams) -> None:
        self.params = params

    def step(self, view, idx, raw, dist_goal, states: list[GiveWayState], docked) -> np.ndarray:
        """Commands for robots ``idx`` (``docked``: per robot)."""
        p = self.params
        out = raw.copy()
        rank = {int(i): (-view.priority[i], dist_goal[k], int(i)) for k, i in enumerate(idx)}
        for k, i in enumerate(idx):
            st = states[i]
            if docked[i] or dist_goal[k] < p.exempt_within_m:
                st.until_s = -np.inf
                continue
            if view.t >= st.until_s and st.blocked_s >= p.after_s:
                # A skid of higher rank that drives on unhindered passes by itself: only one
                # held up by this skid (or held up a while by anything) is given way.
                better = [
                    j
                    for j in st.blockers
                    if j in rank
                    and rank[j] < rank[int(i)]
                    and (int(i) in states[j].blockers or states[j].held_s >= p.after_s)
                ]
                better += [j for j in st.blockers if j not in rank]  # idle/parked skids
                if not better and st.held_s >= p.inherit_after_s:
                    better = [j for j in st.blockers if j in rank]  # they could not clear
                if better:
                    st.from_robot = min(better, key=lambda j: rank.get(j, (-np.inf,)))
                    st.until_s = view.t + p.duration_s
                    st.blocked_s = 0.0
            if view.t < st.until_s:
                j = st.from_robot
                if np.linalg.norm(view.poses[i, :2] - view.poses[j, :2]) > p.clear_m:
                    st.until_s = -np.inf
                    continue
                out[k] = (p.speed_share * view.max_speed[i] * axis_away(view, i, j), 0.0)
        return out


# ---------------------------------------------------------------------- the RVO ladder


@dataclass(frozen=True)
class Stuck:
    """What a rung sees of a stuck skid."""

    view: ControlView
    robot: int
    stuck_for_s: float
    stall: StallWatch
    stall_s: float


class Rung:
    """A step of the deadlock ladder, with its own state."""

    name: ClassVar[str] = ""
    #: While this rung runs, no other rung starts.
    holds: ClassVar[bool] = False

    def running(self, t: float) -> bool:
        return False

    def ready(self, s: Stuck, p: DeadlockParams) -> bool:
        return True

    def start(self, s: Stuck, p: DeadlockParams, backup: BackUpParams) -> None:
        pass

    def stop(self) -> None:
        pass


@dataclass
class PriorityBump(Rung):
    """Raise the stuck skid's ORCA priority by ``bump`` plus up to as much again the nearer
    it is to its goal, so the jam is ordered (nearest first, whatever the robots' order)."""

    name: ClassVar[str] = "priority bump"

    @staticmethod
    def value(p: DeadlockParams, remaining: float) -> float:
        return p.bump * (1.0 + 1.0 / (1.0 + remaining))


@dataclass
class BackOut(Rung):
    """Held still for ``stall_s`` (typically by the collision monitor, when ORCA's holonomic
    centre asks for a turn its corners have no room for): back out straight along the axis,
    away from the nearest skid, for the back-up distance."""

    name: ClassVar[str] = "back out"
    holds: ClassVar[bool] = True
    left_m: float = 0.0
    direction: float = 0.0  # +1 forwards, -1 backwards along the axis

    def running(self, t: float = 0.0) -> bool:
        return self.left_m > 0

    def ready(self, s: Stuck, p: DeadlockParams) -> bool:
        return s.stall.stalled_s >= s.stall_s

    def start(self, s: Stuck, p: DeadlockParams, backup: BackUpParams) -> None:
        self.left_m = backup.distance_m
        self.direction = away_from_nearest(s.view, s.robot)
        s.stall.stalled_s = 0.0

    def advance(self, speed_mps: float, dt: float, blocked: bool) -> None:
        """Count the distance driven; stop when backing out is blocked too."""
        self.left_m -= abs(speed_mps) * dt
        if blocked:
            self.left_m = 0.0

    def stop(self) -> None:
        self.left_m = 0.0


@dataclass
class SideStep(Rung):
    """Every further ``stuck_s`` (from twice ``stuck_s`` on) the preferred velocity points
    ``sidestep_rad`` to the right of the path for ``sidestep_s``."""

    name: ClassVar[str] = "side step"
    until_s: float = -np.inf

    def running(self, t: float) -> bool:
        return t < self.until_s

    def ready(self, s: Stuck, p: DeadlockParams) -> bool:
        return (
            p.sidestep_s > 0
            and s.view.t >= self.until_s + p.stuck_s
            and s.stuck_for_s >= 2 * p.stuck_s
        )

    def start(self, s: Stuck, p: DeadlockParams, backup: BackUpParams) -> None:
        self.until_s = s.view.t + p.sidestep_s

    def stop(self) -> None:
        self.until_s = -np.inf


#: The ladder, in order: the first rung starts when a skid gets stuck and stays on until it
#: makes progress; later, unless a holding rung runs, the first ready rung after it starts.
RUNGS: tuple[type[Rung], ...] = (PriorityBump, BackOut, SideStep)


@dataclass
class DeadlockState:
    """One skid's deadlock watch: the best remaining distance since the last progress and
    when, the open episode (a record in :attr:`DeadlockLadder.episodes`) and the rungs."""

    best_remaining: float = np.inf
    best_t: float = 0.0
    episode: dict | None = None
    rungs: tuple[Rung, ...] = field(default_factory=lambda: tuple(cls() for cls in RUNGS))

    def __post_init__(self) -> None:
        # The first rung of each kind, looked up once (the rungs are a fixed tuple).
        self._rung_of: dict[type, Rung] = {}
        for cls in RUNGS:
            found = [r for r in self.rungs if isinstance(r, cls)]
            if found:
                self._rung_of[cls] = found[0]

    def rung(self, cls: type[Rung]) -> Rung:
        r = self._rung_of.get(cls)
        return r if r is not None else next(r for r in self.rungs if isinstance(r, cls))

    @property
    def back_out(self) -> BackOut:
        return self.rung(BackOut)  # type: ignore[return-value]

    @property
    def side_step(self) -> SideStep:
        return self.rung(SideStep)  # type: ignore[return-value]

    def stop(self) -> None:
        for r in self.rungs:
            r.stop()


class DeadlockLadder:
    """Detect and resolve deadlocks between skids on the move (RVO).

    A skid with an unreached goal that has not made ``progress_m`` of progress for
    ``stuck_s`` is deadlocked (symmetric jams, where every ORCA solution is to wait); it climbs
    the ladder :data:`RUNGS` while it stays stuck, and leaves it when it makes progress again.
    Each episode is recorded in :attr:`episodes` with the rungs taken and the time to clear.
    """

    def __init__(self, params: DeadlockParams, backup: BackUpParams, *, stall_s: float) -> None:
        self.params = params
        self.backup = backup
        self.stall_s = stall_s
        #: Episodes: robot index, start, actions, time to clear.
        self.episodes: list[dict] = []

    def remaining(self, view: ControlView) -> np.ndarray:
        """Remaining distance of every skid to its goal (:mod:`swarmpark.core.progress`)."""
        pos = np.linalg.norm(view.goals[:, :2] - view.poses[:, :2], axis=1)
        yaw = np.abs(wrap_angle(view.goals[:, 2] - view.poses[:, 2]))
        return remaining_m(pos, yaw, self.params.heading_lever_m)

    def step(
        self,
        view: ControlView,
        settled: np.ndarray,
        states: list[DeadlockState],
        stalls: list[StallWatch],
    ) -> np.ndarray:
        """Update every skid's watch and rungs; returns the priority bumps ``(N,)``."""
        p = self.params
        bump = np.zeros(len(view.poses))
        remaining = self.remaining(view)
        # Per-skid flags as Python bools, read once for all.
        idle = (view.goal_changed | ~view.active | settled).tolist()
        gone = (~view.active | settled).tolist()
        for i in range(len(view.poses)):
            st = states[i]
            if idle[i]:
                st.best_remaining, st.best_t = remaining[i], view.t
                st.stop()
                if st.episode is not None and gone[i]:
                    self._close(st, view.t)
                continue
            if made_progress(remaining[i], st.best_remaining, p.progress_m):
                st.best_remaining, st.best_t = remaining[i], view.t
                if st.episode is not None:
                    self._close(st, view.t)
            stuck_for = view.t - st.best_t
            if stuck_for < p.stuck_s:
                continue
            s = Stuck(view, i, stuck_for, stalls[i], self.stall_s)
            self._climb(st, s, i)
            bump[i] = PriorityBump.value(p, remaining[i])
        return bump

    def _climb(self, st: DeadlockState, s: Stuck, i: int) -> None:
        rungs = st.rungs
        first = rungs[0]
        if st.episode is None:
            first.start(s, self.params, self.backup)
            st.episode = {"robot": i, "start_s": round(s.view.t, 3), "actions": [first.name]}
            self.episodes.append(st.episode)
        t = s.view.t
        for r in rungs:
            if r.holds and r.running(t):
                return  # a holding rung runs: no other starts
        for rung in rungs[1:]:
            if rung.ready(s, self.params):
                rung.start(s, self.params, self.backup)
                st.episode["actions"].append(rung.name)
                return

    @staticmethod
    def _close(st: DeadlockState, t: float) -> None:
        st.episode["cleared_after_s"] = round(t - st.episode["start_s"], 3)
        st.episode = None
        st.stop()
