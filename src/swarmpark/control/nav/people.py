"""Right of way for people: skids keep out of the way a person is predicted to walk.

Each person the fleet tracks (position and velocity, :class:`~swarmpark.control.base.
ControlView`) is predicted at constant velocity for ``horizon_s``; the predicted walk, widened
by the person's radius and ``clearance_m``, is the person's *way*. A person slower than
``walking_mps`` stands and may set off in any direction: their way is a disc ``standing_berth_m``
wider. Two rules then act on each skid's command, before the collision monitor:

* **Stop short**: a command whose short forward simulation (``rollout_s``) takes the skid into
  a person's way, or deeper into it, is slowed, then reduced to turning, then stopped (as
  Navigation2's collision monitor scales commands, here against the predicted way instead of
  the person where they stand).
* **Step aside**: a skid standing in a *walking* person's way (the person would walk into it
  where it stands, or pass closer than ``aside_clearance_m``) drives along its own axis to the nearest place clear of the way, of static
  solids and of the other skids, keeping the side it chose while it is in the way. The
  collision monitor checks that move against walls and skids but not against the person it
  leaves room for (its prediction would stop the skid right in the person's way).

The constant-velocity prediction is the one a Kalman people tracker gives
(:meth:`swarmpark.sense.tracking.PeopleTracker.predict`); yielding to predicted human motion
follows the "social" layer of human-aware navigation (Kruse et al., *Human-aware robot
navigation: A survey*, Robotics and Autonomous Systems 61(12), 2013, Sect. 4).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import shapely
from scipy.spatial import cKDTree

from swarmpark.control.base import ControlView
from swarmpark.control.nav.monitor import rollout
from swarmpark.control.nav.params import PeopleParams
from swarmpark.control.nav.scene import Scene
from swarmpark.core.geometry import (
    TOUCH_TOLERANCE_M,
    convex_overlap,
    footprint_corners,
    rect_disc_gap,
)

__all__ = ["PeopleYield", "PeopleWays", "YieldResult"]

#: Scales of the commanded speed tried, fastest first (the turn rate is kept); then a stop.
_SCALES = (1.0, 0.5, 0.25, 0.0)
#: A rollout may come this much closer to a way than the skid is now (rounding).
_DEEPER_TOL_M = 1e-3


@dataclass(frozen=True)
class PeopleWays:
    """The people's ways as discs: centres ``(K, 2)``, radii ``(K,)``, and whether each disc
    belongs to a walking person's predicted walk ``(K,)``."""

    centres: np.ndarray
    radii: np.ndarray
    walking: np.ndarray

    def gaps(self, corners: np.ndarray) -> np.ndarray:
        """Signed gap ``(M, K)`` of footprints ``(M, 4, 2)`` to every disc."""
        m, k = len(corners), len(self.centres)
        if not m or not k:
            return np.zeros((m, k))
        g = rect_disc_gap(
            np.repeat(corners, k, axis=0), np.tile(self.centres, (m, 1)), np.tile(self.radii, m)
        )
        return g.reshape(m, k)


@dataclass(frozen=True)
class YieldResult:
    """Commands ``(len(idx), 2)`` after yielding and which rows step aside ``(len(idx),)``."""

    commands: np.ndarray
    stepping_aside: np.ndarray


def _time_to_shift(shift: float, v0: float, accel: float, vmax: float) -> float:
    """Seconds for a skid moving at ``v0`` along its axis to travel ``shift`` (signed) from
    where it is, accelerating at ``accel`` up to ``vmax`` (a skid already moving one way
    gets out faster on that side)."""
    d, v = abs(shift), v0 * np.sign(shift)
    if v < 0:  # brake first, drifting the wrong way meanwhile
        return -v / accel + _time_to_shift(d + v * v / (2 * accel), 0.0, accel, vmax)
    # From v >= 0: as the time from rest over the distance plus the run-up, less the run-up.
    head = v * v / (2 * accel)
    full = d + head
    d_acc = vmax * vmax / (2 * accel)
    t = np.sqrt(2 * full / accel) if full <= d_acc else vmax / accel + (full - d_acc) / vmax
    return float(t - v / accel)


class PeopleYield:
    """See the module docstring.

    Parameters
    ----------
    params
        :class:`~swarmpark.control.nav.params.PeopleParams`.
    """

    def __init__(self, params: PeopleParams) -> None:
        self.params = params
        p = params
        self.times = np.linspace(p.rollout_s / p.rollout_samples, p.rollout_s, p.rollout_samples)
        n = int(round(p.shift_max_m / p.shift_step_m))
        self.steps = np.arange(1, n + 1) * p.shift_step_m
        #: How far into a walk a skid may stand before it steps aside.
        self._slack = p.clearance_m - p.aside_clearance_m
        #: Per skid, the side (+1 ahead, -1 back) it last stepped aside to, or 0.
        self.side = np.zeros(0, dtype=int)

    # ------------------------------------------------------------------ the ways

    def walking(self, view: ControlView) -> np.ndarray:
        """``(P,)`` bool: the people walking (not standing)."""
        if not len(view.people_xy):
            return np.zeros(0, dtype=bool)
        return np.linalg.norm(view.people_vel, axis=1) >= self.params.walking_mps

    def ways(self, view: ControlView) -> PeopleWays:
        """The people's predicted ways (see the module docstring)."""
        p = self.params
        walking = self.walking(view)
        cs, rs, ws = [], [], []
        for k in range(len(view.people_xy)):
            xy, v, r = view.people_xy[k], view.people_vel[k], float(view.people_radius[k])
            if walking[k]:
                length = float(np.linalg.norm(v)) * p.horizon_s
                m = int(np.ceil(length / p.sample_step_m)) + 1
                cs.append(xy + np.linspace(0.0, p.horizon_s, m)[:, None] * v)
                rs.append(np.full(m, r + p.clearance_m))
                ws.append(np.ones(m, dtype=bool))
            else:
                cs.append(xy[None])
                rs.append(np.array([r + p.clearance_m + p.standing_berth_m]))
                ws.append(np.zeros(1, dtype=bool))
        if not cs:
            return PeopleWays(np.zeros((0, 2)), np.zeros(0), np.zeros(0, dtype=bool))
        return PeopleWays(np.vstack(cs), np.concatenate(rs), np.concatenate(ws))

    def field_view(self, view: ControlView) -> ControlView:
        """``view`` with standing people as wide as their berth, for the potential field: a
        skid passes a standing person at a distance from which it can still get out of the
        way when the person sets off."""
        if not self.params.enabled or not len(view.people_xy):
            return view
        extra = np.where(self.walking(view), 0.0, self.params.standing_berth_m)
        return dataclasses.replace(view, people_radius=view.people_radius + extra)

    @staticmethod
    def without_people(view: ControlView) -> ControlView:
        """``view`` with no people (to check a skid stepping out of a person's way against
        walls and skids only)."""
        z = np.zeros((0, 2))
        return dataclasses.replace(view, people_xy=z, people_vel=z.copy(), people_radius=z[:, 0])

    # ------------------------------------------------------------------ the tick

    def step(
        self, view: ControlView, idx: np.ndarray, raw: np.ndarray, scene: Scene
    ) -> YieldResult:
        """Commands ``raw`` ``(len(idx), 2)`` of skids ``idx`` after giving people the right
        of way."""
        n = len(view.poses)
        if len(self.side) < n:
            self.side = np.concatenate([self.side, np.zeros(n - len(self.side), int)])
        out = np.array(raw, dtype=float, copy=True)
        aside = np.zeros(len(idx), dtype=bool)
        if not self.params.enabled or not len(view.people_xy) or not len(idx):
            self.side[:] = 0
            return YieldResult(out, aside)
        ways = self.ways(view)
        rows = self._near(view, idx, ways)
        self.side[np.setdiff1d(np.arange(n), idx[rows])] = 0
        if not len(rows):
            return YieldResult(out, aside)
        corners = footprint_corners(view.poses[idx[rows]], scene.skids.plain[idx[rows]])
        gap_now = ways.gaps(corners)
        slack = self._slack
        in_walk = ((gap_now < -slack) & ways.walking[None]).any(axis=1)
        # A skid the operator stopped (or not driven) stays where it is.
        free = view.active[idx[rows]]
        if view.stopped is not None:
            free &= ~view.stopped[idx[rows]]
        in_walk &= free
        for r in rows[in_walk]:
            v = self._step_aside(view, int(idx[r]), ways, scene)
            if v is not None:
                out[r] = (v, 0.0)
                aside[r] = True
        for r in rows[~in_walk]:
            self.side[idx[r]] = 0
        rest = rows[~aside[rows]]
        if len(rest):
            out[rest] = self._stop_short(view, idx[rest], out[rest], ways, gap_now[~aside[rows]])
        return YieldResult(out, aside)

    def _near(self, view: ControlView, idx: np.ndarray, ways: PeopleWays) -> np.ndarray:
        """Rows of ``idx`` whose skid could reach a way within the rollout."""
        reach = np.array([view.footprints[i].reach_m for i in idx])
        travel = view.max_speed[idx] * self.params.rollout_s
        d, _ = cKDTree(ways.centres).query(view.poses[idx, :2])
        return np.flatnonzero(d <= reach + travel + ways.radii.max() + self.params.shift_step_m)

    def _stop_short(self, view, rows_i, raw, ways: PeopleWays, gap_now) -> np.ndarray:
        """Scale each command down until its rollout does not go deeper into a way."""
        times = self.times
        S, T = len(_SCALES), len(times)
        scales = np.asarray(_SCALES)
        v_cmd = (raw[:, 0][:, None] * scales[None]).ravel()
        w_cmd = np.repeat(raw[:, 1], S)
        rep = np.repeat(rows_i, S)
        pose = rollout(view, rep, v_cmd, w_cmd, times)  # (len * S, T, 3)
        body = np.repeat(np.stack([view.footprints[i].corners_body() for i in rows_i]), S * T, 0)
        corners = footprint_corners(pose.reshape(-1, 3), body)
        g = ways.gaps(corners).min(axis=1).reshape(len(rows_i), S, T).min(axis=2)
        now = gap_now.min(axis=1)
        ok = (g >= 0) | (g >= now[:, None] - _DEEPER_TOL_M)
        out = np.zeros_like(raw)
        for r in range(len(rows_i)):
            good = np.flatnonzero(ok[r])
            if len(good):
                out[r] = (raw[r, 0] * scales[good[0]], raw[r, 1])
        return out

    def _step_aside(self, view: ControlView, i: int, ways: PeopleWays, scene: Scene):
        """Speed along skid ``i``'s axis to the nearest free place (None if there is none)."""
        p = self.params
        head = np.array([np.cos(view.poses[i, 2]), np.sin(view.poses[i, 2])])
        best, best_side, best_t = None, 0, np.inf
        sides = [self.side[i]] if self.side[i] else [1, -1]
        for s in sides:
            shifts = s * self.steps
            poses = np.repeat(view.poses[i][None], len(shifts), axis=0)
            poses[:, :2] += shifts[:, None] * head
            body = np.repeat(scene.skids.plain[i][None], len(shifts), axis=0)
            corners = footprint_corners(poses, body)
            # The way there must be clear of walls and skids; the end also of every way.
            blocked = self._blocked(view, i, corners, scene)
            passable = np.logical_and.accumulate(~blocked)
            clear = passable & (ways.gaps(corners).min(axis=1) >= -self._slack)
            if clear.any():
                k = int(np.argmax(clear))
                t = _time_to_shift(shifts[k], view.vel[i, 0], view.max_accel[i], view.max_speed[i])
                if best is None or t < best_t:
                    best, best_side, best_t = float(shifts[k]), s, t
        if best is None:
            return None
        self.side[i] = best_side
        v = p.gain_per_s * (best + np.sign(best) * p.overshoot_m)
        return float(np.clip(v, -view.max_speed[i], view.max_speed[i]))

    @staticmethod
    def _blocked(view: ControlView, i: int, corners: np.ndarray, scene: Scene) -> np.ndarray:
        """``(M,)`` whether footprints ``corners`` of skid ``i`` meet a static solid or
        another skid where it stands."""
        polys = shapely.polygons(corners)
        out = np.zeros(len(corners), dtype=bool)
        hit, _ = scene.static.tree.query(polys, predicate="intersects")
        out[hit] = True
        others = np.delete(np.arange(len(view.poses)), i)
        if len(others):
            oc = footprint_corners(view.poses[others], scene.skids.plain[others])
            m, k = len(corners), len(others)
            depth = convex_overlap(np.repeat(corners, k, axis=0), np.tile(oc, (m, 1, 1)))
            out |= (depth.reshape(m, k) > TOUCH_TOLERANCE_M).any(axis=1)
        return out
