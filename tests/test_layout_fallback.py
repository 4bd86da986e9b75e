"""The non-convex decagon whose convex pieces used to put a footprint within the margin of a
wall (and so fell back to stacking): the root cause, a cut keeping only half the margin
from a wall across it, is fixed; the fallback itself still works for a layout that fails
validation."""

import numpy as np
import shapely

from swarmpark.core.geometry import Footprint
from swarmpark.layout import layout

DECAGON = [
    [2.0, 0.0],
    [2.9067372651319343, 0.7422118777635688],
    [1.7551651237807455, 0.958851077208406],
    [1.6209069176044193, 2.5244129544236893],
    [0.1414744033354058, 1.994989973208109],
    [-0.8322936730942848, 1.8185948536513634],
    [-1.9799849932008908, 0.2822400161197344],
    [-1.3072872417272239, -1.5136049906158564],
    [0.5673243709264525, -1.917848549326277],
    [1.920340573300732, -0.5588309963978517],
]


def test_decagon_convex_layout_is_valid_without_fallback():
    res = layout(DECAGON, [Footprint(0.5, 1.0)] * 3, heading=0.0, margin_m=0.5, method="convex")
    assert res.method == "convex"
    assert not any("used the stacking layout" in n for n in res.report["notices"])
    assert res.report["min_boundary_clearance_m"] >= 0.5 - 1e-6
    assert res.report["min_spacing_m"] >= 0.5 - 1e-6


def test_pieces_keep_the_margin_from_walls_across_their_cuts():
    """The column plans over the triangle pieces alone: the skid next to the reflex vertex
    (1.755, 0.959) was 0.36 m from it (half the margin from the cut only); with the walls'
    cutting planes every skid keeps the 0.5 m margin."""
    from swarmpark.layout.convex import allocation
    from swarmpark.layout.convex.refine import free_segments
    from swarmpark.layout.region import make_region, make_skids

    region = make_region(DECAGON, None, 0.0, 0.5)
    skids = make_skids([Footprint(0.5, 1.0)] * 3)
    pieces, how = allocation._pieces_for(region, skids.half)
    assert how == "triangles" and len(pieces) == 3
    no_walls = np.zeros((0, 2, 2))
    for segs, ok in ((no_walls, False), (free_segments(region.free), True)):
        centres, _ = allocation._solve_pieces(region, skids, pieces, segs)
        gaps = shapely.distance(region.boxes(centres, skids.half), region.free.boundary)
        assert (gaps.min() >= 0.5 - 1e-6) == ok, gaps


def test_invalid_convex_solution_still_falls_back_to_stacking(monkeypatch):
    from swarmpark.layout import convex

    def overlapping(region, skids):  # every skid on the same spot: never valid
        return np.zeros((len(skids), 2)), {"iterations": 1, "notices": []}

    monkeypatch.setattr(convex, "solve", overlapping)
    square = [[0, 0], [4, 0], [4, 4], [0, 4]]
    res = layout(square, [Footprint(1.0, 1.0)] * 2, margin_m=0.25, method="convex")
    assert res.method == "stacking"
    assert any(
        n.startswith("convex: ") and "used the stacking layout" in n for n in res.report["notices"]
    )
