"""Convex-optimization layout (Hing et al. 2015, Sect. 3.1): floor planning with cvxpy.

Skids are axis-aligned rectangles in the layout frame with lower-left corners ``(x_i, y_i)``.
Following Boyd & Vandenberghe 8.8.1 as the paper does, the combinatorial no-overlap
condition is replaced by relative-position graphs: skids are arranged in columns; inside a
column each skid is below the next (the vertical graph V, eq. 6:
``y_i + w_i + beta_ij <= y_j``), and every skid of a column is left of every skid of the
next (the horizontal graph H, eq. 5: ``x_i + l_i + alpha_ij <= x_j``). The H edges between
two whole columns are written through one separator variable per column gap,
``x_i + l_i + alpha_i <= s_c <= x_j``, so the problem has O(N) constraints.

Two column schemes, after the two schemes of the paper's Fig. 2: ``"square"`` (columns of
equal size: a rows x columns grid) and ``"diamond"`` (column sizes follow the width of the
region at each column, so narrow ends of a diamond, triangle or trapezoid get fewer
skids). Columns are separated by vertical lines, so this diamond is a column profile, not a
staggered lattice. Several column counts of both schemes are solved and the best kept.

The boundary is a convex polygon ``A z <= b``; every footprint corner ``p_jk`` must satisfy
``a_i^T p_jk + R_j ||a_i|| <= b_i`` (eq. 9; for an axis-aligned rectangle only the corner
farthest along ``a_i`` matters, so one row per edge and skid). The objective is the max-min
of eq. 11 over all ``alpha``, ``beta`` and ``R_j``, each also bounded below by the margin.

Structured optimization (the paper's last step): after a solve, the spacing constraints at
the optimum (the bottleneck) are held at their values and the rest are maximized again, until
all are held or an iteration cap is reached, so skids away from the bottleneck spread out
too. Clarabel (interior point) is used: its solutions lie in the relative interior of the
optimal face, so a spacing equal to the optimum is one that no optimal layout can increase.

A non-convex free region (non-convex boundary, or obstacles inside) is split into convex
pieces (constrained Delaunay triangulation, then adjacent pieces merged while their union
stays convex); skids keep ``R_j / 2`` (at least half the margin) from a cut between pieces,
so two skids on opposite sides of a cut keep the full margin. Skids are shared among the
pieces in proportion to how many fit in each, then moved between pieces while that raises
the smallest spacing.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cvxpy as cp
import numpy as np
import scipy.sparse as sp
import shapely
from shapely.geometry import Polygon

from swarmpark.layout import stacking
from swarmpark.layout.region import LayoutError, Region, Skids, describe_skids, make_skids

__all__ = [
    "SCHEMES",
    "ConvexPiece",
    "convex_pieces",
    "solve",
    "largest",
    "solve_piece",
]

SCHEMES = ("square", "diamond")
#: Structured-optimization rounds (the paper's N_iter).
MAX_STRUCTURED_ITERATIONS = 12
#: A spacing within this of the optimum (metres) counts as active (at the bottleneck).
ACTIVE_TOL_M = 1e-5
#: Held spacings are held this much below their value, so re-solves stay strictly feasible.
HOLD_SLACK_M = 1e-9
#: Weight of a cut between convex pieces in the boundary-distance rows: a skid keeps
#: ``R_j * weight`` from a cut, the skid on the other side as much.
CUT_WEIGHT = 0.5
#: Free regions with more vertices than this (map staircases) are simplified first, by
#: eroding by ``SIMPLIFY_TOL_M`` and simplifying with the same tolerance (stays inside).
SIMPLIFY_ABOVE_VERTICES = 120
SIMPLIFY_TOL_M = 0.05
#: Pieces thinner than this (inradius, metres) hold nothing useful and are dropped.
MIN_PIECE_INRADIUS_M = 1e-3
#: Rounds of moving one skid from the tightest piece to the roomiest.
MAX_REBALANCE_ROUNDS = 8
_SOLVER = "CLARABEL"


@dataclass(frozen=True, eq=False)
class ConvexPiece:
    """A convex piece of the free region, as ``normals @ z <= offsets``.

    Attributes
    ----------
    polygon
        The piece (counter-clockwise), layout frame.
    normals
        ``(E, 2)`` unit outward edge normals.
    offsets
        ``(E,)`` so that the piece is ``normals @ z <= offsets``.
    weights
        ``(E,)`` 1 for an edge on the free region's edge (boundary, wall, obstacle),
        :data:`CUT_WEIGHT` for a cut between pieces.
    """

    polygon: Polygon
    normals: np.ndarray
    offsets: np.ndarray
    weights: np.ndarray

    @property
    def is_whole(self) -> bool:
        return bool(np.all(self.weights == 1.0))


def _is_convex(poly: Polygon) -> bool:
    return len(poly.interiors) == 0 and poly.area >= poly.convex_hull.area * (1.0 - 1e-9)


def _merge_convex(polys: list[Polygon]) -> list[Polygon]:
    """Merge adjacent convex polygons while their union stays convex, across the longest
    shared edges first (Hertel-Mehlhorn style)."""
    polys = [p for p in polys if p.area > 0]
    tree = shapely.STRtree(polys)
    left, right = tree.query(polys, predicate="touches")
    keep = left < right
    left, right = left[keep], right[keep]
    shared = (
        shapely.length(
            shapely.intersection(
                shapely.boundary(np.take(polys, left)), shapely.boundary(np.take(polys, right))
            )
        )
        if len(left)
        else np.zeros(0)
    )
    order = sorted(range(len(left)), key=lambda k: (-round(float(shared[k]), 9), left[k], right[k]))
    parent = list(range(len(polys)))
    merged: dict[int, Polygon] = dict(enumerate(polys))

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for k in order:
        if shared[k] <= 1e-9:
            continue
        ri, rj = find(int(left[k])), find(int(right[k]))
        if ri == rj:
            continue
        union = shapely.union(merged[ri], merged[rj])
        if union.geom_type == "Polygon" and _is_convex(union):
            merged[ri] = union
            parent[rj] = ri
            del merged[rj]
    return [merged[k] for k in sorted(merged)]


def _triangles(part: Polygon) -> list[Polygon]:
    """Constrained Delaunay triangles of a polygon (holes respected)."""
    return [
        t for t in shapely.get_parts(shapely.constrained_delaunay_triangles(part)) if t.area > 0
    ]


def _strips(part: Polygon, axis: int) -> list[Polygon]:
    """Slabs between consecutive vertex coordinates along ``axis``: every component of the
    polygon in a slab with no vertex strictly inside is a trapezoid (convex)."""
    xs = np.unique(np.round(shapely.get_coordinates(part.boundary)[:, axis], 9))
    x0, y0, x1, y1 = part.bounds
    out = []
    for lo, hi in zip(xs[:-1], xs[1:], strict=True):
        if hi - lo < 1e-9:
            continue
        slab = (
            shapely.box(lo, y0 - 1, hi, y1 + 1)
            if axis == 0
            else shapely.box(x0 - 1, lo, x1 + 1, hi)
        )
        for g in shapely.get_parts(part.intersection(slab)):
            if g.geom_type != "Polygon" or g.area <= 1e-12:
                continue
            out.extend([g] if _is_convex(g) else _triangles(g))
    return out


#: Ways to split a non-convex polygon into convex pieces, tried in turn.
DECOMPOSITIONS = ("vertical strips", "horizontal strips", "triangles")


def _make_piece(poly: Polygon, edge_band) -> ConvexPiece | None:
    """A :class:`ConvexPiece` with cut edges marked (``edge_band``: a thin band around the
    free region's boundary)."""
    pts = np.asarray(poly.simplify(0.0).exterior.coords)
    if _signed_area(pts) < 0:
        pts = pts[::-1]
    d = np.diff(pts, axis=0)
    length = np.hypot(d[:, 0], d[:, 1])
    keep = length > 1e-12
    normals = np.column_stack([d[keep, 1], -d[keep, 0]]) / length[keep, None]
    offsets = np.einsum("ij,ij->i", normals, pts[:-1][keep])
    # An edge is a cut only if no stretch of it lies on the free region's edge: the rows are
    # whole lines, so a line that is partly wall must keep the full distance.
    # Tested with a 0.1 um tolerance band: pieces' vertices are computed, not exact. Errors
    # go the safe way (a cut taken for a wall keeps the full distance).
    segs = shapely.linestrings(np.stack([pts[:-1][keep], pts[1:][keep]], axis=1))
    on_edge = shapely.length(shapely.intersection(segs, edge_band)) > 1e-6
    weights = np.where(on_edge, 1.0, CUT_WEIGHT)
    piece = ConvexPiece(Polygon(pts), normals, offsets, weights)
    return piece if _inradius(piece) > MIN_PIECE_INRADIUS_M else None


def convex_pieces(free, score=None) -> tuple[list[ConvexPiece], str]:
    """Split the free region (layout frame) into convex pieces with marked cuts.

    A convex region is one piece. Otherwise every decomposition in :data:`DECOMPOSITIONS`
    is made and the one with the highest ``score(pieces)`` (default: fewest pieces) is
    kept; ties go to the first. Returns the pieces and the decomposition's name.
    """
    if shapely.get_coordinates(free.boundary).shape[0] > SIMPLIFY_ABOVE_VERTICES:
        free = free.buffer(-SIMPLIFY_TOL_M, join_style="mitre").simplify(SIMPLIFY_TOL_M)
    edge = free.boundary.buffer(1e-7)
    shapely.prepare(edge)
    parts = [p for p in shapely.get_parts(free) if not p.is_empty and p.area > 0]
    if all(_is_convex(p) for p in parts):
        pieces = [_make_piece(p, edge) for p in parts]
        return [p for p in pieces if p is not None], "none"
    best: tuple[float, list[ConvexPiece], str] | None = None
    for name in DECOMPOSITIONS:
        polys: list[Polygon] = []
        for part in parts:
            if _is_convex(part):
                polys.append(part)
            elif name == "triangles":
                polys.extend(_merge_convex(_triangles(part)))
            else:
                polys.extend(_merge_convex(_strips(part, 0 if name.startswith("v") else 1)))
        pieces = [p for p in (_make_piece(q, edge) for q in polys) if p is not None]
        value = score(pieces) if score is not None else -len(pieces)
        if best is None or value > best[0]:
            best = (value, pieces, name)
    assert best is not None
    return best[1], best[2]


def _signed_area(pts: np.ndarray) -> float:
    x, y = pts[:, 0], pts[:, 1]
    return 0.5 * float(np.dot(x[:-1], y[1:]) - np.dot(x[1:], y[:-1]))


def _inradius(piece: ConvexPiece) -> float:
    """Radius of the largest disc in the piece (eq. 7), from its vertices (cheap bound)."""
    c = np.asarray(piece.polygon.representative_point().coords[0])
    return float(np.min(piece.offsets - piece.normals @ c))


# --- the linear program ------------------------------------------------------------------


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
        problem.solve(solver=_SOLVER)
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


# --- pieces, allocation, entry points ------------------------------------------------------


def _piece_region(region: Region, piece: ConvexPiece) -> Region:
    """A :class:`Region` for stacking inside one piece (keeps half the margin from cuts)."""
    inner = piece.polygon.buffer(-region.margin * CUT_WEIGHT, join_style="mitre")
    inner = inner.intersection(region.inner)
    shapely.prepare(inner)
    return Region(
        region.heading,
        piece.polygon,
        piece.polygon,
        shapely.Polygon(),
        region.margin,
        inner,
        region.margin * CUT_WEIGHT,
    )


def _stack_capacity(region: Region, footprint_half: np.ndarray) -> int:
    from swarmpark.core.geometry import Footprint

    fp = Footprint(2 * float(footprint_half[0]), 2 * float(footprint_half[1]))
    upper = int(region.free.area / (4 * footprint_half[0] * footprint_half[1])) + 1
    return stacking.stack(region, make_skids([fp] * upper)).fits


def _allocate(n: int, caps: np.ndarray) -> np.ndarray:
    """Share ``n`` skids among pieces in proportion to capacity (largest remainder)."""
    caps = np.asarray(caps, dtype=float)
    if caps.sum() <= 0:
        return np.zeros(len(caps), dtype=int)
    share = np.minimum(n * caps / caps.sum(), caps)
    counts = np.floor(share).astype(int)
    order = np.argsort(-(share - counts), kind="stable")
    k = 0
    while counts.sum() < min(n, int(caps.sum())) and k < 10 * len(caps) + n:
        i = order[k % len(order)]
        if counts[i] < caps[i]:
            counts[i] += 1
        k += 1
    return counts


def solve(region: Region, skids: Skids) -> tuple[np.ndarray, dict]:
    """Layout-frame centres ``(N, 2)`` by convex optimization, and details.

    Raises
    ------
    LayoutError
        The skids do not fit (``fits`` is how many do with this method).
    """
    n = len(skids)
    pieces, how = _pieces_for(region, skids.half)
    notices: list[str] = []
    if how != "none":
        notices.append(
            f"convex: the free region is not convex; it was split into {len(pieces)} convex "
            f"pieces by {how} (skids keep at least half the margin from each cut)"
        )
    result = _solve_pieces(region, skids, pieces)
    if result is None:
        fits = _largest_count(region, skids, pieces)
        raise LayoutError(
            f"park.boundary: only {fits} of {n} skids ({describe_skids(skids)}, margin "
            f"{region.margin:g} m) fit with method 'convex'",
            fits=fits,
        )
    centres, info = result
    info["decomposition"] = how
    info["notices"] = notices + info.get("notices", [])
    return centres, info


def _pieces_for(region: Region, half: np.ndarray) -> tuple[list[ConvexPiece], str]:
    """Convex pieces, choosing the decomposition that stacks the most of the largest skid."""
    big = half[np.argmax(half[:, 0] * half[:, 1])]

    def score(pieces: list[ConvexPiece]) -> float:
        total = sum(_stack_capacity(_piece_region(region, p), big) for p in pieces)
        return total - 1e-3 * len(pieces)  # ties: fewer pieces

    return convex_pieces(region.free, score)


def _solve_pieces(region: Region, skids: Skids, pieces: list[ConvexPiece], structured=True):
    """Allocate skids to pieces and solve each; ``None`` if they cannot all be placed."""
    n = len(skids)
    half = skids.half
    if not pieces:
        return None
    big = half[np.argmax(half[:, 0] * half[:, 1])]
    if len(pieces) == 1:
        counts = np.array([n])
        caps = np.array([n])
    else:
        caps = np.array([_stack_capacity(_piece_region(region, p), big) for p in pieces])
        if caps.sum() < n:
            # Stacking with the largest size is only a guide for mixed sizes: let the pieces
            # take more than it says, in proportion to area.
            caps = np.maximum(
                caps,
                np.ceil(
                    n
                    * np.array([p.polygon.area for p in pieces])
                    / sum(p.polygon.area for p in pieces)
                ).astype(int),
            )
        counts = _allocate(n, caps)
        if counts.sum() < n:
            return None
    # Skids go to pieces largest first, in piece order.
    order = np.argsort(-(half[:, 0] * half[:, 1]), kind="stable")

    def assign(counts):
        groups, k = [], 0
        for c in counts:
            groups.append(order[k : k + c])
            k += c
        return groups

    solutions: dict[int, PieceSolution | None] = {}

    def piece_solution(p: int, members: np.ndarray, structured: bool) -> PieceSolution | None:
        return solve_piece(pieces[p], half[members], region.margin, structured=structured)

    # Find a feasible allocation (move skids out of infeasible pieces) without structure.
    counts = counts.copy()
    for _ in range(n + len(pieces)):
        groups = assign(counts)
        solutions = {p: piece_solution(p, g, False) for p, g in enumerate(groups) if len(g)}
        bad = [p for p, s in solutions.items() if s is None]
        if not bad:
            break
        spare = caps - counts
        p_bad = bad[0]
        cand = [q for q in np.argsort(-spare, kind="stable") if q != p_bad and spare[q] > 0]
        if not cand:
            return None
        counts[p_bad] -= 1
        counts[cand[0]] += 1
    else:
        return None
    if any(s is None for s in solutions.values()):
        return None

    # Rebalance: move one skid from the tightest piece to the roomiest while it helps.
    for _ in range(MAX_REBALANCE_ROUNDS if len(pieces) > 1 else 0):
        obj = {p: s.objective for p, s in solutions.items()}
        worst = min(obj, key=lambda p: (obj[p], p))
        roomy = [p for p in range(len(pieces)) if p != worst and counts[p] < caps[p]]
        if not roomy or counts[worst] <= 0:
            break
        best_p = max(roomy, key=lambda p: (obj.get(p, np.inf), -p))
        trial = counts.copy()
        trial[worst] -= 1
        trial[best_p] += 1
        groups = assign(trial)
        new = {p: piece_solution(p, groups[p], False) for p in (worst, best_p) if len(groups[p])}
        if any(s is None for s in new.values()):
            break
        new_obj = dict(obj)
        new_obj.pop(worst, None)
        new_obj.update({p: s.objective for p, s in new.items()})
        if min(new_obj.values()) <= min(obj.values()) + ACTIVE_TOL_M:
            break
        counts = trial
        solutions = {p: s for p, s in solutions.items() if p not in (worst, best_p)}
        solutions.update(new)

    if not structured:
        return np.zeros((n, 2)), {}
    # Final: structured optimization in every piece.
    groups = assign(counts)
    centres = np.full((n, 2), np.nan)
    details = []
    iterations = 0
    first = np.inf
    for p, members in enumerate(groups):
        if len(members) == 0:
            continue
        prev = solutions.get(p)
        plan = (
            (prev.scheme, tuple(prev.columns))
            if prev is not None and len(prev.columns) and sum(prev.columns) == len(members)
            else None
        )
        sol = solve_piece(pieces[p], half[members], region.margin, structured=True, plan=plan)
        if sol is None:
            return None
        centres[members] = sol.corners + half[members]
        iterations = max(iterations, sol.iterations)
        first = min(first, sol.objective)
        details.append(
            {
                "piece": p,
                "count": len(members),
                "scheme": sol.scheme,
                "columns": sol.columns,
                "objective_m": sol.objective,
                "structured_iterations": sol.iterations,
                "held": sol.held,
            }
        )
    info = {
        "iterations": iterations,
        "objective_m": first,
        "pieces": details,
        "solver": _SOLVER,
        "notices": [],
    }
    return centres, info


def _largest_count(region: Region, skids: Skids, pieces: list[ConvexPiece]) -> int:
    """How many of the skids (largest first dropped last) the convex method can place."""
    order = np.argsort(-(skids.half[:, 0] * skids.half[:, 1]), kind="stable")
    lo, hi = 0, len(skids) - 1  # the full set is known not to fit
    while lo < hi:
        mid = (lo + hi + 1) // 2
        sub = Skids(
            tuple(skids.footprints[i] for i in order[-mid:]),
            skids.half[order[-mid:]],
            skids.offsets[order[-mid:]],
        )
        if _solve_pieces_feasible(region, sub, pieces):
            lo = mid
        else:
            hi = mid - 1
    return lo


def _solve_pieces_feasible(region: Region, skids: Skids, pieces: list[ConvexPiece]) -> bool:
    return _solve_pieces(region, skids, pieces, structured=False) is not None


def largest(region: Region, footprint, upper: int) -> tuple[np.ndarray, dict]:
    """The largest convex layout of one footprint, trying at most ``upper`` skids.

    Returns the centres ``(K, 2)`` (``K`` may be 0) and details.
    """
    pieces, _ = _pieces_for(region, make_skids([footprint]).half)
    lo, hi = 0, upper
    best = None
    while lo < hi:
        mid = (lo + hi + 1) // 2
        res = _solve_pieces(region, make_skids([footprint] * mid), pieces)
        if res is not None:
            lo, best = mid, res
        else:
            hi = mid - 1
    if best is None:
        return np.zeros((0, 2)), {"iterations": 0, "notices": ["convex: no skid fits"]}
    return best
