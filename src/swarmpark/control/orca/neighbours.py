"""Compiled neighbour search of the ORCA kernel: a uniform grid of buckets over the robots.

One pass gives both what a step needs: each robot's ``max_nb`` nearest robots within the
cut-off (nearest first; exact distance ties broken by the relative position, then by
index, so the result does not depend on the robots' order), and every pair within the
safety filter's reach. It replaces two k-d tree queries (build, k-nearest query and pair
query) that cost more than the pair geometry at a thousand robots.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["grid_neighbours"]

#: The grid never has more than this many buckets per robot (bigger buckets instead).
MAX_BUCKETS_PER_ROBOT = 16
#: Relative widening of squared-distance pre-tests (round-off is ~1e-16).
SLACK = 1.0 + 1e-9


@njit(cache=True)
def _buckets(pos, size):
    """Counting sort of the robots into square buckets of side ``size``: ``order`` (robots
    by bucket), ``start`` (first index of each bucket in ``order``, one extra at the end),
    the grid's shape and origin."""
    n = pos.shape[0]
    x0, y0 = pos[:, 0].min(), pos[:, 1].min()
    nx = int((pos[:, 0].max() - x0) / size) + 1
    ny = int((pos[:, 1].max() - y0) / size) + 1
    cell = np.empty(n, np.int64)
    count = np.zeros(nx * ny + 1, np.int64)
    for i in range(n):
        cx = min(int((pos[i, 0] - x0) / size), nx - 1)
        cy = min(int((pos[i, 1] - y0) / size), ny - 1)
        cell[i] = cy * nx + cx
        count[cell[i] + 1] += 1
    for c in range(nx * ny):
        count[c + 1] += count[c]
    start = count.copy()
    order = np.empty(n, np.int64)
    for i in range(n):
        order[count[cell[i]]] = i
        count[cell[i]] += 1
    return order, start, nx, ny, x0, y0


@njit(cache=True, inline="always")
def _before(d, x, y, j, d2, x2, y2, j2):
    """Order of candidates: distance, then relative position, then index."""
    if d != d2:
        return d < d2
    if x != x2:
        return x < x2
    if y != y2:
        return y < y2
    return j < j2


@njit(cache=True)
def grid_neighbours(pos, cut, n_slots, max_nb, near):
    """Nearest neighbours and near pairs of points ``(N, 2)``.

    Returns ``nbr`` ``(N, n_slots)``: for each robot its at most ``max_nb`` nearest other
    robots at distance ``< cut``, nearest first, ``-1`` after the last; and ``pairs``
    ``(P, 2)``: every pair ``i < j`` at distance ``<= near`` (``near < 0``: none).
    """
    n = pos.shape[0]
    nbr = np.full((n, n_slots), -1, np.int64)
    reach = max(cut, near)
    if n == 0 or not (reach > 0):
        return nbr, np.empty((0, 2), np.int64)
    span = max(pos[:, 0].max() - pos[:, 0].min(), pos[:, 1].max() - pos[:, 1].min())
    size = reach
    # Few robots spread far: coarser buckets keep the grid small.
    while (span / size + 1.0) ** 2 > MAX_BUCKETS_PER_ROBOT * n + 64:
        size *= 2.0
    order, start, gx, gy, x0, y0 = _buckets(pos, size)
    steps = int(np.ceil(reach / size))
    m = min(max_nb, n_slots)
    cd, cx, cy = np.empty(m + 1), np.empty(m + 1), np.empty(m + 1)
    cj = np.empty(m + 1, np.int64)
    pairs = np.empty((16, 2), np.int64)
    n_pairs = 0
    near2 = near * near * SLACK if near >= 0 else -1.0
    cut2 = cut * cut * SLACK if cut > 0 else -1.0
    for i in range(n):
        px, py = pos[i, 0], pos[i, 1]
        bx = min(int((px - x0) / size), gx - 1)
        by = min(int((py - y0) / size), gy - 1)
        cnt = 0
        for qy in range(max(by - steps, 0), min(by + steps, gy - 1) + 1):
            for qx in range(max(bx - steps, 0), min(bx + steps, gx - 1) + 1):
                c = qy * gx + qx
                for t in range(start[c], start[c + 1]):
                    j = order[t]
                    if j == i:
                        continue
                    dx, dy = pos[j, 0] - px, pos[j, 1] - py
                    d2 = dx * dx + dy * dy
                    # Squared bounds widened by far more than round-off only skip the
                    # square root where the exact tests below would reject anyway.
                    if not (
                        (j > i and d2 <= near2)
                        or (m > 0 and d2 <= cut2 and (cnt < m or d2 <= cd[m - 1] ** 2 * SLACK))
                    ):
                        continue
                    d = np.sqrt(d2)
                    if j > i and d <= near:
                        if n_pairs == pairs.shape[0]:
                            grown = np.empty((2 * n_pairs, 2), np.int64)
                            grown[:n_pairs] = pairs
                            pairs = grown
                        pairs[n_pairs, 0], pairs[n_pairs, 1] = i, j
                        n_pairs += 1
                    if not d < cut or m == 0:
                        continue
                    if cnt == m and not _before(
                        d, dx, dy, j, cd[m - 1], cx[m - 1], cy[m - 1], cj[m - 1]
                    ):
                        continue
                    # Insertion into the sorted list of the m best so far.
                    q = min(cnt, m - 1)
                    while q > 0 and _before(
                        d, dx, dy, j, cd[q - 1], cx[q - 1], cy[q - 1], cj[q - 1]
                    ):
                        cd[q], cx[q], cy[q], cj[q] = cd[q - 1], cx[q - 1], cy[q - 1], cj[q - 1]
                        q -= 1
                    cd[q], cx[q], cy[q], cj[q] = d, dx, dy, j
                    cnt = min(cnt + 1, m)
        for s in range(cnt):
            nbr[i, s] = cj[s]
    return nbr, pairs[:n_pairs]
