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

import itertools
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from swarmpark.control.base import ControlView
from swarmpark.control.nav.params import AvoidanceParams
from swarmpark.control.nav.scene import Scene
from swarmpark.control.orca.kernel import (
    OrcaParams,
    effective_reach,
    holonomic_speed_limit,
    holonomic_to_unicycle,
    orca_step,
    responsibility_shares,
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


def _facing(centres, u_pref, kk, i, j, cruising, others, near):
    """Per pair (skid ``i`` = ``cruising[kk]``, mover ``j``): whether ``j`` is ahead of ``i``
    (``(c_j - c_i) . u_i > 0``) and comes the other way (``u_j . u_i < 0``).

    These were one matrix-vector product per skid (BLAS, which may fuse the multiply-add);
    the two products summed here round differently, but the sign of the sum is the same
    unless it is exactly zero, so the pairs of skids with a zero are decided again by their
    skid's own matrix-vector products, and the result is the same as before."""
    u = u_pref[i]
    d = centres[j] - centres[i]
    dot_a = d[:, 0] * u[:, 0] + d[:, 1] * u[:, 1]
    dot_o = u_pref[j, 0] * u[:, 0] + u_pref[j, 1] * u[:, 1]
    ahead, oncoming = dot_a > 0, dot_o < 0
    for k in np.unique(kk[(dot_a == 0) | (dot_o == 0)]).tolist():
        ic = cruising[k]
        jk = others[near[k]]
        jk = jk[jk != ic]
        rows = np.flatnonzero(kk == k)  # the same movers, in the same order
        ahead[rows] = (centres[jk] - centres[ic]) @ u_pref[ic] > 0
        oncoming[rows] = u_pref[jk] @ u_pref[ic] < 0
    return ahead, oncoming


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
        """Clockwise turn (rad) of each cruising skid's preferred velocity where another skid
        on the move within ``keep_right_range_m`` ahead comes the other way (their preferred
        velocities more than 90 degrees apart), else 0.

        The turn is ``keep_right_rad`` times twice the skid's largest ORCA share against
        those skids (:func:`~swarmpark.control.orca.kernel.responsibility_shares`), at most
        ``keep_right_max_rad``: between equal priorities each turns ``keep_right_rad``, and
        the lower priority turns more. It fades out near static solids.
        """
        p = self.params
        turn = np.zeros(len(cruising))
        if p.keep_right_rad == 0 or movers.sum() < 2:
            return turn
        others = np.flatnonzero(movers)
        near = cKDTree(centres[others]).query_ball_point(centres[cruising], p.keep_right_range_m)
        # Every (cruising skid, mover near it) pair at once.
        lens = np.fromiter(map(len, near), int, len(near))
        kk = np.repeat(np.arange(len(cruising)), lens)
        j = others[np.fromiter(itertools.chain.from_iterable(near), int, int(lens.sum()))]
        i = cruising[kk]
        kk, i, j = kk[j != i], i[j != i], j[j != i]
        ahead, oncoming = _facing(centres, u_pref, kk, i, j, cruising, others, near)
        meet = ahead & oncoming
        if meet.any():
            kk, i, j = kk[meet], i[meet], j[meet]
            share = responsibility_shares(prio[i], prio[j], p.min_share)
            best = np.full(len(cruising), -np.inf)
            np.maximum.at(best, kk, share)  # the largest share per skid (exact in any order)
            met = np.unique(kk)
            turn[met] = np.minimum(2.0 * best[met] * p.keep_right_rad, p.keep_right_max_rad)
        kd = scene.static.kd
        if kd is not None and turn.any():
            # Beyond keep_right_open_m the fade is 1 whatever the distance (inf included).
            clear, _ = kd.query(centres[cruising], distance_upper_bound=p.keep_right_open_m)
            fade = (clear - p.keep_right_tight_m) / (p.keep_right_open_m - p.keep_right_tight_m)
            turn *= np.clip(fade, 0.0, 1.0)
        return turn
