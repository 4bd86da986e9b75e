"""The seam between the supervisor and the robots: the :class:`RobotLink` protocol.

The supervisor sees robots only through a link, as it would see real ones: at connect the
link gives the fleet's static facts (:class:`FleetInfo`: ids, footprints, limits, the tick
period); then every robot reports stamped messages -- odometry (pose in the robot's own
``odom`` frame, and velocity), a pose estimate in the map frame when the robot localizes
itself, a LIDAR scan when it has one, its status -- and is sent stamped velocity commands
and stops. The simulator is one link (:class:`swarmpark.sim.link.SimLink`); a ROS 2 bridge
is another.

A link may drop, delay, duplicate or reorder messages. :class:`Inbox` folds what arrives
into the latest state per robot by stamp: a message no newer than the one already held is
ignored, and :attr:`Inbox.last_seen` says when each robot was last heard from. Messages
carry the sender's counter ``seq`` too, which orders two messages with the same stamp (a
simulated robot carried by hand reports again within the same tick).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

from swarmpark.core.geometry import Footprint

__all__ = [
    "RobotLink",
    "FleetInfo",
    "Odometry",
    "PoseReport",
    "Scan",
    "Status",
    "TrackedPeople",
    "VelocityCommand",
    "Message",
    "ReportBatch",
    "Arrivals",
    "CommandBatch",
    "Inbox",
]


# ----------------------------------------------------------------------------- static facts


@dataclass(frozen=True)
class FleetInfo:
    """What a link says about its robots once, at connect (SI units, radians).

    ``dt_s`` is the control period the link expects commands at (the simulator's step).
    ``start_poses`` are the poses the robots are declared to start at (the operator's
    initial pose, as RViz's "2D Pose Estimate"), used to seed onboard localization.
    """

    ids: tuple[str, ...]
    footprints: tuple[Footprint, ...]
    max_speed_mps: np.ndarray  # (N,)
    max_yaw_rate_radps: np.ndarray  # (N,)
    max_accel_mps2: np.ndarray  # (N,)
    max_yaw_accel_radps2: np.ndarray  # (N,)
    dt_s: float
    start_poses: np.ndarray  # (N, 3)

    def __post_init__(self) -> None:
        n = len(self.ids)
        if len(set(self.ids)) != n:
            raise ValueError(f"link: duplicate robot id in {list(self.ids)}")
        if len(self.footprints) != n:
            raise ValueError(f"link: {len(self.footprints)} footprints for {n} robots")
        for name in (
            "max_speed_mps",
            "max_yaw_rate_radps",
            "max_accel_mps2",
            "max_yaw_accel_radps2",
        ):
            a = np.asarray(getattr(self, name), float)
            if a.shape != (n,) or not np.all(np.isfinite(a) & (a > 0)):
                raise ValueError(f"link: {name} must be {n} positive numbers (got {a.tolist()})")
        if not (np.isfinite(self.dt_s) and self.dt_s > 0):
            raise ValueError(f"link: dt_s must be > 0 (got {self.dt_s})")
        start = np.asarray(self.start_poses, float)
        if start.shape != (n, 3) or not np.all(np.isfinite(start)):
            raise ValueError(
                f"link: start_poses must be {n} finite (x, y, yaw) (got {start.shape})"
            )

    @property
    def n(self) -> int:
        return len(self.ids)


# ----------------------------------------------------------------------------- messages


@dataclass(frozen=True)
class Odometry:
    """Wheel odometry of one robot: ``pose`` ``(x, y, yaw)`` in the robot's ``odom`` frame
    (it drifts; only its increments mean something) and the measured ``vel`` ``(v, omega)``."""

    robot: str
    stamp: float
    pose: np.ndarray  # (3,)
    vel: np.ndarray  # (2,)
    seq: int = 0


@dataclass(frozen=True)
class PoseReport:
    """A robot's own estimate of its pose in the map frame (e.g. ``amcl_pose``)."""

    robot: str
    stamp: float
    pose: np.ndarray  # (3,)
    seq: int = 0


@dataclass(frozen=True)
class Scan:
    """One LIDAR sweep of a robot: ``ranges`` (m, ``nan`` = no return) over the beams of the
    link's scanner, taken at ``stamp`` from the robot's pivot."""

    robot: str
    stamp: float
    ranges: np.ndarray  # (B,)
    seq: int = 0


@dataclass(frozen=True)
class Status:
    """Free-form robot status (``"ok"``, ``"estopped"``, ...)."""

    robot: str
    stamp: float
    state: str
    seq: int = 0


@dataclass(frozen=True)
class TrackedPeople:
    """People seen by a fleet-level tracker (positions, velocities, radii in the map frame)."""

    stamp: float
    xy: np.ndarray  # (P, 2)
    vel: np.ndarray  # (P, 2)
    radius_m: np.ndarray  # (P,)


Message = Odometry | PoseReport | Scan | Status | TrackedPeople


@dataclass(frozen=True, eq=False)
class ReportBatch:
    """What many robots report at one ``stamp``, as arrays: a fleet's odometry, and its
    map-frame poses and scans where given, one row per robot (each robot once). A simulated
    fleet sends this instead of a message per robot, so the inbox folds it in array by array;
    :meth:`messages` gives the same reports one message per robot (row ``k`` carries the
    counter ``seq[k]`` in each of its messages)."""

    ids: tuple[str, ...]  # robot of each row
    stamp: float
    odom: np.ndarray  # (n, 3) odom frame
    vel: np.ndarray  # (n, 2)
    seq: np.ndarray  # (n,) int
    pose: np.ndarray | None = None  # (n, 3) map frame
    ranges: np.ndarray | None = None  # (n, B)

    def messages(self) -> list[Message]:
        """The reports as single messages, robot by robot (odometry, pose, scan)."""
        out: list[Message] = []
        t = self.stamp
        for k, (rid, sq) in enumerate(zip(self.ids, self.seq.tolist(), strict=True)):
            out.append(Odometry(rid, t, self.odom[k].copy(), self.vel[k].copy(), sq))
            if self.pose is not None:
                out.append(PoseReport(rid, t, self.pose[k].copy(), sq))
            if self.ranges is not None:
                out.append(Scan(rid, t, self.ranges[k], sq))
        return out


class Arrivals(Sequence):
    """Messages as a link delivered them, some of them in :class:`ReportBatch` objects: read as
    a sequence it holds single messages only (batches expanded in place, on first use);
    :meth:`Inbox.absorb` folds the batches in whole (``parts``)."""

    def __init__(self, parts: Iterable[Message | ReportBatch] = ()) -> None:
        self.parts = list(parts)
        self._flat: list[Message] | None = None

    def _messages(self) -> list[Message]:
        if self._flat is None:
            flat: list[Message] = []
            for m in self.parts:
                if isinstance(m, ReportBatch):
                    flat += m.messages()
                else:
                    flat.append(m)
            self._flat = flat
        return self._flat

    def __len__(self) -> int:
        return len(self._messages())

    def __getitem__(self, k):
        return self._messages()[k]

    def __iter__(self) -> Iterator[Message]:
        return iter(self._messages())

    def __eq__(self, other) -> bool:
        return isinstance(other, Sequence) and list(self) == list(other)

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        return f"Arrivals({self._messages()!r})"


@dataclass(frozen=True)
class VelocityCommand:
    """What a robot is told: drive at ``(v, omega)`` (REP-103), sent at ``stamp``."""

    robot: str
    stamp: float
    v: float
    omega: float


@dataclass(frozen=True, eq=False)
class CommandBatch(Sequence):
    """Velocity commands for many robots at one ``stamp``: robot ``ids[rows[k]]`` is told
    ``cmd[k]`` ``(v, omega)``. Read as a sequence it is the :class:`VelocityCommand` objects, so any
    link takes it; the simulator's link applies it as arrays."""

    ids: tuple[str, ...]
    rows: np.ndarray  # (k,) int, each robot once
    stamp: float
    cmd: np.ndarray  # (k, 2)

    def __len__(self) -> int:
        return len(self.rows)

    def __getitem__(self, k):
        if isinstance(k, slice):
            return list(self)[k]
        v, w = self.cmd[k].tolist()
        return VelocityCommand(self.ids[int(self.rows[k])], self.stamp, v, w)

    def __iter__(self) -> Iterator[VelocityCommand]:
        ids, t = self.ids, self.stamp
        for i, (v, w) in zip(self.rows.tolist(), self.cmd.tolist(), strict=True):
            yield VelocityCommand(ids[i], t, v, w)


# ----------------------------------------------------------------------------- the protocol


@runtime_checkable
class RobotLink(Protocol):
    """How the supervisor talks to a fleet.

    One control period: the supervisor :meth:`receive`\\ s what arrived, decides, sends
    :meth:`send` (and :meth:`stop` for robots that must halt at once), then calls
    :meth:`spin`, which lets one period pass (the simulator steps; a real link waits).
    """

    def connect(self) -> FleetInfo:
        """The fleet's static facts (call once, before anything else)."""
        ...

    def now(self) -> float:
        """The link's clock (s): stamps of messages sent now."""
        ...

    def receive(self) -> list[Message]:
        """Messages that arrived since the last call (possibly late, out of order, or none)."""
        ...

    def send(self, commands: list[VelocityCommand]) -> None:
        """Velocity commands; a robot keeps its last one until a newer one arrives or its own
        dead-man time runs out."""
        ...

    def stop(self, robots: list[str]) -> None:
        """Halt these robots now (e-stop: velocity to zero at the next period)."""
        ...

    def spin(self) -> object:
        """Let one control period pass; returns whatever the link reports about it (the
        simulator: its step result, for metrics), or ``None``."""
        ...


# ----------------------------------------------------------------------------- the inbox


@dataclass
class Inbox:
    """The latest of every kind of report per robot, folded by stamp.

    A message whose stamp is not newer than the one held for that robot and kind is
    ignored (duplicates, reordered or late messages). Arrays are indexed like ``ids``.
    """

    ids: tuple[str, ...]
    index: dict[str, int] = field(init=False)
    odom: np.ndarray = field(init=False)  # (N, 3) odom frame
    vel: np.ndarray = field(init=False)  # (N, 2)
    odom_stamp: np.ndarray = field(init=False)
    pose: np.ndarray = field(init=False)  # (N, 3) map frame (robots that report it)
    pose_stamp: np.ndarray = field(init=False)
    scans: list = field(init=False)  # latest ranges per robot (or None)
    scan_stamp: np.ndarray = field(init=False)
    status: list = field(init=False)
    status_stamp: np.ndarray = field(init=False)
    last_seen: np.ndarray = field(init=False)  # stamp of the newest message of any kind
    people: TrackedPeople | None = None
    #: robots with a scan that has not been taken by :meth:`take_scans` yet
    _new_scan: np.ndarray = field(init=False)
    #: per kind of report, the (stamp, seq) of the last one taken from each robot
    _last_stamp: dict = field(init=False)
    _last_seq: dict = field(init=False)
    _batch_ids: tuple | None = field(init=False, default=None)
    _batch_rows: np.ndarray | None = field(init=False, default=None)
    ignored: int = 0  # messages dropped as stale or duplicate

    def __post_init__(self) -> None:
        n = len(self.ids)
        self.index = {rid: i for i, rid in enumerate(self.ids)}
        self.odom = np.full((n, 3), np.nan)
        self.vel = np.zeros((n, 2))
        self.pose = np.full((n, 3), np.nan)
        self.scans = [None] * n
        self.status = ["unknown"] * n
        for name in ("odom_stamp", "pose_stamp", "scan_stamp", "status_stamp", "last_seen"):
            setattr(self, name, np.full(n, -np.inf))
        self._new_scan = np.zeros(n, dtype=bool)
        kinds = ("odom", "pose", "scan", "status")
        self._last_stamp = {k: np.full(n, -np.inf) for k in kinds}
        self._last_seq = {k: np.full(n, -1, dtype=np.int64) for k in kinds}

    def absorb(self, messages: Iterable[Message] | Arrivals) -> None:
        """Fold ``messages`` in (in any order); :class:`ReportBatch` objects are folded whole,
        with the same outcome as their messages one by one."""
        for m in messages.parts if isinstance(messages, Arrivals) else messages:
            if isinstance(m, ReportBatch):
                self._absorb_batch(m)
                continue
            if isinstance(m, TrackedPeople):
                if self.people is None or m.stamp > self.people.stamp:
                    self.people = m
                else:
                    self.ignored += 1
                continue
            i = self.index.get(m.robot)
            if i is None:
                self.ignored += 1  # a robot this fleet does not know
                continue
            if not self._fresh(m, i):
                self.ignored += 1
                continue
            self.last_seen[i] = max(self.last_seen[i], m.stamp)

    def _newer(self, m: Message, kind: str, i: int) -> bool:
        """``m`` is newer than the last message of this kind from robot ``i`` (by stamp, then
        by the sender's counter); if so it becomes the last one."""
        stamps, seqs = self._last_stamp[kind], self._last_seq[kind]
        if (m.stamp, m.seq) <= (float(stamps[i]), int(seqs[i])):
            return False
        stamps[i], seqs[i] = m.stamp, m.seq
        return True

    def _newer_rows(self, kind: str, rows: np.ndarray, stamp: float, seq: np.ndarray):
        """:meth:`_newer` for a batch: which of ``rows`` (distinct) it is newer for."""
        stamps, seqs = self._last_stamp[kind], self._last_seq[kind]
        ls = stamps[rows]
        new = (stamp > ls) | ((stamp == ls) & (seq > seqs[rows]))
        take = rows[new]
        stamps[take] = stamp
        seqs[take] = seq[new]
        self.ignored += int(len(rows) - len(take))
        return new, take

    def _rows(self, ids: tuple[str, ...]) -> np.ndarray:
        """Indices of ``ids`` in this fleet (-1: unknown), kept for the next batch alike."""
        if ids is not self._batch_ids:
            rows = [self.index.get(rid, -1) for rid in ids]
            self._batch_ids, self._batch_rows = ids, np.array(rows, dtype=np.int64)
        return self._batch_rows

    def _absorb_batch(self, b: ReportBatch) -> None:
        rows = self._rows(b.ids)
        known = rows >= 0
        kinds = 1 + (b.pose is not None) + (b.ranges is not None)
        sel = slice(None)
        if not known.all():
            self.ignored += kinds * int((~known).sum())  # robots this fleet does not know
            sel = known
            rows = rows[known]
        seq = np.asarray(b.seq)[sel]
        t = b.stamp
        heard = np.zeros(len(rows), dtype=bool)
        new, take = self._newer_rows("odom", rows, t, seq)
        self.odom[take], self.vel[take], self.odom_stamp[take] = (
            b.odom[sel][new],
            b.vel[sel][new],
            t,
        )
        heard |= new
        if b.pose is not None:
            new, take = self._newer_rows("pose", rows, t, seq)
            self.pose[take], self.pose_stamp[take] = b.pose[sel][new], t
            heard |= new
        if b.ranges is not None:
            new, take = self._newer_rows("scan", rows, t, seq)
            ranges = b.ranges[sel]
            for k, i in zip(np.flatnonzero(new).tolist(), take.tolist(), strict=True):
                self.scans[i] = ranges[k]
            self.scan_stamp[take] = t
            self._new_scan[take] = True
            heard |= new
        seen = rows[heard]
        self.last_seen[seen] = np.maximum(self.last_seen[seen], t)

    def _fresh(self, m: Message, i: int) -> bool:
        if isinstance(m, Odometry):
            if not self._newer(m, "odom", i):
                return False
            self.odom[i], self.vel[i], self.odom_stamp[i] = m.pose, m.vel, m.stamp
        elif isinstance(m, PoseReport):
            if not self._newer(m, "pose", i):
                return False
            self.pose[i], self.pose_stamp[i] = m.pose, m.stamp
        elif isinstance(m, Scan):
            if not self._newer(m, "scan", i):
                return False
            self.scans[i], self.scan_stamp[i] = m.ranges, m.stamp
            self._new_scan[i] = True
        elif isinstance(m, Status):
            if not self._newer(m, "status", i):
                return False
            self.status[i], self.status_stamp[i] = m.state, m.stamp
        else:
            raise TypeError(f"link: unknown message type {type(m).__name__}")
        return True

    def take_scans(self) -> np.ndarray:
        """Indices of robots with a scan not taken yet (and mark them taken)."""
        idx = np.flatnonzero(self._new_scan)
        self._new_scan[:] = False
        return idx

    def age(self, now: float) -> np.ndarray:
        """Seconds since each robot was last heard from (``inf``: never)."""
        return now - self.last_seen
