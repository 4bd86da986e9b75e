"""What a controller sees each tick, and the controller interface.

A controller maps one :class:`ControlView` (a snapshot of the swarm taken before anyone moves)
to commanded ``(v, omega)`` for every skid: the decision phase of a two-phase tick, so results
never depend on the order of the robots.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from swarmpark.core.geometry import Footprint
from swarmpark.core.gridmap import OccupancyGrid

__all__ = ["ControlView", "Controller"]


@dataclass(frozen=True)
class ControlView:
    t: float
    dt: float
    poses: np.ndarray  # (N, 3) pivot poses the controller believes (truth or estimate)
    vel: np.ndarray  # (N, 2) (v, omega)
    goals: np.ndarray  # (N, 3), valid where active
    active: np.ndarray  # (N,) bool: robots the controller should drive
    priority: np.ndarray  # (N,)
    footprints: tuple[Footprint, ...]
    max_speed: np.ndarray
    max_yaw_rate: np.ndarray
    max_accel: np.ndarray
    grid: OccupancyGrid
    people_xy: np.ndarray  # (P, 2)
    people_vel: np.ndarray  # (P, 2)
    people_radius: np.ndarray  # (P,)
    static_pieces: np.ndarray  # (S, 4, 2) known static solids
    goal_changed: np.ndarray  # (N,) bool: the goal was set or changed this tick
    hold: np.ndarray | None = None  # (N,) bool: wait outside hold_zones[i] (fill order)
    hold_zones: tuple = ()  # per robot: shapely Polygon (its parking boundary) or None
    hold_outside: np.ndarray | None = None  # (N,) bool: of hold, those outside a boundary
    stopped: np.ndarray | None = None  # (N,) bool: stopped, e-stopped or teleop (immobile)
    max_yaw_accel: np.ndarray | None = None  # (N,) rad/s^2; None: turns change at once


class Controller(Protocol):
    def compute(self, view: ControlView) -> np.ndarray:
        """Commanded ``(v, omega)`` ``(N, 2)``; inactive robots get zeros."""
        ...
