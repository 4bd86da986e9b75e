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
