"""Hand-built control views for the navigation component tests: no scenario, no simulator."""

from __future__ import annotations

import numpy as np
from shapely.geometry import box

from swarmpark.control.base import ControlView
from swarmpark.core.geometry import Footprint, integrate_unicycle
from swarmpark.core.gridmap import grid_from_walls

#: The skids of the tests: 1.2 m x 0.8 m, pivot in the middle (the scenario default).
FOOTPRINT = Footprint(1.2, 0.8, 0.6)
SIZE_M = (10.0, 6.0)


def box_piece(x0: float, y0: float, x1: float, y1: float) -> np.ndarray:
    """An axis-aligned box as a static piece ``(4, 2)``."""
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], float)


def make_view(
    poses,
    goals=None,
    *,
    t: float = 0.0,
    dt: float = 0.1,
    vel=None,
    active=None,
    priority=None,
    boxes=(),
    people_xy=None,
    people_vel=None,
    people_radius=None,
    goal_changed=None,
    stopped=None,
    max_speed: float = 0.5,
    max_yaw_rate: float = 1.0,
    max_accel: float = 1.0,
) -> ControlView:
    """A view of skids at ``poses`` ``(N, 3)`` (radians) in an open 10 m x 6 m hall with the
    axis-aligned ``boxes`` ``(x0, y0, x1, y1)`` as static solids."""
    poses = np.atleast_2d(np.asarray(poses, float))
    n = len(poses)
    goals = poses.copy() if goals is None else np.atleast_2d(np.asarray(goals, float))
    grid = grid_from_walls(SIZE_M, 0.05, [box(*b) for b in boxes])
    pieces = np.array([box_piece(*b) for b in boxes]).reshape(-1, 4, 2)
    people_xy = np.zeros((0, 2)) if people_xy is None else np.atleast_2d(people_xy).astype(float)
    p = len(people_xy)
    return ControlView(
        t=t,
        dt=dt,
        poses=poses,
        vel=np.zeros((n, 2)) if vel is None else np.atleast_2d(np.asarray(vel, float)),
        goals=goals,
        active=np.ones(n, bool) if active is None else np.asarray(active, bool),
        priority=np.ones(n) if priority is None else np.asarray(priority, float),
        footprints=(FOOTPRINT,) * n,
        max_speed=np.full(n, max_speed),
        max_yaw_rate=np.full(n, max_yaw_rate),
        max_accel=np.full(n, max_accel),
        grid=grid,
        people_xy=people_xy,
        people_vel=np.zeros((p, 2)) if people_vel is None else np.atleast_2d(people_vel) * 1.0,
        people_radius=np.full(p, 0.3) if people_radius is None else np.asarray(people_radius),
        static_pieces=pieces,
        goal_changed=np.zeros(n, bool) if goal_changed is None else np.asarray(goal_changed),
        stopped=None if stopped is None else np.asarray(stopped, bool),
    )


def advance(view: ControlView, cmd: np.ndarray, **changes) -> ControlView:
    """The view one step later with the skids driven by ``cmd`` (velocities change at once)."""
    from dataclasses import replace

    cmd = np.asarray(cmd, float).reshape(-1, 2)
    poses = integrate_unicycle(view.poses, cmd[:, 0], cmd[:, 1], view.dt)
    fields = {"t": view.t + view.dt, "poses": poses, "vel": cmd.copy()}
    fields["goal_changed"] = np.zeros(len(poses), bool)
    fields.update(changes)
    return replace(view, **fields)
