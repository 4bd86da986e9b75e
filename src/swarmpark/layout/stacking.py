"""Stacking layout (Hing et al. 2018, Algorithm 1), testing the whole footprint.

The boundary is scanned from its left-most point along columns (x outer, y inner: the
paper's ``stepX``/``stepY`` loops) and each skid takes the first candidate where its whole
rectangle, grown by the margin, lies in the free region and keeps the margin from every
skid placed before it. The paper's pseudo code tests only the centre point; here the whole
footprint is tested. With ``Region.scan_flip`` an axis is scanned from its high end instead
(the supervisor's room by the opening, :func:`swarmpark.layout.api.layout` ``apron_m``).

All candidates of one footprint size are tested at once (a lattice of centres, one
vectorized shapely ``covers`` call against the eroded region); placing a skid then masks
the candidates it blocks. The lattice step divides the pitch (footprint + margin) exactly,
so a rectangular boundary gives a regular grid.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely

from swarmpark.layout.region import Region, Skids

__all__ = ["stack", "StackResult", "SCAN_ORDERS", "STEPS_PER_PITCH"]

#: Scan orders: "columns" is the paper's (x outer, y inner); "rows" is y outer, x inner.
SCAN_ORDERS = ("columns", "rows")
#: Candidate lattice steps per pitch (footprint + margin). Finer lattices pack non-convex
#: boundaries a little better; 8 keeps N = 100 well under the 0.1 s budget.
STEPS_PER_PITCH = 8
#: Largest lattice step (metres), so big skids in odd shapes still get fine candidates.
MAX_STEP_M = 0.15
#: Candidates that would sit closer than the margin by less than this still conflict;
#: float round-off on the lattice must not open or close a slot.
_CONFLICT_TOL_M = 1e-9


@dataclass(frozen=True)
class StackResult:
    """Outcome of stacking.

    Attributes
    ----------
    centres
        ``(N, 2)`` layout-frame centres; rows of skids that did not fit are NaN.
    placed
        ``(N,)`` bool, True where the skid got a goal.
    order
        The scan order used.
    """

    centres: np.ndarray
    placed: np.ndarray
    order: str

    @property
    def fits(self) -> int:
        return int(self.placed.sum())


def _lattice(region: Region, half: np.ndarray, order: str) -> tuple[np.ndarray, np.ndarray]:
    """Candidate centres ``(C, 2)`` in scan order, and whether each rectangle fits the region."""
    a, b = half
    m_edge, m = region.margin_edge, region.margin
    xmin, ymin, xmax, ymax = region.free.bounds
    axes = []
    for lo, hi, h, flip in zip((xmin, ymin), (xmax, ymax), (a, b), region.scan_flip, strict=True):
        pitch = 2.0 * h + m
        k = max(STEPS_PER_PITCH, int(np.ceil(pitch / MAX_STEP_M)))
        step = pitch / k
        start, end = lo + m_edge + h, hi - m_edge - h
        count = max(int(np.floor((end - start) / step + 1e-9)) + 1, 0)
        if flip:
            axes.append(end - step * np.arange(count))
        else:
            axes.append(start + step * np.arange(count))
    xs, ys = axes
    if order == "columns":
        gx, gy = np.meshgrid(xs, ys, indexing="ij")
    else:
        gy, gx = np.meshgrid(ys, xs, indexing="ij")
    cand = np.column_stack([gx.ravel(), gy.ravel()])
    if len(cand) == 0:
        return cand, np.zeros(0, dtype=bool)
    # Cheap pre-filter on the centre, then the exact whole-rectangle test.
    ok = shapely.contains_xy(region.inner, cand[:, 0], cand[:, 1])
    idx = np.flatnonzero(ok)
    ok[idx] = region.inside(cand[idx], np.broadcast_to(half, (len(idx), 2)))
    return cand, ok


def stack(region: Region, skids: Skids, *, order: str = "columns", count: int | None = None):
    """Place skids by stacking.

    Parameters
    ----------
    region
        The layout-frame region.
    skids
        The footprints. Mixed sizes are placed largest first (a stable sort by area), which
        packs better than the given order; goals are still returned in the given order.
    order
        ``"columns"`` (the paper's scan) or ``"rows"``.
    count
        Place at most this many skids; ``None`` places every skid in ``skids`` it can. For
        capacity, pass a :class:`Skids` of one footprint repeated and ``count=None``.

    Returns
    -------
    StackResult
    """
    if order not in SCAN_ORDERS:
        raise ValueError(f"stacking order must be one of {SCAN_ORDERS} (got {order!r})")
    n = len(skids)
    limit = n if count is None else min(count, n)
    half = skids.half
    sizes, cls = np.unique(half, axis=0, return_inverse=True)
    cls = np.asarray(cls).ravel()
    lattices = [_lattice(region, sizes[c], order) for c in range(len(sizes))]
    cands = [lat[0] for lat in lattices]
    open_ = [lat[1].copy() for lat in lattices]
    centres = np.full((n, 2), np.nan)
    placed = np.zeros(n, dtype=bool)
    area = half[:, 0] * half[:, 1]
    sequence = np.argsort(-area, kind="stable")
    done = 0
    for i in sequence:
        if done >= limit:
            break
        c = cls[i]
        if not open_[c].any():
            continue
        j = int(np.argmax(open_[c]))  # first open candidate in scan order
        p = cands[c][j]
        centres[i] = p
        placed[i] = True
        done += 1
        # Mask every candidate (of every size) that this rectangle now blocks.
        for k in range(len(sizes)):
            reach = sizes[k] + half[i] + region.margin - _CONFLICT_TOL_M
            d = np.abs(cands[k] - p)
            open_[k] &= ~((d[:, 0] < reach[0]) & (d[:, 1] < reach[1]))
    return StackResult(centres, placed, order)
