"""The potential-field drive: attraction of the leading action point to the follower's target
and 1/d^3 repulsion from static outlines, other skids and people (2015 paper, Sect. 3.2; the
math is in :mod:`swarmpark.control.nav.apf`), turned into ``(v, omega)`` commands."""

from __future__ import annotations

import itertools

import numpy as np
from scipy.spatial import cKDTree

from swarmpark.control.base import ControlView
from swarmpark.control.nav.apf import attraction, forces_to_command, repulsion
from swarmpark.control.nav.params import FieldParams
from swarmpark.control.nav.scene import Scene
from swarmpark.core.geometry import transform_points, wrap_angle
from swarmpark.core.progress import remaining_m

__all__ = ["PotentialField"]

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
        fps = view.footprints
        x_front = np.array([fps[i].length_m - fps[i].pivot for i in idx])
        x_rear = -np.array([fps[i].pivot for i in idx])
        half_w = np.array([fps[i].width_m / 2 for i in idx])
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
        f_front, f_rear = self.repulsion(view, idx, scene, x_front, x_rear, half_w, influence)
        raw = forces_to_command(f_goal, x_goal, f_front, f_rear, x_front, x_rear)
        # Turn before driving when the wanted direction is far off (the skid can spin in place).
        rel = np.arctan2(f_goal[:, 1], np.abs(f_goal[:, 0]))
        raw[:, 0] *= np.clip(np.cos(rel), 0.0, 1.0) ** 2
        raw[:, 0] = np.clip(raw[:, 0], -view.max_speed[idx], view.max_speed[idx])
        raw[:, 1] = np.clip(raw[:, 1], -view.max_yaw_rate[idx], view.max_yaw_rate[idx])
        return raw, dist_goal

    def repulsion(self, view, idx, scene: Scene, x_front, x_rear, half_w, influence):
        """Summed body-frame repulsion on the front and rear action points of robots ``idx``."""
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
        person = owner == _PERSON
        if person.any():
            # A person's rim is closer than the centre by the radius: move the point inwards.
            rad = view.people_radius[pt[person] - len(scene.skids.points)]
            nrm = np.linalg.norm(body[person], axis=1, keepdims=True)
            body[person] *= np.maximum(1 - rad[:, None] / np.maximum(nrm, 1e-9), 0.0)
        front, rear, _ = repulsion(
            rob, body, gain, x_rear[rob], x_front[rob], half_w[rob], influence[rob]
        )
        out_f, out_r = np.zeros((n_act, 2)), np.zeros((n_act, 2))
        out_f[: len(front)] = front
        out_r[: len(rear)] = rear
        return out_f, out_r

    def _neighbours(self, view, idx, scene: Scene, influence):
        """Repulsion points within reach of each robot: (robot row, point index, whether the
        point is dynamic, its owner, the dynamic points), or ``rob=None`` when there are none."""
        n_act = len(idx)
        skids = scene.skids
        # Other skids' outlines in the world, and people (their rims are handled later).
        robot_pts = transform_points(view.poses[skids.owner], skids.points[:, None, :])[:, 0]
        dyn = np.vstack([robot_pts, view.people_xy])
        dyn_owner = np.concatenate([skids.owner, np.full(len(view.people_xy), _PERSON)])
        if not self.dynamic:
            dyn, dyn_owner = dyn[:0], dyn_owner[:0]
        reach = skids.reach[idx] + influence
        rob_l, pt_l, src_l = [], [], []
        sources = [(scene.static.kd, reach, 0)]
        if len(dyn):
            rim = view.people_radius.max(initial=0.0)
            sources.append((cKDTree(dyn), reach + rim, 1))
        for kd, r, src in sources:
            if kd is None:
                continue
            hits = kd.query_ball_point(view.poses[idx, :2], r)
            lens = np.fromiter((len(h) for h in hits), int, len(hits))
            if lens.sum():
                rob_l.append(np.repeat(np.arange(n_act), lens))
                pt_l.append(np.fromiter(itertools.chain.from_iterable(hits), int, lens.sum()))
                src_l.append(np.full(lens.sum(), src, int))
        if not rob_l:
            return None, None, None, None, dyn
        rob, pt, src = np.concatenate(rob_l), np.concatenate(pt_l), np.concatenate(src_l)
        is_dyn = src == 1
        owner = np.full(len(pt), _STATIC)
        owner[is_dyn] = dyn_owner[pt[is_dyn]]
        keep = owner != idx[rob]
        return rob[keep], pt[keep], is_dyn[keep], owner[keep], dyn
