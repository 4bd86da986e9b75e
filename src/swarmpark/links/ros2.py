"""A :class:`~swarmpark.links.base.RobotLink` to a ROS 2 fleet, with no ROS install.

The transport is DDS (``cyclonedds``) on ROS 2's topic names (``rt/<topic>``) and DDS type
names (``pkg::msg::dds_::T_``); the messages are CDR bytes from ``rosbags``
(:mod:`.ros2_msgs`); the QoS profiles are rclpy's (:mod:`.ros2_qos`). ``docs/ros2.md`` lists
every topic.

Per robot (namespace ``/<id>/``) the link subscribes ``odom`` (``nav_msgs/Odometry``),
``scan`` (``sensor_msgs/LaserScan``, sensor-data QoS) and, with ``amcl_pose=True``,
``amcl_pose`` (``geometry_msgs/PoseWithCovarianceStamped``); it publishes ``cmd_vel``
(``geometry_msgs/Twist``, or ``TwistStamped``). Fleet-wide it publishes ``/map`` (latched),
``/tf`` (``map -> <id>/odom``), ``/swarmpark/goals``, ``/swarmpark/markers`` and
``/swarmpark/estop`` (latched), and takes operator commands on ``/swarmpark/command``
(``std_msgs/String``: one scenario command as JSON) and ``/swarmpark/estop``.

Localization: a robot that does not report ``amcl_pose`` is placed by its odometry and the
``map -> odom`` transform fixed when its first odometry arrives (its declared start pose,
the operator's "2D Pose Estimate"); one that does moves that transform with each estimate.
Either way the link reports the map pose to the supervisor and publishes the transform.

Time: :meth:`Ros2Link.now` is the wall clock (the ROS clock) minus the wall time of
:meth:`Ros2Link.connect`, so scenario command times count from the start; message stamps
are mapped the same way (the robots' clocks must be synchronized, e.g. chrony). This link is
not deterministic -- it is real time.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass

import numpy as np

from swarmpark.links import ros2_msgs as rm
from swarmpark.links.base import (
    FleetInfo,
    Message,
    Odometry,
    PoseReport,
    Scan,
    VelocityCommand,
)
from swarmpark.links.ros2_qos import cyclone_config, qos
from swarmpark.world.scenario import World

__all__ = ["Ros2Link", "Ros2Options", "TOPICS"]

#: ROS 2 messages carry no sender counter: they are ordered by header stamp alone, so a
#: duplicate (same stamp) is ignored by the inbox like an older message.
_SEQ = 0

#: topic -> (ROS type, QoS profile, direction) as seen from swarmpark; ``{id}`` is a robot.
TOPICS = {
    "/{id}/odom": ("nav_msgs/msg/Odometry", "state", "in"),
    "/{id}/scan": ("sensor_msgs/msg/LaserScan", "sensor", "in"),
    "/{id}/amcl_pose": ("geometry_msgs/msg/PoseWithCovarianceStamped", "state", "in"),
    "/{id}/cmd_vel": ("geometry_msgs/msg/Twist", "default", "out"),
    "/map": ("nav_msgs/msg/OccupancyGrid", "latched", "out"),
    "/tf": ("tf2_msgs/msg/TFMessage", "default", "out"),
    "/swarmpark/goals": ("geometry_msgs/msg/PoseArray", "default", "out"),
    "/swarmpark/markers": ("visualization_msgs/msg/MarkerArray", "default", "out"),
    "/swarmpark/estop": ("std_msgs/msg/Bool", "latched", "in/out"),
    "/swarmpark/command": ("std_msgs/msg/String", "default", "in"),
}


@dataclass(frozen=True)
class Ros2Options:
    """How the link reaches the fleet.

    ``domain_id`` is ``ROS_DOMAIN_ID``; ``loopback`` keeps DDS on 127.0.0.1 (tests, one
    machine); ``interface`` picks the network interface otherwise. ``cmd_stamped`` publishes
    ``TwistStamped`` on ``cmd_vel``; ``amcl_pose`` takes the robots' own pose estimates.
    ``connect_timeout_s`` is how long :meth:`Ros2Link.connect` waits for every robot's first
    odometry. ``state_period_s`` is the period of ``/tf``, goals and markers.
    """

    domain_id: int = 0
    loopback: bool = False
    interface: str | None = None
    cmd_stamped: bool = False
    amcl_pose: bool = False
    connect_timeout_s: float = 20.0
    state_period_s: float = 0.2
    map_frame: str = "map"
    #: :meth:`Ros2Link.spin` waits out the control period (``False``: the caller paces, as
    #: the served UI does).
    paced: bool = True


class _Endpoint:
    """One DDS reader or writer of raw CDR samples of a ROS 2 type."""

    def __init__(
        self,
        participant,
        topic: str,
        typename: str,
        profile: str,
        write: bool,
        *,
        ignore_local: bool = False,
    ):
        from cyclonedds.pub import DataWriter
        from cyclonedds.sub import DataReader
        from cyclonedds.topic import Topic

        self.typename = typename
        self.topic = Topic(participant, "rt" + topic, rm.dds_type(typename))
        q = qos(profile)
        if ignore_local:
            from cyclonedds.qos import Policy, Qos

            q = Qos(*q, Policy.IgnoreLocal.Participant)
        self.entity = (
            DataWriter(participant, self.topic, qos=q)
            if write
            else DataReader(participant, self.topic, qos=q)
        )

    def write(self, message) -> None:
        self.write_cdr(rm.serialize(message, self.typename))

    def write_cdr(self, data: bytes) -> None:
        """Write one sample already in CDR (with its encapsulation header)."""
        from cyclonedds._clayer import ddspy_write

        data = data.ljust((len(data) + 3) & ~3, b"\0")  # DDS samples are padded to 4 bytes
        ret = ddspy_write(self.entity._ref, data)
        if ret < 0:
            raise RuntimeError(f"ros2: writing {self.topic.name} failed ({ret})")

    def take(self, n: int = 256) -> list:
        from cyclonedds._clayer import ddspy_take
        from cyclonedds.core import InstanceState, SampleState, ViewState

        mask = SampleState.Any | ViewState.Any | InstanceState.Any
        ret = ddspy_take(self.entity._ref, mask, n)
        if isinstance(ret, int):
            raise RuntimeError(f"ros2: taking {self.topic.name} failed ({ret})")
        return [rm.deserialize(data, self.typename) for data, info in ret if info.valid_data]


class Ros2Link:
    """The supervisor's link to ROS 2 robots (see the module docstring).

    Parameters
    ----------
    world
        The scenario: robot ids (namespaces), footprints, limits, start poses, the map.
    options
        :class:`Ros2Options`.
    """

    sim = None  # no simulator behind this link: the supervisor has no truth

    def __init__(self, world: World, options: Ros2Options | None = None) -> None:
        self.world = world
        self.opt = options or Ros2Options()
        self.ids = tuple(world.ids)
        self._index = {rid: i for i, rid in enumerate(self.ids)}
        n = len(self.ids)
        self.t0 = 0.0
        self.dt = float(world.scenario.dt_s)
        self._next_tick = 0.0
        self._map_T_odom = np.full((n, 3), np.nan)
        self._odom_pose = np.full((n, 3), np.nan)
        self._last_state = -math.inf
        self._operator: list[dict] = []
        self.estop_heard: bool | None = None
        self._estop_published: bool | None = None
        self.received = 0
        self._participant = None

    # ------------------------------------------------------------------ DDS set-up

    def _open(self) -> None:
        from cyclonedds.domain import Domain, DomainParticipant

        o = self.opt
        self._domain = Domain(
            o.domain_id, cyclone_config(loopback=o.loopback, interface=o.interface)
        )
        dp = self._participant = DomainParticipant(o.domain_id)
        self._odom, self._scan, self._amcl, self._cmd = [], [], [], []
        cmd_type = "geometry_msgs/msg/TwistStamped" if o.cmd_stamped else "geometry_msgs/msg/Twist"
        for rid in self.ids:
            self._odom.append(
                _Endpoint(dp, f"/{rid}/odom", "nav_msgs/msg/Odometry", "state", False)
            )
            self._scan.append(
                _Endpoint(dp, f"/{rid}/scan", "sensor_msgs/msg/LaserScan", "sensor", False)
            )
            if o.amcl_pose:
                self._amcl.append(
                    _Endpoint(
                        dp,
                        f"/{rid}/amcl_pose",
                        "geometry_msgs/msg/PoseWithCovarianceStamped",
                        "state",
                        False,
                    )
                )
            self._cmd.append(_Endpoint(dp, f"/{rid}/cmd_vel", cmd_type, "default", True))
        self._map = _Endpoint(dp, "/map", "nav_msgs/msg/OccupancyGrid", "latched", True)
        self._tf = _Endpoint(dp, "/tf", "tf2_msgs/msg/TFMessage", "default", True)
        self._goals = _Endpoint(
            dp, "/swarmpark/goals", "geometry_msgs/msg/PoseArray", "default", True
        )
        self._markers = _Endpoint(
            dp, "/swarmpark/markers", "visualization_msgs/msg/MarkerArray", "default", True
        )
        self._estop_out = _Endpoint(dp, "/swarmpark/estop", "std_msgs/msg/Bool", "latched", True)
        # (its own e-stop samples are not news: the reader ignores this participant's)
        self._estop_in = _Endpoint(
            dp, "/swarmpark/estop", "std_msgs/msg/Bool", "latched", False, ignore_local=True
        )
        self._command_in = _Endpoint(
            dp, "/swarmpark/command", "std_msgs/msg/String", "default", False
        )

    def close(self) -> None:
        """Stop every robot (zero ``cmd_vel``) and leave the DDS domain."""
        if self._participant is None:
            return
        try:
            self._send_zero(range(len(self.ids)))
        finally:
            self._participant = None
            self._domain = None

    # ------------------------------------------------------------------ the protocol

    def connect(self) -> FleetInfo:
        """Join the domain, publish the map, and wait for every robot's first odometry."""
        robots = self.world.robots
        info = FleetInfo(
            ids=self.ids,
            footprints=tuple(r.footprint for r in robots),
            max_speed_mps=np.array([r.max_speed_mps for r in robots], float),
            max_yaw_rate_radps=np.array([r.max_yaw_rate_radps for r in robots], float),
            max_accel_mps2=np.array([r.max_accel_mps2 for r in robots], float),
            max_yaw_accel_radps2=np.array([r.max_yaw_accel_radps2 for r in robots], float),
            dt_s=self.dt,
            start_poses=np.stack([r.start for r in robots]).astype(float),
        )
        self._start = info.start_poses
        self._open()
        self.t0 = time.time()
        self._publish_map()
        self._pending: list[Message] = []
        deadline = time.monotonic() + self.opt.connect_timeout_s
        while time.monotonic() < deadline:
            self._pending += self._take()
            if not self._missing():
                break
            time.sleep(0.02)
        else:
            missing = self._missing()
            self.close()
            raise TimeoutError(
                f"ros2: within {self.opt.connect_timeout_s} s: {'; '.join(missing)} "
                f"(domain {self.opt.domain_id})"
            )
        self._next_tick = self.now() + self.dt
        return info

    def _missing(self) -> list[str]:
        """What connect still waits for: each robot's first odometry, and a subscriber on
        its ``cmd_vel`` (a command written before DDS matched one would be lost)."""
        out = []
        no_odom = [
            r for r, ok in zip(self.ids, np.isfinite(self._map_T_odom[:, 0]), strict=True) if not ok
        ]
        if no_odom:
            out.append(f"no odometry from {no_odom} on /<id>/odom")
        deaf = [
            r
            for r, w in zip(self.ids, self._cmd, strict=True)
            if not w.entity.get_matched_subscriptions()
        ]
        if deaf:
            out.append(f"no subscriber on /<id>/cmd_vel of {deaf}")
        return out

    def now(self) -> float:
        return time.time() - self.t0

    def receive(self) -> list[Message]:
        pending, self._pending = self._pending, []
        return pending + self._take()

    def send(self, commands: list[VelocityCommand]) -> None:
        for c in commands:
            i = self._index.get(c.robot)
            if i is None:
                raise ValueError(f"link.send: unknown robot {c.robot!r}")
            self._write_cmd(i, c.v, c.omega, c.stamp + self.t0)

    def stop(self, robots: list[str]) -> None:
        idx = []
        for rid in robots:
            i = self._index.get(rid)
            if i is None:
                raise ValueError(f"link.stop: unknown robot {rid!r}")
            idx.append(i)
        self._send_zero(idx)

    def spin(self) -> None:
        """Wait for the end of the control period (real time; no catching up when late)."""
        wait = self._next_tick - self.now()
        if wait > 0 and self.opt.paced:
            time.sleep(wait)
        self._next_tick = max(self._next_tick + self.dt, self.now())
        return None

    # ------------------------------------------------------------------ robots in

    def _take(self) -> list[Message]:
        out: list[Message] = []
        for i, rid in enumerate(self.ids):
            for m in self._odom[i].take():
                out += self._from_odom(i, rid, m)
            for m in self._scan[i].take():
                out.append(Scan(rid, rm.stamp_of(m) - self.t0, rm.scan_ranges(m), _SEQ))
            if self._amcl:
                out += [self._from_amcl(i, m) for m in self._amcl[i].take()]
        self.received += len(out)
        for m in self._estop_in.take():
            self.estop_heard = bool(m.data)
            self._operator.append({"estop": True} if m.data else {"resume": "all"})
        for m in self._command_in.take():
            try:
                cmd = json.loads(m.data)
            except json.JSONDecodeError as exc:
                cmd = {"invalid": f"/swarmpark/command: not JSON ({exc.msg}): {m.data[:80]!r}"}
            self._operator.append(cmd)
        return out

    def _from_odom(self, i: int, rid: str, m) -> list[Message]:
        stamp = rm.stamp_of(m) - self.t0
        pose = rm.pose_of(m.pose.pose)
        vel = np.array([m.twist.twist.linear.x, m.twist.twist.angular.z])
        if not np.isfinite(self._map_T_odom[i, 0]):
            # The first odometry: the robot stands at its declared start pose.
            self._map_T_odom[i] = rm.compose(self._start[i], rm.inverse(pose))
        self._odom_pose[i] = pose
        seq = _SEQ
        out: list[Message] = [Odometry(rid, stamp, pose, vel, seq)]
        if not self.opt.amcl_pose:
            out.append(PoseReport(rid, stamp, rm.compose(self._map_T_odom[i], pose), seq))
        return out

    def _from_amcl(self, i: int, m) -> PoseReport:
        pose = rm.pose_of(m.pose.pose)
        if np.isfinite(self._odom_pose[i, 0]):
            self._map_T_odom[i] = rm.compose(pose, rm.inverse(self._odom_pose[i]))
        return PoseReport(self.ids[i], rm.stamp_of(m) - self.t0, pose, _SEQ)

    # ------------------------------------------------------------------ robots out

    def _write_cmd(self, i: int, v: float, omega: float, stamp: float) -> None:
        if self.opt.cmd_stamped:
            m = rm.twist_stamped(stamp, f"{self.ids[i]}/base_link", v, omega)
            self._cmd[i].write(m)
        else:
            self._cmd[i].write_cdr(rm.twist_cdr(v, omega))

    def _send_zero(self, idx) -> None:
        t = time.time()
        for i in idx:
            self._write_cmd(i, 0.0, 0.0, t)

    def publish_estop(self, on: bool) -> None:
        """Latch ``/swarmpark/estop``: robots that listen stop (and late joiners hear it)."""
        self._estop_out.write(rm.msg("std_msgs/msg/Bool")(data=bool(on)))
        self._estop_published = bool(on)

    def _publish_map(self) -> None:
        g = self.world.grid
        self._map.write(
            rm.occupancy_grid(
                self.t0, self.opt.map_frame, g.occupied, g.resolution_m, tuple(g.origin)
            )
        )

    # ------------------------------------------------------------------ supervisor state out

    def take_operator_commands(self) -> list[dict]:
        """Operator commands heard since the last call (scenario command dicts)."""
        out, self._operator = self._operator, []
        return out

    def sync(self, sup) -> None:
        """After a supervisor tick: run the operator's commands, mirror the e-stop on the
        latched topic, publish ``/tf``, goals and markers (every ``state_period_s``)."""
        from swarmpark.links.ros2_viz import markers
        from swarmpark.world.scenario import CommandSpec

        for d in self.take_operator_commands():
            try:
                sup.execute(CommandSpec.model_validate(d))
            except ValueError as exc:  # pydantic's ValidationError is a ValueError
                sup._refuse("operator", f"/swarmpark/command: {exc}".splitlines()[0])
        if sup.estopped != self._estop_published:
            self.publish_estop(sup.estopped)  # mirrored, latched: late joiners hear it too
        t = self.now()
        if t - self._last_state < self.opt.state_period_s:
            return
        self._last_state = t
        stamp = t + self.t0
        frame = self.opt.map_frame
        if getattr(sup, "sensing", None) is not None:
            # swarmpark localizes the robots (AMCL on their scans): map -> odom from its
            # estimates and the odometry they were made with.
            est, odom = sup.estimates, sup.inbox.odom
            for i in np.flatnonzero(np.isfinite(est[:, 0]) & np.isfinite(odom[:, 0])):
                self._map_T_odom[i] = rm.compose(est[i], rm.inverse(odom[i]))
        tfs = [
            rm.transform(stamp, frame, f"{rid}/odom", self._map_T_odom[i])
            for i, rid in enumerate(self.ids)
            if np.isfinite(self._map_T_odom[i, 0])
        ]
        self._tf.write(rm.tf_message(tfs))
        self._goals.write(rm.pose_array(stamp, frame, sup.goals[sup.has_goal]))
        self._markers.write(markers(sup, stamp, frame))


# ----------------------------------------------------------------------------- command line


def add_link_args(p) -> None:
    """``--link`` and the ROS 2 options of ``swarmpark run`` / ``swarmpark serve``."""
    p.add_argument(
        "--link", choices=("sim", "ros2"), default="sim", help="the robots: simulator or ROS 2"
    )
    p.add_argument("--domain-id", type=int, default=None, help="ROS_DOMAIN_ID (ros2 link)")
    p.add_argument(
        "--loopback", action="store_true", help="ros2 link: DDS on 127.0.0.1 only (one machine)"
    )
    p.add_argument("--cmd-stamped", action="store_true", help="ros2 link: TwistStamped cmd_vel")
    p.add_argument("--amcl-pose", action="store_true", help="ros2 link: robots report amcl_pose")


def link_from_args(world: World, args, *, paced: bool = True):
    """The link ``args`` ask for (``None``: the simulator)."""
    import os

    if getattr(args, "link", "sim") != "ros2":
        return None
    domain = args.domain_id
    if domain is None:
        domain = int(os.environ.get("ROS_DOMAIN_ID", "0") or 0)
    if not 0 <= domain <= 232:
        raise ValueError(f"--domain-id must be 0..232 (got {domain})")
    opts = Ros2Options(
        domain_id=domain,
        loopback=args.loopback,
        cmd_stamped=args.cmd_stamped,
        amcl_pose=args.amcl_pose,
        paced=paced,
    )
    return Ros2Link(world, opts)
