"""A convex layout that fails validation falls back to stacking, with a notice (regression:
a non-convex decagon where the convex pieces put a footprint outside the margin)."""

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


def test_invalid_convex_solution_falls_back_to_stacking():
    res = layout(DECAGON, [Footprint(0.5, 1.0)] * 3, heading=0.0, margin_m=0.5, method="convex")
    assert res.method == "stacking"
    assert any(
        n.startswith("convex: ") and "used the stacking layout" in n for n in res.report["notices"]
    )
    assert res.report["min_boundary_clearance_m"] >= 0.5 - 1e-6
    assert res.report["min_spacing_m"] >= 0.5 - 1e-6
