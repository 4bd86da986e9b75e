"""A* on a costmap grid (compiled with numba): least-cost paths from one start to a few goals.

The metric is ``skimage.graph.MCP_Geometric``'s (8-connected, a move costs its length times
the mean of the two cells' costs, ``inf`` impassable), so the costs of the paths are the
same as a Dijkstra flood's; the search is guided by the octile distance to the nearest goal
(admissible and consistent because every cell costs at least 1 per cell length), so it expands
the cells near the way instead of the whole map. Ties are broken as the flood breaks them
(the cell reached more cheaply first), so the paths are mostly the flood's; where float
rounding decides a tie they may differ (a different but equally cheap path).

The search arrays are kept between calls (:class:`Workspace`, one per grid shape) and marked
per search instead of cleared, so a search on a large map costs the cells it expands, not the
map. They are shared by the searches of one process, which therefore must not run searches
from several threads at once (the controller plans in the tick, one search at a time).
"""

from __future__ import annotations

import heapq

import numpy as np
from numba import njit

__all__ = ["Workspace", "search"]

_SQRT2 = np.sqrt(2.0)
#: The 8 moves (row, col) and their lengths in cells, in the order skimage lists its offsets.
_DR = np.array([-1, -1, -1, 0, 0, 1, 1, 1], np.int64)
_DC = np.array([-1, 0, 1, -1, 1, -1, 0, 1], np.int64)
_LEN = np.sqrt(_DR.astype(float) ** 2 + _DC.astype(float) ** 2)


class Workspace:
    """Per-cell search arrays for one grid shape, reused by every search on it: the cost so
    far, the move that reached each cell, and per-search marks (a cell's entries are valid
    when its mark is the current search's), so nothing is cleared between searches."""

    def __init__(self, shape: tuple[int, int]) -> None:
        size = int(shape[0]) * int(shape[1])
        self.shape = (int(shape[0]), int(shape[1]))
        self.g = np.empty(size)
        self.move = np.empty(size, np.int8)
        self.seen = np.zeros(size, np.int32)
        self.done = np.zeros(size, np.int32)
        self.mark = 0

    def next_mark(self) -> int:
        self.mark += 1
        if self.mark >= np.iinfo(np.int32).max:  # wrapped: clear once
            self.seen[:] = 0
            self.done[:] = 0
            self.mark = 1
        return self.mark


_WORKSPACES: dict[tuple[int, int], Workspace] = {}


def _workspace(shape: tuple[int, int]) -> Workspace:
    ws = _WORKSPACES.get(shape)
    if ws is None:
        _WORKSPACES.clear()  # one map at a time: do not hold the arrays of old maps
        ws = _WORKSPACES[shape] = Workspace(shape)
    return ws


@njit(cache=True)
def _heuristic(r, c, goals, open_):
    """Octile distance (cell lengths) to the nearest goal still open (``open_[k]``)."""
    best = np.inf
    for k in range(goals.shape[0]):
        if not open_[k]:
            continue
        dr = abs(r - goals[k, 0])
        dc = abs(c - goals[k, 1])
        lo = min(dr, dc)
        h = (max(dr, dc) - lo) + 1.4142135623730951 * lo
        if h < best:
            best = h
    return best


@njit(cache=True)
def _astar(cost, start, goals, g, move, seen, done, mark, dr, dc, ln, budget):
    """Expand from ``start`` until every goal is settled (or the budget or the heap runs out).
    Returns the number of cells expanded."""
    h_, w_ = cost.shape
    s0 = start[0] * w_ + start[1]
    g[s0] = 0.0
    seen[s0] = mark
    move[s0] = -1
    open_ = np.ones(goals.shape[0], np.bool_)
    left = goals.shape[0]
    h0 = _heuristic(start[0], start[1], goals, open_)
    heap = [(np.round(h0 * 1e9) * 1e-9, 0.0, s0)]
    expanded = 0
    while len(heap) > 0 and left > 0 and expanded < budget:
        _, _, s = heapq.heappop(heap)
        if done[s] == mark:
            continue
        done[s] = mark
        expanded += 1
        r = s // w_
        c = s % w_
        settled = False
        for k in range(goals.shape[0]):
            if open_[k] and goals[k, 0] == r and goals[k, 1] == c:
                open_[k] = False
                left -= 1
                settled = True
        if settled and left > 0:
            # Guide the rest of the search by the goals still open (a consistent heuristic
            # again), re-keying the open cells; with the settled goal's pull left in, every
            # cell as cheap as the farthest goal would be expanded.
            rekeyed = [(0.0, 0.0, s)]
            rekeyed.clear()
            for _, _, t in heap:
                if done[t] != mark:
                    ht = _heuristic(t // w_, t % w_, goals, open_)
                    rekeyed.append((np.round((g[t] + ht) * 1e9) * 1e-9, g[t], t))
            heapq.heapify(rekeyed)
            heap = rekeyed
        gs = g[s]
        cs = cost[r, c]
        for m in range(8):
            nr = r + dr[m]
            nc = c + dc[m]
            if nr < 0 or nc < 0 or nr >= h_ or nc >= w_:
                continue
            cn = cost[nr, nc]
            if not np.isfinite(cn) or cn < 0:
                continue
            ns = nr * w_ + nc
            if done[ns] == mark:
                continue
            ng = gs + ln[m] * 0.5 * (cs + cn)
            if seen[ns] != mark or ng < g[ns]:
                seen[ns] = mark
                g[ns] = ng
                move[ns] = m
                hn = _heuristic(nr, nc, goals, open_)
                # Ties on f go to the cell reached more cheaply, as a Dijkstra flood would pop
                # them: each cell then keeps the parent the flood gives it and the paths are
                # mostly the flood's (132 of 150 on two suite maps). Deeper-first ties would
                # expand fewer cells (one way instead of the band of equally cheap ones) but
                # change the paths. f is rounded (to 1e-9 cell lengths) so that rounding
                # noise does not break the ties.
                heapq.heappush(heap, (np.round((ng + hn) * 1e9) * 1e-9, ng, ns))
    return expanded


@njit(cache=True)
def _trace(goal, w_, move, dr, dc):
    """Cells (row, col) from the start to ``goal`` following the recorded moves back."""
    s = goal[0] * w_ + goal[1]
    n = 1
    t = s
    while move[t] >= 0:
        m = move[t]
        t = (t // w_ - dr[m]) * w_ + (t % w_ - dc[m])
        n += 1
    out = np.empty((n, 2), np.int64)
    t = s
    for k in range(n - 1, -1, -1):
        out[k, 0] = t // w_
        out[k, 1] = t % w_
        if k > 0:
            m = move[t]
            t = (t // w_ - dr[m]) * w_ + (t % w_ - dc[m])
    return out


def search(
    cost: np.ndarray, start_rc, goals_rc, *, budget: int = 1 << 62
) -> tuple[np.ndarray, list[np.ndarray | None], int]:
    """Least-cost paths on ``cost`` (``(H, W)``, ``>= 1`` or ``inf``) from cell ``start_rc``
    to each cell of ``goals_rc`` ``(G, 2)`` (all in bounds).

    Returns the cost of each path in cell lengths (``inf`` where none; as
    ``MCP_Geometric.find_costs`` gives at the goal), the cells of each path from the start to
    the goal (None where none) and the number of cells expanded. ``budget`` caps the cells
    expanded (goals not reached by then get no path).
    """
    cost = np.ascontiguousarray(cost, dtype=float)
    ws = _workspace(cost.shape)
    mark = ws.next_mark()
    start = np.asarray(start_rc, np.int64).reshape(2)
    goals = np.asarray(goals_rc, np.int64).reshape(-1, 2)
    expanded = _astar(
        cost, start, goals, ws.g, ws.move, ws.seen, ws.done, mark, _DR, _DC, _LEN, int(budget)
    )
    w = cost.shape[1]
    flat = goals[:, 0] * w + goals[:, 1]
    reached = ws.done[flat] == mark
    costs = np.where(reached, ws.g[flat], np.inf)
    paths = [
        _trace(g, w, ws.move, _DR, _DC) if ok else None
        for g, ok in zip(goals, reached, strict=True)
    ]
    return costs, paths, int(expanded)
