"""Convex-optimization layout (Hing et al. 2015, Sect. 3.1): floor planning with cvxpy.

Skids are axis-aligned rectangles in the layout frame. Following Boyd & Vandenberghe 8.8.1
as the paper does, the combinatorial no-overlap condition is replaced by relative-position
graphs H and V (:mod:`.graph`; eqs. 5-6): every pair of skids is joined by a path in one of
them. Graphs come from column plans (``square`` and ``diamond``, after the paper's Fig. 2,
:mod:`.columns`) and from the stacking layout of the same skids, which seeds the program so
that convex fits at least as many skids as stacking (:mod:`.refine`).

The boundary is ``A z <= b`` (eq. 9) for a convex piece, or per-skid convex cells of
separating planes around an arrangement. The objective is the max-min of eq. 11 over every
gap and ``R_j``, each also bounded below by the margin. The best start is then refined with
the distance constraints linearized as in eq. 4 (:func:`.refine.refine`), re-linearized
while the spacing grows, and finished by structured optimization (:mod:`.program`).

Column plans in a non-convex region work in convex pieces (:mod:`.pieces`); skids keep
``R_j / 2`` from a cut and ``R_j`` from every wall, including walls across a cut (cutting
planes, :func:`.columns.wall_cuts`). Skids are shared among the pieces in proportion to how
many fit in each, then moved between pieces while that raises the smallest spacing
(:mod:`.allocation`).
"""

from swarmpark.layout.convex.allocation import MAX_REBALANCE_ROUNDS, largest, solve
from swarmpark.layout.convex.columns import SCHEMES, PieceSolution, solve_piece
from swarmpark.layout.convex.graph import ConstraintGraph, from_arrangement, from_columns
from swarmpark.layout.convex.pieces import (
    CUT_WEIGHT,
    DECOMPOSITIONS,
    MIN_PIECE_INRADIUS_M,
    SIMPLIFY_ABOVE_VERTICES,
    SIMPLIFY_TOL_M,
    ConvexPiece,
    convex_pieces,
)
from swarmpark.layout.convex.program import (
    ACTIVE_TOL_M,
    HOLD_SLACK_M,
    MAX_STRUCTURED_ITERATIONS,
)
from swarmpark.layout.convex.refine import (
    DistanceConstraints,
    cells_around,
    distance_constraints,
    free_segments,
    refine,
    seeded,
)

__all__ = [
    "SCHEMES",
    "ConvexPiece",
    "PieceSolution",
    "ConstraintGraph",
    "DistanceConstraints",
    "convex_pieces",
    "from_arrangement",
    "from_columns",
    "free_segments",
    "cells_around",
    "distance_constraints",
    "seeded",
    "refine",
    "solve",
    "largest",
    "solve_piece",
    "CUT_WEIGHT",
    "DECOMPOSITIONS",
    "ACTIVE_TOL_M",
    "HOLD_SLACK_M",
    "MAX_STRUCTURED_ITERATIONS",
    "MAX_REBALANCE_ROUNDS",
    "MIN_PIECE_INRADIUS_M",
    "SIMPLIFY_ABOVE_VERTICES",
    "SIMPLIFY_TOL_M",
]
