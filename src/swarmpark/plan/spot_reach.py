"""Which parking spots can a skid actually drive into, in the order they are filled?

The layout's egress check (:mod:`swarmpark.layout.egress`) asks whether a disc as wide as the
skid reaches each spot from the opening with the earlier spots occupied: the necessary
condition. A rectangle may still be unable to get in: a spot between a pillar and a parked
neighbour may need an entry heading the aisle has no room to turn to. This module asks the
full question on the manoeuvre lattice (:mod:`swarmpark.plan.lattice`): from the spot's pose,
with the walls and the spots filled before it as obstacles, can the skid's rectangle drive
(forwards, backwards, turning on the spot) to a place where it can turn all the way round,
from where the grid planner's disc paths take over? Moves are reversible, so this is the same
as driving in. Spots that fail are reported with the reason, for the operator to see before
the skids set off; nothing is moved.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy.signal import fftconvolve

from swarmpark.core.geometry import Footprint
from swarmpark.plan.lattice import HEADING_STEPS, HEADINGS, rect_mask, snap_state, stamp_footprint

__all__ = ["SpotReach", "as_report", "spot_reach"]


@dataclass(frozen=True)
class SpotReach:
    """One spot that no manoeuvre reaches: its index in the layout, its pose (rad) and why."""

    spot: int
    pose: tuple[float, float, float]
    reason: str


def as_report(flags: list[SpotReach]) -> list[dict]:
    """The flags for people and JSON: ``spot``, ``pose`` ``[x_m, y_m, heading_deg]``,
    ``reason``."""
    return [
        {
            "spot": f.spot,
            "pose": [
                round(f.pose[0], 3),
                round(f.pose[1], 3),
                round(float(np.degrees(f.pose[2])), 1),
            ],
            "reason": f.reason,
        }
        for f in flags
    ]


@njit(cache=True)
def _flood(hits, steps, start, seen, queue):
    """Breadth-first search over lattice states from ``start`` until a state where the skid
    can turn all the way round or one on the window's edge (True), or every reachable state
    is seen (False). ``hits[k]`` counts the occupied cells under the footprint at heading
    ``k``, ``hits[16 + k]`` under it half way from heading ``k`` to ``k + 1``, ``hits[32]``
    under the turn-all-round disc. ``seen`` (all False) is left all False again."""
    n_k = steps.shape[0]
    n_r, n_c = hits.shape[1], hits.shape[2]
    queue[0, 0], queue[0, 1], queue[0, 2] = start[0], start[1], start[2]
    seen[start[0], start[1], start[2]] = True
    head, tail = 0, 1
    found = False
    while head < tail:
        k, r, c = queue[head, 0], queue[head, 1], queue[head, 2]
        head += 1
        if hits[2 * n_k, r, c] < 0.5 or r == 0 or c == 0 or r == n_r - 1 or c == n_c - 1:
            found = True
            break
        for m in range(4):
            if m < 2:
                d = 1 if m == 0 else -1
                nk, nr, nc = k, r + d * steps[k, 1], c + d * steps[k, 0]
                if nr < 0 or nc < 0 or nr >= n_r or nc >= n_c or hits[nk, nr, nc] >= 0.5:
                    continue
            else:
                nk, nr, nc = (k + (1 if m == 2 else -1)) % n_k, r, c
                lo = k if m == 2 else nk
                if hits[nk, nr, nc] >= 0.5 or hits[n_k + lo, nr, nc] >= 0.5:
                    continue
            if seen[nk, nr, nc]:
                continue
            seen[nk, nr, nc] = True
            queue[tail, 0], queue[tail, 1], queue[tail, 2] = nk, nr, nc
            tail += 1
    for q in range(tail):
        seen[queue[q, 0], queue[q, 1], queue[q, 2]] = False
    return found


def spot_reach(
    occupied: np.ndarray,
    origin: np.ndarray,
    res: float,
    poses: np.ndarray,
    footprints: list[Footprint],
    fill_order: tuple[int, ...],
    *,
    margin_m: float = 3.0,
    grow_m: float = 0.02,
) -> list[SpotReach]:
    """The spots of a layout that no manoeuvre reaches in fill order (empty when all do).

    Parameters
    ----------
    occupied
        The static map's occupied cells ``(H, W)`` (True occupied), cell ``(r, c)`` centred
        at ``origin + ((c + 0.5) res, (r + 0.5) res)``.
    poses, footprints
        The spots' pivot poses ``(N, 3)`` (rad) and the footprint parked on each.
    fill_order
        Spot indices in the order they are filled: each spot is checked with the spots before
        it in place (grown by ``grow_m``).
    margin_m
        The search window is the spots' bounding box grown by this; a skid that reaches the
        window's edge counts as out.
    """
    poses = np.asarray(poses, float)
    reach = max(f.reach_m for f in footprints)
    lo = poses[:, :2].min(axis=0) - reach - margin_m
    hi = poses[:, :2].max(axis=0) + reach + margin_m
    h, w = occupied.shape
    c0 = max(int(np.floor((lo[0] - origin[0]) / res)), 0)
    r0 = max(int(np.floor((lo[1] - origin[1]) / res)), 0)
    c1 = min(int(np.ceil((hi[0] - origin[0]) / res)), w)
    r1 = min(int(np.ceil((hi[1] - origin[1]) / res)), h)
    win_origin = np.array([origin[0] + c0 * res, origin[1] + r0 * res])
    occ = np.asarray(occupied[r0:r1, c0:c1], bool).copy()
    seen = np.zeros((_K,) + occ.shape, np.bool_)
    queue = np.empty((seen.size, 3), np.int64)
    tests = {}  # per footprint: the 33 masks and their hit counts on occ (kept up to date)
    out: list[SpotReach] = []
    for n, j in enumerate(fill_order):
        fp = footprints[j]
        key = (fp.length_m, fp.width_m, fp.pivot)
        if key not in tests:
            masks = _masks(fp, res, grow_m)
            tests[key] = (masks, _hits(occ, masks))
        masks, hits = tests[key]
        k, r, c = snap_state(poses[j], win_origin, res)
        found = True  # a spot off the map window: the map's own checks speak for it
        if 0 <= r < occ.shape[0] and 0 <= c < occ.shape[1]:
            keep = hits[k, r, c]
            hits[k, r, c] = 0.0  # the spot itself is clear by the layout's construction
            found = _flood(hits, HEADING_STEPS, np.array([k, r, c], np.int64), seen, queue)
            hits[k, r, c] = keep
        if not found:
            before = n
            out.append(
                SpotReach(
                    int(j),
                    (float(poses[j, 0]), float(poses[j, 1]), float(poses[j, 2])),
                    "no manoeuvre (forwards, backwards, turning on the spot) gets a "
                    f"{fp.length_m:g} x {fp.width_m:g} m skid in between the walls"
                    + (f" and the {before} spot(s) filled before it" if before else ""),
                )
            )
        before_occ = occ.copy()
        stamp_footprint(occ, win_origin, res, poses[j], fp, grow_m)
        new = occ & ~before_occ
        for masks, hits in tests.values():
            _add_hits(hits, new, masks)
    return out


_K = len(HEADING_STEPS)


def _masks(fp: Footprint, res: float, grow_m: float) -> np.ndarray:
    """``(33, S, S)``: the 16 heading masks, the 16 half-way (turn) masks and the
    turn-all-round disc, grown as :func:`swarmpark.plan.lattice.free_masks` grows them."""
    grow = grow_m + res * np.sqrt(0.5)
    heads = [rect_mask(fp, a, res, grow) for a in HEADINGS]
    mids = []
    for k in range(_K):
        a, b = HEADINGS[k], HEADINGS[(k + 1) % _K]
        mid = np.arctan2(np.sin(a) + np.sin(b), np.cos(a) + np.cos(b))
        mids.append(rect_mask(fp, mid, res, grow))
    size = heads[0].shape[0]
    off = (np.arange(size) - size // 2) * res
    dx, dy = np.meshgrid(off, off)
    disc = np.hypot(dx, dy) <= fp.reach_m + grow
    return np.stack(heads + mids + [disc]).astype(float)


def _hits(occ: np.ndarray, masks: np.ndarray) -> np.ndarray:
    """``(33, H, W)``: how many occupied cells lie under each mask with the pivot at each
    cell (a correlation, by FFT, all masks at once)."""
    stack = np.broadcast_to(occ.astype(float), (len(masks),) + occ.shape)
    return fftconvolve(stack, masks[:, ::-1, ::-1], mode="same", axes=(1, 2))


def _add_hits(hits: np.ndarray, new: np.ndarray, masks: np.ndarray) -> None:
    """Add the hits of newly occupied cells ``new`` to ``hits`` (in place), on the box around
    them only: the correlation is linear in the occupancy."""
    rows, cols = np.nonzero(new)
    if not rows.size:
        return
    a, b, c, d = rows.min(), rows.max() + 1, cols.min(), cols.max() + 1
    patch = new[a:b, c:d].astype(float)
    r = masks.shape[1] // 2
    h, w = new.shape
    # full-mode output (i, j) lands on same-mode cell (a + i - r, c + j - r)
    y0, x0 = a - r, c - r
    ys, xs = max(y0, 0), max(x0, 0)
    ye, xe = min(y0 + patch.shape[0] + 2 * r, h), min(x0 + patch.shape[1] + 2 * r, w)
    full = fftconvolve(patch[None], masks[:, ::-1, ::-1], mode="full", axes=(1, 2))
    hits[:, ys:ye, xs:xe] += full[:, ys - y0 : ye - y0, xs - x0 : xe - x0]
