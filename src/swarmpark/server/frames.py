"""Compact state messages for the browser: the static world once, then small per-frame deltas.

A *frame* carries what changes every tick (poses, states, people and the people the fleet
tracks, the clock) as rounded arrays, plus the slow parts (goals, planned paths, park-group
boundaries, the command log, the metrics summary, each skid's last order) only when they
changed since the previous frame. The heavy layers (obstacles detected by onboard sensing,
each skid's last velocity command and localization error) are looked at twice a second
(:data:`HEAVY_EVERY`) and sent only when they changed. A client that joins,
or that missed a frame, gets a *full* frame with every slow part. Angles are degrees here:
this is the user's edge.
"""

from __future__ import annotations

import io
from collections import deque
from typing import Any

import numpy as np

from swarmpark.supervisor.core import ROBOT_STATES, Supervisor
from swarmpark.supervisor.sensing import DETECTION_SQUARE_M

__all__ = ["FrameEncoder", "world_info", "map_png", "jsonable", "SLOW_KEYS"]

#: Decimal places: millimetres for poses, centimetres for drawn lines, tenths of a degree.
XY_DEC, LINE_DEC, DEG_DEC, V_DEC = 3, 2, 1, 2
#: Outcomes shown in the command log (most recent last).
LOG_LENGTH = 40
#: The metrics summary is recomputed every this many frames (it walks every robot).
METRICS_EVERY = 10
#: The heavy layers are looked at every this many frames (2 Hz at 20 frames a second).
HEAVY_EVERY = 10
#: Detected-obstacle squares sent at most (the first ones in order; ``total`` says how many).
MAX_DETECTED = 5_000
SLOW_KEYS = ("goals", "paths", "groups", "log", "metrics", "orders", "detected", "robot_info")
#: Robot ids listed per log entry (the count is always given).
LOG_ROBOTS = 8
_STATE_CODE = {s: k for k, s in enumerate(ROBOT_STATES)}


def jsonable(obj: Any) -> Any:
    """Plain JSON types from numpy scalars/arrays, tuples and nested containers."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, float | np.floating):
        f = float(obj)
        return f if np.isfinite(f) else None
    if obj is None or isinstance(obj, str | int | bool):
        return obj
    return str(obj)


def _poses_deg(poses: np.ndarray) -> list[list[float]]:
    out = np.column_stack(
        [np.round(poses[:, :2], XY_DEC), np.round(np.rad2deg(poses[:, 2]), DEG_DEC)]
    )
    return out.tolist()


def _ring(poly) -> list[list[float]]:
    """Exterior of a shapely polygon without the repeated closing vertex."""
    return np.round(np.asarray(poly.exterior.coords)[:-1], LINE_DEC).tolist()


def world_info(sup: Supervisor) -> dict:
    """Everything about the scenario that does not change while it runs."""
    world = sup.world
    grid = world.grid
    h, w = grid.shape
    return {
        "robots": [
            {
                "id": r.id,
                "length_m": r.footprint.length_m,
                "width_m": r.footprint.width_m,
                "pivot_from_rear_m": r.footprint.pivot,
                "max_speed_mps": r.max_speed_mps,
                "max_yaw_rate_radps": r.max_yaw_rate_radps,
            }
            for r in world.robots
        ],
        "states": list(ROBOT_STATES),
        "map": {
            "resolution_m": grid.resolution_m,
            "origin_m": [float(v) for v in grid.origin],
            "size_px": [int(w), int(h)],
            "bounds_m": [float(v) for v in grid.bounds],
        },
        "walls": [_ring(p) for p in world.wall_polygons],
        "obstacles": [_ring(p) for p in world.static_obstacles],
        "people": [{"id": p.id, "radius_m": p.radius_m} for p in world.people],
        # Onboard sensing: skids localize themselves (a localization error per skid) and
        # detect obstacles (drawn as squares of this side).
        "sensing": sup.sensing is not None,
        "detection_square_m": DETECTION_SQUARE_M if sup.sensing is not None else None,
    }


def map_png(sup: Supervisor) -> bytes:
    """The occupancy grid as a greyscale PNG, one pixel per cell, north (max y) up."""
    from PIL import Image

    grid = sup.world.grid
    img = np.full(grid.shape, 255, np.uint8)
    img[grid.unknown] = 205
    img[grid.occupied] = 60
    buf = io.BytesIO()
    # Row 0 of the grid is the lowest y; row 0 of an image is the top.
    Image.fromarray(np.flipud(img), mode="L").save(buf, format="PNG", optimize=True)
    return buf.getvalue()


class FrameEncoder:
    """Builds frames for one supervisor; remembers the slow parts last sent."""

    def __init__(self, sup: Supervisor) -> None:
        self.sup = sup
        self._cache: dict[str, Any] = {}
        self._paths_ref: list | None = None
        self._goals_key: bytes | None = None
        self._groups_key: tuple | None = None
        self._log_n = -1
        self._orders_n = 0
        self._orders: list[list | None] = [None] * sup.n
        self._frames = 0
        self.metrics_now = True
        self._cache_ref: dict[str, Any] = {}
        #: Whether the last frame's delta carried a slow part (a viewer that missed it
        #: needs a full frame; one that missed only frames without any can take a delta).
        self.last_had_slow = True

    # ------------------------------------------------------------------ slow parts

    def _goals(self) -> list | None:
        sup = self.sup
        key = sup.goals.tobytes() + sup.has_goal.tobytes()
        if key == self._goals_key:
            return None
        self._goals_key = key
        poses = _poses_deg(sup.goals)
        return [p if h else None for p, h in zip(poses, sup.has_goal.tolist(), strict=True)]

    def _paths(self) -> list | None:
        paths_fn = getattr(self.sup.controller, "paths", None)
        if paths_fn is None:
            return None if "paths" in self._cache else []
        paths = list(paths_fn())
        prev = self._paths_ref
        # The controller replaces a path array when it replans: identity tells us cheaply.
        # Holding the previous list keeps those arrays alive, so ids cannot be reused.
        if (
            prev is not None
            and len(prev) == len(paths)
            and all(a is b for a, b in zip(prev, paths, strict=True))
        ):
            return None
        self._paths_ref = paths
        out: list = []
        for p in paths:
            if p is None or len(p) == 0:
                out.append(None)
            else:
                out.append(np.round(np.asarray(p, float)[:, :2], LINE_DEC).ravel().tolist())
        # Pad: a controller may not know robots that never had a goal yet.
        out += [None] * (self.sup.n - len(out))
        return out

    def _groups(self) -> list | None:
        groups = self.sup.groups
        key = tuple((id(g), len(g.robots), g.goal_of.tobytes()) for g in groups)
        if key == self._groups_key:
            return None
        self._groups_key = key
        ids = self.sup.ids
        return [
            {
                "robots": [ids[i] for i in g.robots],
                "boundary": _ring(g.boundary),
                "method": g.method,
            }
            for g in groups
        ]

    def _log(self) -> list | None:
        outcomes = self.sup.outcomes
        if len(outcomes) == self._log_n:
            return None
        self._log_n = len(outcomes)
        shown: deque = deque(maxlen=LOG_LENGTH)
        last_teleop: str | None = None
        # Walk back only as far as needed: teleop keep-alives repeat and are collapsed.
        for o in outcomes[-LOG_LENGTH * 20 :]:
            robot = o.detail.get("robot") if o.detail else None
            if o.accepted and o.command == "teleop":
                if last_teleop == robot:
                    continue
                last_teleop = robot
            elif o.command in ("release",):
                last_teleop = None
            shown.append(
                {
                    "accepted": o.accepted,
                    "command": o.command,
                    "reason": o.reason,
                    "t_s": round(o.t_s, 2),
                    **({"robot": robot} if robot else {}),
                    # Which skids a command applied to (the first few, and how many).
                    **(
                        {
                            "robots": list(o.detail["robots"][:LOG_ROBOTS]),
                            "n": len(o.detail["robots"]),
                        }
                        if o.detail and isinstance(o.detail.get("robots"), list)
                        else {}
                    ),
                }
            )
        return list(shown)

    def _orders_now(self) -> list | None:
        """Per skid, the last command applied to it: ``[command, t_s]`` or ``None``."""
        outcomes, sup = self.sup.outcomes, self.sup
        if len(outcomes) == self._orders_n:
            return None
        changed = False
        for o in outcomes[self._orders_n :]:
            if not o.accepted:
                continue
            if o.command == "estop":
                names = sup.ids
            elif o.detail and isinstance(o.detail.get("robots"), list):
                names = o.detail["robots"]
            elif o.detail and o.detail.get("robot") in sup.index:
                names = [o.detail["robot"]]
            else:
                continue  # a teleop keep-alive names no one new
            entry = [o.command, round(o.t_s, 2)]
            for name in names:
                i = sup.index.get(name)
                if i is not None and self._orders[i] != entry:
                    self._orders[i] = entry
                    changed = True
        self._orders_n = len(outcomes)
        return list(self._orders) if changed or "orders" not in self._cache else None

    def _detected(self) -> dict | None:
        """Obstacles the skids' scans detected (onboard sensing), as the squares holding
        them: ``{"squares": [i0, j0, i1, j1, ...], "total": K}`` (square ``(i, j)`` spans
        ``[i, i + 1) * detection_square_m`` of ``/api/world`` in x, likewise in y)."""
        sensing = self.sup.sensing
        if sensing is None:
            return None
        sq = sensing.detected_squares
        if sq is self._cache_ref.get("detected"):
            return None  # replaced, never changed in place, when the detections change
        self._cache_ref["detected"] = sq
        out = {"squares": sq[:MAX_DETECTED].ravel().tolist(), "total": len(sq)}
        return None if out == self._cache.get("detected") else out

    def _robot_info(self) -> dict | None:
        """Per skid: the last velocity command sent ``cmd`` ``[[v, omega], ...]`` and, when
        the skids localize onboard in the simulator, the localization error ``loc_err_m``
        (estimate against the truth, at the last scan)."""
        sup = self.sup
        # + 0.0: no "-0.0" for a command rounded to zero
        out: dict[str, Any] = {"cmd": (np.round(sup.sent, V_DEC) + 0.0).tolist()}
        if sup.sensing is not None and sup.loc_errors:
            out["loc_err_m"] = np.round(sup.loc_errors[-1], XY_DEC).tolist()
        return None if out == self._cache.get("robot_info") else out

    def _tracked(self) -> list | None:
        """The people the fleet avoids as its tracker reports them, ``[[x, y, vx, vy], ...]``
        (with onboard sensing, the onboard tracker's people that walked)."""
        sensing = self.sup.sensing
        people = self.sup.inbox.people if sensing is None else sensing.people
        if people is None or not len(people.xy):
            return None
        rows = np.column_stack([np.round(people.xy, LINE_DEC), np.round(people.vel, V_DEC)])
        return rows.tolist()

    def _metrics(self) -> dict:
        sup = self.sup
        r = sup.metrics.result(sup.t, sup.truth_poses(), sup.goals, sup.has_goal)
        commanded = sum(1 for s in r["robots"].values() if s["commanded"])
        parked = sum(1 for s in r["robots"].values() if s["parked"])
        return {
            "success": r["success"],
            "parked": parked,
            "commanded": commanded,
            "time_to_park_s": r["time_to_park_s"],
            "lower_bound_s": r["lower_bound_s"],
            "collisions": len(r["collisions"]),
            "min_clearance_m": r["min_clearance_m"],
            "deadlocks": len(r["deadlocks"]),
            "path_length_m": round(float(sum(r["path_length_m"].values())), 2),
        }

    # ------------------------------------------------------------------ frames

    def frame(self, extra: dict, *, want_delta: bool = True, want_full: bool = False):
        """Build this frame: returns ``(delta, full)`` dicts (``None`` where not wanted).

        Must be called once per broadcast so "changed since last frame" stays true.
        """
        sup = self.sup
        poses, vel = sup.truth_poses(), sup.truth_vel()  # a real link: what the robots report
        states = [_STATE_CODE[m] for m in sup.modes()]
        robots = np.column_stack(
            [
                np.round(poses[:, :2], XY_DEC),
                np.round(np.rad2deg(poses[:, 2]), DEG_DEC),
                states,
                np.round(vel[:, 0], V_DEC),
            ]
        ).tolist()
        for row in robots:  # the state code is an index, not a float
            row[3] = int(row[3])
        ppos = sup.sim.person_positions() if sup.sim is not None else np.zeros((0, 2))
        people = [[round(float(x), LINE_DEC), round(float(y), LINE_DEC)] for x, y in ppos.tolist()]
        fast = {
            "type": "state",
            "t_s": round(sup.t, 3),
            "estop": bool(sup.estopped),
            "robots": robots,
            "people": people,
            **extra,
        }
        tracked = self._tracked()
        if tracked is not None:
            fast["tracked"] = tracked
        parts = [("goals", self._goals), ("paths", self._paths), ("groups", self._groups)]
        parts.append(("orders", self._orders_now))
        if self._frames % HEAVY_EVERY == 0:
            parts += [("detected", self._detected), ("robot_info", self._robot_info)]
        changed: dict[str, Any] = {}
        for key, fn in parts:
            val = fn()
            if val is not None:
                changed[key] = val
        log = self._log()
        if log is not None:
            changed["log"] = log
        if self.metrics_now or self._frames % METRICS_EVERY == 0:
            m = self._metrics()
            if m != self._cache.get("metrics"):
                changed["metrics"] = m
            self.metrics_now = False
        self._frames += 1
        self.last_had_slow = bool(changed)
        self._cache.update(changed)
        delta = {**fast, "full": False, **changed} if want_delta else None
        full = {**fast, "full": True, **self._cache} if want_full else None
        return delta, full
