"""Keep right: skids meeting oncoming traffic turn their aim clockwise, so a head-on meeting
or a crossing resolves as a roundabout instead of a symmetric stand-off (ROS 2 Navigation2
has no rule for it; RVO2's examples break the symmetry with noise; the convention of lane
traffic and of Open-RMF's lanes). Used by both avoidance modes: RVO turns the preferred
velocity (:mod:`.avoidance`), the monitor mode turns the follower's lookahead point about the
skid (:class:`KeepRight`).
"""

from __future__ import annotations

import itertools

import numpy as np
from scipy.spatial import cKDTree

from swarmpark.control.nav.params import KeepRightParams
from swarmpark.control.nav.scene import Scene
from swarmpark.control.orca.kernel import responsibility_shares
from swarmpark.core.geometry import rotation

__all__ = ["KeepRight", "keep_right_turns"]


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


def _one_way(u: np.ndarray) -> bool:
    """Whether every direction of ``u`` ``(M, 2)`` lies within an arc narrower than 90 deg
    (by a margin far above rounding), so that no two have a negative dot product: the usual
    park, where the fleet drives one way, skips the neighbour search."""
    ang = np.sort(np.arctan2(u[:, 1], u[:, 0]))
    if len(ang) < 2:
        return True
    gaps = np.diff(np.append(ang, ang[0] + 2 * np.pi))
    return bool(2 * np.pi - gaps.max() < np.pi / 2 - 1e-6)


def keep_right_turns(
    centres: np.ndarray,
    u_pref: np.ndarray,
    prio: np.ndarray,
    cruising: np.ndarray,
    movers: np.ndarray,
    scene: Scene,
    params: KeepRightParams,
) -> np.ndarray:
    """Clockwise turn (rad) of each cruising skid's wanted direction where another skid on the
    move (``movers``) within ``params.range_m`` ahead comes the other way (their wanted
    directions ``u_pref`` more than 90 degrees apart), else 0.

    The turn is ``params.rad`` times twice the skid's largest share against those skids
    (:func:`~swarmpark.control.orca.kernel.responsibility_shares`, clipped to ``min_share``),
    at most ``max_rad``: between equal priorities each turns ``rad``, and the lower priority
    turns more. It fades out from static solids ``open_m`` away to none at ``tight_m`` (in a
    door both keeping right would wedge on the jambs). ``enabled`` and ``near_goal_m`` are
    the caller's to apply.
    """
    rad, max_rad, range_m = params.rad, params.max_rad, params.range_m
    open_m, tight_m, min_share = params.open_m, params.tight_m, params.min_share
    turn = np.zeros(len(cruising))
    if rad == 0 or movers.sum() < 2 or not len(cruising):
        return turn
    others = np.flatnonzero(movers)
    if _one_way(u_pref[np.union1d(others, cruising)]):
        return turn  # no two skids more than 90 deg apart: nobody comes the other way
    near = cKDTree(centres[others]).query_ball_point(centres[cruising], range_m)
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
        share = responsibility_shares(prio[i], prio[j], min_share)
        best = np.full(len(cruising), -np.inf)
        np.maximum.at(best, kk, share)  # the largest share per skid (exact in any order)
        met = np.unique(kk)
        turn[met] = np.minimum(2.0 * best[met] * rad, max_rad)
    kd = scene.static.kd
    if kd is not None and turn.any():
        # Beyond open_m the fade is 1 whatever the distance (inf included).
        clear, _ = kd.query(centres[cruising], distance_upper_bound=open_m)
        turn *= np.clip((clear - tight_m) / (open_m - tight_m), 0.0, 1.0)
    return turn


class KeepRight:
    """Monitor mode: turns the lookahead point of each skid following its path clockwise
    about the skid when a skid on the move comes the other way ahead (:func:`keep_right_turns`).

    Parameters
    ----------
    params
        :class:`~swarmpark.control.nav.params.KeepRightParams`.
    """

    def __init__(self, params: KeepRightParams) -> None:
        self.params = params

    def turn_targets(
        self,
        poses: np.ndarray,
        targets: np.ndarray,
        goals: np.ndarray,
        prio: np.ndarray,
        cruising: np.ndarray,
        movers: np.ndarray,
        scene: Scene,
    ) -> np.ndarray:
        """``targets`` ``(N, 3)`` (one per skid) with those of ``cruising`` (indices) turned
        clockwise about their skid's pivot, pose headings with them. ``movers`` ``(N,)``: the
        skids on the move; each wants to go to its target (or its goal if not cruising)."""
        p = self.params
        out = targets
        if not p.enabled or not len(cruising):
            return out
        aim = goals[:, :2].copy()
        aim[cruising] = targets[cruising, :2]
        d = aim - poses[:, :2]
        u = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-9)
        turn = keep_right_turns(poses[:, :2], u, prio, cruising, movers, scene, p)
        k = np.flatnonzero(turn)
        if len(k):
            out = targets.copy()
            rows = cruising[k]
            rel = np.einsum("nij,nj->ni", rotation(-turn[k]), d[rows])
            out[rows, :2] = poses[rows, :2] + rel
            out[rows, 2] = out[rows, 2] - turn[k]
        return out
