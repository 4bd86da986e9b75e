"""Helpers for the tests: tiny worlds built from dicts, scripted controllers, a small room
and a route driven through it for the sensing tests; the repository's scripts as modules."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
from shapely.geometry import Polygon, box

from swarmpark.core.geometry import wrap_angle
from swarmpark.core.gridmap import OccupancyGrid, grid_from_walls
from swarmpark.world.scenario import build_world, parse_scenario

ROOT = Path(__file__).resolve().parent.parent
SCENARIOS = ROOT / "scenarios"
DATA = ROOT / "tests" / "data"


def assert_goto_refused(sup, robot: str, pose, reason: str, kept) -> None:
    """A goto of ``robot`` to ``pose`` is refused with exactly ``reason``, and the robot keeps
    its previous goal ``kept`` (a refused command changes nothing)."""
    out = sup.command("goto", {"robot": robot, "pose": pose})
    assert not out.accepted
    assert out.reason == reason
    np.testing.assert_allclose(sup.goals[sup.index[robot]], kept)


def load_script(name: str):
    """``scripts/<name>.py`` of the repository, imported as a module."""
    spec = importlib.util.spec_from_file_location(name, ROOT / "scripts" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def hall_walls(width: float, height: float, t: float = 0.3) -> list:
    """The four outer walls, ``t`` thick, of a ``width`` x ``height`` hall (scenario form)."""
    return [
        [[0, 0], [width, 0], [width, t], [0, t]],
        [[0, height - t], [width, height - t], [width, height], [0, height]],
        [[0, t], [t, t], [t, height - t], [0, height - t]],
        [[width - t, t], [width, t], [width, height - t], [width - t, height - t]],
    ]


def make_world(**overrides):
    """A small open world (10 x 6 m) with one robot; keys override the scenario dict."""
    data = {
        "name": "t",
        "duration_s": 20,
        "map": {"size_m": [10, 6], "resolution_m": 0.05},
        "robots": [{"id": "a", "pose": [2.0, 3.0, 0.0]}],
    }
    data.update(overrides)
    return build_world(parse_scenario(data))


class Scripted:
    """A controller that replays a function of time: ``fn(t) -> (N, 2)`` commands."""

    def __init__(self, fn):
        self.fn = fn

    def compute(self, view):
        return np.asarray(self.fn(view.t), float).reshape(-1, 2)


def asymmetric_room() -> OccupancyGrid:
    """8 m x 5 m room, 10 cm walls, with a partition, a bench, a corner block and a wedge placed
    so that no rotation or mirror of the room looks the same."""
    w, h, t = 8.0, 5.0, 0.1
    walls = [
        box(0, 0, w, t),
        box(0, h - t, w, h),
        box(0, 0, t, h),
        box(w - t, 0, w, h),
        box(2.0, 0.0, 2.2, 2.0),
        box(5.0, 3.2, 6.5, 3.5),
        Polygon([(6.5, 0.1), (7.9, 0.1), (7.9, 1.2)]),
        box(0.1, 4.3, 0.6, 4.9),
    ]
    return grid_from_walls((w, h), 0.05, walls)


def drive(waypoints, v=0.5, w=1.0, dt=0.1) -> np.ndarray:
    """True poses ``(T, 3)`` every ``dt`` for a skid that turns in place at each waypoint and
    drives straight between them."""
    out, yaw = [], None
    pts = np.asarray(waypoints, dtype=float)
    for a, b in zip(pts[:-1], pts[1:], strict=True):
        heading = float(np.arctan2(b[1] - a[1], b[0] - a[0]))
        if yaw is not None:
            turn = float(wrap_angle(heading - yaw))
            for s in np.linspace(0, 1, int(abs(turn) / (w * dt)), endpoint=False):
                out.append([a[0], a[1], yaw + s * turn])
        yaw = heading
        n = int(np.linalg.norm(b - a) / (v * dt))
        for s in np.linspace(0, 1, n, endpoint=False):
            out.append([*(a + s * (b - a)), yaw])
    return np.array(out)
