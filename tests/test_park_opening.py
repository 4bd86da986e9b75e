"""Where a park's skids come in (supervisor/commands.py ``_opening``) and the room the layout
leaves there (layout ``apron_m``): through a door, the opening is at the door, not at the
boundary point nearest to the skids as the crow flies, and no spot is laid out in the
door's mouth while the skids fit elsewhere."""

import numpy as np
import shapely
from shapely.geometry import Polygon

from swarmpark.core.geometry import footprint_polygon
from swarmpark.supervisor.core import Supervisor
from swarmpark.world.build import build_world
from swarmpark.world.scenario import ParkCmd, parse_scenario

DOOR_Y = (1.0, 3.0)  # a 2 m door in the wall at x = 8-8.3, low in the wall
BOX = [[9.3, 0.5], [15.0, 0.5], [15.0, 7.5], [9.3, 7.5]]


def _supervisor():
    walls = [
        [[0, 0], [16, 0], [16, 0.2], [0, 0.2]],
        [[0, 7.8], [16, 7.8], [16, 8], [0, 8]],
        [[0, 0.2], [0.2, 0.2], [0.2, 7.8], [0, 7.8]],
        [[15.8, 0.2], [16, 0.2], [16, 7.8], [15.8, 7.8]],
        [[8.0, 0.2], [8.3, 0.2], [8.3, DOOR_Y[0]], [8.0, DOOR_Y[0]]],
        [[8.0, DOOR_Y[1]], [8.3, DOOR_Y[1]], [8.3, 7.8], [8.0, 7.8]],
    ]
    robots = [
        {"id": f"s{k}", "pose": [2.0 + 2.0 * (k % 2), 5.0 + 1.2 * (k // 2), 0.0]} for k in range(4)
    ]
    return Supervisor(
        build_world(
            parse_scenario(
                {
                    "name": "door-opening",
                    "seed": 0,
                    "dt_s": 0.05,
                    "duration_s": 10.0,
                    "map": {"size_m": [16, 8], "resolution_m": 0.05, "walls": walls},
                    "robots": robots,
                }
            )
        )
    )


def test_the_skids_come_in_at_the_door_and_its_mouth_gets_no_spot():
    sup = _supervisor()
    cmd = ParkCmd(robots=[f"s{k}" for k in range(4)], boundary=BOX, heading_deg=0)
    _, boundary, lay, _ = sup.plan_layout(cmd)
    ox, oy = lay.report["opening"]
    # The skids stand at y 5-6.2: the boundary as the crow flies is nearest at y ~5.6.
    assert ox == 9.3 and DOOR_Y[0] - 0.5 <= oy <= DOOR_Y[1] + 0.5, (ox, oy)
    assert lay.report["room_by_opening"] == "apron"
    fps = [sup.info.footprints[i] for i in range(4)]
    apron = shapely.Point(ox, oy).buffer(2.0 * max(f.reach_m for f in fps))
    spots = [footprint_polygon(p, f) for p, f in zip(lay.poses, fps, strict=True)]
    assert not any(s.intersects(apron) for s in spots)
    assert all(Polygon(BOX).contains(s) for s in spots)
    # The fill order is peeled from the door: the spot nearest to it fills last.
    last = lay.poses[lay.fill_order[-1], :2]
    near = np.hypot(*(lay.poses[:, :2] - [ox, oy]).T)
    assert np.hypot(*(last - [ox, oy])) == near.min()
