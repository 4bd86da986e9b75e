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
import shapely
from numba import njit
from scipy.signal import fftconvolve

from swarmpark.core.geometry import Footprint, footprint_polygon
from swarmpark.core.gridmap import refine_occupancy
from swarmpark.plan.lattice import (
    HEADING_STEPS,
    cells_near,
    heading_masks,
    snap_state,
    stamp_footprint,
)

__all__ = [
    "SpotReach",
    "SpotWindow",
    "as_report",
    "manoeuvre_blocks",
    "manoeuvre_order",
    "spot_reach",
    "spot_windows",
]


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
def _flood(hits, steps, starts, seen, queue, parent):
    """Breadth-first search over lattice states from ``starts`` ``(M, 3)`` until a state where
    the skid can turn all the way round or one on the window's edge (its row in ``queue``,
    whose ``parent`` rows lead back to a start, rows 0 to M - 1), or every reachable state is
    seen (-1). ``hits[k]`` counts the occupied cells under the footprint at heading
    ``k``, ``hits[16 + k]`` under it half way from heading ``k`` to ``k + 1``, ``hits[32]``
    under the turn-all-round disc. ``seen`` (all False) is left all False again."""
    n_k = steps.shape[0]
    n_r, n_c = hits.shape[1], hits.shape[2]
    tail = 0
    for m in range(starts.shape[0]):
        k0, r0, c0 = starts[m, 0], starts[m, 1], starts[m, 2]
        if seen[k0, r0, c0]:
            continue
        queue[tail, 0], queue[tail, 1], queue[tail, 2] = k0, r0, c0
        seen[k0, r0, c0] = True
        parent[tail] = -1
        tail += 1
    head = 0
    found = -1
    while head < tail:
        k, r, c = queue[head, 0], queue[head, 1], queue[head, 2]
        head += 1
        if hits[2 * n_k, r, c] < 0.5 or r == 0 or c == 0 or r == n_r - 1 or c == n_c - 1:
            found = head - 1
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
            parent[tail] = head - 1
            tail += 1
    for q in range(tail):
        seen[queue[q, 0], queue[q, 1], queue[q, 2]] = False
    return found


class SpotWindow:
    """The lattice window of a layout's spots, with any subset of the spots in place.

    Holds the static map's occupied cells around the spots, each spot's footprint stamp
    (grown by ``grow_m``) and, per footprint, the hit counts of :func:`_masks` on the cells
    occupied now, kept up to date as spots are put in place (:meth:`add`) or taken away
    (:meth:`remove`): the correlation is linear in the occupancy, so only the cells that
    change are convolved. :meth:`reachable` asks whether a skid gets into a spot with the
    spots in place as obstacles. Parameters as :func:`spot_reach`; with ``pieces`` (the static
    solids, ``(S, 4, 2)``) and ``max_cell_m`` the window is searched on cells at most that
    big, its walls made from the pieces (:func:`swarmpark.core.gridmap.refine_occupancy`);
    with ``goal_tol_m`` a spot also counts as reached from the free cells that near its own,
    at its heading.
    """

    def __init__(
        self,
        occupied: np.ndarray,
        origin: np.ndarray,
        res: float,
        poses: np.ndarray,
        footprints: list[Footprint],
        *,
        margin_m: float = 3.0,
        grow_m: float = 0.02,
        pieces: np.ndarray | None = None,
        max_cell_m: float | None = None,
        goal_tol_m: float = 0.0,
    ) -> None:
        poses = np.asarray(poses, float)
        reach = max(f.reach_m for f in footprints)
        lo = poses[:, :2].min(axis=0) - reach - margin_m
        hi = poses[:, :2].max(axis=0) + reach + margin_m
        h, w = occupied.shape
        c0 = max(int(np.floor((lo[0] - origin[0]) / res)), 0)
        r0 = max(int(np.floor((lo[1] - origin[1]) / res)), 0)
        c1 = min(int(np.ceil((hi[0] - origin[0]) / res)), w)
        r1 = min(int(np.ceil((hi[1] - origin[1]) / res)), h)
        self.origin = np.array([origin[0] + c0 * res, origin[1] + r0 * res])
        walls = np.asarray(occupied[r0:r1, c0:c1], bool)
        split = 1 if max_cell_m is None else int(np.ceil(res / max_cell_m - 1e-9))
        if split > 1 and pieces is not None:
            walls = refine_occupancy(walls, self.origin, res, split, pieces)
            res = res / split
        self.res, self.grow_m, self.goal_tol_m = res, grow_m, goal_tol_m
        self.poses, self.footprints = poses, list(footprints)
        n = len(poses)
        # How many things cover each cell (walls count n + 1, so they never clear).
        self.count = walls.astype(np.int32) * (n + 1)
        self.present = np.zeros(n, dtype=bool)
        self.stamps = []
        for pose, fp in zip(poses, footprints, strict=True):
            st = np.zeros(walls.shape, bool)
            stamp_footprint(st, self.origin, res, pose, fp, grow_m)
            self.stamps.append(st)
        self.seen = np.zeros((_K,) + walls.shape, np.bool_)
        self.queue = np.empty((self.seen.size, 3), np.int64)
        self.parent = np.empty(self.seen.size, np.int64)
        self.tests: dict = {}  # per footprint: the 33 masks and their hit counts (up to date)

    def _test(self, fp: Footprint):
        key = (fp.length_m, fp.width_m, fp.pivot)
        if key not in self.tests:
            masks = _masks(fp, self.res, self.grow_m)
            self.tests[key] = (masks, _hits(self.count > 0, masks))
        return self.tests[key]

    def add(self, j: int) -> None:
        """Put spot ``j`` in place."""
        if self.present[j]:
            return
        new = self.stamps[j] & (self.count == 0)
        self.count += self.stamps[j]
        self.present[j] = True
        for masks, hits in self.tests.values():
            _add_hits(hits, new, masks)

    def remove(self, j: int) -> None:
        """Take spot ``j`` away."""
        if not self.present[j]:
            return
        self.count -= self.stamps[j]
        self.present[j] = False
        freed = self.stamps[j] & (self.count == 0)
        for masks, hits in self.tests.values():
            _add_hits(hits, freed, masks, -1.0)

    def reachable(self, j: int) -> bool:
        """Whether a manoeuvre gets a skid into spot ``j`` (not in place itself) between the
        walls and the spots in place. A spot off the window is left to the map's own checks
        (True)."""
        return self.way_out(j) is not None

    def way_out(self, j: int) -> np.ndarray | None:
        """The cell centres ``(M, 2)`` of the manoeuvre :meth:`reachable` finds out of spot
        ``j`` (to where the skid can turn all the way round), or None if there is none; an
        empty array for a spot off the window."""
        masks, hits = self._test(self.footprints[j])
        k, r, c = snap_state(self.poses[j], self.origin, self.res)
        n_r, n_c = hits.shape[1], hits.shape[2]
        if not (0 <= r < n_r and 0 <= c < n_c):
            return np.zeros((0, 2))
        keep = hits[k, r, c]
        hits[k, r, c] = 0.0  # the spot itself is clear by the layout's construction
        # Also from the free cells beside it within goal_tol_m (as the manoeuvre planner
        # ends there: swarmpark.plan.lattice.plan_manoeuvre).
        rows, cols, _ = cells_near(r, c, self.goal_tol_m, self.res, (n_r, n_c))
        ok = hits[k, rows, cols] < 0.5
        starts = np.column_stack([np.full(int(ok.sum()), k), rows[ok], cols[ok]]).astype(np.int64)
        end = _flood(hits, HEADING_STEPS, starts, self.seen, self.queue, self.parent)
        hits[k, r, c] = keep
        if end < 0:
            return None
        rows = []
        while end >= 0:
            rows.append(end)
            end = self.parent[end]
        cells = self.queue[np.array(rows), 1:]
        return self.origin + (cells[:, ::-1] + 0.5) * self.res

    def flag(self, j: int, before: int) -> SpotReach:
        """The flag of spot ``j``, unreachable with ``before`` spots in place."""
        fp = self.footprints[j]
        pose = self.poses[j]
        return SpotReach(
            int(j),
            (float(pose[0]), float(pose[1]), float(pose[2])),
            "no manoeuvre (forwards, backwards, turning on the spot in steps of 18-27 deg) "
            f"gets a {fp.length_m:g} x {fp.width_m:g} m skid in between the walls"
            + (f" and the {before} spot(s) filled before it" if before else "")
            + "; a skid may still make it in with smaller turns",
        )


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
    finer: dict | None = None,
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
    finer
        ``pieces``, ``max_cell_m``, ``goal_tol_m`` of :class:`SpotWindow`: if a spot is
        flagged on the map's cells, the spots are checked again so (the flags are then
        those).
    """
    out: list[SpotReach] = []
    args = (occupied, origin, res, poses, footprints)
    for win in spot_windows(*args, finer=finer, margin_m=margin_m, grow_m=grow_m):
        out = []
        for n, j in enumerate(fill_order):
            if not win.reachable(j):
                out.append(win.flag(j, n))
            win.add(j)
        if not out:
            break
    return out


def spot_windows(
    occupied: np.ndarray,
    origin: np.ndarray,
    res: float,
    poses: np.ndarray,
    footprints: list[Footprint],
    *,
    finer: dict | None = None,
    **kwargs,
):
    """The :class:`SpotWindow` of the spots on the map's cells, then (when the caller asks
    for the next one, having found a spot out of reach there) with ``finer`` (``pieces``,
    ``max_cell_m``, ``goal_tol_m``): the manoeuvre planner's cells, several times the work,
    so only then. ``kwargs`` go to both windows."""
    args = (occupied, origin, res, poses, footprints)
    yield SpotWindow(*args, **kwargs)
    if finer is not None:
        yield SpotWindow(*args, **kwargs, **finer)


def manoeuvre_order(
    win: SpotWindow, prefer: tuple[int, ...]
) -> tuple[tuple[int, ...], list[SpotReach]]:
    """A fill order in which a manoeuvre reaches every spot with the spots before it in
    place, when there is one, and the spots it cannot make reachable (flagged).

    Built backwards: with every spot in place, the last spot to fill must be reachable with
    all the others in place; take it away and find the one before it likewise. Reachability
    only grows as spots are taken away, so taking any reachable spot never spoils a later
    choice: if some order works, this finds one (and flags nothing). Among the reachable
    spots the one latest in ``prefer`` (the layout's order) is taken, so a layout whose order
    works is kept as it is. When none is reachable the latest in ``prefer`` is taken and
    flagged. ``win`` is left with no spot in place.
    """
    for j in prefer:
        win.add(j)
    left = list(prefer)
    backwards: list[int] = []
    stuck: list[int] = []
    while left:
        pick = None
        for j in reversed(left):
            win.remove(j)
            if win.reachable(j):
                pick = j
                break
            win.add(j)
        if pick is None:
            pick = left[-1]
            win.remove(pick)
            stuck.append(pick)
        backwards.append(pick)
        left.remove(pick)
    order = tuple(backwards[::-1])
    pos = {j: n for n, j in enumerate(order)}
    return order, [win.flag(j, pos[j]) for j in sorted(stuck, key=pos.get)]


def manoeuvre_blocks(win: SpotWindow, order: tuple[int, ...]) -> tuple[tuple[int, ...], ...]:
    """For each spot k, the spots j before it in ``order`` that a manoeuvre reaches with the
    spots before j in place but not once k is in place too: k must stay free until they are
    filled (as :func:`swarmpark.supervisor.fill_order.blockers`, for the rectangle instead of
    a disc). ``win`` must have no spot in place; it is left so."""
    blocks: list[set[int]] = [set() for _ in range(len(win.poses))]
    # A spot whose footprint keeps off the way out found for j cannot shut it: only the
    # others are put in place and j searched again.
    grow = win.grow_m + win.res
    feet = np.array(
        [
            footprint_polygon(p, f).buffer(grow)
            for p, f in zip(win.poses, win.footprints, strict=True)
        ],
        dtype=object,
    )
    for n, j in enumerate(order):
        way = win.way_out(j)
        if way is not None and len(way):
            swept = shapely.LineString(np.vstack([way, way[-1:]])).buffer(
                win.footprints[j].reach_m + grow
            )
            later = np.array(order[n + 1 :], dtype=int)
            near = later[shapely.intersects(feet[later], swept)] if len(later) else later
            for k in near.tolist():
                win.add(k)
                if not win.reachable(j):
                    blocks[k].add(j)
                win.remove(k)
        win.add(j)
    for j in order:
        win.remove(j)
    return tuple(tuple(sorted(b)) for b in blocks)


_K = len(HEADING_STEPS)


def _masks(fp: Footprint, res: float, grow_m: float) -> np.ndarray:
    """``(33, S, S)``: the 16 heading masks, the 16 half-way (turn) masks and the
    turn-all-round disc, grown as :func:`swarmpark.plan.lattice.free_masks` grows them."""
    masks = heading_masks(fp, res, grow_m)
    grow = grow_m + res * np.sqrt(0.5)  # as heading_masks grows the rectangle
    size = masks.shape[1]
    off = (np.arange(size) - size // 2) * res
    dx, dy = np.meshgrid(off, off)
    disc = np.hypot(dx, dy) <= fp.reach_m + grow
    return np.concatenate([masks, disc[None]]).astype(float)


def _hits(occ: np.ndarray, masks: np.ndarray) -> np.ndarray:
    """``(33, H, W)``: how many occupied cells lie under each mask with the pivot at each
    cell (a correlation, by FFT, all masks at once)."""
    stack = np.broadcast_to(occ.astype(float), (len(masks),) + occ.shape)
    return fftconvolve(stack, masks[:, ::-1, ::-1], mode="same", axes=(1, 2))


def _add_hits(hits: np.ndarray, new: np.ndarray, masks: np.ndarray, sign: float = 1.0) -> None:
    """Add the hits of newly occupied cells ``new`` to ``hits`` (in place; ``sign`` -1:
    take away those of newly freed cells), on the box around them only: the correlation is
    linear in the occupancy."""
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
    hits[:, ys:ye, xs:xe] += sign * full[:, ys - y0 : ye - y0, xs - x0 : xe - x0]
