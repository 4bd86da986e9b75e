"""The simulator as a :class:`~swarmpark.links.base.RobotLink`, with the robots' sensors and
injected link faults.

:class:`SimLink` owns the :class:`~swarmpark.sim.simulator.Simulator` (the truth) and turns
it into what real skids would report: wheel odometry (drifting, in each robot's ``odom``
frame, when the scenario has onboard sensing; else exact), LIDAR scans taken at the true
poses (with sensing), a pose report per robot when the skids are taken to know their pose
(``sensing.localization: truth``), and the people as a fleet-level tracker would see them
(without sensing). Commands arrive stamped; a robot keeps its last command for
:data:`CMD_TIMEOUT_S` (its dead-man), then stops.

Scenario ``faults`` act on the link, not on the robots: for one robot and a time window,
messages are dropped (both ways), delayed (delivered late, so possibly out of order) or
their poses made noisy. Ground truth leaves this module only through :attr:`SimLink.sim`,
for metrics and scripted events (kidnaps), never through the messages.
"""

from __future__ import annotations

import heapq
from dataclasses import dataclass

import numpy as np

from swarmpark.core.geometry import pad_polygons, triangulate, wrap_angle
from swarmpark.links.base import (
    Arrivals,
    CommandBatch,
    FleetInfo,
    Message,
    Odometry,
    PoseReport,
    ReportBatch,
    Scan,
    Status,
    TrackedPeople,
    VelocityCommand,
)
from swarmpark.sim.simulator import Simulator, StepResult
from swarmpark.world.scenario import World

__all__ = ["SimLink", "LinkFaults", "CMD_TIMEOUT_S"]

#: A robot whose last command is older than this stops (its own dead-man, not the link's).
CMD_TIMEOUT_S = 0.5
#: Distance along a person's route used to read its walking direction.
PERSON_LOOKAHEAD_M = 1e-3


@dataclass(frozen=True)
class LinkFaults:
    """Scenario ``faults`` as arrays: per fault the robot index, window and effects."""

    robot: np.ndarray  # (F,) int
    from_s: np.ndarray
    to_s: np.ndarray
    drop: np.ndarray  # (F,) bool
    delay_s: np.ndarray
    noise_m: np.ndarray
    noise_rad: np.ndarray

    @classmethod
    def from_world(cls, world: World) -> LinkFaults:
        f = world.scenario.faults
        index = {rid: i for i, rid in enumerate(world.ids)}
        return cls(
            np.array([index[x.robot] for x in f], dtype=int),
            np.array([x.from_s for x in f], float),
            np.array([x.to_s for x in f], float),
            np.array([x.drop for x in f], bool),
            np.array([x.delay_s for x in f], float),
            np.array([x.noise_m for x in f], float),
            np.deg2rad(np.array([x.noise_deg for x in f], float)),
        )

    def active(self, robot: int, t: float) -> np.ndarray:
        """Mask of the faults acting on ``robot`` at time ``t`` (window ``[from_s, to_s)``)."""
        return (self.robot == robot) & (self.from_s <= t + 1e-9) & (t + 1e-9 < self.to_s)

    def __bool__(self) -> bool:
        return bool(len(self.robot))


class SimLink:
    """The simulator behind the :class:`~swarmpark.links.base.RobotLink` protocol.

    Parameters
    ----------
    world
        The scenario's world; ``world.scenario.sensing`` decides what the robots report and
        ``world.scenario.faults`` what the link does to the messages.
    sim
        An existing simulator of ``world`` to wrap (by default a new one).
    """

    def __init__(self, world: World, sim: Simulator | None = None) -> None:
        self.world = world
        self.sim = sim if sim is not None else Simulator(world)
        sim = self.sim
        self.ids = tuple(world.ids)
        self._index = {rid: i for i, rid in enumerate(self.ids)}
        cfg = world.scenario.sensing
        self.sensing = cfg.localization == "amcl"
        self.faults = LinkFaults.from_world(world)
        n = sim.n
        self._cmd = np.zeros((n, 2))
        self._cmd_t = np.full(n, -np.inf)
        self._hold = np.zeros(n, dtype=bool)
        # (deliver at, seq, message or a whole fleet's reports)
        self._queue: list[tuple[float, int, Message | ReportBatch]] = []
        self._seq = 0
        # The status last reported per robot: 1 blocked, 0 ok, -1 nothing reported yet.
        self._blocked = np.full(n, -1, dtype=np.int8)
        seed = np.random.SeedSequence(world.scenario.seed)
        scan_seed, loc_seed = seed.spawn(2)
        # The odometry's stream is the one the fleet localizer used to give it (its last
        # child), so the drift is the same as when odometry lived beside the filters.
        odom_seed = loc_seed.spawn(n + 1)[n]
        self._noise_rng = np.random.default_rng(
            np.random.SeedSequence(world.scenario.seed).spawn(3)[2]
        )
        self.odometry = None
        if self.sensing:
            from swarmpark.sense.lidar import LidarSpec, prepare_grid
            from swarmpark.sim.odometry import OdometryDrift

            self.lidar_spec = LidarSpec(
                num_beams=cfg.lidar_beams,
                max_range_m=cfg.lidar_range_m,
                range_noise_std_m=cfg.range_noise_std_m,
                dropout_prob=cfg.dropout_prob,
            )
            self._scan_field = prepare_grid(world.grid)
            tris = [t for poly in world.static_obstacles for t in triangulate(poly)]
            self._obstacle_tris = pad_polygons(tris, 4) if tris else np.zeros((0, 4, 2))
            self._scan_rng = np.random.default_rng(scan_seed)
            self.odometry = OdometryDrift(sim.poses.copy(), rng=np.random.default_rng(odom_seed))

    # ------------------------------------------------------------------ the protocol

    def connect(self) -> FleetInfo:
        sim = self.sim
        info = FleetInfo(
            ids=self.ids,
            footprints=tuple(sim.footprints),
            max_speed_mps=sim.max_speed.copy(),
            max_yaw_rate_radps=sim.max_yaw_rate.copy(),
            max_accel_mps2=sim.max_accel.copy(),
            max_yaw_accel_radps2=sim.max_yaw_accel.copy(),
            dt_s=sim.dt,
            start_poses=np.stack([r.start for r in self.world.robots]).astype(float),
        )
        self._publish(scan=False)
        return info

    def now(self) -> float:
        return self.sim.t

    def receive(self) -> Arrivals:
        out = []
        now = self.sim.t + 1e-9
        while self._queue and self._queue[0][0] <= now:
            out.append(heapq.heappop(self._queue)[2])
        return Arrivals(out)

    def send(self, commands: list[VelocityCommand] | CommandBatch) -> None:
        if isinstance(commands, CommandBatch) and not self.faults and commands.ids == self.ids:
            # A whole fleet's commands as arrays (the same outcome as one by one below).
            i, stamp = commands.rows, commands.stamp
            newer = stamp >= self._cmd_t[i]
            self._cmd[i[newer]] = commands.cmd[newer]
            self._cmd_t[i[newer]] = stamp
            return
        for c in commands:
            i = self._index.get(c.robot)
            if i is None:
                raise ValueError(f"link.send: unknown robot {c.robot!r}")
            if self.faults:
                act = self.faults.active(i, self.sim.t)
                if np.any(self.faults.drop[act]):
                    continue  # lost on the way: the robot keeps its last command
            if c.stamp >= self._cmd_t[i]:
                self._cmd[i] = (c.v, c.omega)
                self._cmd_t[i] = c.stamp

    def stop(self, robots: list[str]) -> None:
        for rid in robots:
            i = self._index.get(rid)
            if i is None:
                raise ValueError(f"link.stop: unknown robot {rid!r}")
            self._hold[i] = True

    def spin(self) -> StepResult:
        """One simulator step with the commands in force, then the robots report."""
        sim = self.sim
        fresh = sim.t - self._cmd_t <= CMD_TIMEOUT_S + 1e-9
        cmd = np.where(fresh[:, None], self._cmd, 0.0)
        held = self._hold.copy()
        step = sim.step(cmd, hold=held)
        self._hold &= ~held  # a stop that came during the step holds the next one
        self._publish(scan=self.sensing, step=step)
        return step

    # ------------------------------------------------------------------ scripted events (truth)

    def teleport(self, i: int, pose: np.ndarray) -> None:
        """Carry robot ``i`` to ``pose`` by hand (a kidnapping): it stops, and its odometry does
        not notice the jump. Its wheels report standing still at once."""
        sim = self.sim
        sim.poses[i] = pose
        sim.vel[i] = 0.0
        if self.odometry is not None:
            self.odometry.kidnap(i, pose[None])
        self._emit(self._odometry_msg(i, self._odom_poses()))
        if not self.sensing:
            self._emit(PoseReport(self.ids[i], sim.t, sim.poses[i].copy(), self._next_seq()))

    # ------------------------------------------------------------------ reports

    def _next_seq(self) -> int:
        self._seq += 1
        return self._seq

    def _odom_poses(self) -> np.ndarray:
        return self.sim.poses if self.odometry is None else self.odometry.odom

    def _odometry_msg(self, i: int, odom: np.ndarray) -> Odometry:
        return Odometry(
            self.ids[i], self.sim.t, odom[i].copy(), self.sim.vel[i].copy(), self._next_seq()
        )

    def _publish(self, *, scan: bool, step: StepResult | None = None) -> None:
        """What every robot (and the people tracker) reports after a step."""
        sim = self.sim
        if self.odometry is not None and step is not None:
            self.odometry.step(sim.poses)
        odom = self._odom_poses()
        ranges = self._scan() if scan else None
        if self.faults:
            self._publish_each(odom, ranges, step)
        else:
            # No faults act on the messages: the fleet's reports go as one batch (the inbox
            # takes them as it would one by one; each robot gets its own counter value).
            n = sim.n
            seq = np.arange(self._seq + 1, self._seq + 1 + n)
            self._seq += n
            batch = ReportBatch(
                self.ids,
                sim.t,
                odom.copy(),
                sim.vel.copy(),
                seq,
                pose=None if self.sensing else sim.poses.copy(),
                ranges=ranges,
            )
            heapq.heappush(self._queue, (batch.stamp, self._next_seq(), batch))
            blocked = np.zeros(n, np.int8) if step is None else step.blocked.astype(np.int8)
            for i in np.flatnonzero(blocked != self._blocked).tolist():
                self._report_status(i, int(blocked[i]))
        if not self.sensing:
            self._emit(self._people())

    def _publish_each(self, odom: np.ndarray, ranges, step: StepResult | None) -> None:
        """The reports one message per robot, each through the faults of its link."""
        sim = self.sim
        for i, rid in enumerate(self.ids):
            self._emit(self._odometry_msg(i, odom))
            if not self.sensing:
                self._emit(PoseReport(rid, sim.t, sim.poses[i].copy(), self._next_seq()))
            if ranges is not None:
                self._emit(Scan(rid, sim.t, ranges[i], self._next_seq()))
            blocked = int(step is not None and step.blocked[i])
            if blocked != self._blocked[i]:
                self._report_status(i, blocked)

    def _report_status(self, i: int, blocked: int) -> None:
        """Robot ``i``'s status changed: report it (1 blocked, 0 ok)."""
        self._blocked[i] = blocked
        state = "blocked" if blocked else "ok"
        self._emit(Status(self.ids[i], self.sim.t, state, self._next_seq()))

    def _emit(self, m: Message) -> None:
        """Queue a robot's message for delivery, through the faults of its link."""
        deliver = m.stamp
        if self.faults and not isinstance(m, TrackedPeople):
            i = self._index[m.robot]
            act = self.faults.active(i, m.stamp)
            if act.any():
                if np.any(self.faults.drop[act]):
                    return
                deliver += float(self.faults.delay_s[act].max())
                m = self._noisy(m, act)
        heapq.heappush(self._queue, (deliver, self._next_seq(), m))

    def _noisy(self, m: Message, act: np.ndarray) -> Message:
        sd_xy = float(np.hypot.reduce(self.faults.noise_m[act]))
        sd_yaw = float(np.hypot.reduce(self.faults.noise_rad[act]))
        if not isinstance(m, Odometry | PoseReport) or (sd_xy == 0 and sd_yaw == 0):
            return m
        z = self._noise_rng.standard_normal(3)
        pose = m.pose + np.array([sd_xy * z[0], sd_xy * z[1], sd_yaw * z[2]])
        pose[2] = wrap_angle(pose[2])
        if isinstance(m, Odometry):
            return Odometry(m.robot, m.stamp, pose, m.vel, m.seq)
        return PoseReport(m.robot, m.stamp, pose, m.seq)

    def _scan(self) -> np.ndarray:
        """Every robot's scan from its true pose: walls, static obstacles, other skids, people."""
        from swarmpark.sense.lidar import scan

        sim = self.sim
        polys = np.concatenate([sim.corners(), self._obstacle_tris])
        owner = np.concatenate([np.arange(sim.n), np.full(len(self._obstacle_tris), -1)])
        return scan(
            self.lidar_spec,
            sim.poses,
            self._scan_field,
            polygons=polys,
            polygon_owner=owner,
            discs=sim.person_positions(),
            disc_radii=sim.person_radius,
            rng=self._scan_rng,
        )

    def _people(self) -> TrackedPeople:
        """The people as a perfect tracker sees them: where they are and how they walk."""
        sim = self.sim
        ppos = sim.person_positions()
        pvel = np.zeros_like(ppos)
        if len(ppos):
            ahead = sim.person_positions(sim.person_s + PERSON_LOOKAHEAD_M)
            moving = np.array(
                [
                    sim.t >= p.start_s and (p.loop or s < p.route_length_m - 1e-9)
                    for p, s in zip(sim.people, sim.person_s, strict=True)
                ],
                dtype=bool,
            )
            speed = np.array([p.speed_mps for p in sim.people])
            dirn = ahead - ppos
            norm = np.linalg.norm(dirn, axis=1, keepdims=True)
            # A reacting person standing for a skid has pace 0, one backing off a negative one.
            speed = speed * sim.reaction.pace
            pvel = np.where(
                (norm > 0) & moving[:, None], dirn / np.maximum(norm, 1e-12) * speed[:, None], 0.0
            )
        return TrackedPeople(sim.t, ppos, pvel, sim.person_radius.copy())
