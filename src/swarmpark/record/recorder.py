"""The run recorder: an observer of the tick loop that writes ROS 2 channels to its sinks.

Channels (stamps are simulated time):

==========================  ==================================  ===========================
topic                       type                                when
==========================  ==================================  ===========================
``/map``                    nav_msgs/OccupancyGrid              at the start
``/world``                  visualization_msgs/MarkerArray      walls, obstacles; at start
``/tf_static``              tf2_msgs/TFMessage                  base_link -> laser; start
``/tf``                     tf2_msgs/TFMessage                  map -> ``<id>/base_link``
``/<id>/odom``              nav_msgs/Odometry                   every record step
``/<id>/cmd_vel``           geometry_msgs/Twist                 every record step
``/<id>/scan``              sensor_msgs/LaserScan               every scan step (sensing)
``/footprints``             visualization_msgs/MarkerArray      every record step
``/people``                 visualization_msgs/MarkerArray      every record step (people)
``/goals``                  visualization_msgs/MarkerArray      when goals change
``/boundary``               visualization_msgs/MarkerArray      when park groups change
``/paths``                  visualization_msgs/MarkerArray      when planned paths change
``/swarmpark/state``        std_msgs/String (JSON)              states, e-stop; record step
``/swarmpark/commands``     std_msgs/String (JSON)              every command outcome
``/swarmpark/operator``     std_msgs/String (JSON)              operator requests (server)
``/swarmpark/alarms``       std_msgs/String (JSON)              collisions, deadlocks, ...
==========================  ==================================  ===========================

MCAP metadata: ``swarmpark.run`` (scenario, seed, rates), ``swarmpark.world`` (the world
description the UI draws), ``swarmpark.result`` (the run result, at the end).

The recorder reads the supervisor as the server's frames do (``sup.sim.poses``, goals,
groups, outcomes). Two values the supervisor does not keep, the velocity command of the
tick and the LIDAR ranges, are read by *taps*: the recorder wraps the instance's
``sim.step`` and ``localizer.step`` to keep a reference to their arguments (no copy of the
state, no change of behaviour).
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence

import numpy as np

from swarmpark.record import messages as m
from swarmpark.record.audit import AlarmTracker
from swarmpark.record.sinks import Sink

__all__ = ["Recorder", "RecordConfig", "TOPICS"]

#: Topics of the whole fleet (per-robot topics are ``/<id>/odom``, ``scan``, ``cmd_vel``).
TOPICS = {
    "/map": "map",
    "/world": "markers",
    "/tf_static": "tf",
    "/tf": "tf",
    "/footprints": "markers",
    "/people": "markers",
    "/goals": "markers",
    "/boundary": "markers",
    "/paths": "markers",
    "/swarmpark/state": "string",
    "/swarmpark/commands": "string",
    "/swarmpark/operator": "string",
    "/swarmpark/alarms": "string",
}
#: Topics written once or on change, which a late viewer needs again (ROS "latched").
LATCHED = ("/map", "/world", "/tf_static", "/goals", "/boundary", "/paths")
NS = 1_000_000_000
#: Decimal places of the path points (cm) and of drawn lines.
LINE_DEC = 2


class RecordConfig:
    """How often the recorder samples the run.

    Parameters
    ----------
    rate_hz
        Poses, velocities, footprints, people and states per simulated second (``None``:
        every tick). 10 Hz keeps the overhead on a 50-skid tick under 10 % (see
        ``swarmpark bench --only record``); the goals, boundaries, paths, commands and
        alarms are written whenever they change, whatever the rate.
    scan_rate_hz
        LIDAR scans per simulated second (``None``: with every pose sample). Scans are most
        of a recording's size.
    """

    def __init__(self, *, rate_hz: float | None = 10.0, scan_rate_hz: float | None = 5.0):
        for name, v in (("rate_hz", rate_hz), ("scan_rate_hz", scan_rate_hz)):
            if v is not None and not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name}: must be > 0 or None (got {v!r})")
        self.rate_hz = rate_hz
        self.scan_rate_hz = scan_rate_hz if scan_rate_hz is not None else rate_hz

    def as_dict(self) -> dict:
        return {"rate_hz": self.rate_hz, "scan_rate_hz": self.scan_rate_hz}


class _Every:
    """True once per period of simulated time (every call when the rate is ``None``)."""

    def __init__(self, rate_hz: float | None) -> None:
        self.rate = rate_hz
        self.last = -1

    def __call__(self, t: float) -> bool:
        if self.rate is None:
            return True
        k = math.floor(t * self.rate + 1e-6)
        if k > self.last:
            self.last = k
            return True
        return False


def _t_ns(t: float) -> int:
    return int(round(t * NS))


class Recorder:
    """Observer of a run (``on_start``/``on_tick``/``on_command``/``on_alarm``/``on_end``).

    Parameters
    ----------
    sinks
        Where the messages go (an :class:`~swarmpark.record.sinks.McapSink`, a
        :class:`~swarmpark.record.sinks.FoxgloveSink`, or both).
    config
        Sampling rates.
    owned
        Sinks closed by :meth:`on_end` (default: all). A live server keeps its Foxglove sink
        open across scenario resets.
    meta
        Extra ``swarmpark.run`` metadata (e.g. the scenario file).
    """

    def __init__(
        self,
        sinks: Sequence[Sink],
        config: RecordConfig | None = None,
        *,
        owned: Sequence[Sink] | None = None,
        meta: dict | None = None,
    ) -> None:
        self.sinks = list(sinks)
        self.owned = list(self.sinks if owned is None else owned)
        self.config = config or RecordConfig()
        self.meta = dict(meta or {})
        self.sup = None
        self.ended = False
        self.messages = 0
        self.last_t_ns = 0

    # ------------------------------------------------------------------ plumbing

    def _open(self, topic: str, kind: str) -> None:
        typename = m.TYPES[kind]
        self._ch[topic] = ([s.channel(topic, typename) for s in self.sinks], typename)

    def _put(self, topic: str, t_ns: int, msg) -> None:
        ids, typename = self._ch[topic]
        data = m.serialize(msg, typename)
        for s, cid in zip(self.sinks, ids, strict=True):
            s.write(cid, t_ns, data)
        self.messages += 1
        if topic in LATCHED:
            self._latched[topic] = (t_ns, data)

    def republish(self, sink: Sink) -> None:
        """Send ``sink`` the last message of each latched topic (the map, the walls, goals,
        boundaries, paths): a viewer that subscribes late still sees them."""
        k = self.sinks.index(sink)
        for topic, (t_ns, data) in self._latched.items():
            sink.write(self._ch[topic][0][k], t_ns, data)

    def _json(self, topic: str, t_ns: int, obj) -> None:
        self._put(topic, t_ns, m.json_string(obj))

    # ------------------------------------------------------------------ observer

    def on_start(self, sup) -> None:
        """Declare the channels and write what does not change (map, walls, metadata)."""
        from swarmpark.server.frames import jsonable, world_info
        from swarmpark.supervisor.core import ROBOT_STATES

        self.sup = sup
        self._state_code = {s: k for k, s in enumerate(ROBOT_STATES)}
        self._ch: dict[str, tuple[list[int], str]] = {}
        self._latched: dict[str, tuple[int, bytes]] = {}
        self._pose_due = _Every(self.config.rate_hz)
        self._scan_due = _Every(self.config.scan_rate_hz)
        self._n_out = 0
        self._alarm_tracker = AlarmTracker()
        self._goals_key = None
        self._groups_key = None
        self._n_groups = 0
        self._paths_ref = None
        self._cmd = None
        self._ranges = None
        self._tap(sup)
        self.ids = list(sup.ids)
        self.scanning = getattr(sup, "localizer", None) is not None
        for topic, kind in TOPICS.items():
            if topic == "/people" and not len(sup.sim.people):
                continue
            self._open(topic, kind)
        for rid in self.ids:
            self._open(f"/{rid}/odom", "odom")
            self._open(f"/{rid}/cmd_vel", "twist")
            if self.scanning:
                self._open(f"/{rid}/scan", "scan")
        info = jsonable(world_info(sup))
        scn = sup.world.scenario
        run = {
            "scenario": scn.name,
            "seed": str(scn.seed),
            "dt_s": repr(scn.dt_s),
            "duration_s": repr(scn.duration_s),
            "robots": ",".join(self.ids),
            "record": json.dumps(self.config.as_dict()),
            **{k: str(v) for k, v in self.meta.items()},
        }
        for s in self.sinks:
            s.metadata("swarmpark.run", run)
            s.metadata("swarmpark.world", {"json": json.dumps(info, separators=(",", ":"))})
        self._static(sup, info)
        self.on_tick(sup)

    def _tap(self, sup) -> None:
        """Keep a reference to the tick's velocity command and scans (see module doc)."""
        rec = self
        sim_step = sup.sim.step

        def step(cmd, *args, **kwargs):
            rec._cmd = cmd
            return sim_step(cmd, *args, **kwargs)

        sup.sim.step = step
        loc = getattr(sup, "localizer", None)
        if loc is not None:
            loc_step = loc.step

            def loc_tap(poses, ranges, *args, **kwargs):
                rec._ranges = ranges
                return loc_step(poses, ranges, *args, **kwargs)

            loc.step = loc_tap

    def _static(self, sup, info: dict) -> None:
        g = sup.world.grid
        self._put("/map", 0, m.occupancy_grid(0, g.occupied, g.unknown, g.resolution_m, g.origin))
        self._put("/world", 0, m.world_markers(0, info["walls"], info["obstacles"]))
        spec = getattr(sup, "lidar_spec", None)
        mount = np.array([spec.mount]) if spec is not None else np.zeros((1, 3))
        self._put(
            "/tf_static",
            0,
            m.tf_message(
                0,
                [f"{rid}/base_link" for rid in self.ids],
                [f"{rid}/laser" for rid in self.ids],
                np.repeat(mount, len(self.ids), axis=0),
            ),
        )
        sim = sup.sim
        self._dims = np.array([[fp.length_m, fp.width_m] for fp in sim.footprints])
        self._centre = np.asarray(sim.center_offset, float)

    def on_tick(self, sup) -> None:
        """Sample the state after a tick (rate-limited) and every change since the last."""
        t = sup.t
        t_ns = _t_ns(t)
        self.last_t_ns = t_ns
        self._commands(t_ns)
        self._alarms(sup, t_ns)
        self._slow_parts(sup, t_ns)
        # The samples are most of the cost: none while nobody reads them (a live view with
        # no subscriber). Commands, alarms and the latched topics above are always written.
        if not any(s.active() for s in self.sinks):
            return
        if self._pose_due(t):
            self._poses(sup, t_ns)
        if self.scanning and self._ranges is not None and self._scan_due(t):
            self._scans(sup, t_ns)

    def _poses(self, sup, t_ns: int) -> None:
        sim = sup.sim
        poses, vel = sim.poses, sim.vel
        self._put("/tf", t_ns, m.tf_message(t_ns, "map", self._frames, poses))
        cmd = self._cmd if self._cmd is not None else np.zeros((sim.n, 2))
        for i, rid in enumerate(self.ids):
            self._put(f"/{rid}/odom", t_ns, m.odometry(t_ns, f"{rid}/base_link", poses[i], vel[i]))
            self._put(f"/{rid}/cmd_vel", t_ns, m.twist(cmd[i, 0], cmd[i, 1]))
        self._put(
            "/footprints",
            t_ns,
            m.footprint_markers(t_ns, self.ids, poses, self._dims, self._centre),
        )
        if "/people" in self._ch:
            xy = sim.person_positions()
            pid = [p.id for p in sim.people]
            self._put("/people", t_ns, m.people_markers(t_ns, pid, xy, sim.person_radius))
        code = self._state_code
        self._json(
            "/swarmpark/state",
            t_ns,
            {
                "t_s": round(sup.t, 6),
                "estop": bool(sup.estopped),
                "states": [code[s] for s in sup.modes()],
            },
        )

    @property
    def _frames(self) -> list[str]:
        return [f"{rid}/base_link" for rid in self.ids]

    def _scans(self, sup, t_ns: int) -> None:
        spec = sup.lidar_spec
        ranges = np.asarray(self._ranges).reshape(len(self.ids), -1)
        period = 1.0 / self.config.scan_rate_hz if self.config.scan_rate_hz else sup.sim.dt
        for i, rid in enumerate(self.ids):
            msg = m.laser_scan(
                t_ns,
                f"{rid}/laser",
                ranges[i],
                angle_min=spec.angle_min_rad,
                angle_increment=spec.angle_increment_rad,
                range_max=spec.max_range_m,
                scan_time=period,
            )
            self._put(f"/{rid}/scan", t_ns, msg)

    def _slow_parts(self, sup, t_ns: int) -> None:
        key = sup.goals.tobytes() + sup.has_goal.tobytes()
        if key != self._goals_key:
            self._goals_key = key
            self._put("/goals", t_ns, m.goal_markers(t_ns, self.ids, sup.goals, sup.has_goal))
        groups = sup.groups
        gkey = tuple((id(g), len(g.robots), g.goal_of.tobytes()) for g in groups)
        if gkey != self._groups_key:
            self._groups_key = gkey
            rows = [
                {
                    "robots": [self.ids[i] for i in g.robots],
                    "boundary": np.round(
                        np.asarray(g.boundary.exterior.coords)[:-1], LINE_DEC
                    ).tolist(),
                    "method": g.method,
                }
                for g in groups
            ]
            self._put("/boundary", t_ns, m.boundary_markers(t_ns, rows, self._n_groups))
            self._n_groups = len(rows)
        paths_fn = getattr(sup.controller, "paths", None)
        if paths_fn is not None:
            paths = list(paths_fn())
            prev = self._paths_ref
            if (
                prev is None
                or len(prev) != len(paths)
                or any(a is not b for a, b in zip(prev, paths, strict=True))
            ):
                self._paths_ref = paths
                self._put("/paths", t_ns, self._path_markers(t_ns, paths))

    def _path_markers(self, t_ns: int, paths: list):
        out = []
        for i, rid in enumerate(self.ids):
            p = paths[i] if i < len(paths) else None
            if p is None or len(p) < 2:
                out.append(m._marker(t_ns, "paths", i, m.LINE_STRIP, action=m.DELETE, text=rid))
            else:
                pts = np.round(np.asarray(p, float)[:, :2], LINE_DEC).tolist()
                out.append(
                    m._marker(t_ns, "paths", i, m.LINE_STRIP, scale=(m.LINE_WIDTH_M, 0, 0), rgba=m.GOAL_RGBA, points=pts, text=rid)
                )  # fmt: skip
        return m._array(out)

    def _commands(self, t_ns: int) -> None:
        outs = self.sup.outcomes
        for o in outs[self._n_out :]:
            self._json("/swarmpark/commands", t_ns, o.as_dict() | {"t_s": round(o.t_s, 6)})
        self._n_out = len(outs)

    def _alarms(self, sup, t_ns: int) -> None:
        for a in self._alarm_tracker.new(sup):
            self.on_alarm(a, t_ns)

    def on_command(self, entry: dict) -> None:
        """An operator request as the server saw it (client, token, answer): the audit."""
        if self.sup is not None and not self.ended:
            self._json("/swarmpark/operator", self.last_t_ns, entry)

    def on_alarm(self, entry: dict, t_ns: int | None = None) -> None:
        if self.sup is None or self.ended:
            return
        t_ns = self.last_t_ns if t_ns is None else t_ns
        self._json("/swarmpark/alarms", t_ns, {"t_s": t_ns / NS, **entry})

    def on_end(self, sup, result: dict | None = None) -> None:
        """Write the last changes and the result (MCAP metadata), close the owned sinks."""
        if self.ended:
            return
        if self.sup is not None:
            t_ns = self.last_t_ns
            self._commands(t_ns)
            self._alarms(sup, t_ns)
        self.ended = True
        if result is not None:
            from swarmpark.server.frames import jsonable

            text = json.dumps(jsonable(result), separators=(",", ":"))
            for s in self.sinks:
                s.metadata("swarmpark.result", {"json": text})
        for s in self.owned:
            s.close()
