"""Convex layout of given skids (:func:`solve`) and of as many of one size as fit
(:func:`largest`): the starts (the column plans over the convex pieces, and the stacking
layouts' constraint graphs), the best of them refined by the linearized distance
constraints. For the column plans, skids are shared among the pieces in proportion to how
many fit in each and moved between pieces while that raises the smallest spacing."""

from __future__ import annotations

import numpy as np
import shapely

from swarmpark.layout import stacking
from swarmpark.layout.convex.columns import PieceSolution, solve_piece
from swarmpark.layout.convex.pieces import CUT_WEIGHT, ConvexPiece, convex_pieces
from swarmpark.layout.convex.program import ACTIVE_TOL_M, SOLVER
from swarmpark.layout.convex.refine import free_segments, refine, seeded
from swarmpark.layout.region import LayoutError, Region, Skids, describe_skids, make_skids

__all__ = ["solve", "largest", "MAX_REBALANCE_ROUNDS"]

#: Rounds of moving one skid from the tightest piece to the roomiest.
MAX_REBALANCE_ROUNDS = 8


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


def _quality(region: Region, centres: np.ndarray, half: np.ndarray) -> float:
    """Smallest gap of a layout: between two footprints or to the free region's edge."""
    boxes = region.boxes(centres, half)
    edge = shapely.distance(boxes, region.free.boundary).min()
    if len(boxes) < 2:
        return float(edge)
    tree = shapely.STRtree(boxes)
    _, dist = tree.query_nearest(boxes, exclusive=True, return_distance=True, all_matches=False)
    return float(min(edge, dist.min()))


def _seeded_candidates(region: Region, skids: Skids, segs: np.ndarray) -> list:
    """``(quality, centres, details)`` from the constraint graphs of the stacking layouts
    (column and row scan) of all the skids, where stacking fits them."""
    n = len(skids)
    out = []
    for order in stacking.SCAN_ORDERS:
        st = stacking.stack(region, skids, order=order, count=n)
        if st.fits < n:
            continue
        found = seeded(segs, st.centres, skids.half, region.margin)
        if found is None:
            continue
        centres, objective, graph = found
        details = {
            "scheme": f"stacking graph ({order})",
            "h_edges": len(graph.h),
            "v_edges": len(graph.v),
            "objective_m": objective,
        }
        out.append((_quality(region, centres, skids.half), centres, details))
    return out


def _candidates(region: Region, skids: Skids, pieces: list[ConvexPiece], segs: np.ndarray):
    """Every start for the distance program: the column plans over the pieces first (ties
    go to them), then the stacking-seeded graphs."""
    out = []
    result = _solve_pieces(region, skids, pieces, segs)
    if result is not None:
        centres, info = result
        out.append((_quality(region, centres, skids.half), centres, info))
    out += [(q, c, {"seed": d}) for q, c, d in _seeded_candidates(region, skids, segs)]
    return out


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
    segs = free_segments(region.free)
    cands = _candidates(region, skids, pieces, segs)
    if not cands:
        fits = _largest_count(region, skids, pieces, segs)
        raise LayoutError(
            f"park.boundary: only {fits} of {n} skids ({describe_skids(skids)}, margin "
            f"{region.margin:g} m) fit with method 'convex'",
            fits=fits,
        )
    centres, info = _finish(region, skids, cands, segs)
    info["decomposition"] = how
    info["notices"] = notices + info.get("notices", [])
    return centres, info


def _finish(region: Region, skids: Skids, cands: list, segs: np.ndarray):
    """The best start (largest smallest gap; ties: the first), refined by the linearized
    distance constraints (eqs. 3-4) and structured optimization."""
    k = max(range(len(cands)), key=lambda i: cands[i][0] - 1e-9 * i)
    quality, start, info = cands[k]
    info = dict(info)
    info.setdefault("pieces", [])
    info.setdefault("notices", [])
    info["start"] = "column plans" if "seed" not in info else info["seed"]["scheme"]
    info["start_min_gap_m"] = quality
    info["solver"] = SOLVER
    done = refine(segs, start, skids.half, region.margin)
    if done is not None and _quality(region, done[0], skids.half) >= quality - 1e-7:
        centres, rinfo = done[0], done[1]
        info.update(rinfo)
    else:
        centres = start
        info.setdefault("iterations", 1)
        info["notices"].append("convex: the distance program failed; kept its start")
    return centres, info


def _pieces_for(region: Region, half: np.ndarray) -> tuple[list[ConvexPiece], str]:
    """Convex pieces, choosing the decomposition that stacks the most of the largest skid."""
    big = half[np.argmax(half[:, 0] * half[:, 1])]

    def score(pieces: list[ConvexPiece]) -> float:
        total = sum(_stack_capacity(_piece_region(region, p), big) for p in pieces)
        return total - 1e-3 * len(pieces)  # ties: fewer pieces

    return convex_pieces(region.free, score)


def _initial_counts(region: Region, skids: Skids, pieces: list[ConvexPiece]):
    """``(counts, caps)``: skids per piece in proportion to capacity, and the capacities;
    ``None`` if the pieces cannot take them all."""
    n = len(skids)
    half = skids.half
    if len(pieces) == 1:
        return np.array([n]), np.array([n])
    big = half[np.argmax(half[:, 0] * half[:, 1])]
    caps = np.array([_stack_capacity(_piece_region(region, p), big) for p in pieces])
    if caps.sum() < n:
        # Stacking with the largest size is only a guide for mixed sizes: let the pieces
        # take more than it says, in proportion to area.
        areas = np.array([p.polygon.area for p in pieces])
        caps = np.maximum(
            caps, np.ceil(n * areas / sum(p.polygon.area for p in pieces)).astype(int)
        )
    counts = _allocate(n, caps)
    if counts.sum() < n:
        return None
    return counts, caps


class _Pieces:
    """The skids of one layout spread over the pieces: who goes where for given counts
    (largest skids first, in piece order) and each piece's solution."""

    def __init__(self, region: Region, skids: Skids, pieces: list[ConvexPiece], segs):
        self.region = region
        self.segs = segs
        self.half = skids.half
        self.pieces = pieces
        self.order = np.argsort(-(self.half[:, 0] * self.half[:, 1]), kind="stable")
        # A piece's solution depends only on the sizes it holds: moving skids between
        # pieces shifts who is where, mostly among equal sizes, so most re-solves repeat.
        self._cache: dict = {}

    def groups(self, counts) -> list[np.ndarray]:
        groups, k = [], 0
        for c in counts:
            groups.append(self.order[k : k + c])
            k += c
        return groups

    def solve(
        self, p: int, members: np.ndarray, *, structured: bool = False, plan=None
    ) -> PieceSolution | None:
        """Piece ``p`` holding ``members`` (the search solves without structure)."""
        key = (p, self.half[members].tobytes(), structured, plan)
        if key not in self._cache:
            self._cache[key] = solve_piece(
                self.pieces[p],
                self.half[members],
                self.region.margin,
                structured=structured,
                plan=plan,
                walls=self.segs,
            )
        return self._cache[key]


def _feasible(spread: _Pieces, counts: np.ndarray, caps: np.ndarray):
    """Move skids out of infeasible pieces (into the one with the most spare capacity) until
    every piece solves. ``(counts, solutions)`` or ``None``."""
    n = len(spread.half)
    counts = counts.copy()
    solutions: dict[int, PieceSolution | None] = {}
    for _ in range(n + len(spread.pieces)):
        groups = spread.groups(counts)
        solutions = {p: spread.solve(p, g) for p, g in enumerate(groups) if len(g)}
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
    return counts, solutions


def _rebalance(spread: _Pieces, counts: np.ndarray, caps: np.ndarray, solutions: dict):
    """Move one skid from the tightest piece to the roomiest while that raises the smallest
    max-min spacing. Returns the new ``(counts, solutions)``."""
    for _ in range(MAX_REBALANCE_ROUNDS if len(spread.pieces) > 1 else 0):
        obj = {p: s.objective for p, s in solutions.items()}
        worst = min(obj, key=lambda p: (obj[p], p))
        roomy = [p for p in range(len(spread.pieces)) if p != worst and counts[p] < caps[p]]
        if not roomy or counts[worst] <= 0:
            break
        best_p = max(roomy, key=lambda p: (obj.get(p, np.inf), -p))
        trial = counts.copy()
        trial[worst] -= 1
        trial[best_p] += 1
        groups = spread.groups(trial)
        new = {p: spread.solve(p, groups[p]) for p in (worst, best_p) if len(groups[p])}
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
    return counts, solutions


def _gather(spread: _Pieces, counts: np.ndarray, solutions: dict):
    """Centres of every skid from the pieces' solutions, and the pieces' details."""
    n = len(spread.half)
    centres = np.full((n, 2), np.nan)
    details = []
    first = np.inf
    for p, members in enumerate(spread.groups(counts)):
        if len(members) == 0:
            continue
        sol = solutions[p]
        centres[members] = sol.centres
        first = min(first, sol.objective)
        details.append(
            {
                "piece": p,
                "count": len(members),
                "scheme": sol.scheme,
                "columns": sol.columns,
                "objective_m": sol.objective,
            }
        )
    return centres, {"objective_m": first, "pieces": details, "notices": []}


def _solve_pieces(region: Region, skids: Skids, pieces: list[ConvexPiece], segs, layout=True):
    """Allocate skids to pieces and solve each (column plans, max-min); ``None`` if they
    cannot all be placed. Without ``layout`` only feasibility is decided."""
    if not pieces:
        return None
    start = _initial_counts(region, skids, pieces)
    if start is None:
        return None
    counts, caps = start
    spread = _Pieces(region, skids, pieces, segs)
    found = _feasible(spread, counts, caps)
    if found is None:
        return None
    counts, solutions = found
    if not layout:
        return np.zeros((len(skids), 2)), {}
    counts, solutions = _rebalance(spread, counts, caps, solutions)
    return _gather(spread, counts, solutions)


def _subset(skids: Skids, idx: np.ndarray) -> Skids:
    return Skids(tuple(skids.footprints[i] for i in idx), skids.half[idx], skids.offsets[idx])


def _largest_count(region: Region, skids: Skids, pieces: list[ConvexPiece], segs) -> int:
    """How many of the skids (smallest first, the largest dropped first) the convex method
    places: at least as many as stacking (its graph seeds the program), more where the
    column plans fit more."""
    order = np.argsort(-(skids.half[:, 0] * skids.half[:, 1]), kind="stable")
    lo = 0
    for scan in stacking.SCAN_ORDERS:
        st = stacking.stack(region, skids, order=scan)
        lo = max(lo, st.fits)
    hi = len(skids) - 1  # the full set is known not to fit
    while lo < hi:
        mid = (lo + hi + 1) // 2
        sub = _subset(skids, order[-mid:])
        if _solve_pieces(region, sub, pieces, segs, layout=False) is not None:
            lo = mid
        else:
            hi = mid - 1
    return lo


#: ``largest`` tries at most this many skids beyond the stacking count.
MAX_EXTRA = 4


def largest(region: Region, footprint, stacked: int) -> tuple[np.ndarray, dict]:
    """The largest convex layout of one footprint. ``stacked`` skids fit by stacking, so as
    many fit here (the stacking graph seeds the program); up to :data:`MAX_EXTRA` more are
    tried with the column plans.

    Returns the centres ``(K, 2)`` (``K`` may be 0) and details.
    """
    pieces, how = _pieces_for(region, make_skids([footprint]).half)
    segs = free_segments(region.free)
    best = None
    k = stacked
    for extra in range(MAX_EXTRA + 1):
        skids = make_skids([footprint] * (stacked + extra))
        if extra == 0:
            cands = _candidates(region, skids, pieces, segs) if stacked > 0 else []
        else:
            found = _solve_pieces(region, skids, pieces, segs)
            cands = [] if found is None else [(_quality(region, found[0], skids.half), *found)]
        if not cands:
            break
        best, k = (cands, skids), stacked + extra
    if best is None:
        return np.zeros((0, 2)), {"iterations": 0, "notices": ["convex: no skid fits"]}
    cands, skids = best
    centres, info = _finish(region, skids, cands, segs)
    info["decomposition"] = how
    info["capacity_beyond_stacking"] = k - stacked
    return centres, info
