"""Parking layout: goal poses for skids inside an operator-drawn boundary.

Three methods (registered in :data:`LAYOUT_METHODS`, see :mod:`swarmpark.layout.methods`),
after Hing et al. (2015, 2018): ``"stacking"`` (2018 Algorithm 1, testing
the whole footprint), ``"potential"`` (2018 eqs. 1-4, from the stacking result) and
``"convex"`` (2015 Sect. 3.1 floor planning with cvxpy, structured optimization). Every
layout is validated (inside the free region with the margin, no two skids within the
margin) and comes with a deepest-first fill order from the opening.

>>> from swarmpark.core.geometry import Footprint
>>> res = layout([[0, 0], [6, 0], [6, 4], [0, 4]], [Footprint(1.2, 0.8)] * 4)
>>> res.poses.shape, res.report["egress_ok"]
((4, 3), True)
"""

from swarmpark.layout.api import METHODS, LayoutResult, candidate_headings, capacity, layout
from swarmpark.layout.methods import LAYOUT_METHODS, LayoutMethod
from swarmpark.layout.region import LayoutError

__all__ = [
    "METHODS",
    "LAYOUT_METHODS",
    "LayoutMethod",
    "LayoutResult",
    "LayoutError",
    "layout",
    "capacity",
    "candidate_headings",
]
