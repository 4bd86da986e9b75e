"""Relative-position constraint graphs of the convex layout (Hing et al. 2015, Sect. 3.1,
after Boyd & Vandenberghe 8.8.1): a horizontal graph H and a vertical graph V over the skids.

An edge ``(i, j)`` of H says skid ``i`` is left of skid ``j`` (eq. 5:
``x_i + l_i + alpha_ij <= x_j``), an edge of V that ``i`` is below ``j`` (eq. 6:
``y_i + w_i + beta_ij <= y_j``). The floor plan has no overlap when every pair of skids is
joined by a directed path in H or in V: along the path the gaps add up, so the pair is at
least one gap (``>= margin``) apart on that axis.

Graphs come from two places:

- :func:`from_columns`: a column arrangement (the ``square`` and ``diamond`` schemes). Every
  skid of column ``c`` is left of every skid of column ``c + 1``; to keep O(N) edges the
  complete bipartite H block between two columns goes through one zero-size *separator*
  node per column gap (``i -> s_c -> j``).
- :func:`from_arrangement`: any valid arrangement, e.g. the stacking layout. Each pair that
  is apart on x by at least the margin gets an H relation, every other pair (apart on y) a V
  relation; both relations are then transitively reduced (an edge implied by a path is
  dropped). The arrangement itself satisfies every edge with ``alpha, beta >= margin``, so a
  program built on this graph is feasible wherever the arrangement is: seeded with the
  stacking layout, convex places at least as many skids as stacking.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "ConstraintGraph",
    "from_columns",
    "from_arrangement",
    "from_relations",
    "axis_relations",
    "transitive_reduction",
]

#: Slack (metres) when reading which axis separates two skids of an arrangement: stacking
#: keeps its gaps to 1e-9 m.
SEPARATION_TOL_M = 1e-7


@dataclass(frozen=True)
class ConstraintGraph:
    """H and V graphs over ``n`` skids and ``separators`` zero-size separator nodes.

    Nodes ``0 .. n-1`` are skids, ``n .. n + separators - 1`` separators (H only). An edge
    into a separator carries the gap ``alpha`` of its skid; an edge out of one is a plain
    ``x_s <= x_j``.

    Attributes
    ----------
    n
        Number of skids.
    h
        ``(E_h, 2)`` int edges ``(i, j)``: ``i`` left of ``j``.
    v
        ``(E_v, 2)`` int edges ``(i, j)``: ``i`` below ``j`` (skids only).
    separators
        Number of separator nodes.
    name
        Where the graph came from (``"square"``, ``"diamond"``, ``"stacking"``...).
    """

    n: int
    h: np.ndarray
    v: np.ndarray
    separators: int = 0
    name: str = ""

    def reach(self) -> tuple[np.ndarray, np.ndarray]:
        """Boolean ``(n, n)`` reachability between skids in H and in V (strict paths)."""
        m = self.n + self.separators
        return _closure(_adjacency(self.h, m))[: self.n, : self.n], _closure(_adjacency(self.v, m))[
            : self.n, : self.n
        ]

    def covers_all_pairs(self) -> bool:
        """True if every pair of skids is joined by a directed path in H or in V."""
        rh, rv = self.reach()
        joined = rh | rh.T | rv | rv.T
        np.fill_diagonal(joined, True)
        return bool(joined.all())


def _adjacency(edges: np.ndarray, m: int) -> np.ndarray:
    a = np.zeros((m, m), dtype=bool)
    if len(edges):
        a[edges[:, 0], edges[:, 1]] = True
    return a


def _closure(a: np.ndarray) -> np.ndarray:
    """Transitive closure of a DAG's adjacency (repeated squaring, boolean)."""
    r = a.copy()
    while True:
        nxt = r | ((r.astype(np.int32) @ r.astype(np.int32)) > 0)
        if (nxt == r).all():
            return r
        r = nxt


def transitive_reduction(a: np.ndarray) -> np.ndarray:
    """Edges ``(E, 2)`` of the transitive reduction of the DAG with adjacency ``a``.

    >>> a = np.array([[0, 1, 1], [0, 0, 1], [0, 0, 0]], dtype=bool)
    >>> transitive_reduction(a).tolist()
    [[0, 1], [1, 2]]
    """
    r = _closure(a)
    implied = (r.astype(np.int32) @ r.astype(np.int32)) > 0  # a path of two or more steps
    keep = r & ~implied
    return np.argwhere(keep)


def from_columns(columns: list[list[int]], name: str) -> ConstraintGraph:
    """The graph of a column arrangement: V chains inside each column (in the given order,
    bottom to top), H through one separator per column gap."""
    n = sum(len(c) for c in columns)
    h, v = [], []
    for c, col in enumerate(columns):
        v += [(i, j) for i, j in zip(col[:-1], col[1:], strict=True)]
        if c + 1 < len(columns):
            s = n + c
            h += [(i, s) for i in col]
            h += [(s, j) for j in columns[c + 1]]
    return ConstraintGraph(
        n,
        np.asarray(h, dtype=int).reshape(-1, 2),
        np.asarray(v, dtype=int).reshape(-1, 2),
        max(len(columns) - 1, 0),
        name,
    )


def axis_relations(centres: np.ndarray, half: np.ndarray, margin: float):
    """``(left, below)``, boolean ``(n, n)``: ``left[i, j]`` if skid ``i`` is left of ``j``
    by at least the margin, ``below[i, j]`` likewise on y (both can hold)."""
    c = np.asarray(centres, dtype=float)
    hs = np.asarray(half, dtype=float)
    dx = c[None, :, 0] - c[:, None, 0]  # dx[i, j] = x_j - x_i
    dy = c[None, :, 1] - c[:, None, 1]
    need_x = hs[:, None, 0] + hs[None, :, 0] + margin - SEPARATION_TOL_M
    need_y = hs[:, None, 1] + hs[None, :, 1] + margin - SEPARATION_TOL_M
    return dx >= need_x, dy >= need_y


def from_relations(left: np.ndarray, below: np.ndarray, name: str) -> ConstraintGraph:
    """H from ``left`` and V from ``below`` minus the pairs already in H, both
    transitively reduced."""
    below = below & ~(left | left.T)
    return ConstraintGraph(
        len(left), transitive_reduction(left), transitive_reduction(below), 0, name
    )


def from_arrangement(
    centres: np.ndarray, half: np.ndarray, margin: float, name: str = "arrangement"
) -> ConstraintGraph:
    """The H and V graphs of a valid arrangement of axis-aligned skids.

    Parameters
    ----------
    centres, half
        ``(n, 2)`` centres and half sizes (layout frame).
    margin
        Every pair must be apart by at least this on x or on y (stacking guarantees it).

    Raises
    ------
    ValueError
        Two skids are closer than ``margin`` on both axes (the arrangement overlaps).
    """
    left, below = axis_relations(centres, half, margin)
    joined = left | left.T | below | below.T
    np.fill_diagonal(joined, True)
    if not joined.all():
        i, j = np.argwhere(~joined)[0]
        raise ValueError(
            f"from_arrangement: skids {int(i)} and {int(j)} are closer than the margin "
            f"{margin:g} m on both axes"
        )
    return from_relations(left, below, name)
