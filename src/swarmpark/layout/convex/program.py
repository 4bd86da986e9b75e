"""The linear program of the convex layout in one convex piece (Hing et al. 2015, eqs. 5-11):
column arrangements, the max-min LP solved with cvxpy, and structured optimization."""

from __future__ import annotations

from dataclasses import dataclass, field

import cvxpy as cp
import numpy as np
import scipy.sparse as sp
import shapely

from swarmpark.layout.convex.pieces import ConvexPiece

__all__ = [
    "SCHEMES",
    "PieceSolution",
    "solve_piece",
    "MAX_STRUCTURED_ITERATIONS",
    "ACTIVE_TOL_M",
    "HOLD_SLACK_M",
    "SOLVER",
]

SCHEMES = ("square", "diamond")
#: Structured-optimization rounds (the paper's N_iter).
MAX_STRUCTURED_ITERATIONS = 12
#: A spacing within this of the optimum (metres) counts as active (at the bottleneck).
ACTIVE_TOL_M = 1e-5
#: Held spacings are held this much below their value, so re-solves stay strictly feasible.
HOLD_SLACK_M = 1e-9
#: Interior point: its solutions lie in the relative interior of the optimal face.
SOLVER = "CLARABEL"


@dataclass
class _Program:
    """``A z <= b`` for one piece and one column arrangement, with the spacing items.

    ``z = [x (n), y (n), R (n), s (C - 1), t]``. Each spacing item ``k`` (an alpha, beta or
    R) is the affine expression ``G[k] @ z + h[k]``.
    """

    n: int
    columns: list[list[int]]
    a_fixed: sp.csr_matrix
    b_fixed: np.ndarray
    g: sp.csr_matrix
    h: np.ndarray
    kinds: list[str]
    nvar: int


def _build(piece: ConvexPiece, half: np.ndarray, columns: list[list[int]], margin: float):
    """Rows of the LP that do not change between structured iterations."""
    n = len(half)
    ncol = len(columns)
    size = 2.0 * half
    ix, iy, ir = 0, n, 2 * n
    isep = 3 * n
    it = isep + ncol - 1
    nvar = it + 1
    rows, cols, vals, rhs = [], [], [], []
    r = 0

    # Eq. 9, one row per skid and edge: the corner farthest along the normal.
    for i in range(n):
        for a, off, w in zip(piece.normals, piece.offsets, piece.weights, strict=True):
            reach = (size[i, 0] if a[0] > 0 else 0.0) * a[0] + (
                size[i, 1] if a[1] > 0 else 0.0
            ) * a[1]
            rows += [r, r, r]
            cols += [ix + i, iy + i, ir + i]
            vals += [a[0], a[1], w]
            rhs.append(off - reach)
            r += 1
    # Separators: every skid of column c+1 starts right of s_c (the alpha rows come below).
    for c in range(ncol - 1):
        for j in columns[c + 1]:
            rows += [r, r]
            cols += [isep + c, ix + j]
            vals += [1.0, -1.0]
            rhs.append(0.0)
            r += 1
    a_fixed = sp.csr_matrix((vals, (rows, cols)), shape=(r, nvar))

    # Spacing items g_k(z) = G z + h.
    grows, gcols, gvals, h, kinds = [], [], [], [], []
    k = 0
    for c, col in enumerate(columns):
        for i in col:
            if c < ncol - 1:  # alpha_i = s_c - x_i - l_i  (eq. 5)
                grows += [k, k]
                gcols += [isep + c, ix + i]
                gvals += [1.0, -1.0]
                h.append(-size[i, 0])
                kinds.append("alpha")
                k += 1
        for i, j in zip(col[:-1], col[1:], strict=True):  # beta = y_j - y_i - w_i  (eq. 6)
            grows += [k, k]
            gcols += [iy + j, iy + i]
            gvals += [1.0, -1.0]
            h.append(-size[i, 1])
            kinds.append("beta")
            k += 1
    for i in range(n):  # R_i
        grows.append(k)
        gcols.append(ir + i)
        gvals.append(1.0)
        h.append(0.0)
        kinds.append("R")
        k += 1
    g = sp.csr_matrix((gvals, (grows, gcols)), shape=(k, nvar))
    return _Program(n, columns, a_fixed, np.asarray(rhs), g, np.asarray(h), kinds, nvar)


def _solve_lp(prog: _Program, margin: float, held: np.ndarray, hold_values: np.ndarray):
    """Maximize t subject to the fixed rows, every spacing >= margin, free spacings >= t and
    held spacings >= their held value. Returns ``(z, t)`` or ``None`` if infeasible."""
    nk = prog.g.shape[0]
    t_col = sp.csr_matrix(
        (np.ones(nk), (np.arange(nk), np.full(nk, prog.nvar - 1))), shape=(nk, prog.nvar)
    )
    free = ~held
    lower = margin
    blocks = [prog.a_fixed, -prog.g, (t_col - prog.g)[free], -prog.g[held]]
    rhs = [
        prog.b_fixed,
        prog.h - lower,
        prog.h[free],
        prog.h[held] - hold_values[held],
    ]
    a = sp.vstack(blocks).tocsr()
    b = np.concatenate(rhs)
    z = cp.Variable(prog.nvar)
    problem = cp.Problem(cp.Maximize(z[prog.nvar - 1]), [a @ z <= b])
    try:
        problem.solve(solver=SOLVER)
    except cp.error.SolverError:
        return None
    if problem.status not in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE) or z.value is None:
        return None
    zv = np.asarray(z.value, dtype=float)
    # Reject solutions that violate the rows by more than the solver's accuracy.
    if np.max(a @ zv - b) > 1e-6:
        return None
    return zv, float(zv[-1])


@dataclass
class PieceSolution:
    """Result for one piece: lower-left corners, the first and final objective, details."""

    corners: np.ndarray
    objective: float
    scheme: str
    columns: list[int]
    iterations: int
    held: int = 0
    notes: list[str] = field(default_factory=list)


def _column_plans(piece: ConvexPiece, half: np.ndarray, margin: float):
    """Candidate column arrangements ``(scheme, counts)`` for the skids of a piece."""
    n = len(half)
    x0, y0, x1, y1 = piece.polygon.bounds
    px = float(2 * half[:, 0].max() + margin)
    py = float(2 * half[:, 1].max() + margin)
    ratio = max((x1 - x0) / px, 1e-9) / max((y1 - y0) / py, 1e-9)
    c0 = float(np.sqrt(n * ratio))
    cands = sorted(
        {
            int(np.clip(c, 1, n))
            for c in (np.floor(c0) - 1, np.floor(c0), np.ceil(c0), np.ceil(c0) + 1, np.ceil(c0) + 2)
        }
    )
    plans: list[tuple[str, tuple[int, ...]]] = []
    for ncol in cands:
        base, extra = divmod(n, ncol)
        square = tuple(base + (1 if c < extra else 0) for c in range(ncol))
        plans.append(("square", square))
        # Diamond: column sizes follow the piece's height at each column's centre line.
        xs = x0 + (np.arange(ncol) + 0.5) * (x1 - x0) / ncol
        lines = shapely.linestrings(
            np.stack(
                [
                    np.column_stack([xs, np.full(ncol, y0 - 1)]),
                    np.column_stack([xs, np.full(ncol, y1 + 1)]),
                ],
                axis=1,
            )
        )
        heights = shapely.length(shapely.intersection(piece.polygon, lines))
        if n >= ncol and heights.sum() > 0:
            share = heights / heights.sum() * (n - ncol)
            counts = 1 + np.floor(share).astype(int)
            rest = n - counts.sum()
            order = np.argsort(-(share - np.floor(share)), kind="stable")
            counts[order[:rest]] += 1
            diamond = tuple(int(c) for c in counts)
            if diamond != square:
                plans.append(("diamond", diamond))
    return plans


def _columns_from_counts(order: np.ndarray, counts: tuple[int, ...]) -> list[list[int]]:
    out, k = [], 0
    for c in counts:
        out.append([int(i) for i in order[k : k + c]])
        k += c
    return out


def solve_piece(
    piece: ConvexPiece,
    half: np.ndarray,
    margin: float,
    *,
    structured: bool = True,
    max_iterations: int = MAX_STRUCTURED_ITERATIONS,
    plan: tuple[str, tuple[int, ...]] | None = None,
) -> PieceSolution | None:
    """Lay out skids with half sizes ``half`` in one convex piece; ``None`` if infeasible.

    Every candidate column arrangement is solved once; the best max-min objective wins
    (ties: the first, square before diamond, fewer columns first) and is then refined by
    structured optimization. ``plan`` = ``(scheme, column counts)`` skips the search.
    """
    n = len(half)
    if n == 0:
        return PieceSolution(np.zeros((0, 2)), np.inf, "none", [], 0)
    # Larger skids first, so each column starts with the biggest.
    order = np.argsort(-(half[:, 0] * half[:, 1]), kind="stable")
    best = None
    plans = [plan] if plan is not None else _column_plans(piece, half, margin)
    for scheme, counts in plans:
        columns = _columns_from_counts(order, counts)
        prog = _build(piece, half, columns, margin)
        held = np.zeros(prog.g.shape[0], dtype=bool)
        sol = _solve_lp(prog, margin, held, np.zeros(len(held)))
        if sol is not None and (best is None or sol[1] > best[2] + ACTIVE_TOL_M):
            best = (scheme, counts, sol[1], prog, sol[0])
    if best is None:
        return None
    scheme, counts, objective, prog, z = best
    iterations = 1
    held = np.zeros(prog.g.shape[0], dtype=bool)
    values = np.zeros(len(held))
    if structured:
        t = objective
        while iterations < max_iterations:
            g = prog.g @ z + prog.h
            active = ~held & (g <= t + ACTIVE_TOL_M)
            if not active.any():
                break
            held |= active
            values[active] = np.minimum(g[active], t) - HOLD_SLACK_M
            if held.all():
                break
            sol = _solve_lp(prog, margin, held, values)
            if sol is None:  # numerically stuck: keep the last layout
                break
            z, t = sol
            iterations += 1
    corners = np.column_stack([z[:n], z[n : 2 * n]])
    return PieceSolution(corners, objective, scheme, list(counts), iterations, int(held.sum()))
