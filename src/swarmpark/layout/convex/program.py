"""The linear programs of the convex layout (Hing et al. 2015, eqs. 4-11), solved with cvxpy,
and structured optimization.

Variables are the skids' centres ``c_i`` (layout frame), their boundary distances ``R_i``,
the separators of column graphs and the max-min value ``t``. Every row is one of:

- a *cell* row, a half-plane ``n . p + R_i w <= b`` for every corner ``p`` of skid ``i``
  (eq. 9; for an axis-aligned rectangle only the corner farthest along ``n`` matters):
  the edges of a convex piece, or the separating planes of :mod:`.refine`;
- a *gap* item ``g = a . (c_j - c_i) - (|a_x| (l_i + l_j) + |a_y| (w_i + w_j)) / 2``, the gap
  between skids ``i`` and ``j`` along the unit direction ``a``: ``a = (1, 0)`` is an H edge
  (eq. 5, ``g = alpha_ij``), ``a = (0, 1)`` a V edge (eq. 6, ``g = beta_ij``), any other
  ``a`` the linear approximation of a distance constraint (eq. 4);
- a separator item ``alpha_i = s - x_i - l_i`` and row ``s <= x_j`` (column graphs).

Every gap and every ``R_i`` is at least the margin; the objective is their minimum (eq. 11).
Structured optimization (the paper's last step) then holds the items at the bottleneck and
maximizes the rest again. Clarabel (interior point) is used: its solutions lie in the
relative interior of the optimal face, so an item equal to the optimum is one that no
optimal layout can increase.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import cvxpy as cp
import numpy as np
import scipy.sparse as sp

from swarmpark.layout.convex.graph import ConstraintGraph

__all__ = [
    "Program",
    "ProgramBuilder",
    "Solved",
    "solve_lp",
    "structured",
    "graph_program",
    "MAX_STRUCTURED_ITERATIONS",
    "ACTIVE_TOL_M",
    "HOLD_SLACK_M",
    "SOLVER",
]

#: Structured-optimization rounds (the paper's N_iter).
MAX_STRUCTURED_ITERATIONS = 12
#: A spacing within this of the optimum (metres) counts as active (at the bottleneck).
ACTIVE_TOL_M = 1e-5
#: Held spacings are held this much below their value, so re-solves stay strictly feasible.
HOLD_SLACK_M = 1e-9
#: Interior point: its solutions lie in the relative interior of the optimal face.
SOLVER = "CLARABEL"
#: Largest violation of a row (metres) accepted from the solver.
ROW_TOL_M = 1e-6


@dataclass
class Program:
    """``A z <= b`` and the spacing items ``G z + h`` of one program.

    ``z = [cx (n), cy (n), R (n), s (separators), t]``.
    """

    n: int
    half: np.ndarray
    a_fixed: sp.csr_matrix
    b_fixed: np.ndarray
    g: sp.csr_matrix
    h: np.ndarray
    kinds: list[str]
    nvar: int

    def centres(self, z: np.ndarray) -> np.ndarray:
        return np.column_stack([z[: self.n], z[self.n : 2 * self.n]])

    def add_rows(self, a: sp.csr_matrix, b: np.ndarray) -> None:
        """Append fixed rows (cutting planes)."""
        self.a_fixed = sp.vstack([self.a_fixed, a]).tocsr()
        self.b_fixed = np.concatenate([self.b_fixed, b])


class ProgramBuilder:
    """Collects the rows of a :class:`Program` (sparse triplets)."""

    def __init__(self, half: np.ndarray, separators: int = 0):
        self.half = np.asarray(half, dtype=float)
        self.n = len(self.half)
        self.isep = 3 * self.n
        self.nvar = self.isep + separators + 1
        self._rows: list[list] = [[], [], [], []]  # row, col, val, rhs
        self._items: list[list] = [[], [], [], []]  # row, col, val, h
        self.kinds: list[str] = []

    def cell_rows(self, i: np.ndarray, normals: np.ndarray, offsets: np.ndarray, weights):
        """Rows ``n . c_i + support_i(n) + w R_i <= b`` (one per entry, vectorized)."""
        i = np.asarray(i, dtype=int)
        nrm = np.asarray(normals, dtype=float).reshape(-1, 2)
        w = np.broadcast_to(np.asarray(weights, dtype=float), (len(i),))
        support = np.einsum("kd,kd->k", np.abs(nrm), self.half[i])
        rows, cols, vals, rhs = self._rows
        r0 = len(rhs)
        r = r0 + np.arange(len(i))
        rows += np.repeat(r, 3).tolist()
        cols += np.column_stack([i, self.n + i, 2 * self.n + i]).ravel().tolist()
        vals += np.column_stack([nrm[:, 0], nrm[:, 1], w]).ravel().tolist()
        rhs += (np.asarray(offsets, dtype=float) - support).tolist()

    def gap_items(self, i: np.ndarray, j: np.ndarray, a: np.ndarray, kind: str):
        """Items ``a . (c_j - c_i) - support`` (eqs. 4-6), vectorized over pairs."""
        i, j = np.asarray(i, dtype=int), np.asarray(j, dtype=int)
        a = np.asarray(a, dtype=float).reshape(-1, 2)
        rows, cols, vals, h = self._items
        k = len(h) + np.arange(len(i))
        rows += np.repeat(k, 4).tolist()
        cols += np.column_stack([j, self.n + j, i, self.n + i]).ravel().tolist()
        vals += np.column_stack([a[:, 0], a[:, 1], -a[:, 0], -a[:, 1]]).ravel().tolist()
        h += (-np.einsum("kd,kd->k", np.abs(a), self.half[i] + self.half[j])).tolist()
        self.kinds += [kind] * len(i)

    def gap_rows(self, i: np.ndarray, j: np.ndarray, a: np.ndarray, minimum: float):
        """Rows ``a . (c_j - c_i) - support >= minimum``: a gap that is kept but is not an
        item of the objective."""
        i, j = np.asarray(i, dtype=int), np.asarray(j, dtype=int)
        a = np.asarray(a, dtype=float).reshape(-1, 2)
        rows, cols, vals, rhs = self._rows
        r = len(rhs) + np.arange(len(i))
        rows += np.repeat(r, 4).tolist()
        cols += np.column_stack([j, self.n + j, i, self.n + i]).ravel().tolist()
        vals += np.column_stack([-a[:, 0], -a[:, 1], a[:, 0], a[:, 1]]).ravel().tolist()
        support = np.einsum("kd,kd->k", np.abs(a), self.half[i] + self.half[j])
        rhs += (-support - minimum).tolist()

    def separator(self, s: int, into: list[int], out: list[int]):
        """Skids ``into`` left of separator ``s`` (alpha items), ``out`` right of it."""
        rows, cols, vals, h = self._items
        for i in into:
            rows += [len(h), len(h)]
            cols += [self.isep + s, i]
            vals += [1.0, -1.0]
            h.append(-float(self.half[i, 0]))
            self.kinds.append("alpha")
        rows, cols, vals, rhs = self._rows
        for j in out:
            rows += [len(rhs), len(rhs)]
            cols += [self.isep + s, j]
            vals += [1.0, -1.0]
            rhs.append(-float(self.half[j, 0]))

    def r_items(self):
        """``R_i`` itself is a spacing item (eq. 11)."""
        rows, cols, vals, h = self._items
        k0 = len(h)
        rows += list(range(k0, k0 + self.n))
        cols += list(range(2 * self.n, 3 * self.n))
        vals += [1.0] * self.n
        h += [0.0] * self.n
        self.kinds += ["R"] * self.n

    def build(self) -> Program:
        rows, cols, vals, rhs = self._rows
        a = sp.csr_matrix((vals, (rows, cols)), shape=(len(rhs), self.nvar))
        rows, cols, vals, h = self._items
        g = sp.csr_matrix((vals, (rows, cols)), shape=(len(h), self.nvar))
        return Program(
            self.n,
            self.half,
            a,
            np.asarray(rhs, float),
            g,
            np.asarray(h, float),
            self.kinds,
            self.nvar,
        )


def graph_program(
    graph: ConstraintGraph, half: np.ndarray, cells: tuple[np.ndarray, ...]
) -> Program:
    """The program of eqs. 5, 6, 9 and 11 for a constraint graph.

    ``cells = (skid, normals, offsets, weights)``: the boundary half-planes of each skid.
    """
    b = ProgramBuilder(half, graph.separators)
    b.cell_rows(*cells)
    n = graph.n
    h = graph.h
    direct = (h[:, 0] < n) & (h[:, 1] < n)
    b.gap_items(h[direct, 0], h[direct, 1], np.tile([1.0, 0.0], (int(direct.sum()), 1)), "alpha")
    b.gap_items(graph.v[:, 0], graph.v[:, 1], np.tile([0.0, 1.0], (len(graph.v), 1)), "beta")
    for s in range(graph.separators):
        node = n + s
        b.separator(s, h[h[:, 1] == node, 0].tolist(), h[h[:, 0] == node, 1].tolist())
    b.r_items()
    return b.build()


@dataclass
class Solved:
    """A solution: ``z``, the first objective, the structured rounds and items held."""

    z: np.ndarray
    objective: float
    iterations: int = 1
    held: int = 0
    notes: list[str] = field(default_factory=list)


def solve_lp(prog: Program, margin: float, held=None, hold_values=None):
    """Maximize t subject to the fixed rows, every item >= margin, free items >= t and held
    items >= their held value. Returns ``(z, t)`` or ``None`` if infeasible."""
    nk = prog.g.shape[0]
    if held is None:
        held = np.zeros(nk, dtype=bool)
        hold_values = np.zeros(nk)
    t_col = sp.csr_matrix(
        (np.ones(nk), (np.arange(nk), np.full(nk, prog.nvar - 1))), shape=(nk, prog.nvar)
    )
    free = ~held
    a = sp.vstack([prog.a_fixed, -prog.g, (t_col - prog.g)[free], -prog.g[held]]).tocsr()
    b = np.concatenate(
        [prog.b_fixed, prog.h - margin, prog.h[free], prog.h[held] - hold_values[held]]
    )
    z = cp.Variable(prog.nvar)
    problem = cp.Problem(cp.Maximize(z[prog.nvar - 1]), [a @ z <= b])
    try:
        with warnings.catch_warnings():
            # "Solution may be inaccurate": the rows are checked below instead.
            warnings.simplefilter("ignore", UserWarning)
            problem.solve(solver=SOLVER)
    except cp.error.SolverError:
        return None
    if problem.status not in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE) or z.value is None:
        return None
    zv = np.asarray(z.value, dtype=float)
    # Reject solutions that violate the rows by more than the solver's accuracy.
    if np.max(a @ zv - b) > ROW_TOL_M:
        return None
    return zv, float(zv[-1])


def structured(
    prog: Program,
    margin: float,
    first: tuple[np.ndarray, float],
    max_iterations: int = MAX_STRUCTURED_ITERATIONS,
    solve=solve_lp,
) -> Solved:
    """Structured optimization from the max-min solution ``first = (z, t)``: hold the items
    at the bottleneck at their values and maximize the rest, until all are held."""
    z, t = first
    objective = t
    held = np.zeros(prog.g.shape[0], dtype=bool)
    values = np.zeros(len(held))
    iterations = 1
    while iterations < max_iterations:
        g = prog.g @ z + prog.h
        active = ~held & (g <= t + ACTIVE_TOL_M)
        if not active.any():
            break
        held |= active
        values[active] = np.minimum(g[active], t) - HOLD_SLACK_M
        if held.all():
            break
        sol = solve(prog, margin, held, values)
        if sol is None:  # numerically stuck: keep the last layout
            break
        z, t = sol
        iterations += 1
    return Solved(z, objective, iterations, int(held.sum()))
