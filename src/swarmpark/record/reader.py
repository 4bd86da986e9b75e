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
        raise RecordingError(f"{path}: not a complete MCAP recording, cut short or damaged ({_why(exc)})") from None


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
        raise RecordingError(f"{path}: not a complete MCAP recording, cut short or damaged ({_why(exc)})") from None
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


def load_recording(path: str | Path) -> Recording:
    """Read a recording written by :class:`~swarmpark.record.recorder.Recorder`."""
    path = Path(path)
    meta, chans = _summary(path)
    world = json.loads(meta["swarmpark.world"]["json"])
    run = meta.get("swarmpark.run", {})
    result = json.loads(meta["swarmpark.result"]["json"]) if "swarmpark.result" in meta else None
    ids = [r["id"] for r in world["robots"]]
    index = {rid: i for i, rid in enumerate(ids)}
    n = len(ids)
    stamps: dict[str, list[float]] = {t: [] for t in chans}
    odom: dict[float, np.ndarray] = {}
    state_rows: dict[float, tuple[bool, list[int]]] = {}
    people: list[tuple[float, np.ndarray]] = []
    rec: dict = {
        "goals": [],
        "groups": [],
        "paths": [],
        "commands": [],
        "operator": [],
        "alarms": [],
    }
    grid = None
    wanted = [t for t in chans if not t.endswith("/scan") and not t.endswith("/cmd_vel")]
    for topic, _, t, msg in read_channels(path, wanted):
        stamps[topic].append(t)
        if topic.endswith("/odom"):
            row = odom.setdefault(t, np.full((n, 5), np.nan))
            p = msg.pose.pose
            q = np.array([p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w])
            row[index[topic.split("/")[1]]] = (
                p.position.x, p.position.y, m.quaternion_yaw(q),
                msg.twist.twist.linear.x, msg.twist.twist.angular.z,
            )  # fmt: skip
        elif topic == "/swarmpark/state":
            d = json.loads(msg.data)
            state_rows[t] = (d["estop"], d["states"])
        elif topic == "/people":
            people.append(
                (t, np.array([[mk.pose.position.x, mk.pose.position.y] for mk in msg.markers]))
            )
        elif topic == "/goals":
            g = np.full((n, 3), np.nan)
            for mk in msg.markers:
                if mk.action != m.DELETE:
                    o = mk.pose.orientation
                    g[mk.id] = (
                        mk.pose.position.x,
                        mk.pose.position.y,
                        m.quaternion_yaw(np.array([o.x, o.y, o.z, o.w])),
                    )
            rec["goals"].append((t, g))
        elif topic == "/boundary":
            rec["groups"].append((t, _marker_groups(msg)))
        elif topic == "/paths":
            paths = [None] * n
            for mk in msg.markers:
                if mk.action != m.DELETE:
                    paths[mk.id] = [v for p in mk.points for v in (p.x, p.y)]
            rec["paths"].append((t, paths))
        elif topic == "/swarmpark/commands":
            rec["commands"].append(json.loads(msg.data))
        elif topic == "/swarmpark/operator":
            rec["operator"].append(json.loads(msg.data))
        elif topic == "/swarmpark/alarms":
            rec["alarms"].append(json.loads(msg.data))
        elif topic == "/map" and grid is None:
            grid = msg
    if grid is None or not odom:
        raise RecordingError(f"{path}: a swarmpark recording without a map or poses")
    for topic in chans:
        if topic.endswith("/scan") or topic.endswith("/cmd_vel"):
            stamps[topic] = [t for _, _, t, _ in _stamps_only(path, topic)]
    times = np.array(sorted(odom))
    rows = np.stack([odom[t] for t in times])
    states = np.array([state_rows.get(t, (False, [0] * n))[1] for t in times], dtype=np.int64)
    estop = np.array([state_rows.get(t, (False, None))[0] for t in times], dtype=bool)
    data = np.asarray(grid.data, np.int8).reshape(grid.info.height, grid.info.width)
    pt = np.array([t for t, _ in people]) if people else np.zeros(0)
    pxy = np.stack([xy for _, xy in people]) if people else np.zeros((0, 0, 2))
    return Recording(
        path=path,
        run=run,
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
        people_times=pt,
        people_xy=pxy,
        stamps={k: np.array(v) for k, v in stamps.items()},
        types=chans,
        **rec,
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
