"""The ORCA adapter: skid-skid and skid-person avoidance with velocity obstacles (RVO mode).

ORCA with priorities runs on every skid's effective centre (:mod:`swarmpark.control.orca.
kernel`, which this module only calls). Skids following a path prefer to move their centre
straight at a lookahead point at full speed (RVO's preferred velocity), turned right when
another skid comes the other way (keep right) or when side-stepping out of a deadlock; near
the goal the field's and the docking command is the preferred velocity. Settled skids (and
skids backing out of a deadlock) move only along their own axis. Stopped skids and skids
without orders are immobile: everyone else takes the full share against them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarmpark.control.base import ControlView
from swarmpark.control.nav.keep_right import keep_right_turns
from swarmpark.control.nav.params import AvoidanceParams, KeepRightParams
from swarmpark.control.nav.scene import Scene
from swarmpark.control.orca.kernel import (
    OrcaParams,
    effective_reach,
    holonomic_speed_limit,
    holonomic_to_unicycle,
    orca_step,
    skid_shapes,
    tracking_error_bound,
    unicycle_to_holonomic,
)
from swarmpark.core.geometry import rotation

__all__ = ["AvoidanceInput", "AvoidanceResult", "OrcaAdapter"]

#: A settled skid moving along its axis faster than this has been pushed off its spot.
_PUSHED_MPS = 1e-3


@dataclass(frozen=True)
class AvoidanceInput:
    """The other components' say in one ORCA step, per skid ``(N,)`` unless noted.

    ``settled``: on their goal (yield, move along the axis); ``immobile``: stopped or without
    orders; ``room_speed``/``aside``: making room (:mod:`.make_room`); ``bump``: priority bumps
    of the deadlock ladder; ``side_step``: per cruising skid, side-stepping now;
    ``backing``/``back_dir``: backing out along the axis (+1 forwards, -1 backwards).
    """

    settled: np.ndarray
    immobile: np.ndarray
    room_speed: np.ndarray
    aside: np.ndarray
    bump: np.ndarray
    side_step: np.ndarray
    backing: np.ndarray
    back_dir: np.ndarray


@dataclass(frozen=True)
class AvoidanceResult:
    """Commands ``(N, 2)``, the speed along each skid's axis ORCA chose ``(N,)`` and which
    skids were held to their axis."""

    commands: np.ndarray
    along: np.ndarray
    on_axis: np.ndarray


class OrcaAdapter:
    """Preferred velocities and priorities in, unicycle commands out.

    Parameters
    ----------
    params
        :class:`~swarmpark.control.nav.params.AvoidanceParams` (the ORCA parameters are
        built from them once, here).
    room_priority
        Priority of skids making room (above ``parked_priority``).
    sidestep_rad
        Clockwise turn of a side-stepping skid's preferred velocity.
    back_speed_share
        Speed of a skid backing out, as a share of its top speed.
    """

    def __init__(
        self,
        params: AvoidanceParams,
        *,
        room_priority: float,
        sidestep_rad: float,
        back_speed_share: float,
    ) -> None:
        self.params = params
        self.room_priority = room_priority
        self.sidestep_rad = sidestep_rad
        self.back_speed_share = back_speed_share
        self.orca = OrcaParams(min_share=params.min_share, time_horizon_s=params.horizon_s)
        self._keep_right = KeepRightParams(
            rad=params.keep_right_rad,
            max_rad=params.keep_right_max_rad,
            range_m=params.keep_right_range_m,
            open_m=params.keep_right_open_m,
            tight_m=params.keep_right_tight_m,
            min_share=params.min_share,
        )

    def step(
        self,
        view: ControlView,
        raw: np.ndarray,
        cruising: np.ndarray,
        aims: np.ndarray,
        scene: Scene,
        a: AvoidanceInput,
    ) -> AvoidanceResult:
        """One ORCA step for all skids: ``raw`` ``(N, 2)`` are the field's and docking's
        commands, ``cruising`` the skids following a path towards lookahead points ``aims``."""
        p = self.params
        plain = scene.skids.plain
        d = view.max_speed / view.max_yaw_rate  # effective centre: full speed is reachable
        u_lim = holonomic_speed_limit(view.max_speed, view.max_yaw_rate, d)
        err = tracking_error_bound(u_lim, view.max_yaw_rate, effective_reach(plain, d), view.dt)
        h = np.column_stack([np.cos(view.poses[:, 2]), np.sin(view.poses[:, 2])])
        u_now = unicycle_to_holonomic(view.poses, view.vel[:, 0], view.vel[:, 1], offset_m=d)
        u_pref = unicycle_to_holonomic(view.poses, raw[:, 0], raw[:, 1], offset_m=d)
        settled, immobile = a.settled, a.immobile
        # Settled skids move along their axis only: turning in a tight formation would sweep
        # their corners into their neighbours.
        along_pref = np.where(a.aside, a.room_speed, raw[:, 0])
        u_pref[settled] = along_pref[settled, None] * h[settled]
        # Skids on the move keep a little more room (margin_m) than the tracking bound: their
        # turns lag the command by the yaw acceleration limit. Parked ones only move straight
        # and sit close together, so they keep the bound alone.
        margin = err + np.where(settled | immobile, 0.0, p.margin_m)
        centres, shapes = skid_shapes(view.poses, plain, offset_m=d, margin_m=margin)
        steered = np.zeros(len(view.poses), dtype=bool)  # preferred velocity turned off the path
        if len(cruising):
            to_aim = aims[:, :2] - centres[cruising]
            dist = np.linalg.norm(to_aim, axis=1, keepdims=True)
            u_pref[cruising] = to_aim / np.maximum(dist, 1e-9) * u_lim[cruising, None]
            movers = ~settled & ~immobile & view.active
            turn = self.keep_right(
                view, centres, u_pref, view.priority + a.bump, cruising, movers, scene
            )
            turn[a.side_step] = self.sidestep_rad
            u_pref[cruising] = np.einsum("nij,nj->ni", rotation(-turn), u_pref[cruising])
            steered[cruising] = turn != 0
        backing = a.backing
        for i in np.flatnonzero(backing):
            u_pref[i] = a.back_dir[i] * self.back_speed_share * view.max_speed[i] * h[i]
        prio = np.where(settled, p.parked_priority, view.priority + a.bump)
        prio = np.where(a.room_speed != 0, self.room_priority, prio)
        on_axis = settled | backing
        res = orca_step(
            centres,
            u_now,
            u_pref,
            u_lim,
            prio,
            shapes,
            dt_s=view.dt,
            params=self.orca,
            immobile=immobile,
            people_positions=view.people_xy,
            people_velocities=view.people_vel,
            people_radii=view.people_radius,
            obstacles=scene.static.orca_obstacles,
            axes=np.where(on_axis[:, None], h, np.nan),
        )
        v, w = holonomic_to_unicycle(
            view.poses,
            res.velocities,
            offset_m=d,
            v_max=view.max_speed,
            omega_max=view.max_yaw_rate,
        )
        out = np.column_stack([v, w])
        along = np.clip(np.einsum("ij,ij->i", res.velocities, h), -view.max_speed, view.max_speed)
        out[on_axis] = np.column_stack([along, np.zeros_like(along)])[on_axis]
        # Pure turns in place (u = 0 at the centre would drop them) pass through when ORCA
        # left the preferred velocity unchanged (and it was the path's, not kept right).
        same = (np.linalg.norm(res.velocities - u_pref, axis=1) < 1e-9) & ~on_axis & ~steered
        out[same] = raw[same]
        out[immobile] = 0.0
        return AvoidanceResult(out, along, on_axis)

    @staticmethod
    def pushed(settled: np.ndarray, along: np.ndarray) -> np.ndarray:
        """Settled skids ORCA moved off their spot (they dock again afterwards)."""
        return settled & (np.abs(along) > _PUSHED_MPS)

    def keep_right(
        self,
        view: ControlView,
        centres: np.ndarray,
        u_pref: np.ndarray,
        prio: np.ndarray,
        cruising: np.ndarray,
        movers: np.ndarray,
        scene: Scene,
    ) -> np.ndarray:
        """Clockwise turn (rad) of each cruising skid's preferred velocity
        (:func:`.keep_right.keep_right_turns` with this mode's parameters)."""
        return keep_right_turns(centres, u_pref, prio, cruising, movers, scene, self._keep_right)
