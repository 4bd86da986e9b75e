"""Path following: where a skid stands on its path, the lookahead pose it steers for, and
which end of the skid leads (2015 paper, extension 1: the end with the shorter arc)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from swarmpark.control.base import ControlView
from swarmpark.control.nav.apf import arc_length
from swarmpark.control.nav.params import FollowerParams
from swarmpark.core.geometry import wrap_angle

__all__ = ["PathFollower", "PathGeometry", "PathState", "point_at", "station"]


@dataclass(frozen=True)
class PathGeometry:
    """What projecting onto a polyline needs that does not depend on the point: its segments
    ``(K, 2)``, their lengths ``(K,)`` and the cumulative arc lengths of its vertices
    ``(K + 1,)``. Computed once per path, not every tick."""

    seg: np.ndarray
    seg_len: np.ndarray
    cum: np.ndarray

    @classmethod
    def of(cls, path: np.ndarray) -> PathGeometry:
        seg = np.diff(path, axis=0)
        seg_len = np.linalg.norm(seg, axis=1)
        return cls(seg, seg_len, np.concatenate([[0.0], np.cumsum(seg_len)]))


@dataclass
class PathState:
    """One skid's plan: the path (world points), the goal it was planned for and when, whether
    planning failed, and which end leads (``reverse``: the rear). ``path`` and ``path_goal``
    are replaced on a new plan, never changed in place (caches go by identity)."""

    path: np.ndarray | None = None
    path_goal: np.ndarray | None = None
    planned_t: float = -np.inf
    failed: bool = False
    reverse: bool = False
    #: The least remaining path length reached on this plan and when (for plan repairs).
    best_left_m: float = np.inf
    best_t: float = -np.inf
    # The geometry of ``_geom_path`` (held, so identity tells whether ``path`` was replaced).
    _geom_path: np.ndarray | None = field(default=None, repr=False, compare=False)
    _geom: PathGeometry | None = field(default=None, repr=False, compare=False)

    def is_for(self, goal: np.ndarray) -> bool:
        """Whether the current plan was made for ``goal``."""
        return self.path_goal is not None and not np.any(np.abs(self.path_goal - goal) > 1e-9)

    def geometry(self) -> PathGeometry:
        """:class:`PathGeometry` of the current path (a path of 2 points or more), cached
        until the path is replaced."""
        if self._geom is None or self._geom_path is not self.path:
            self._geom, self._geom_path = PathGeometry.of(self.path), self.path
        return self._geom


def station(
    path: np.ndarray, xy: np.ndarray, geom: PathGeometry | None = None
) -> tuple[np.ndarray, int, float]:
    """Where ``xy`` projects onto a polyline: the cumulative arc lengths of its vertices,
    the segment it projects onto, and the arc length there (``geom``: the path's
    :class:`PathGeometry`, if known)."""
    geom = PathGeometry.of(path) if geom is None else geom
    seg, seg_len, cum = geom.seg, geom.seg_len, geom.cum
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


class PackedPaths:
    """Every skid's path in padded arrays, so projection and lookahead run for the whole fleet
    at once: segment starts and vectors ``(N, K, 2)``, lengths ``(N, K)``, cumulative arc
    lengths ``(N, K + 1)`` (``inf`` past the end), segment counts ``(N,)`` (0: no usable
    path) and the goals the paths were planned for ``(N, 3)``. A row is refilled only when
    its path is replaced (by identity), so per-path data is computed once per plan."""

    _ARRAYS = ("start", "seg", "seg_len", "cum", "nseg", "goal", "has_goal")

    def __init__(self) -> None:
        self._refs: list[tuple] = []
        self._alloc(0, 1)

    def _alloc(self, n: int, k: int) -> None:
        """(Re)allocate for ``n`` skids and ``k`` segments, keeping the rows filled so far."""
        old = {name: getattr(self, name, None) for name in self._ARRAYS}
        self.start = np.zeros((n, k, 2))
        self.seg = np.zeros((n, k, 2))
        self.seg_len = np.zeros((n, k))
        self.cum = np.full((n, k + 1), np.inf)
        self.nseg = np.zeros(n, dtype=int)
        self.goal = np.zeros((n, 3))
        self.has_goal = np.zeros(n, dtype=bool)
        for name, arr in old.items():
            if arr is not None:
                getattr(self, name)[tuple(slice(0, d) for d in arr.shape)] = arr

    def update(self, states: list[PathState]) -> None:
        """Refill the rows whose path or goal was replaced since the last call."""
        n = len(states)
        if n > len(self._refs):
            self._alloc(n, self.seg_len.shape[1])
            self._refs += [(None, None)] * (n - len(self._refs))
        refs = self._refs
        changed = [
            i
            for i, st in enumerate(states)
            if st.path is not refs[i][0] or st.path_goal is not refs[i][1]
        ]
        if not changed:
            return
        need = max(
            (len(states[i].path) - 1 for i in changed if states[i].path is not None), default=0
        )
        k = self.seg_len.shape[1]
        if need > k:
            self._alloc(len(self.nseg), max(need, 2 * k))
        for i in changed:
            self._fill(i, states[i])
            refs[i] = (states[i].path, states[i].path_goal)

    def _fill(self, i: int, st: PathState) -> None:
        path = st.path
        self.has_goal[i] = st.path_goal is not None
        self.goal[i] = 0.0 if st.path_goal is None else st.path_goal
        self.start[i], self.seg[i], self.seg_len[i], self.cum[i] = 0.0, 0.0, 0.0, np.inf
        if path is None or len(path) < 2:
            self.nseg[i] = 0
            return
        g = st.geometry()
        k = len(g.seg_len)
        self.nseg[i] = k
        self.start[i, :k] = path[:-1]
        self.seg[i, :k] = g.seg
        self.seg_len[i, :k] = g.seg_len
        self.cum[i, : k + 1] = g.cum

    def is_for(self, rows: np.ndarray, goals: np.ndarray) -> np.ndarray:
        """:meth:`PathState.is_for` for ``rows`` and their ``goals`` ``(len(rows), 3)``."""
        off = np.any(np.abs(self.goal[rows] - goals) > 1e-9, axis=1)
        return self.has_goal[rows] & ~off

    def project(self, rows: np.ndarray, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:func:`station` for ``rows`` (with usable paths) at points ``xy``: the segment each
        projects onto and the arc length there."""
        A, D, L = self.start[rows], self.seg[rows], self.seg_len[rows]
        t = np.clip(np.einsum("rkj,rkj->rk", xy[:, None, :] - A, D) / np.maximum(L**2, 1e-12), 0, 1)
        dist = np.linalg.norm(A + t[..., None] * D - xy[:, None, :], axis=2)
        dist[np.arange(L.shape[1])[None, :] >= self.nseg[rows][:, None]] = np.inf
        j = np.argmin(dist, axis=1)
        r = np.arange(len(rows))
        return j, self.cum[rows, j] + t[r, j] * L[r, j]

    def point_at(self, rows: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:func:`point_at` for ``rows`` at arc lengths ``s``: the points and segments."""
        C = self.cum[rows]
        m = np.clip((C <= s[:, None]).sum(axis=1) - 1, 0, self.nseg[rows] - 1)
        r = np.arange(len(rows))
        c0 = C[r, m]
        f = (s - c0) / np.maximum(C[r, m + 1] - c0, 1e-12)
        return self.start[rows, m] + f[:, None] * self.seg[rows, m], m


class PathFollower:
    """Targets along the planned paths for the potential field.

    Parameters
    ----------
    params
        :class:`~swarmpark.control.nav.params.FollowerParams`.
    """

    def __init__(self, params: FollowerParams) -> None:
        self.params = params
        self.packed = PackedPaths()

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

    def waiting(self, view: ControlView, idx: np.ndarray, states: list[PathState]) -> np.ndarray:
        """Which of robots ``idx`` have no plan for their current goal yet (queued)."""
        self.packed.update(states)
        return ~self.packed.is_for(idx, view.goals[idx])

    def targets(
        self,
        view: ControlView,
        idx: np.ndarray,
        states: list[PathState],
        lookahead_m: float | None = None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Temporary goal pose per robot (``lookahead_m`` ahead on its path, or its goal),
        whether it is in its final approach (within ``approach_m`` of the path's end) and the
        path left to its staging point while it drives there first (``inf`` otherwise; see
        :meth:`_staging`). All robots at once, on :class:`PackedPaths`."""
        p = self.params
        lookahead_m = p.lookahead_m if lookahead_m is None else lookahead_m
        targets = view.goals[idx].copy()
        final = np.ones(len(idx), dtype=bool)
        stage_left = np.full(len(idx), np.inf)
        pk = self.packed
        pk.update(states)
        k = np.flatnonzero(pk.nseg[idx] > 0)
        if not len(k):
            return targets, final, stage_left
        rows = idx[k]
        _, s_here = pk.project(rows, view.poses[rows, :2])
        end = pk.cum[rows, pk.nseg[rows]]
        stage_s = self._staging(view, rows)
        staging = stage_s - s_here > p.stage_reach_m
        go = (end - s_here > p.approach_m) | staging
        stage_left[k[staging]] = (stage_s - s_here)[staging]
        # Those not yet at their staging point aim no farther along the path than it.
        end = np.where(staging, stage_s, end)
        k, rows, s_here, end = k[go], rows[go], s_here[go], end[go]
        final[k] = False
        pt, m = pk.point_at(rows, np.minimum(s_here + lookahead_m, end))
        seg = pk.seg[rows, m]
        # Aiming at the staging point itself: straight at it (the skid turns there anyway;
        # the path's heading into it made the field swing round and past it).
        at_stage = staging[go] & (s_here + lookahead_m >= end)
        seg[at_stage] = pt[at_stage] - view.poses[rows[at_stage], :2]
        back = np.array([states[i].reverse for i in rows], dtype=bool)
        heading = np.arctan2(seg[:, 1], seg[:, 0]) + np.where(back, np.pi, 0.0)
        targets[k, :2] = pt
        targets[k, 2] = wrap_angle(heading)
        return targets, final, stage_left

    def _staging(self, view: ControlView, rows: np.ndarray) -> np.ndarray:
        """Arc length of each path's staging point where the skid must drive there before it
        turns onto the goal's axis (``-inf`` elsewhere): the path's last segment is the run
        along the goal's axis (:meth:`~.planner.Planner.plan`) and the path turns onto it by
        more than ``stage_corner_rad``. Cutting that corner in the final approach, a skid came
        to its spot from the side, turned on the spot 1 m off the axis and backed in on a
        diagonal and ran up again (12 s where driving on, turning and backing in takes 7 s)."""
        pk = self.packed
        out = np.full(len(rows), -np.inf)
        n = pk.nseg[rows]
        ok = n >= 2
        if not ok.any():
            return out
        last = pk.seg[rows, np.maximum(n - 1, 0)]
        inc = pk.seg[rows, np.maximum(n - 2, 0)]
        g = view.goals[rows, 2]
        # The last segment lies on the goal's axis (either way).
        on_axis = np.abs(last[:, 0] * np.sin(g) - last[:, 1] * np.cos(g)) <= 1e-6 * (
            1.0 + np.hypot(last[:, 0], last[:, 1])
        )
        corner = np.abs(
            np.arctan2(
                inc[:, 0] * last[:, 1] - inc[:, 1] * last[:, 0],
                inc[:, 0] * last[:, 0] + inc[:, 1] * last[:, 1],
            )
        )
        sharp = ok & on_axis & (corner > self.params.stage_corner_rad)
        out[sharp] = pk.cum[rows, np.maximum(n - 1, 0)][sharp]
        return out


def paths_ahead(
    view: ControlView,
    rows: np.ndarray,
    states: list[PathState],
    packed: PackedPaths,
    length_m: float,
) -> list[np.ndarray]:
    """Skids ``rows``' paths from their rears to ``length_m`` ahead of their pivots (a polyline
    each), projected for all of them at once on ``packed`` (refilled from ``states`` first)."""
    packed.update(states)
    fps = [view.footprints[i] for i in rows.tolist()]
    pose = view.poses[rows]
    back_m = np.array(
        [
            f.length_m - f.pivot if states[i].reverse else f.pivot
            for i, f in zip(rows.tolist(), fps, strict=True)
        ]
    )
    head = np.column_stack([np.cos(pose[:, 2]), np.sin(pose[:, 2])])
    back = pose[:, :2] - head * back_m[:, None]
    nseg = packed.nseg[rows]
    use = np.flatnonzero(nseg > 0)
    # No usable path: from the rear to the pivot.
    out = [np.vstack([back[k], pose[k, :2]]) if n == 0 else None for k, n in enumerate(nseg)]
    if not len(use):
        return out
    on = rows[use]
    j, s_here = packed.project(on, pose[use, :2])
    s_end = np.minimum(s_here + length_m, packed.cum[on, nseg[use]])
    tip, _ = packed.point_at(on, s_end)
    for k, i, jk, end, t in zip(use.tolist(), on.tolist(), j.tolist(), s_end, tip, strict=True):
        path = states[i].path
        cum = packed.cum[i, jk + 1 : len(path)]
        out[k] = np.vstack([back[k], pose[k, :2], path[jk + 1 :][cum < end], t])
    return out
