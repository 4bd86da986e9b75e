"""Goal assignment (2018 paper, Algorithm 2): Hungarian assignment with a chosen cost.

Costs: ``sequential`` (goal i to robot i, the 2015 behaviour), ``euclidean``, ``formation``
(the robots' centroid shifted onto the goals' centroid, then distances, so the group keeps its
shape and nobody crosses the others' lanes), ``path`` (shortest free-space path lengths, given
by the caller as a matrix). The costs are registered in :data:`ASSIGNMENT_COSTS` (the
scenario schema, the API and the UI read the names from it). Goals only go to robots whose
footprint fits them. Re-assignment every tick uses hysteresis so assignments do not chatter.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.sparse import coo_matrix, csr_matrix
from scipy.sparse.csgraph import maximum_bipartite_matching, min_weight_full_bipartite_matching
from scipy.spatial.distance import cdist

from swarmpark.core.registry import Registry

__all__ = [
    "ASSIGNMENT_COSTS",
    "COSTS",
    "cost_matrix",
    "assign",
    "sparse_assign",
    "reassign",
    "reassign_local",
    "pair_costs",
    "bottleneck_assignment",
    "AssignmentError",
]

#: Cost that marks a robot/goal pair as impossible (the footprint does not fit the goal).
INFEASIBLE = 1e9
#: A swap must lower the total cost by this share (and this absolute amount) to be taken.
HYSTERESIS_FRACTION = 0.1
HYSTERESIS_ABS_M = 0.5
#: Candidate goals per robot (and robots per goal) in the sparse k-nearest graph.
SPARSE_K = 20
#: Groups larger than this re-assign by swaps between neighbours (:func:`reassign_local`)
#: instead of a Hungarian re-solve every tick (O(n^3): 1.6 ms at 200 robots, 29 ms at 500,
#: 265 ms at 1000 on a fleet park; one core).
LOCAL_REASSIGN_ABOVE = 100
#: Neighbours per robot whose goals it may swap with in :func:`reassign_local`.
SWAP_K = 8


class AssignmentError(ValueError):
    """No assignment exists (more robots than goals, or footprints that fit no goal)."""


#: ``cost(robot_xy (R, 2), goal_xy (G, 2), path_lengths (R, G) or None) -> (R, G)``
CostFunction = Callable[[np.ndarray, np.ndarray, "np.ndarray | None"], np.ndarray]
#: The assignment costs by name, in the order they were registered.
ASSIGNMENT_COSTS: Registry[CostFunction] = Registry("assignment cost", "park.assignment")


@ASSIGNMENT_COSTS.register("sequential", "goal i to robot i (the 2015 behaviour)")
def _sequential(robot_xy, goal_xy, path_lengths):
    c = np.full((len(robot_xy), len(goal_xy)), INFEASIBLE / 2)
    k = min(len(robot_xy), len(goal_xy))
    c[np.arange(k), np.arange(k)] = 0.0
    return c


@ASSIGNMENT_COSTS.register("euclidean", "straight-line distance to the goal")
def _euclidean(robot_xy, goal_xy, path_lengths):
    # cdist: the same values as the norm of the broadcast differences, 7-9x faster.
    return cdist(robot_xy, goal_xy)


@ASSIGNMENT_COSTS.register(
    "formation", "the group keeps its shape: distances after moving its centroid onto the goals'"
)
def _formation(robot_xy, goal_xy, path_lengths):
    shifted = robot_xy - robot_xy.mean(axis=0) + goal_xy.mean(axis=0)
    # Distances of the shifted formation, plus a small share of the true distance to break
    # ties between mirror-image matchings.
    # cdist: the same values as the norm of the broadcast differences, 7-9x faster.
    return cdist(shifted, goal_xy) + 1e-2 * cdist(robot_xy, goal_xy)


@ASSIGNMENT_COSTS.register("path", "length of the shortest free path to the goal (path length)")
def _path(robot_xy, goal_xy, path_lengths):
    if path_lengths is None:
        raise ValueError("cost 'path' needs path_lengths")
    c = np.asarray(path_lengths, float).copy()
    c[~np.isfinite(c)] = INFEASIBLE
    return c


#: Names of the registered costs at import (kept for callers of the first release).
COSTS = ASSIGNMENT_COSTS.names()


def cost_matrix(
    robot_xy: np.ndarray,
    goal_xy: np.ndarray,
    cost: str,
    *,
    path_lengths: np.ndarray | None = None,
    fits: np.ndarray | None = None,
) -> np.ndarray:
    """Cost ``(R, G)`` of sending robot r to goal g.

    Examples
    --------
    >>> r = np.array([[0.0, 0.0], [0.0, 1.0]])
    >>> g = np.array([[5.0, 1.0], [5.0, 0.0]])
    >>> cost_matrix(r, g, "formation").round(2).tolist()  # the shapes match crosswise
    [[1.05, 0.05], [0.05, 1.05]]
    """
    robot_xy = np.asarray(robot_xy, float).reshape(-1, 2)
    goal_xy = np.asarray(goal_xy, float).reshape(-1, 2)
    c = ASSIGNMENT_COSTS.get(cost)(robot_xy, goal_xy, path_lengths)
    if fits is not None:
        c = np.where(fits, c, INFEASIBLE)
    return c


def assign(cost: np.ndarray) -> np.ndarray:
    """Optimal assignment: ``goal_of[r]`` for every robot (Hungarian, scipy).

    Raises :class:`AssignmentError` when some robot can only take an infeasible goal.
    """
    cost = np.asarray(cost, float)
    r, g = cost.shape
    if r > g:
        raise AssignmentError(f"assignment: {r} robots but only {g} goals")
    rows, cols = linear_sum_assignment(cost)
    goal_of = np.empty(r, dtype=int)
    goal_of[rows] = cols
    if np.any(cost[np.arange(r), goal_of] >= INFEASIBLE):
        bad = int(np.flatnonzero(cost[np.arange(r), goal_of] >= INFEASIBLE)[0])
        raise AssignmentError(f"assignment: robot {bad} fits no free goal")
    return goal_of


def sparse_assign(cost: np.ndarray, k: int = SPARSE_K) -> np.ndarray:
    """Assignment on the k-nearest sparse graph: ``goal_of[r]`` for every robot.

    Keeps, for every robot, its ``k`` cheapest goals and, for every goal, its ``k`` cheapest
    robots (so that goals far from everyone's favourites stay reachable), and solves the
    minimum-cost full matching on those edges (scipy's ``min_weight_full_bipartite_matching``,
    LAPJVsp). Optimal on the graph, not always on the full matrix; where the graph has no
    full matching it falls back to the dense Hungarian solve (:func:`assign`).

    Measured (formation cost, N = 1000, CPU time): the dense solve takes 60-160 ms and this
    one 150-250 ms at ``k = 20`` with a total cost within 0.5 % of the optimum, so
    :func:`assign` stays dense; this is the option for fleets whose dense matrix does not
    fit in memory.
    """
    cost = np.asarray(cost, float)
    r, g = cost.shape
    if r > g:
        raise AssignmentError(f"assignment: {r} robots but only {g} goals")
    if k < 1:
        raise ValueError(f"sparse_assign: k must be >= 1 (got {k!r})")
    if min(k, g) >= g or min(k, r) >= r:
        return assign(cost)
    per_robot = np.argpartition(cost, k - 1, axis=1)[:, :k]
    per_goal = np.argpartition(cost, k - 1, axis=0)[:k]
    rows = np.concatenate([np.repeat(np.arange(r), k), per_goal.ravel()])
    cols = np.concatenate([per_robot.ravel(), np.tile(np.arange(g), k)])
    keep = cost[rows, cols] < INFEASIBLE
    rows, cols = rows[keep], cols[keep]
    # The matcher drops zero weights (missing edges): shift all by a constant, which every
    # full matching (r edges) pays equally.
    shift = 1.0 - min(0.0, float(cost[rows, cols].min(initial=0.0)))
    graph = coo_matrix((cost[rows, cols] + shift, (rows, cols)), shape=(r, g)).tocsr()
    graph.sum_duplicates()
    # Duplicated edges were summed: restore their single weight.
    graph.data = cost[np.repeat(np.arange(r), np.diff(graph.indptr)), graph.indices] + shift
    try:
        rr, cc = min_weight_full_bipartite_matching(graph)
    except ValueError:
        return assign(cost)
    goal_of = np.empty(r, dtype=int)
    goal_of[rr] = cc
    return goal_of


def reassign(
    cost: np.ndarray,
    current: np.ndarray,
    locked: np.ndarray | None = None,
    *,
    fraction: float = HYSTERESIS_FRACTION,
    absolute: float = HYSTERESIS_ABS_M,
) -> tuple[np.ndarray, bool]:
    """Re-run the assignment with hysteresis.

    The new optimum replaces ``current`` only if it lowers the total cost by more than
    ``fraction`` of it and by more than ``absolute``. Robots in ``locked`` (parked) keep their
    goals in the re-solve unless freeing them is what makes the saving. Returns the
    assignment and whether it changed.
    """
    cost = np.asarray(cost, float)
    idx = np.arange(len(current))
    now = cost[idx, current].sum()
    c = cost.copy()
    if locked is not None and locked.any():
        # Keep parked robots on their goals by making every other choice expensive for them.
        c[locked] = np.where(
            np.arange(c.shape[1])[None] == current[locked][:, None],
            c[locked],
            c[locked] + absolute * 4,
        )
    best = assign(c)
    new = cost[idx, best].sum()
    if now - new > max(fraction * now, absolute):
        return best, True
    return current, False


def pair_costs(
    robot_xy: np.ndarray, goal_xy: np.ndarray, rows: np.ndarray, cols: np.ndarray, cost: str
) -> np.ndarray:
    """``cost_matrix(robot_xy, goal_xy, cost)[rows, cols]`` without the whole matrix (for the
    ``euclidean`` and ``formation`` costs, which are per pair once the centroids are known)."""
    robot_xy = np.asarray(robot_xy, float).reshape(-1, 2)
    goal_xy = np.asarray(goal_xy, float).reshape(-1, 2)
    r, g = robot_xy[rows], goal_xy[cols]
    direct = np.hypot(*(r - g).T)
    if cost == "euclidean":
        return direct
    if cost == "formation":
        shifted = r - robot_xy.mean(axis=0) + goal_xy.mean(axis=0)
        return np.hypot(*(shifted - g).T) + 1e-2 * direct
    raise ValueError(f"pair_costs: cost must be 'euclidean' or 'formation' (got {cost!r})")


def reassign_local(
    robot_xy: np.ndarray,
    goal_xy: np.ndarray,
    current: np.ndarray,
    cost: str,
    *,
    fits=None,
    locked: np.ndarray | None = None,
    k: int = SWAP_K,
    fraction: float = HYSTERESIS_FRACTION,
    absolute: float = HYSTERESIS_ABS_M,
) -> tuple[np.ndarray, bool]:
    """Re-assignment for large groups: goal swaps between each robot and its ``k`` nearest.

    A swap is taken when it lowers the pair's cost by more than ``fraction`` of it and more
    than ``absolute`` (the hysteresis of :func:`reassign`, per pair), the best swaps first,
    each robot in at most one swap per call; robots in ``locked`` keep their goals.
    ``fits(rows, cols)``: whether robot ``rows`` fits goal ``cols`` (elementwise), if some do
    not. A local improvement (2-opt), O(n k) per call instead of the Hungarian re-solve's
    O(n^3). Returns the assignment and whether it changed.
    """
    from scipy.spatial import cKDTree

    current = np.asarray(current, int)
    n = len(current)
    kk = min(k, n - 1)
    if kk < 1:
        return current, False
    _, nb = cKDTree(robot_xy).query(robot_xy, kk + 1)
    i = np.repeat(np.arange(n), kk)
    j = np.asarray(nb)[:, 1:].ravel()
    lo, hi = np.minimum(i, j), np.maximum(i, j)
    key = np.unique(lo * n + hi)
    i, j = key // n, key % n
    if locked is not None:
        free = ~locked[i] & ~locked[j]
        i, j = i[free], j[free]
    gi, gj = current[i], current[j]
    now = pair_costs(robot_xy, goal_xy, i, gi, cost) + pair_costs(robot_xy, goal_xy, j, gj, cost)
    new = pair_costs(robot_xy, goal_xy, i, gj, cost) + pair_costs(robot_xy, goal_xy, j, gi, cost)
    take = now - new > np.maximum(fraction * now, absolute)
    if fits is not None:
        take &= fits(i, gj) & fits(j, gi)
    if not take.any():
        return current, False
    i, j, gain = i[take], j[take], (now - new)[take]
    out = current.copy()
    used = np.zeros(n, bool)
    order = np.argsort(-gain, kind="stable")
    for a, b in zip(i[order].tolist(), j[order].tolist(), strict=True):
        if not (used[a] or used[b]):
            used[a] = used[b] = True
            out[a], out[b] = current[b], current[a]
    return out, True


def bottleneck_assignment(cost: np.ndarray) -> tuple[np.ndarray, float]:
    """Assignment minimizing the largest cost (for lower bounds on makespan).

    Binary search over the sorted costs for the smallest threshold admitting a perfect
    matching (scipy's Hopcroft-Karp), then a Hungarian solve on the admissible pairs.

    >>> c = np.array([[1.0, 10.0], [2.0, 3.0]])
    >>> goal_of, worst = bottleneck_assignment(c)
    >>> goal_of.tolist(), float(worst)
    ([0, 1], 3.0)
    """
    cost = np.asarray(cost, float)
    r = cost.shape[0]
    values = np.unique(cost[np.isfinite(cost)])
    lo, hi = 0, len(values) - 1

    def perfect(th: float) -> bool:
        m = maximum_bipartite_matching(csr_matrix((cost <= th).astype(np.int8)), perm_type="column")
        return bool(np.all(m >= 0))

    if len(values) == 0 or not perfect(values[hi]):
        raise AssignmentError("assignment: no finite bottleneck assignment exists")
    while lo < hi:
        mid = (lo + hi) // 2
        if perfect(values[mid]):
            hi = mid
        else:
            lo = mid + 1
    th = values[lo]
    goal_of = assign(np.where(cost <= th, cost, INFEASIBLE))
    return goal_of, float(cost[np.arange(r), goal_of].max())


def footprint_fits(
    robot_dims: Sequence[tuple[float, float]], goal_dims: Sequence[tuple[float, float]]
) -> np.ndarray:
    """``(R, G)`` bool: robot r's (length, width) fits within goal g's slot (length, width)."""
    rd = np.asarray(robot_dims, float).reshape(-1, 2)
    gd = np.asarray(goal_dims, float).reshape(-1, 2)
    tol = 1e-9
    return (rd[:, None, 0] <= gd[None, :, 0] + tol) & (rd[:, None, 1] <= gd[None, :, 1] + tol)
