"""The supervisor: per-robot state and the tick that holds the loop together.

The supervisor sees the robots only through a :class:`~swarmpark.links.base.RobotLink` (the
simulator's :class:`~swarmpark.sim.link.SimLink` by default), as it would see real ones:
what they report (pose or odometry, scans, status) is folded into an
:class:`~swarmpark.links.base.Inbox`, and they are sent velocity commands and stops.

Each :meth:`Supervisor.tick` runs the scenario's due commands (:mod:`.commands`) and
scripted events, re-runs the parking groups' assignment, asks the controller for velocities
from one snapshot of the swarm (holding skids back by the fill order, :mod:`.fill_order`),
sends them, lets the link spin one period, localizes and detects on what came back
(:mod:`.sensing`) and feeds the metrics.

Truth -- the simulator behind a SimLink, :attr:`Supervisor.sim` -- goes only to the metrics,
the reports (:mod:`.reports`) and the scripted events (kidnaps); the decision path reads the
inbox.
"""

from __future__ import annotations

import numpy as np

from swarmpark.control.base import Controller, ControlView
from swarmpark.core.geometry import body_corners
from swarmpark.links.base import CommandBatch, Inbox, RobotLink
from swarmpark.metrics import (
    HEADING_TOL_RAD,
    POSITION_TOL_M,
    MetricsRecorder,
    goal_errors,
)
from swarmpark.plan.spot_reach import manoeuvre_blocks, manoeuvre_order, spot_windows
from swarmpark.sim.link import SimLink
from swarmpark.sim.simulator import Simulator, StepResult
from swarmpark.supervisor import fill_order, reports
from swarmpark.supervisor.commands import CommandsMixin, Outcome, ParkGroup
from swarmpark.supervisor.health import Health, HealthParams
from swarmpark.supervisor.sensing import OnboardSensing
from swarmpark.supervisor.spot_watch import SpotWatch
from swarmpark.world.scenario import World

__all__ = ["Supervisor", "Outcome", "ParkGroup", "ROBOT_STATES", "TELEOP_TIMEOUT_S"]

#: A robot's state; "lost": its odometry stopped arriving (:mod:`.health`).
ROBOT_STATES = ("idle", "moving", "parked", "stopped", "estopped", "teleop", "stuck", "lost")
#: Teleop commands older than this are dropped (the operator let go or the link died).
TELEOP_TIMEOUT_S = 0.5


#: With onboard localization, a wall counts as seen from a cell if it is within this share of
#: the LIDAR's range: a wall at the range's edge returns a few grazing beams at most, one at
#: 0.8 of it the beams of a 74 degree fan (coastal navigation, :func:`default_controller`).
COASTAL_SEEN_FRACTION = 0.8


def default_controller(world: World) -> Controller:
    """The navigation stack of the scenario's ``navigation`` (mode and avoidance). When the
    skids localize with their LIDAR (``sensing.localization: amcl``), paths keep within sight
    of walls (coastal navigation, :func:`~swarmpark.plan.grid.build_costmap`): each metre
    farther than :data:`COASTAL_SEEN_FRACTION` of ``sensing.lidar_range_m`` from every wall
    costs ``sensing.coastal_weight`` metres more."""
    from swarmpark.control.nav.params import NavParams, PlannerParams
    from swarmpark.control.nav.stack import make_controller

    nav, sensing = world.scenario.navigation, world.scenario.sensing
    params = None
    if sensing.localization == "amcl" and sensing.coastal_weight > 0:
        planner = PlannerParams(
            seen_within_m=COASTAL_SEEN_FRACTION * sensing.lidar_range_m,
            blind_weight=sensing.coastal_weight,
        )
        params = NavParams(avoidance=nav.avoidance, planner=planner)
    return make_controller(nav.mode, nav.avoidance, params)


class Supervisor(CommandsMixin):
    """Runs a :class:`World` with a controller over a robot link.

    Parameters
    ----------
    world
        The scenario's world (map, obstacles the operator knows, commands, sensing options).
    controller
        The navigation stack (default: the scenario's ``navigation.mode``, see
        :func:`~swarmpark.control.nav.stack.make_controller`).
    link
        The robots: a :class:`~swarmpark.links.base.RobotLink`; ``None`` builds a
        :class:`~swarmpark.sim.link.SimLink` of ``world``; a bare
        :class:`~swarmpark.sim.simulator.Simulator` is wrapped in one.
    health
        Heartbeat and command-following limits (:class:`~.health.HealthParams`).
    """

    def __init__(
        self,
        world: World,
        controller: Controller | None = None,
        link: RobotLink | Simulator | None = None,
        health: HealthParams | None = None,
    ) -> None:
        self.world = world
        if link is None:
            link = SimLink(world)
        elif isinstance(link, Simulator):
            link = SimLink(world, sim=link)
        self.link = link
        #: The simulator behind the link, if any: truth for metrics, reports and scripted
        #: events only (``None`` for a link to real robots).
        self.sim: Simulator | None = getattr(link, "sim", None)
        self.info = link.connect()
        if list(self.info.ids) != list(world.ids):
            raise ValueError(
                f"link: robots {list(self.info.ids)} differ from the scenario's {world.ids}"
            )
        self.controller = controller if controller is not None else default_controller(world)
        n = self.n = self.info.n
        self.ids = list(self.info.ids)
        self.index = {rid: i for i, rid in enumerate(self.ids)}
        self.inbox = Inbox(self.info.ids)
        self.inbox.absorb(link.receive())
        self.goals = np.zeros((n, 3))
        self.has_goal = np.zeros(n, dtype=bool)
        self.priority = np.array([r.priority for r in world.robots], float)
        self.stopped = np.zeros(n, dtype=bool)
        self.estopped = False
        self._tick_start: float | None = None  # t at the start of the tick under way
        self._goto_costmap: tuple | None = None  # (grid, half width, costmap) for goto checks
        self.teleop = np.zeros(n, dtype=bool)
        self._teleop_cmd = np.zeros((n, 2))
        self._teleop_t = np.full(n, -np.inf)
        self.goal_changed = np.zeros(n, dtype=bool)
        self.groups: list[ParkGroup] = []
        self.formations: list = []
        self.outcomes: list[Outcome] = []
        self._corners_body = body_corners(list(self.info.footprints))
        self._static_pieces, self._static_owner = world.static_convex_pieces()
        # What the skids know of the world for planning: the map plus the static obstacles
        # (ground truth until onboard sensing feeds detections into the costmap).
        base = world.believed_grid if world.believed_grid is not None else world.grid
        self._known_grid = base.with_polygons(list(world.static_obstacles))
        self._base_grid = base
        self.sensing: OnboardSensing | None = None
        self.loc_errors: list[np.ndarray] = []
        self.loc_times: list[float] = []
        self.kidnapped: list[tuple[int, float]] = []  # (robot, time) of each kidnapping done
        self._kidnaps = sorted(world.scenario.sensing.kidnap, key=lambda k: k.at_s)
        if self._kidnaps and not hasattr(link, "teleport"):
            raise ValueError("sensing.kidnap: needs a link that can carry robots (the simulator)")
        if world.scenario.sensing.localization == "amcl":
            self.sensing = OnboardSensing(world, self.info, self.inbox, self._base_grid)
        self.spot_watch = SpotWatch()
        #: Robots lost (stale odometry) or not following their commands (:mod:`.health`).
        self.health = Health(self.ids, self.info, health)
        self.health.heartbeat(self.t, self.inbox.odom_stamp)
        self._sent = np.zeros((n, 2))
        self.metrics = MetricsRecorder(self.ids, self.truth_poses().copy())
        self.metrics.explain = self._explain
        self.metrics.max_speed_mps = np.asarray(self.info.max_speed_mps, float)
        self._pending = sorted(
            enumerate(world.scenario.commands), key=lambda kv: (kv[1].at_s, kv[0])
        )
        # Per-map work of the controller (costmaps, bottleneck zones) done at load, so the
        # first tick (often a park command for the whole fleet) does not carry it.
        prepare = getattr(self.controller, "prepare", None)
        if prepare is not None:
            prepare(self.view())

    # ------------------------------------------------------------------ state

    @property
    def t(self) -> float:
        return self.link.now()

    @property
    def poses_known(self) -> np.ndarray:
        """The poses the controller decides from: the skids' AMCL estimates when they
        localize onboard (``sensing.localization: amcl``), else the poses they report."""
        return self.sensing.estimates if self.sensing is not None else self.inbox.pose

    @property
    def estimates(self) -> np.ndarray:
        return self.poses_known

    @property
    def localizer(self):
        """The fleet's AMCL filters (``None`` without onboard localization)."""
        return self.sensing.localizer if self.sensing is not None else None

    @property
    def lidar_spec(self):
        """The skids' scanner (``None`` without sensing)."""
        return self.sensing.lidar_spec if self.sensing is not None else None

    @property
    def costmap(self):
        """Onboard obstacle detection (``None`` without sensing)."""
        return self.sensing.costmap if self.sensing is not None else None

    @property
    def known_grid(self):
        """The map the skids plan in: the map, plus static obstacles or detections."""
        return self.sensing.known_grid if self.sensing is not None else self._known_grid

    @property
    def sent(self) -> np.ndarray:
        """``(N, 2)``: the ``(v, omega)`` last commanded to each robot (zero when none was)."""
        return self._sent

    def truth_poses(self) -> np.ndarray:
        """Where the skids really are (the simulator's truth; without one, what they report).
        For metrics and reports only."""
        return self.sim.poses if self.sim is not None else self.poses_known

    def truth_vel(self) -> np.ndarray:
        return self.sim.vel if self.sim is not None else self.inbox.vel

    def modes(self) -> list[str]:
        """Per-robot state: idle, moving, parked, stopped, estopped, teleop or stuck."""
        pos_err, head_err = goal_errors(self.truth_poses(), self.goals)
        at_goal = self.has_goal & (pos_err <= POSITION_TOL_M) & (head_err <= HEADING_TOL_RAD)
        stuck = self.metrics.stuck()
        out = []
        for i in range(self.n):
            if self.estopped:
                out.append("estopped")
            elif self.health.lost[i]:
                out.append("lost")
            elif self.teleop[i]:
                out.append("teleop")
            elif self.stopped[i]:
                out.append("stopped")
            elif at_goal[i]:
                out.append("parked")
            elif stuck[i]:
                out.append("stuck")
            elif self.has_goal[i]:
                out.append("moving")
            else:
                out.append("idle")
        return out

    def pending_done(self) -> bool:
        return not self._pending

    # ------------------------------------------------------------------ fill order

    def _fill_holds(self, goals: np.ndarray, fps, boundary, order):
        """Fill-order holds of a new group on the planning map: ``(order, blocks, reach,
        flags)``.

        For a group with holds (:func:`.fill_order.reach`), the order is first made one in
        which a manoeuvre reaches every spot with the spots before it in place, where the
        layout's is not (:func:`swarmpark.plan.spot_reach.manoeuvre_order`), and a goal
        blocks those its rectangle would shut out (:func:`~swarmpark.plan.spot_reach.
        manoeuvre_blocks`) as well as those it shuts out for a disc
        (:func:`.fill_order.blockers`); ``flags`` is then empty, else None (the spots are
        checked in the layout's order as before)."""
        r = fill_order.reach(goals, fps, boundary, self.known_grid)
        flags, lattice = None, ()
        if r is not None:
            grid = self.park_map.grid()
            args = (grid.occupied, grid.origin, grid.resolution_m, goals, list(fps))
            # On the map's cells; if some spot is out of reach there, on the manoeuvre
            # planner's.
            for win in spot_windows(*args, finer=self._spot_window()):
                found, stuck = manoeuvre_order(win, order)
                if not stuck:
                    break
            if not stuck:
                # With spots no order reaches, the layout's is kept (filling those first
                # made the skids try the hopeless spots first: measured, see the docs).
                order, flags = found, []
            lattice = manoeuvre_blocks(win, order)
        blocks = fill_order.blockers(goals, fps, boundary, order, self.known_grid, r)
        if lattice:
            blocks = tuple(
                tuple(sorted(set(a) | set(b))) for a, b in zip(blocks, lattice, strict=True)
            )
        return order, blocks, r, flags

    def _spot_window(self) -> dict:
        """How the spot checks search (:class:`~swarmpark.plan.spot_reach.SpotWindow`): as
        the manoeuvre planner does by default (its cell size and goal tolerance), with the
        walls from the solids the skids avoid: the check says what the manoeuvres can do."""
        from swarmpark.control.nav.params import ManoeuvreParams

        pieces = self.sensing.static_view if self.sensing is not None else self._static_pieces
        mp = ManoeuvreParams()
        return {"pieces": pieces, "max_cell_m": mp.max_cell_m, "goal_tol_m": mp.goal_tol_m}

    def held(self) -> np.ndarray:
        """Robots the fill order holds back (:func:`.fill_order.holds`): outside their
        boundary, or short of their own spot."""
        outside, short = fill_order.holds(self.groups, self.poses_known)
        return outside | short

    # ------------------------------------------------------------------ the tick

    def _run_due_kidnaps(self) -> None:
        """Carry skids to their kidnap poses (a scripted event on the truth: the link's
        simulator moves them; their odometry does not see it)."""
        eps = 1e-9
        while self._kidnaps and self._kidnaps[0].at_s <= self.t + eps:
            kid = self._kidnaps.pop(0)
            i = self.index[kid.robot]
            pose = np.array([kid.pose[0], kid.pose[1], np.deg2rad(kid.pose[2])], float)
            self.link.teleport(i, pose)
            self.metrics.moved_by_hand(i, pose)
            self.kidnapped.append((i, self.t))

    def _explain(self, i: int) -> str:
        """What holds robot ``i`` up, for a deadlock report: the fill order, a stop, or what
        the controller says (with robot ids)."""
        if self.stopped[i] or self.teleop[i] or self.estopped:
            return "stopped by the operator"
        held = self.held()
        prefix = ""
        if len(held) == self.n and held[i]:
            if self._waiting_held(held)[i]:
                return "held back by the fill order"
            prefix = "held back by the fill order, not at its stop: "
        explain = getattr(self.controller, "explain", None)
        if explain is None:
            return prefix + "no progress"
        reason, others = explain(i)
        return prefix + (
            reason if not others else f"{reason}: {', '.join(self.ids[j] for j in others)}"
        )

    def _run_due_commands(self) -> None:
        eps = 1e-9
        while self._pending and self._pending[0][1].at_s <= self.t + eps:
            _, cmd = self._pending.pop(0)
            self.execute(cmd)

    def view(self) -> ControlView:
        info = self.info
        outside, short = fill_order.holds(self.groups, self.poses_known)
        if self.sensing is not None:
            # Onboard sensing: avoid the walls and what the scans detected (people included,
            # as still obstacles refreshed every scan), not the scenario's obstacles and people;
            # people the onboard tracker saw walk also with their velocities.
            people = self.sensing.people
            ppos, pvel, prad = people.xy, people.vel, people.radius_m
            static_pieces = self.sensing.static_view
        else:
            people = self.inbox.people  # as the link's people tracker reports them
            if people is None:
                ppos, prad = np.zeros((0, 2)), np.zeros(0)
                pvel = np.zeros_like(ppos)
            else:
                ppos, pvel, prad = people.xy, people.vel, people.radius_m
            static_pieces = self._static_pieces
        return ControlView(
            t=self.t,
            dt=info.dt_s,
            poses=self.poses_known.copy(),
            vel=self.inbox.vel.copy(),
            goals=self.goals.copy(),
            active=self.has_goal
            & ~self.stopped
            & ~self.teleop
            & (not self.estopped)
            & ~self.health.faulted
            & ~self._formation_mask(),
            priority=self.priority.copy(),
            footprints=info.footprints,
            max_speed=info.max_speed_mps,
            max_yaw_rate=info.max_yaw_rate_radps,
            max_accel=info.max_accel_mps2,
            max_yaw_accel=info.max_yaw_accel_radps2,
            grid=self.known_grid,
            people_xy=ppos,
            people_vel=pvel,
            people_radius=prad,
            static_pieces=static_pieces,
            goal_changed=self.goal_changed.copy(),
            hold=outside | short,
            # A lost robot is an immobile obstacle at its last known pose.
            stopped=self.stopped | self.teleop | self.estopped | self.health.faulted,
            hold_zones=tuple(self.hold_zones(short)),
            hold_outside=outside,  # fill_order.holds: outside and short never overlap
        )

    def _commands(self, view: ControlView) -> np.ndarray:
        """``(N, 2)`` velocity commands: the controller's, the formation plans', teleop."""
        cmd = np.asarray(self.controller.compute(view), float).reshape(self.n, 2)
        cmd[~view.active] = 0.0
        for f in self._running_formations():
            go = ~self.stopped[f.idx] & ~self.teleop[f.idx] & (not self.estopped)
            fc = f.command(
                self.t,
                self.poses_known[f.idx],
                view.people_xy,
                self.info.max_speed_mps[f.idx],
                self.info.max_yaw_rate_radps[f.idx],
            )
            cmd[f.idx] = np.where(go[:, None], fc, 0.0)
        fresh = self.teleop & (self.t - self._teleop_t <= TELEOP_TIMEOUT_S)
        cmd[fresh] = self._teleop_cmd[fresh]
        # Teleop and the formation plans go through the collision monitor too: the command is
        # slowed, and stopped, before the skid would touch a wall, an obstacle, a person or a
        # skid (a formation's paths are checked against the map once, but it is tracked
        # with errors, and the people it yields to may still step into it).
        guard = getattr(self.controller, "guard", None)
        rows = np.flatnonzero(fresh | self._formation_mask())
        if guard is not None and len(rows) and np.any(cmd[rows] != 0.0):
            cmd[rows] = guard(view, rows, cmd[rows])
        cmd[self.health.faulted] = 0.0
        return cmd

    def tick(self):
        """One decision phase for every robot from one snapshot, then one move phase."""
        try:
            return self._tick()
        finally:
            self._tick_start = None

    def _tick(self):
        self._run_due_commands()
        if self._kidnaps:
            self._run_due_kidnaps()
        self.inbox.absorb(self.link.receive())
        self._reassign()
        self._hand_over()
        view = self.view()
        # From here on a command accepted from another thread (the e-stop) may come too late
        # for this tick's decisions or step: it is stamped with the tick's end.
        self._tick_start = self.t
        cmd = self._commands(view)
        self.goal_changed[:] = False
        t = self.t
        # Never a command to a robot whose state is unknown (it never reported).
        known = ~self.health.unknown
        rows = np.flatnonzero(known)
        self.link.send(CommandBatch(self.info.ids, rows, t, cmd[rows]))
        self._sent = np.where(known[:, None], cmd, 0.0)
        if self.estopped:
            self.link.stop(list(self.ids))
        step = self.link.spin()
        if step is None:
            step = StepResult()
        self.inbox.absorb(self.link.receive())
        self._check_health()
        if self.sensing is not None:
            self._sense()
        # Waiting on purpose (stopped, held back by the fill order) is not a deadlock.
        hold = self._waiting_held(view.hold)
        paused = self.stopped | self.teleop | self.estopped | hold | self.health.faulted
        aside = self._per_robot("making_room")  # standing aside (RVO)
        if aside is not None:
            paused = paused | aside
        queued = self._per_robot("queued")  # queued at a door
        if queued is not None:
            paused = paused | self._queue_paused(queued)
        self.metrics.on_step(
            self.t,
            self.truth_poses(),
            self.goals,
            self.has_goal,
            paused,
            step,
            self._per_robot("activity"),
        )
        return step

    def _queue_paused(self, queued: np.ndarray) -> np.ndarray:
        """Of the skids ``queued`` at a bottleneck, those waiting on purpose: all, except
        those whose zone is held only by skids in a deadlock episode (the controller's
        ``queue_holders``). Such a queue waits for nothing that will come, so it is reported
        as deadlocked as well, with its holders as the cause (on a generated door, a skid
        queued for the door stood still from 124 s to the end of the run in front of the
        holder, which waited for it, and only the holder's episode told)."""
        holders = getattr(self.controller, "queue_holders", None)
        if holders is None:
            return queued
        stuck = self.metrics.stuck()
        if not stuck.any():
            return queued
        out = queued.copy()
        for i in np.flatnonzero(queued).tolist():
            them = holders(i)
            if them and stuck[them].all():
                out[i] = False
        return out

    def _waiting_held(self, held: np.ndarray) -> np.ndarray:
        """Of the skids ``held`` back by the fill order, those waiting on purpose: a held
        skid waits from when it stands at its stop (the controller's ``at_hold``); on its way
        there it is driving, and a skid stuck on the way is reported like any other. A
        controller that does not say where its held skids stand has them all waiting."""
        at_hold = self._per_robot("at_hold")
        return held if at_hold is None else held & at_hold

    def _per_robot(self, name: str) -> np.ndarray | None:
        """The controller's per-robot array ``name`` (``making_room``, ``queued``,
        ``at_hold``, ``activity``), or None if it has none for the whole fleet this tick."""
        value = getattr(self.controller, name, None)
        return value if value is not None and len(value) == self.n else None

    def _check_health(self) -> None:
        """Heartbeat and command following on what came back (:mod:`.health`); a robot
        that does not follow is stopped (a lost one gets zero commands; its own dead-man
        stops it if those do not arrive either)."""
        h = self.health
        h.heartbeat(self.t, self.inbox.odom_stamp)
        # A robot that reports itself blocked (in contact) says why it does not follow.
        blocked = np.array([st == "blocked" for st in self.inbox.status], dtype=bool)
        watch = ~h.lost & ~self.stopped & (not self.estopped) & ~blocked
        bad = h.follow(self.t, self.info.dt_s, self._sent, self.inbox.vel, watch)
        if bad.any():
            self.stopped[bad] = True
            self.link.stop([self.ids[i] for i in np.flatnonzero(bad)])

    def _sense(self) -> None:
        """Localize and detect on what the link reported; record the error against the truth."""
        half_widths = np.array([f.width_m / 2 for f in self.info.footprints])
        self.goal_changed |= self.sensing.update(
            self.t,
            self.inbox,
            self.has_goal,
            getattr(self.controller, "paths", None),
            half_widths,
        )
        self._watch_spots()
        if self.sim is not None:  # a report on the run, not an input to it
            est, truth = self.sensing.estimates, self.sim.poses
            self.loc_errors.append(np.hypot(est[:, 0] - truth[:, 0], est[:, 1] - truth[:, 1]))
            self.loc_times.append(self.t)

    def _watch_spots(self) -> None:
        """Lay a parking group out again when the scans show something on one of its spots
        (:mod:`.spot_watch`): an obstacle the map lacks that no scan had seen at the park."""
        if not self.groups:
            return
        sensing = self.sensing
        for g in self.spot_watch.due(
            self.t, self.groups, self._corners_body, sensing.detected_points, sensing.people.xy
        ):
            # The skids the group has now (the operator may have taken some elsewhere since).
            cmd = g.command.model_copy(update={"robots": [self.ids[i] for i in g.robots]})
            out = self.apply_park(self.prepare_park(cmd, check_reach=False))
            new = self.groups[-1] if out.accepted else g
            new.relayouts = g.relayouts + 1
            new.blocked_checks = 0

    def settled(self) -> bool:
        """Every commanded robot is at its goal and at rest, and nothing else is pending."""
        if self._pending or not self.has_goal.any():
            return False
        pos_err, head_err = goal_errors(self.truth_poses(), self.goals)
        at = (pos_err <= POSITION_TOL_M) & (head_err <= HEADING_TOL_RAD)
        at_rest = np.abs(self.truth_vel()).max(initial=0.0) < 1e-3
        people_done = self.sim.people_done() if self.sim is not None else True
        return bool(np.all(at[self.has_goal]) and at_rest and people_done)

    # ------------------------------------------------------------------ reports

    def localization_summary(self) -> dict:
        """Localization error over the run and per kidnapping (:mod:`.reports`)."""
        return reports.localization_summary(self)

    def snapshot(self) -> dict:
        """The state streamed to the operator interface (:mod:`.reports`)."""
        return reports.snapshot(self)
