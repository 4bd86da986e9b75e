"""A recording read back: the MCAP channels of a run as arrays, for replay and checks.

:func:`load_recording` decodes what :class:`~swarmpark.record.recorder.Recorder` wrote
(poses from ``/<id>/odom``, states, people, goals, park boundaries, paths, commands, alarms
and the metadata). A file that is not an MCAP recording of swarmpark, or that was cut short,
raises :class:`RecordingError` with one line saying why.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from swarmpark.record import messages as m

__all__ = ["Recording", "RecordingError", "load_recording", "read_channels"]

NS = 1e9


class RecordingError(ValueError):
    """The file cannot be read as a swarmpark recording (the message says why)."""


@dataclass
class Recording:
    """A run as recorded. Times in seconds; poses ``(K, N, 3)`` in metres and radians."""

    path: Path
    run: dict
    world: dict
    result: dict | None
    ids: list[str]
    occupied: np.ndarray
    unknown: np.ndarray
    resolution_m: float
    origin: tuple[float, float]
    times: np.ndarray
    poses: np.ndarray
    vel: np.ndarray
    states: np.ndarray
    estop: np.ndarray
    people_times: np.ndarray
    people_xy: np.ndarray
    #: (t_s, goals (N, 3) with NaN rows for skids without a goal)
    goals: list = field(default_factory=list)
    #: (t_s, [{"robots", "boundary", "method"}, ...])
    groups: list = field(default_factory=list)
    #: (t_s, [flat xy list or None per robot])
    paths: list = field(default_factory=list)
    commands: list[dict] = field(default_factory=list)
    operator: list[dict] = field(default_factory=list)
    alarms: list[dict] = field(default_factory=list)
    #: topic -> stamps (s) of every message, in file order.
    stamps: dict[str, np.ndarray] = field(default_factory=dict)
    #: topic -> message type.
    types: dict[str, str] = field(default_factory=dict)

    @property
    def duration_s(self) -> float:
        return float(self.times[-1]) if len(self.times) else 0.0

    def index_at(self, t: float) -> int:
        """The last pose sample at or before ``t`` (the first one before the start)."""
        return max(int(np.searchsorted(self.times, t + 1e-9, side="right")) - 1, 0)


def _reader(f):
    from mcap.reader import make_reader

    return make_reader(f, validate_crcs=True)


def read_channels(path: str | Path, topics: list[str] | None = None):
    """Yield ``(topic, typename, t_s, decoded message)`` for the messages of ``topics``
    (all if ``None``) in log-time order; raises :class:`RecordingError` for a bad file."""
    path = Path(path)
    try:
        with open(path, "rb") as f:
            rd = _reader(f)
            for schema, channel, msg in rd.iter_messages(topics=topics, log_time_order=True):
                if schema is None or schema.encoding != "ros2msg":
                    continue
                yield (
                    channel.topic,
                    schema.name,
                    msg.log_time / NS,
                    m.deserialize(msg.data, schema.name),
                )
    except RecordingError:
        raise
    except FileNotFoundError:
        raise RecordingError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise RecordingError(f"{path}: is a directory, not an .mcap file") from None
    except Exception as exc:  # mcap raises many kinds for a damaged file
        raise RecordingError(
            f"{path}: not a complete MCAP recording, cut short or damaged ({_why(exc)})"
        ) from None


def _why(exc: Exception) -> str:
    text = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
    if len(text) > 80:
        text = text[:77] + "..."
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def _summary(path: Path) -> tuple[dict, dict[str, dict]]:
    """Metadata records and the channels (topic -> schema name)."""
    try:
        with open(path, "rb") as f:
            rd = _reader(f)
            header = rd.get_header()
            summary = rd.get_summary()
            if summary is None:
                raise RecordingError(
                    f"{path}: the MCAP file has no summary (the recording was cut short)"
                )
            meta = {r.name: dict(r.metadata) for r in rd.iter_metadata()}
            schemas = summary.schemas
            chans = {c.topic: schemas[c.schema_id].name for c in summary.channels.values()}
    except RecordingError:
        raise
    except FileNotFoundError:
        raise RecordingError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise RecordingError(f"{path}: is a directory, not an .mcap file") from None
    except Exception as exc:
        raise RecordingError(
            f"{path}: not a complete MCAP recording, cut short or damaged ({_why(exc)})"
        ) from None
    if header.profile != "ros2" or "swarmpark.world" not in meta:
        raise RecordingError(
            f"{path}: an MCAP file, but not a swarmpark recording "
            f"(profile {header.profile!r}, metadata {sorted(meta)})"
        )
    return meta, chans


def _marker_groups(msg) -> list[dict]:
    out = []
    for mk in msg.markers:
        if mk.action == m.DELETE:
            continue
        info = json.loads(mk.text)
        ring = [[p.x, p.y] for p in mk.points[:-1]]
        out.append({"robots": info["robots"], "boundary": ring, "method": info["method"]})
    return out


def _yaw(o) -> float:
    return float(m.quaternion_yaw(np.array([o.x, o.y, o.z, o.w])))


class _Collector:
    """Decoded messages sorted into the parts of a :class:`Recording`, one topic at a time."""

    def __init__(self, ids: list[str]) -> None:
        self.index = {rid: i for i, rid in enumerate(ids)}
        self.n = len(ids)
        self.odom: dict[float, np.ndarray] = {}
        self.state_rows: dict[float, tuple[bool, list[int]]] = {}
        self.people: list[tuple[float, np.ndarray]] = []
        self.grid = None
        self.parts: dict[str, list] = {
            k: [] for k in ("goals", "groups", "paths", "commands", "operator", "alarms")
        }
        self.by_topic = {
            "/swarmpark/state": self._state,
            "/people": self._people,
            "/goals": self._goals,
            "/boundary": lambda t, msg: self.parts["groups"].append((t, _marker_groups(msg))),
            "/paths": self._paths,
            "/swarmpark/commands": lambda t, msg: self.parts["commands"].append(
                json.loads(msg.data)
            ),
            "/swarmpark/operator": lambda t, msg: self.parts["operator"].append(
                json.loads(msg.data)
            ),
            "/swarmpark/alarms": lambda t, msg: self.parts["alarms"].append(json.loads(msg.data)),
            "/map": self._map,
        }

    def add(self, topic: str, t: float, msg) -> None:
        if topic.endswith("/odom"):
            self._odom(topic.split("/")[1], t, msg)
        elif topic in self.by_topic:
            self.by_topic[topic](t, msg)

    def _odom(self, rid: str, t: float, msg) -> None:
        row = self.odom.setdefault(t, np.full((self.n, 5), np.nan))
        p, tw = msg.pose.pose, msg.twist.twist
        row[self.index[rid]] = (
            p.position.x, p.position.y, _yaw(p.orientation), tw.linear.x, tw.angular.z,
        )  # fmt: skip

    def _state(self, t: float, msg) -> None:
        d = json.loads(msg.data)
        self.state_rows[t] = (d["estop"], d["states"])

    def _people(self, t: float, msg) -> None:
        xy = np.array([[mk.pose.position.x, mk.pose.position.y] for mk in msg.markers])
        self.people.append((t, xy))

    def _goals(self, t: float, msg) -> None:
        g = np.full((self.n, 3), np.nan)
        for mk in msg.markers:
            if mk.action != m.DELETE:
                g[mk.id] = (mk.pose.position.x, mk.pose.position.y, _yaw(mk.pose.orientation))
        self.parts["goals"].append((t, g))

    def _paths(self, t: float, msg) -> None:
        paths: list = [None] * self.n
        for mk in msg.markers:
            if mk.action != m.DELETE:
                paths[mk.id] = [v for p in mk.points for v in (p.x, p.y)]
        self.parts["paths"].append((t, paths))

    def _map(self, t: float, msg) -> None:
        if self.grid is None:
            self.grid = msg


def load_recording(path: str | Path) -> Recording:
    """Read a recording written by :class:`~swarmpark.record.recorder.Recorder`."""
    path = Path(path)
    meta, chans = _summary(path)
    world = json.loads(meta["swarmpark.world"]["json"])
    result = json.loads(meta["swarmpark.result"]["json"]) if "swarmpark.result" in meta else None
    ids = [r["id"] for r in world["robots"]]
    col = _Collector(ids)
    stamps: dict[str, list[float]] = {t: [] for t in chans}
    # Scans and twists are most of a file and not drawn: counted, not decoded.
    bulky = [t for t in chans if t.endswith(("/scan", "/cmd_vel"))]
    for topic, _, t, msg in read_channels(path, [t for t in chans if t not in bulky]):
        stamps[topic].append(t)
        col.add(topic, t, msg)
    grid = col.grid
    if grid is None or not col.odom:
        raise RecordingError(f"{path}: a swarmpark recording without a map or poses")
    for topic in bulky:
        stamps[topic] = [t for _, _, t, _ in _stamps_only(path, topic)]
    times = np.array(sorted(col.odom))
    rows = np.stack([col.odom[t] for t in times])
    none = (False, [0] * len(ids))
    states = np.array([col.state_rows.get(t, none)[1] for t in times], dtype=np.int64)
    estop = np.array([col.state_rows.get(t, none)[0] for t in times], dtype=bool)
    data = np.asarray(grid.data, np.int8).reshape(grid.info.height, grid.info.width)
    people = col.people
    return Recording(
        path=path,
        run=meta.get("swarmpark.run", {}),
        world=world,
        result=result,
        ids=ids,
        occupied=data == m.OCC_OCCUPIED,
        unknown=data == m.OCC_UNKNOWN,
        resolution_m=float(grid.info.resolution),
        origin=(grid.info.origin.position.x, grid.info.origin.position.y),
        times=times,
        poses=rows[:, :, :3],
        vel=rows[:, :, 3:],
        states=states,
        estop=estop,
        people_times=np.array([t for t, _ in people]) if people else np.zeros(0),
        people_xy=np.stack([xy for _, xy in people]) if people else np.zeros((0, 0, 2)),
        stamps={k: np.array(v) for k, v in stamps.items()},
        types=chans,
        **col.parts,
    )


def _stamps_only(path: Path, topic: str):
    """Messages of one topic without decoding them (scans are most of a file)."""
    with open(path, "rb") as f:
        for _, channel, msg in _reader(f).iter_messages(topics=[topic], log_time_order=True):
            yield channel.topic, None, msg.log_time / NS, None


def scans(path: str | Path, robot: str) -> tuple[np.ndarray, np.ndarray]:
    """Stamps ``(S,)`` and ranges ``(S, B)`` of one skid's ``/<robot>/scan``."""
    ts, rs = [], []
    for _, _, t, msg in read_channels(path, [f"/{robot}/scan"]):
        ts.append(t)
        rs.append(np.asarray(msg.ranges, float))
    return np.array(ts), (np.stack(rs) if rs else np.zeros((0, 0)))
