"""What a controller sees each tick, and the placeholder go-to-pose law.

A controller maps one :class:`ControlView` (a snapshot of the swarm taken before anyone moves)
to commanded ``(v, omega)`` for every skid: the decision phase of a two-phase tick, so results
never depend on the order of the robots.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from ..geometry import Footprint, wrap_angle
from ..gridmap import OccupancyGrid

__all__ = ["ControlView", "Controller", "GoToPoseController"]


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
    stopped: np.ndarray | None = None  # (N,) bool: stopped, e-stopped or teleop (immobile)


class Controller(Protocol):
    def compute(self, view: ControlView) -> np.ndarray:
        """Commanded ``(v, omega)`` ``(N, 2)``; inactive robots get zeros."""
        ...


class GoToPoseController:
    """Placeholder: turn toward the goal, drive (forwards or backwards, whichever faces it),
    then turn to the goal heading. No obstacle avoidance; the navigation stack replaces it."""

    def __init__(
        self,
        *,
        k_rho: float = 1.0,
        k_alpha: float = 2.0,
        k_yaw: float = 2.0,
        pos_tol_m: float = 0.03,
    ) -> None:
        self.k_rho, self.k_alpha, self.k_yaw, self.pos_tol_m = k_rho, k_alpha, k_yaw, pos_tol_m

    def compute(self, view: ControlView) -> np.ndarray:
        p, g = view.poses, view.goals
        d = g[:, :2] - p[:, :2]
        rho = np.linalg.norm(d, axis=1)
        bearing = np.arctan2(d[:, 1], d[:, 0])
        alpha = wrap_angle(bearing - p[:, 2])
        backwards = np.abs(alpha) > np.pi / 2
        alpha = np.where(backwards, wrap_angle(alpha + np.pi), alpha)
        sign = np.where(backwards, -1.0, 1.0)
        v = sign * np.minimum(self.k_rho * rho, view.max_speed) * np.clip(np.cos(alpha), 0, 1) ** 4
        w = self.k_alpha * alpha
        at_goal = rho < self.pos_tol_m
        v = np.where(at_goal, 0.0, v)
        w = np.where(at_goal, self.k_yaw * wrap_angle(g[:, 2] - p[:, 2]), w)
        cmd = np.column_stack([v, w])
        cmd[~view.active] = 0.0
        return cmd
