"""The potential-field drive: attraction of the leading action point to the follower's target
and 1/d^3 repulsion from static outlines, other skids and people (2015 paper, Sect. 3.2; the
math is in :mod:`swarmpark.control.nav.apf`), turned into ``(v, omega)`` commands."""

from __future__ import annotations

import itertools

import numpy as np
from scipy.spatial import cKDTree

from swarmpark.control.base import ControlView
from swarmpark.control.nav.apf import attraction, forces_to_command, repulsion, turn_throttle
from swarmpark.control.nav.kernels import outline_pairs
from swarmpark.control.nav.params import FieldParams
from swarmpark.control.nav.scene import Scene
from swarmpark.core.geometry import transform_points, wrap_angle
from swarmpark.core.progress import remaining_m

__all__ = ["PotentialField"]


def _ball_pairs(kd: cKDTree, xy: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The (query row, point) pairs of a ball query of ``kd`` at ``xy`` with radii ``r``, by
    row and then point index (as the sorted lists of ``query_ball_point``)."""
    hits = kd.query_ball_point(xy, r)
    lens = np.fromiter(map(len, hits), int, len(hits))
    pt = np.fromiter(itertools.chain.from_iterable(hits), int, int(lens.sum()))
    return np.repeat(np.arange(len(xy)), lens), pt


#: Owner codes of repulsion points that are not skids.
_STATIC, _PERSON = -1, -2


class PotentialField:
    """Commands from the field for the active robots.

    Parameters
    ----------
    params
        :class:`~swarmpark.control.nav.params.FieldParams`.
    dynamic
        Whether other skids and people repel (False with RVO: the velocity obstacles avoid
        them, and the field only follows the path and keeps off static solids).
    """

    def __init__(self, params: FieldParams, *, dynamic: bool = True) -> None:
        self.params = params
        self.dynamic = dynamic
        self._outline = None  # the SkidOutlines the per-skid point ranges below are for
        self._fps = None  # the footprints the action points below are for
        self._points: tuple = ()

    def drive(
        self,
        view: ControlView,
        idx: np.ndarray,
        scene: Scene,
        targets: np.ndarray,
        reverse: np.ndarray,
        final: np.ndarray,
        near_m: float,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Commands ``(len(idx), 2)`` for robots ``idx`` towards ``targets`` (leading with the
        rear where ``reverse``), and their distances to the goal. In the final approach
        (``final``) and within ``near_m`` of the goal only obstacles within
        ``influence_at_goal_m`` repel (parked neighbours sit just beyond)."""
        p = self.params
        front, rear, half = self._action_points(view.footprints)
        x_front, x_rear, half_w = front[idx], rear[idx], half[idx]
        poses = view.poses[idx]
        # Attraction, weighted by the distance still to go (core.progress) to the goal.
        dist_goal = np.linalg.norm(view.goals[idx, :2] - poses[:, :2], axis=1)
        head_err = np.abs(wrap_angle(view.goals[idx, 2] - poses[:, 2]))
        weight = np.clip(
            view.max_speed[idx]
            * remaining_m(dist_goal, head_err, p.heading_lever_m)
            / p.slow_radius_m,
            p.min_goal_speed_mps,
            view.max_speed[idx],
        )
        f_goal, x_goal = attraction(poses, targets, x_front, x_rear, reverse, weight)
        influence = np.where(final & (dist_goal < near_m), p.influence_at_goal_m, p.influence_m)
        f_front, f_rear = self.repulsion(
            view, idx, scene, x_front, x_rear, half_w, influence, reverse
        )
        raw = forces_to_command(f_goal, x_goal, f_front, f_rear, x_front, x_rear)
        raw[:, 0] *= turn_throttle(f_goal, x_goal, raw[:, 1], follow_turn=p.throttle_turning)
        raw[:, 0] = np.clip(raw[:, 0], -view.max_speed[idx], view.max_speed[idx])
        raw[:, 1] = np.clip(raw[:, 1], -view.max_yaw_rate[idx], view.max_yaw_rate[idx])
        return raw, dist_goal

    def _action_points(self, fps) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Body-x of every skid's front and rear action points and its half width ``(N,)``,
        kept while the footprints stay the same."""
        if fps is not self._fps and fps != self._fps:
            self._points = (
                np.array([f.length_m - f.pivot for f in fps]),
                -np.array([f.pivot for f in fps]),
                np.array([f.width_m / 2 for f in fps]),
            )
        self._fps = fps
        return self._points

    def repulsion(self, view, idx, scene: Scene, x_front, x_rear, half_w, influence, reverse):
        """Summed body-frame repulsion on the front and rear action points of robots ``idx``
        (``reverse``: which of them drive rear first, for ``ignore_followers``)."""
        p = self.params
        n_act = len(idx)
        static = scene.static
        rob, pt, is_dyn, owner, dyn = self._neighbours(view, idx, scene, influence)
        if rob is None:
            z = np.zeros((n_act, 2))
            return z, z.copy()
        world = np.empty((len(pt), 2))
        world[is_dyn] = dyn[pt[is_dyn]]
        world[~is_dyn] = static.points[pt[~is_dyn]]
        gain = np.where(
            owner == _STATIC, p.k_static, np.where(owner == _PERSON, p.k_person, p.k_robot)
        )
        pose = view.poses[idx[rob]]
        d = world - pose[:, :2]
        c, s = np.cos(pose[:, 2]), np.sin(pose[:, 2])
        body = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]])
        if p.ignore_followers:
            # Outline points of other skids behind the pivot (as the skid drives) do not push:
            # a skid that follows keeps its own distance, and a push on the trailing end
            # would only turn the leader off its path (the monitor still guards its swing).
            lead = np.where(reverse[rob], -1.0, 1.0)
            keep = (owner < 0) | (body[:, 0] * lead >= 0.0)
            rob, pt, owner, gain, body = rob[keep], pt[keep], owner[keep], gain[keep], body[keep]
        person = owner == _PERSON
        if person.any():
            # A person's rim is closer than the centre by the radius: move the point inwards.
            rad = view.people_radius[pt[person] - len(scene.skids.points)]
            nrm = np.linalg.norm(body[person], axis=1, keepdims=True)
            body[person] *= np.maximum(1 - rad[:, None] / np.maximum(nrm, 1e-9), 0.0)
        front, rear, _ = repulsion(
            rob, body, gain, x_rear[rob], x_front[rob], half_w[rob], influence[rob], p.lever_split
        )
        out_f, out_r = np.zeros((n_act, 2)), np.zeros((n_act, 2))
        out_f[: len(front)] = front
        out_r[: len(rear)] = rear
        return out_f, out_r

    def _dynamic_pairs(self, view, idx, skids, dyn, r):
        """The (robot row, point) pairs of robots ``idx`` and the dynamic points ``dyn`` (the
        skids' outline points, then people) within ``r`` ``(len(idx),)``, as a ball query
        (:func:`_ball_pairs`) gives them. Only the outlines of skids whose pivots are near are
        measured, instead of a tree of every outline point each tick."""
        n_pts = len(skids.points)
        if self._outline is not skids:
            # Per skid: its points' index range and their reach about its pivot.
            self._outline = skids
            starts = np.searchsorted(skids.owner, np.arange(len(skids.reach)))
            self._starts = starts
            self._counts = np.diff(np.append(starts, n_pts))
            self._rad = np.zeros(len(skids.reach))
            np.maximum.at(self._rad, skids.owner, np.hypot(*skids.points.T))
        here = view.poses[idx, :2]
        r = np.asarray(r, dtype=float)
        rob_l, pt_l = [], []
        if n_pts and len(dyn) >= n_pts:
            near = cKDTree(view.poses[:, :2]).sparse_distance_matrix(
                cKDTree(here), float(r.max() + self._rad.max()), output_type="ndarray"
            )
            sk, rb = near["i"].astype(np.int64), near["j"].astype(np.int64)
            # By robot row, then skid: each skid's points are one ascending run, and the
            # runs ascend with the skid, so the pairs come out sorted by (row, point).
            by_row = np.lexsort((sk, rb))
            # Compiled (kernels.outline_pairs): the points of those skids within reach.
            rob, pt = outline_pairs(
                rb[by_row],
                sk[by_row],
                self._starts.astype(np.int64),
                self._counts.astype(np.int64),
                np.ascontiguousarray(dyn[:n_pts], dtype=float),
                np.ascontiguousarray(here, dtype=float),
                r,
            )
            rob_l.append(rob)
            pt_l.append(pt)
        if len(dyn) > n_pts:  # people: few, every pair
            rob, k = np.divmod(np.arange(len(idx) * (len(dyn) - n_pts)), len(dyn) - n_pts)
            d = dyn[n_pts + k] - here[rob]
            keep = d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] <= r[rob] * r[rob]
            rob_l.append(rob[keep])
            pt_l.append(n_pts + k[keep])
        if not rob_l:
            return np.zeros(0, int), np.zeros(0, int)
        rob, pt = np.concatenate(rob_l), np.concatenate(pt_l)
        if len(rob_l) == 1 and len(dyn) == n_pts:
            return rob, pt  # skids only: already in (row, point) order
        order = np.lexsort((pt, rob))
        return rob[order], pt[order]

    def _neighbours(self, view, idx, scene: Scene, influence):
        """Repulsion points within reach of each robot: (robot row, point index, whether the
        point is dynamic, its owner, the dynamic points), or ``rob=None`` when there are none."""
        skids = scene.skids
        # Other skids' outlines in the world, and people (their rims are handled later).
        robot_pts = transform_points(view.poses[skids.owner], skids.points[:, None, :])[:, 0]
        dyn = np.vstack([robot_pts, view.people_xy])
        dyn_owner = np.concatenate([skids.owner, np.full(len(view.people_xy), _PERSON)])
        if not self.dynamic:
            dyn, dyn_owner = dyn[:0], dyn_owner[:0]
        reach = skids.reach[idx] + influence
        rob_l, pt_l, src_l = [], [], []
        if scene.static.kd is not None:
            rob, pt = _ball_pairs(scene.static.kd, view.poses[idx, :2], reach)
            rob_l.append(rob)
            pt_l.append(pt)
            src_l.append(np.zeros(len(pt), int))
        if len(dyn):
            rim = view.people_radius.max(initial=0.0)
            rob, pt = self._dynamic_pairs(view, idx, skids, dyn, reach + rim)
            rob_l.append(rob)
            pt_l.append(pt)
            src_l.append(np.ones(len(pt), int))
        rob_l = [a for a in rob_l if len(a)]
        pt_l = [a for a in pt_l if len(a)]
        src_l = [a for a in src_l if len(a)]
        if not rob_l:
            return None, None, None, None, dyn
        rob, pt, src = np.concatenate(rob_l), np.concatenate(pt_l), np.concatenate(src_l)
        is_dyn = src == 1
        owner = np.full(len(pt), _STATIC)
        owner[is_dyn] = dyn_owner[pt[is_dyn]]
        keep = owner != idx[rob]
        return rob[keep], pt[keep], is_dyn[keep], owner[keep], dyn
