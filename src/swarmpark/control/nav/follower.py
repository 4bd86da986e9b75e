"""Path following: where a skid stands on its path, the lookahead pose it steers for, and
which end of the skid leads (2015 paper, extension 1: the end with the shorter arc)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarmpark.control.base import ControlView
from swarmpark.control.nav.apf import arc_length
from swarmpark.control.nav.params import FollowerParams
from swarmpark.core.geometry import wrap_angle

__all__ = ["PathFollower", "PathState", "point_at", "station"]


@dataclass
class PathState:
    """One skid's plan: the path (world points), the goal it was planned for and when, whether
    planning failed, and which end leads (``reverse``: the rear)."""

    path: np.ndarray | None = None
    path_goal: np.ndarray | None = None
    planned_t: float = -np.inf
    failed: bool = False
    reverse: bool = False

    def is_for(self, goal: np.ndarray) -> bool:
        """Whether the current plan was made for ``goal``."""
        return self.path_goal is not None and not np.any(np.abs(self.path_goal - goal) > 1e-9)


def station(path: np.ndarray, xy: np.ndarray) -> tuple[np.ndarray, int, float]:
    """Where ``xy`` projects onto a polyline: the cumulative arc lengths of its vertices,
    the segment it projects onto, and the arc length there."""
    seg = np.diff(path, axis=0)
    seg_len = np.linalg.norm(seg, axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg_len)])
    rel = xy - path[:-1]
    t = np.clip(np.einsum("ij,ij->i", rel, seg) / np.maximum(seg_len**2, 1e-12), 0, 1)
    proj = path[:-1] + t[:, None] * seg
    j = int(np.argmin(np.linalg.norm(proj - xy, axis=1)))
    return cum, j, float(cum[j] + t[j] * seg_len[j])


def point_at(path: np.ndarray, cum: np.ndarray, s: float) -> tuple[np.ndarray, int]:
    """The point at arc length ``s`` (within ``[0, cum[-1]]``) of a polyline and its segment."""
    m = int(np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(path) - 2))
    f = (s - cum[m]) / max(cum[m + 1] - cum[m], 1e-12)
    return path[m] + f * (path[m + 1] - path[m]), m


def end_arcs(view: ControlView, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Arc lengths to the goal of the front and of the rear action point (2015 paper,
    extension 1: the skid leads with whichever end has the shorter arc)."""
    fps = [view.footprints[i] for i in idx]
    xf = np.array([f.length_m - f.pivot for f in fps])
    xr = -np.array([f.pivot for f in fps])
    pose, goal = view.poses[idx], view.goals[idx]
    u = np.column_stack([np.cos(pose[:, 2]), np.sin(pose[:, 2])])
    ug = np.column_stack([np.cos(goal[:, 2]), np.sin(goal[:, 2])])
    front = arc_length(pose[:, :2] + xf[:, None] * u, goal[:, :2] + xf[:, None] * ug, goal[:, 2])
    rear = arc_length(
        pose[:, :2] + xr[:, None] * u, goal[:, :2] + xr[:, None] * ug, goal[:, 2] + np.pi
    )
    return front, rear


class PathFollower:
    """Targets along the planned paths for the potential field.

    Parameters
    ----------
    params
        :class:`~swarmpark.control.nav.params.FollowerParams`.
    """

    def __init__(self, params: FollowerParams) -> None:
        self.params = params

    def choose_end(self, view: ControlView, i: int, path: np.ndarray) -> bool:
        """Which end leads along a fresh path (True: the rear): the one facing the path's
        first stretch, forwards unless the skid faces more than ``face_away_rad`` away from
        it (it may turn in place). Near the goal the end is chosen again (:meth:`update_ends`)."""
        if len(path) < 2:
            front, rear = end_arcs(view, np.array([i]))
            return bool(rear[0] < front[0])
        ahead = path[min(len(path) - 1, 1)] - path[0]
        tangent = np.arctan2(ahead[1], ahead[0])
        return bool(abs(wrap_angle(view.poses[i, 2] - tangent)) > self.params.face_away_rad)

    def update_ends(
        self, view: ControlView, idx: np.ndarray, final: np.ndarray, states: list[PathState]
    ) -> np.ndarray:
        """Which end leads for robots ``idx`` (True: the rear): fixed along a path; in the
        final approach (``final``) by the shorter arc, switching only for an arc shorter by
        ``switch_ratio`` (hysteresis). Updates ``states``."""
        reverse = np.array([states[i].reverse for i in idx])
        if final.any():
            cur = reverse[final]
            lf, lr = end_arcs(view, idx[final])
            ratio = self.params.switch_ratio
            switch = np.where(cur, lf < ratio * lr, lr < ratio * lf)
            new = np.where(switch, ~cur, cur)
            reverse[final] = new
            for k, i in enumerate(idx[final]):
                states[i].reverse = bool(new[k])
        return reverse

    def targets(
        self,
        view: ControlView,
        idx: np.ndarray,
        states: list[PathState],
        lookahead_m: float | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Temporary goal pose per robot (``lookahead_m`` ahead on its path, or its goal)
        and whether it is in its final approach (within ``approach_m`` of the path's end)."""
        p = self.params
        lookahead_m = p.lookahead_m if lookahead_m is None else lookahead_m
        targets = view.goals[idx].copy()
        final = np.ones(len(idx), dtype=bool)
        for k, i in enumerate(idx):
            st = states[i]
            path = st.path
            if path is None or len(path) < 2:
                continue
            cum, _, s_here = station(path, view.poses[i, :2])
            if cum[-1] - s_here <= p.approach_m:
                continue
            final[k] = False
            pt, m = point_at(path, cum, min(s_here + lookahead_m, cum[-1]))
            seg = path[m + 1] - path[m]
            heading = np.arctan2(seg[1], seg[0]) + (np.pi if st.reverse else 0.0)
            targets[k] = [pt[0], pt[1], wrap_angle(heading)]
        return targets, final


def path_ahead(view: ControlView, i: int, state: PathState, length_m: float) -> np.ndarray:
    """Skid ``i``'s path from its rear to ``length_m`` ahead of its pivot (a polyline)."""
    path = state.path
    pose = view.poses[i]
    fp = view.footprints[i]
    head = np.array([np.cos(pose[2]), np.sin(pose[2])])
    back = pose[:2] - head * (fp.length_m - fp.pivot if state.reverse else fp.pivot)
    if path is None or len(path) < 2:
        return np.vstack([back, pose[:2]])
    cum, j, s_here = station(path, pose[:2])
    s_end = min(s_here + length_m, cum[-1])
    inner = path[j + 1 :][cum[j + 1 :] < s_end]
    tip, _ = point_at(path, cum, s_end)
    return np.vstack([back, pose[:2], inner, tip])
