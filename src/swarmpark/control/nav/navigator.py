"""Navigation for parking: the default controller, composed of named components.

As in the 2018 paper (Sect. 3.4), each skid plans a least-cost path on the inflated costmap to
its assigned goal (:mod:`.planner`) and the potential field (:mod:`.field`) drives it along the
path towards a lookahead pose (:mod:`.follower`); near the goal the docking manoeuvre
(:mod:`.docking`) takes it to the exact pose. Skid-skid avoidance is either the collision
monitor alone (:mod:`.monitor`, as Navigation2's, with right of way at bottlenecks, keep right
on the field's aim, :mod:`.keep_right`, and parked skids making room, :mod:`.make_room`, for a
skid of higher priority or one walled in by parked skids, which ranks above the others until it
docks, and skids waiting for the fill order or a door stepping out of the way of those on the
move) or ORCA (:mod:`.avoidance`, with :mod:`.make_room`) followed by the monitor. Skids held
still or making no progress recover (:mod:`.recovery`). Shared geometry is in :mod:`.scene`,
every tuning value in :mod:`.params`.

One tick (:meth:`Navigator.compute`), in this order: bring the scene up to date, plan, follow,
keep right (monitor mode), drive with the field, dock; then either make room for priority,
give way and monitor, or make room, climb the deadlock ladder, run ORCA and monitor jointly;
hold back skids waiting for the fill order; watch for stalls.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from swarmpark.control.base import ControlView
from swarmpark.control.nav.avoidance import AvoidanceInput, OrcaAdapter
from swarmpark.control.nav.docking import Docking, DockState
from swarmpark.control.nav.field import PotentialField
from swarmpark.control.nav.fleetmap import FleetState
from swarmpark.control.nav.follower import PathFollower, PathState
from swarmpark.control.nav.hold import hold_outside
from swarmpark.control.nav.keep_right import KeepRight
from swarmpark.control.nav.make_room import MakeRoom, RoomState, cut_off
from swarmpark.control.nav.manoeuvre import ManoeuvrePlanner, ManoeuvreState
from swarmpark.control.nav.monitor import CollisionMonitor, MonitorResult
from swarmpark.control.nav.params import NavParams
from swarmpark.control.nav.people import PeopleYield
from swarmpark.control.nav.planner import Planner
from swarmpark.control.nav.recovery import (
    BackUp,
    BackUpState,
    DeadlockLadder,
    DeadlockState,
    GiveWay,
    GiveWayState,
    StallWatch,
)
from swarmpark.control.nav.scene import Scene
from swarmpark.control.nav.traffic import TrafficControl, TrafficState
from swarmpark.core.activity import ACTIVITIES
from swarmpark.core.geometry import footprint_corners, rect_disc_gap

__all__ = ["NavParams", "Navigator", "RobotNav"]


@dataclass
class RobotNav:
    """One skid's navigation state: one state machine per component."""

    path: PathState = field(default_factory=PathState)
    dock: DockState = field(default_factory=DockState)
    room: RoomState = field(default_factory=RoomState)
    stall: StallWatch = field(default_factory=StallWatch)
    backup: BackUpState = field(default_factory=BackUpState)
    give_way: GiveWayState = field(default_factory=GiveWayState)
    deadlock: DeadlockState = field(default_factory=DeadlockState)
    manoeuvre: ManoeuvreState = field(default_factory=ManoeuvreState)
    traffic: TrafficState = field(default_factory=TrafficState)


#: Each activity's code in :attr:`Navigator.activity`.
_ACTIVITY = {name: k for k, name in enumerate(ACTIVITIES)}


class Navigator:
    """The default controller: plan, follow with the potential field, dock, avoid, recover.

    Parameters
    ----------
    params
        :class:`~swarmpark.control.nav.params.NavParams` (the defaults if None).
    """

    def __init__(self, params: NavParams | None = None) -> None:
        p = NavParams() if params is None else params
        if not isinstance(p, NavParams):
            raise ValueError(f"Navigator.params must be a NavParams (got {p!r})")
        self.params = p
        stall_s = p.stall.time_s
        self.scene = Scene(p.apf.outline_step_m, p.monitor.margin_m)
        self.follower = PathFollower(p.follower)
        self.traffic = TrafficControl(p.traffic)
        self.planner = Planner(
            p.planner,
            staging_m=p.docking.runup_m,
            direct_within_m=p.docking.manoeuvre_radius_m,
            fleet_params=p.fleet_map,
            people=p.people if p.people.enabled else None,
            zones=self.traffic.bottlenecks,
        )
        self.field = PotentialField(p.apf, dynamic=p.avoidance != "rvo")
        self.docking = Docking(p.docking, BackUp(p.backup, stall_s=stall_s), stall_s=stall_s)
        self.monitor = CollisionMonitor(p.monitor)
        self.manoeuvre = ManoeuvrePlanner(p.manoeuvre)
        self.give_way = GiveWay(p.give_way)
        self.keep_right = KeepRight(p.keep_right)
        self.make_room = MakeRoom(p.make_room)
        self.people = PeopleYield(p.people)
        self.ladder = DeadlockLadder(p.deadlock, p.backup, stall_s=stall_s)
        self.avoidance = OrcaAdapter(
            p.rvo,
            room_priority=p.make_room.priority,
            sidestep_rad=p.deadlock.sidestep_rad,
            back_speed_share=p.backup.speed_share,
        )
        self.robots: list[RobotNav] = []
        self._state_key: tuple[int, int] | None = None
        self._state_lists: dict[str, list] = {}
        #: (N,) skids standing aside for another on purpose this tick (RVO; not deadlocked).
        self.making_room = np.zeros(0, dtype=bool)
        #: (N,) skids waiting for a bottleneck this tick (queued on purpose; not deadlocked).
        self.queued = np.zeros(0, dtype=bool)
        self._view: ControlView | None = None  # the last tick's view (for :meth:`explain`)
        #: (N,) skids the fill order holds back that have come to where it stops them (near
        #: their boundary, or their own spot when following a skid bound deeper); kept while
        #: the hold lasts. Only these wait on purpose: a held skid farther out is on its way.
        self.at_hold = np.zeros(0, dtype=bool)
        #: Per skid, the bounds of its hold zone on the last tick (a hold that moves ends the
        #: wait at its stop).
        self._held_at: list = []
        #: (N,) what each skid did on purpose this tick (codes into
        #: :data:`swarmpark.core.activity.ACTIVITIES`), for the run result's lost time.
        self.activity = np.zeros(0, dtype=np.int8)

    @property
    def recoveries(self) -> list[dict]:
        """Deadlock recoveries (RVO): robot index, start, actions, time to clear."""
        return self.ladder.episodes

    def paths(self) -> list[np.ndarray | None]:
        """Current planned paths (world points), for display."""
        return [r.path.path for r in self.robots]

    def _states(self, name: str) -> list:
        """Every skid's state of one component (e.g. ``"path"``), in skid order. The state
        objects live as long as their skid, so the lists are kept until the fleet grows (or
        :attr:`robots` is replaced) instead of being gathered several times per tick."""
        key = (id(self.robots), len(self.robots))
        if key != self._state_key:
            self._state_key, self._state_lists = key, {}
        out = self._state_lists.get(name)
        if out is None:
            out = self._state_lists[name] = [getattr(r, name) for r in self.robots]
        return out

    def prepare(self, view: ControlView) -> None:
        """Per-map work done before the first tick (the supervisor calls it at load): the
        scene's outlines, each footprint's costmap and the bottleneck zones. Each is kept
        until the map or the fleet changes, so the ticks give the same commands as without."""
        self.scene.update(view)
        for fp in view.footprints:
            self.planner.costmap(view, fp)
        if self.params.traffic.enabled:
            self.traffic.prepare(view)

    # ------------------------------------------------------------------ the tick

    def compute(self, view: ControlView) -> np.ndarray:
        """Commanded ``(v, omega)`` ``(N, 2)``; inactive robots get zeros."""
        p = self.params
        n = len(view.poses)
        while len(self.robots) < n:
            self.robots.append(RobotNav())
        cmd = np.zeros((n, 2))
        self._view = view
        idx = np.flatnonzero(view.active)
        if len(idx) == 0:
            return cmd
        view = self._inherit(view)
        scene = self.scene.update(view)
        paths = self._states("path")
        if p.avoidance == "rvo":
            self._cut_off(view)
        fleet = self._fleet(view)
        self.planner.update(view, paths, self.follower, fleet if p.fleet_map.enabled else None)
        targets, final, stage_left = self.follower.targets(view, idx, paths)
        # Skids whose path is for an older goal (queued for planning) hold still meanwhile.
        waiting = self.follower.waiting(view, idx, paths)
        reverse = self.follower.update_ends(view, idx, final, paths)
        # Docked now (before this tick's docking step), per robot.
        docked_now = np.array([r.dock.docked for r in self.robots], dtype=bool)
        if p.avoidance != "rvo":
            targets = self._keep_right(view, idx, targets, final | waiting, fleet, docked_now)
        # On the way to a staging point a skid is parking already: as in its final approach,
        # only obstacles very near push it (the walls beside its spot held one still 1.3 m
        # from it, in a local minimum of the field).
        staging = np.isfinite(stage_left)
        raw, dist_goal = self.field.drive(
            self.people.field_view(view),
            idx,
            scene,
            targets,
            reverse,
            final | staging,
            p.follower.approach_m,
        )
        raw[waiting] = 0.0
        # On the way to a staging point to turn there: brake to stop on it.
        if staging.any():
            share = p.follower.stage_brake_share
            cap = np.sqrt(2.0 * share * view.max_accel[idx[staging]] * stage_left[staging])
            raw[staging, 0] = np.clip(raw[staging, 0], -cap, cap)
        # A skid stuck for a while drives a planned manoeuvre instead (not docked, not held
        # back by the fill order or queued at a door: fleet.waiting).
        docked = docked_now[idx]
        man_states = self._states("manoeuvre")
        # With RVO the deadlock ladder is the recovery: manoeuvres on top of it made the
        # 20-skid circle slower (126.7 s against 86.7 s without them).
        use = p.manoeuvre.enabled and p.avoidance != "rvo"
        eligible = ~docked & ~waiting & ~fleet.waiting[idx] & use
        # Walled in is judged against the settled skids, which could make room.
        settled = self._settled(view)[0] if p.make_room.for_walled else None
        # A skid that cannot turn on the spot to its path plans one sooner.
        tight = eligible & ~final
        cramped = np.zeros(len(idx), dtype=bool)
        if use and tight.any():
            cramped[tight] = self.manoeuvre.cramped(
                view, idx[tight], targets[tight, 2], scene.static.kd if scene.static else None
            )
        man = self.manoeuvre.step(
            view, idx, raw, man_states, eligible, settled, paths, cramped, targets[:, 2]
        )
        for i in idx[man]:
            self.robots[i].dock.runup = False  # the docking starts afresh after it
        mraw = raw[man].copy()
        raw = self.docking.step(
            view,
            idx,
            raw,
            final & ~waiting & ~man,
            self._states("dock"),
            self._states("stall"),
            self._states("backup"),
        )
        raw[man] = mraw
        if p.avoidance == "rvo":
            full = np.zeros((n, 2))
            full[idx] = raw
            cruising = ~final & ~waiting & ~man
            aims, _, _ = self.follower.targets(view, idx[cruising], paths, p.rvo.lookahead_m)
            full = self._avoid(view, full, idx[cruising], aims)
            moving = np.flatnonzero(np.any(np.abs(full) > 0, axis=1) | view.active)
            full[moving], aside = self._yield(view, moving, full[moving])
            cmd[moving] = self._monitor(view, moving, full[moving], joint=True)
            self._guard_aside(view, moving[aside], full, cmd)
        else:
            raw = self._make_room(view, idx, raw, fleet.waiting)
            docked_all = [r.dock.docked for r in self.robots]  # per robot, not per row
            raw = self.give_way.step(
                view, idx, raw, dist_goal, self._states("give_way"), docked_all
            )
            raw[man] = mraw
            raw, aside = self._yield(view, idx, raw)
            # A skid whose turn alone hits a wall drives on straight (RVO steers instead).
            cmd[idx] = self._monitor(view, idx, raw, straight=True)
            full = np.zeros((n, 2))
            full[idx] = raw
            self._guard_aside(view, idx[aside], full, cmd)
        self.manoeuvre.observe(view, idx, man_states, raw, cmd[idx])
        held = self._hold(view, idx, cmd)
        self.queued = np.zeros(n, dtype=bool)
        if p.traffic.enabled:
            self.queued[idx] = self.traffic.step(
                view, idx, cmd, paths, self.follower, self._states("traffic"), fleet.parked
            )
        # How long the monitor or the field has kept each skid (nearly) still. A skid waiting
        # outside its boundary for the fill order or at a door for its turn is not stuck: it
        # does not back up (it backed 0.5 m out of the queue and drove back, 4-5 s lost each
        # time, on a generated elevator site).
        robots = [self.robots[i] for i in idx]
        waits = held & self.at_hold[idx]  # standing at its stop for the fill order
        paused = (waits | self.queued[idx]).tolist()
        StallWatch.update_all(
            p.stall,
            [r.stall for r in robots],
            cmd[idx],
            [r.dock.docked or w for r, w in zip(robots, paused, strict=True)],
            view.dt,
        )
        self._activity(n, idx, waits)
        return cmd

    def _activity(self, n: int, idx: np.ndarray, held: np.ndarray) -> None:
        """Fill :attr:`activity` for skids ``idx`` (``held``: waiting for the fill order):
        of :data:`~swarmpark.core.activity.ACTIVITIES` the first that applies of waiting for
        the fill order, queued, manoeuvring, held by the monitor, making room."""
        act = np.zeros(n, dtype=np.int8)
        rows = [
            ("making_room", self.making_room[idx] if len(self.making_room) == n else None),
            ("monitor", np.array([self.robots[i].stall.stalled_s > 0 for i in idx], bool)),
            ("manoeuvring", np.array([self.robots[i].manoeuvre.running() for i in idx], bool)),
            ("queued", self.queued[idx]),
            ("fill_order", held),
        ]
        for name, mask in rows:  # the later ones take precedence
            if mask is not None and mask.any():
                act[idx[mask]] = _ACTIVITY[name]
        self.activity = act

    def explain(self, i: int) -> tuple[str, list[int]]:
        """Why skid ``i`` is not getting anywhere, as far as navigation knows (for deadlock
        reports): a reason and the skids involved."""
        if i >= len(self.robots):
            return "not driven", []
        r = self.robots[i]
        if r.path.failed:
            return "no path to its goal on the known map", []
        person = self._person_at_spot(i)
        if person:
            return person, []
        holders = self.queue_holders(i)
        if holders:
            return "queued at a bottleneck held by skids that make no progress", holders
        if r.manoeuvre.running():
            return "manoeuvring towards its goal", []
        if r.manoeuvre.walled:
            return "walled in by parked skids (they make room for it)", []
        blockers = sorted(r.give_way.blockers)
        if blockers:
            return "held by the collision monitor before other skids", blockers
        if r.stall.stalled_s > 0:
            if r.manoeuvre.failed:
                return "held still; no manoeuvre to its goal found around the skids standing", []
            return "held still by the collision monitor (walls, obstacles or people)", []
        if self.making_room is not None and i < len(self.making_room) and self.making_room[i]:
            return "making room for another skid", []
        return "moving without progress (a local minimum of the potential field)", []

    def queue_holders(self, i: int) -> list[int]:
        """The skids holding the grant for the bottleneck zone skid ``i`` is queued at (empty
        if it is not queued), as of the last tick."""
        if i >= len(self.queued) or not self.queued[i]:
            return []
        zone = self.robots[i].traffic.waiting
        return [j for j, r in enumerate(self.robots) if j != i and zone and r.traffic.zone == zone]

    def _person_at_spot(self, i: int) -> str:
        """A person standing within the berth skids keep from standing people (the
        people's ``clearance_m`` plus ``standing_berth_m``) of skid ``i``'s goal footprint,
        as of the last tick: the skid cannot dock while they stand there."""
        view, pp = self._view, self.params.people
        if view is None or i >= len(view.poses) or not len(view.people_xy):
            return ""
        standing = np.linalg.norm(view.people_vel, axis=1) < pp.walking_mps
        if not standing.any():
            return ""
        body = view.footprints[i].corners_body()[None]
        corners = np.repeat(footprint_corners(view.goals[i][None], body), standing.sum(), axis=0)
        gap = float(
            np.min(rect_disc_gap(corners, view.people_xy[standing], view.people_radius[standing]))
        )
        berth = pp.clearance_m + pp.standing_berth_m
        if gap >= berth:
            return ""
        return (
            f"a person stands {max(gap, 0.0):.2f} m from its spot (skids keep {berth:.2f} m "
            "from a standing person)"
        )

    def _yield(self, view: ControlView, idx: np.ndarray, raw: np.ndarray):
        """People's right of way (:mod:`.people`): the commands of skids ``idx`` and which
        of them step out of a person's way (they dock again afterwards)."""
        res = self.people.step(view, idx, raw, self.scene)
        for i in idx[res.stepping_aside]:
            self.robots[i].dock.docked = False
        return res.commands, res.stepping_aside

    def _guard_aside(self, view: ControlView, rows: np.ndarray, full, cmd) -> None:
        """Skids stepping out of a person's way are checked against walls and skids only."""
        if len(rows):
            free = self.people.without_people(view)
            cmd[rows] = self.monitor.check(free, rows, full[rows], self.scene).commands

    def _inherit(self, view: ControlView) -> ControlView:
        """Monitor mode: the view with walled-in skids ranked above all others (until they
        dock or get a new goal), so that parked skids in their way make room."""
        p = self.params
        if not p.make_room.for_walled or p.avoidance == "rvo":
            return view
        walled = np.zeros(len(view.poses), dtype=bool)
        for i, r in enumerate(self.robots[: len(view.poses)]):
            st = r.manoeuvre
            if st.walled and (r.dock.docked or view.goal_changed[i] or not view.active[i]):
                st.walled = False
            walled[i] = st.walled
        if not walled.any():
            return view
        pr = np.asarray(view.priority, dtype=float).copy()
        pr[walled] = pr.max() + 1.0
        return replace(view, priority=pr)

    def _keep_right(self, view, idx, targets, not_cruising, fleet, docked) -> np.ndarray:
        """Monitor mode: the lookahead points of skids ``idx`` following their paths, turned
        clockwise where a skid on the move comes the other way (:mod:`.keep_right`). On the
        move: active, not docked, not held back or queued, not stopped, and farther than
        ``keep_right.near_goal_m`` from its goal (nearer, it is parking). ``docked``: per
        robot."""
        full = view.goals.copy()
        full[idx] = targets
        away = (
            np.hypot(*(view.goals[:, :2] - view.poses[:, :2]).T)
            > self.params.keep_right.near_goal_m
        )
        movers = view.active & ~docked & ~fleet.waiting & away
        if view.stopped is not None:
            movers &= ~view.stopped
        cruising = idx[~not_cruising]
        cruising = cruising[movers[cruising]]
        full = self.keep_right.turn_targets(
            view.poses, full, view.goals, view.priority, cruising, movers, self.scene
        )
        return full[idx]

    def _hold(self, view: ControlView, idx: np.ndarray, cmd: np.ndarray):
        """The fill order's holds (:func:`.hold.hold_outside`, in place on ``cmd``): which of
        ``idx`` are held outside. Updates :attr:`at_hold`: a skid counts as waiting from when
        it first reaches its stop until the hold ends (a follower held short of its spot
        stood still 21 m from it, its clock stopped, for 65 s on a generated corridor site,
        taken for waiting). A skid whose hold moves (from outside its boundary to short of its
        own spot, when the skid it follows is on its way in) is on its way again: latched, it
        stood 4 m outside a dead-end bay, its command held still as a waiting skid's, until the
        skid ahead had parked (a new user's site: each of five skids in file waited so)."""
        n = len(view.poses)
        held, at_stop = hold_outside(view, idx, cmd, self.params.hold)
        zones = [
            None if z is None else z.bounds
            for z in (view.hold_zones if view.hold is not None else ())
        ]
        zones += [None] * (n - len(zones))
        reached = np.zeros(n, dtype=bool)
        reached[idx[at_stop]] = True
        if view.hold_outside is not None:
            # Held outside and kept still on its way to its stop: it stands in the queue for
            # its boundary, behind the skids held before it, and waits where it stands.
            # Not one that stands in the boundary already (in its door, in everyone's way).
            after = self.params.hold.stuck_s
            out = idx[view.hold_outside[idx] & held].tolist()
            reached[[i for i in out if self.robots[i].stall.stalled_s >= after]] = True
        if len(self.at_hold) == n:
            same = np.array([a == b for a, b in zip(self._held_at, zones, strict=True)], bool)
            reached |= self.at_hold & same
        hold = np.zeros(n, dtype=bool) if view.hold is None else view.hold
        self.at_hold = reached & hold
        self._held_at = zones
        return held

    def _make_room(
        self, view: ControlView, idx: np.ndarray, raw: np.ndarray, waiting: np.ndarray
    ) -> np.ndarray:
        """Monitor mode: parked skids in the way of a skid of higher priority move aside
        along their axis (:mod:`.make_room`) and dock again once it has passed; skids
        ``waiting`` on purpose (fill order, queues) move out of the way of skids on the move."""
        settled, _ = self._settled(view)
        p = self.params
        room = self.make_room.step(
            view,
            settled,
            self._states("path"),
            self._states("room"),
            self.scene,
            by_priority=True,
            people=p.people.enabled,
        )
        speed, aside = room.speed, room.aside
        if p.make_room.for_waiting:
            wait = self.make_room.step_waiting(
                view,
                waiting,
                settled,
                self._states("path"),
                self._states("room"),
                self.scene,
                p.hold.gap_m,
            )
            speed = np.where(wait.aside, wait.speed, speed)
            aside = aside | wait.aside
        self.making_room = aside
        for i in np.flatnonzero(room.undock):
            self.robots[i].dock.docked = False  # dock again precisely once the way is clear
        rows = np.flatnonzero(aside[idx])
        if len(rows):
            raw = raw.copy()
            raw[rows, 0] = speed[idx[rows]]
            raw[rows, 1] = 0.0
        return raw

    def _settled(self, view: ControlView) -> tuple[np.ndarray, np.ndarray]:
        """The skids settled on their goal that can move, and the immobile ones (stopped,
        e-stopped or idle), each ``(N,)``."""
        immobile = ~view.active
        if view.stopped is not None:
            immobile |= view.stopped
        settled = np.array([r.dock.settled for r in self.robots], dtype=bool) & ~immobile
        return settled, immobile

    def _cut_off(self, view: ControlView) -> None:
        """RVO: a skid pushed off its spot with another parked in between since is on the move
        again, its plan repaired round the parked skids (:func:`.make_room.cut_off`)."""
        settled, _ = self._settled(view)
        if settled.sum() < 2:
            return
        shut = cut_off(view, settled, self.scene.skids.plain, self.params.docking.resume_pos_m)
        for i in np.flatnonzero(shut):
            self.robots[i].dock.new_goal()
            self.planner.repair(i)

    def _fleet(self, view: ControlView) -> FleetState:
        """The fleet as the planner sees it (:class:`~.fleetmap.FleetState`)."""
        settled = np.array([r.dock.settled for r in self.robots], dtype=bool)
        stopped = np.zeros(len(settled), bool) if view.stopped is None else view.stopped
        parked = settled | ~view.active | stopped
        held = np.array([r.stall.stalled_s for r in self.robots]) >= self.params.fleet_map.still_s
        bound = view.active & ~settled
        waiting = np.array([r.traffic.waiting > 0 for r in self.robots], dtype=bool)
        if view.hold is not None and len(self.at_hold) == len(waiting):
            waiting |= view.hold & self.at_hold
        return FleetState(parked=parked, bound=bound, still=bound & held, waiting=waiting)

    def guard(self, view: ControlView, idx: np.ndarray, raw: np.ndarray) -> np.ndarray:
        """Commands ``raw`` of skids ``idx`` not driven by this controller (teleop, formation
        plans), scaled down by the collision monitor until their short forward simulation is
        free."""
        while len(self.robots) < len(view.poses):
            self.robots.append(RobotNav())
        self.scene.update(view)
        idx = np.asarray(idx, int)
        return self.monitor.check(view, idx, np.asarray(raw, float), self.scene).commands

    def _monitor(self, view: ControlView, idx: np.ndarray, raw: np.ndarray, **kw) -> np.ndarray:
        """The monitor's safe commands; it also tells give-way who held each skid up."""
        res: MonitorResult = self.monitor.check(view, idx, raw, self.scene, **kw)
        for k, i in enumerate(idx):
            self.robots[i].give_way.observe(res.blockers[k], view.dt)
        return res.commands

    def _avoid(
        self, view: ControlView, raw: np.ndarray, cruising: np.ndarray, aims: np.ndarray
    ) -> np.ndarray:
        """RVO: make room, climb the deadlock ladder, then one ORCA step for all skids."""
        robots = self.robots
        settled, immobile = self._settled(view)
        room = self.make_room.step(
            view, settled, self._states("path"), self._states("room"), self.scene
        )
        self.making_room = room.aside
        for i in np.flatnonzero(room.undock):
            robots[i].dock.docked = False  # dock again precisely once the way is clear
        ladders = self._states("deadlock")
        bump = self.ladder.step(view, settled, ladders, self._states("stall"))
        backs = [d.back_out for d in ladders]
        backing = np.array([b.running() for b in backs], dtype=bool)
        backing &= ~immobile
        res = self.avoidance.step(
            view,
            raw,
            cruising,
            aims,
            self.scene,
            AvoidanceInput(
                settled=settled,
                immobile=immobile,
                room_speed=room.speed,
                aside=room.aside,
                bump=bump,
                side_step=np.array(
                    [ladders[i].side_step.running(view.t) for i in cruising.tolist()], dtype=bool
                ),
                backing=backing,
                back_dir=np.array([b.direction for b in backs]),
            ),
        )
        for i in np.flatnonzero(self.avoidance.pushed(settled, res.along)):
            robots[i].dock.docked = False  # pushed aside: dock again precisely afterwards
        stall_s = self.params.stall.time_s
        for i in np.flatnonzero(backing):
            r = robots[i]
            r.deadlock.back_out.advance(view.vel[i, 0], view.dt, r.stall.stalled_s >= stall_s)
        return res.commands
