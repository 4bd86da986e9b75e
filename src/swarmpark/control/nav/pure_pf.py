"""Pure potential-field navigation, the 2015 paper's baseline (Sect. 3.2): no planner.

Each skid's goal pose attracts its leading action point directly (the end with the shorter
arc leads, extension 1; the goal force falls off near the goal, extension 3), and static
outlines, other skids and people repel it (:mod:`.field`, :mod:`.apf`). Nothing looks
further than the field does, so a skid facing a wall or a U-shaped obstacle between it and
its goal stops where attraction and repulsion balance: the local minima the 2015 paper
reports (Sect. 4: "certain robots reaching local minimums") and the 2018 paper's planner
was added to overcome (Sect. 3.4). It exists to reproduce that comparison
(``navigation: {mode: pure-pf}``); the default stack is :mod:`.navigator`.

Beside the field it keeps only what is not navigation: the docking manoeuvre within
``docking.manoeuvre_radius_m`` of the goal (the exact final pose, as the default stack
docks), the collision monitor as the safety layer (it scales commands down before a
contact; it never steers) and the fill-order hold. No path, no recovery, no give-way.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from swarmpark.control.base import ControlView
from swarmpark.control.nav.docking import Docking, DockState
from swarmpark.control.nav.field import PotentialField
from swarmpark.control.nav.follower import end_arcs
from swarmpark.control.nav.hold import hold_outside
from swarmpark.control.nav.monitor import CollisionMonitor
from swarmpark.control.nav.params import NavParams
from swarmpark.control.nav.recovery import BackUp, BackUpState, StallWatch
from swarmpark.control.nav.scene import Scene

__all__ = ["PurePotentialField", "PureState"]


@dataclass
class PureState:
    """One skid's state: which end leads, the docking state machine, its stall time."""

    reverse: bool = False
    dock: DockState = field(default_factory=DockState)
    stall: StallWatch = field(default_factory=StallWatch)
    backup: BackUpState = field(default_factory=BackUpState)


class PurePotentialField:
    """The 2015 controller: the potential field straight to the goal (module docstring).

    Parameters
    ----------
    params
        :class:`~swarmpark.control.nav.params.NavParams` (the defaults if None); its
        ``apf``, ``follower.switch_ratio`` (end-choice hysteresis), ``docking``,
        ``monitor``, ``stall`` and ``hold`` are used. ``avoidance`` must be ``"monitor"``.
    """

    def __init__(self, params: NavParams | None = None) -> None:
        p = NavParams() if params is None else params
        if not isinstance(p, NavParams):
            raise ValueError(f"PurePotentialField.params must be a NavParams (got {p!r})")
        if p.avoidance != "monitor":
            raise ValueError(
                f"PurePotentialField.params.avoidance must be 'monitor' (got {p.avoidance!r})"
            )
        self.params = p
        stall_s = p.stall.time_s
        self.scene = Scene(p.apf.outline_step_m, p.monitor.margin_m)
        self.field = PotentialField(p.apf, dynamic=True)
        self.docking = Docking(p.docking, BackUp(p.backup, stall_s=stall_s), stall_s=stall_s)
        self.monitor = CollisionMonitor(p.monitor)
        self.robots: list[PureState] = []

    def _grow(self, n: int) -> None:
        while len(self.robots) < n:
            self.robots.append(PureState())

    def _ends(self, view: ControlView, idx: np.ndarray) -> np.ndarray:
        """Which end leads (True: the rear): the shorter arc to the goal, switching only for
        an arc shorter by ``follower.switch_ratio`` (hysteresis, so the skid does not dither)."""
        robots = self.robots
        changed = view.goal_changed[idx]
        cur = np.array([robots[i].reverse for i in idx], dtype=bool)
        lf, lr = end_arcs(view, idx)
        ratio = self.params.follower.switch_ratio
        switch = np.where(cur, lf < ratio * lr, lr < ratio * lf)
        new = np.where(changed, lr < lf, np.where(switch, ~cur, cur))
        for k, i in enumerate(idx.tolist()):
            robots[i].reverse = bool(new[k])
        return new

    def compute(self, view: ControlView) -> np.ndarray:
        """Commanded ``(v, omega)`` ``(N, 2)``; inactive robots get zeros."""
        p = self.params
        n = len(view.poses)
        self._grow(n)
        cmd = np.zeros((n, 2))
        idx = np.flatnonzero(view.active)
        if len(idx) == 0:
            return cmd
        scene = self.scene.update(view)
        reverse = self._ends(view, idx)
        # The goal itself is the field's target all the way (no path, no lookahead).
        every = np.ones(len(idx), dtype=bool)
        raw, dist_goal = self.field.drive(
            view, idx, scene, view.goals[idx], reverse, every, p.follower.approach_m
        )
        # Docking only next to the goal: farther out, its back-up recovery would be an
        # escape manoeuvre the 2015 field does not have.
        near = dist_goal < p.docking.manoeuvre_radius_m
        robots = self.robots
        for i in idx[~near & view.goal_changed[idx]]:
            robots[i].dock.new_goal()
        if near.any():
            raw[near] = self.docking.step(
                view,
                idx[near],
                raw[near],
                every[near],
                [r.dock for r in robots],
                [r.stall for r in robots],
                [r.backup for r in robots],
            )
        cmd[idx] = self.monitor.check(view, idx, raw, scene).commands
        hold_outside(view, idx, cmd, p.hold)
        StallWatch.update_all(
            p.stall,
            [robots[i].stall for i in idx],
            cmd[idx],
            [robots[i].dock.docked for i in idx],
            view.dt,
        )
        return cmd

    def guard(self, view: ControlView, idx: np.ndarray, raw: np.ndarray) -> np.ndarray:
        """Commands ``raw`` of skids ``idx`` not driven here (teleop, formation plans), scaled
        down by the collision monitor until their short forward simulation is free."""
        self._grow(len(view.poses))
        self.scene.update(view)
        idx = np.asarray(idx, int)
        return self.monitor.check(view, idx, np.asarray(raw, float), self.scene).commands
