"""With onboard sensing a park is laid out on the map the skids know (supervisor/known_map.py):
the prior map plus what the scans detected and what lies unseen behind it, never the
scenario's obstacles. A crate the scans saw before the park gets no spot; one no scan saw is
not known, and the group is laid out again when the skids find it (supervisor/spot_watch.py)."""

import numpy as np
import pytest
from helpers import assert_goto_refused
from shapely.geometry import Polygon

from swarmpark.core.geometry import body_corners, footprint_corners
from swarmpark.core.gridmap import OccupancyGrid
from swarmpark.sense.lidar import LidarSpec, scan
from swarmpark.sense.shadow import shadowed_cells
from swarmpark.supervisor.core import Supervisor
from swarmpark.supervisor.known_map import OperatorMap, SensedMap
from swarmpark.supervisor.spot_watch import blocked_goals
from swarmpark.world.build import build_world
from swarmpark.world.scenario import ParkCmd, parse_scenario

# Each where the layout puts a spot while it does not know the crate (the aprons it keeps
# free by the opening, in front of the skids, hold no spot).
SEEN = [[4.7, 1.0], [5.7, 1.0], [5.7, 2.4], [4.7, 2.4]]  # 3.3 m ahead of the skids
UNSEEN = [[11.7, 1.0], [12.7, 1.0], [12.7, 2.4], [11.7, 2.4]]  # 10 m away, beyond the 5 m LIDAR
NEAR_BOX = [[4.0, 1.0], [8.0, 1.0], [8.0, 7.0], [4.0, 7.0]]
FAR_BOX = [[11.0, 1.0], [15.0, 1.0], [15.0, 7.0], [11.0, 7.0]]


def _scenario(localization="amcl", park_at=1.0, boundary=NEAR_BOX, duration=90.0):
    return parse_scenario(
        {
            "name": "sensed-layout",
            "seed": 0,
            "dt_s": 0.05,
            "duration_s": duration,
            "map": {
                "size_m": [16, 8],
                "resolution_m": 0.05,
                "walls": [
                    [[0, 0], [16, 0], [16, 0.2], [0, 0.2]],
                    [[0, 7.8], [16, 7.8], [16, 8], [0, 8]],
                    [[0, 0.2], [0.2, 0.2], [0.2, 7.8], [0, 7.8]],
                    [[15.8, 0.2], [16, 0.2], [16, 7.8], [15.8, 7.8]],
                ],
            },
            "robots": [
                {"id": "a1", "pose": [1.5, 3.0, 0.0]},
                {"id": "a2", "pose": [1.5, 4.5, 0.0]},
            ],
            "obstacles": [{"polygon": SEEN}, {"polygon": UNSEEN}],
            "commands": [{"at_s": park_at, "park": {"robots": ["a1", "a2"], "boundary": boundary}}],
            "sensing": {"localization": localization},
        }
    )


def _on(goals, sup, crate) -> list[bool]:
    """Per goal: does the footprint laid out there overlap ``crate``?"""
    goals = np.asarray(goals, float)
    corners = footprint_corners(goals, body_corners(list(sup.info.footprints[: len(goals)])))
    return [Polygon(c).intersects(Polygon(crate)) for c in corners]


def _run_until(sup, t):
    while sup.t < t - 1e-9:
        sup.tick()


def test_a_crate_the_scans_saw_before_the_park_gets_no_spot():
    sup = Supervisor(build_world(_scenario()))
    assert isinstance(sup.park_map, SensedMap)
    # Before any scan the skids know only the map: the same park puts a spot on the crate.
    _, _, lay, _ = sup.plan_layout(ParkCmd(robots=["a1", "a2"], boundary=NEAR_BOX))
    assert any(_on(lay.poses, sup, SEEN))
    _run_until(sup, 1.0 + 1e-6)  # the park at 1 s ran, after 20 scans
    out = sup.outcomes[-1]
    assert out.command == "park" and out.accepted, out
    assert not any(_on(out.detail["goals"], sup, SEEN))
    # The check of the spots runs on the same knowledge: the crate's face is in its grid.
    grid = sup.park_map.grid()
    face = grid.world_to_cell(np.array([[4.72, 1.7]]))[0]
    assert grid.occupied[face[0], face[1]]


def test_a_crate_no_scan_saw_is_not_known_to_the_layout():
    sup = Supervisor(build_world(_scenario()))
    _run_until(sup, 1.0)
    region = Polygon(FAR_BOX)
    solids = sup.park_map.solids(region)
    assert solids is None or not solids.intersects(Polygon(UNSEEN).buffer(-0.05))
    _, _, lay, _ = sup.plan_layout(ParkCmd(robots=["a1", "a2"], boundary=FAR_BOX))
    assert any(_on(lay.poses, sup, UNSEEN))
    grid = sup.park_map.grid()
    inside = grid.world_to_cell(np.array([[12.2, 1.7]]))[0]
    assert not grid.occupied[inside[0], inside[1]]
    # Without sensing the operator knows the scenario's obstacles, as before.
    truth = Supervisor(build_world(_scenario("truth")))
    assert isinstance(truth.park_map, OperatorMap)
    assert truth.park_map.solids(region).contains(Polygon(UNSEEN).buffer(-0.05))


def test_the_shadow_covers_a_crate_behind_its_face_and_no_more():
    g = OccupancyGrid(np.zeros((80, 160), bool), 0.05)  # 8 x 4 m, no walls
    spec = LidarSpec(num_beams=1000)
    pose = np.array([[0.5, 2.0, 0.0]])
    crate = np.array([[[3.0, 1.5], [4.0, 1.5], [4.0, 2.5], [3.0, 2.5]]])
    sh = shadowed_cells(g, spec, pose, scan(spec, pose, g, polygons=crate))

    def at(x, y):
        r, c = g.world_to_cell(np.array([[x, y]]))[0]
        return bool(sh[r, c])

    assert at(3.5, 2.0) and at(3.9, 1.7)  # inside the crate
    assert not at(2.5, 2.0) and not at(3.5, 3.2) and not at(6.0, 2.0)  # before, beside, past 1.5 m
    # A second scanner that sees the space behind from the side clears what it sees free.
    two = np.array([[0.5, 2.0, 0.0], [5.0, 3.6, -np.pi / 2]])
    sh2 = shadowed_cells(g, spec, two, scan(spec, two, g, polygons=crate))
    r, c = g.world_to_cell(np.array([[4.3, 2.0]]))[0]
    assert sh[r, c] and not sh2[r, c]


def test_blocked_goals_tests_points_in_the_rotated_footprint():
    corners = np.array([[[-0.6, -0.4], [0.6, -0.4], [0.6, 0.4], [-0.6, 0.4]]] * 2)
    goals = np.array([[0.0, 0.0, 0.0], [5.0, 0.0, np.pi / 2]])
    pts = np.array([[0.5, 0.3], [5.5, 0.0]])  # in the first; beside the turned second
    assert blocked_goals(goals, corners, pts).tolist() == [True, False]
    assert blocked_goals(goals, corners, np.array([[5.0, 0.55]])).tolist() == [False, True]
    assert blocked_goals(goals, corners, np.zeros((0, 2))).tolist() == [False, False]


@pytest.mark.slow
def test_a_spot_found_blocked_on_arrival_is_laid_out_again_and_the_group_parks():
    from swarmpark.apps.run import run_world

    world = build_world(_scenario(park_at=0.5, boundary=FAR_BOX, duration=90.0))
    res = run_world(world).result
    parks = [c for c in res["commands"] if c["command"] == "park"]
    assert len(parks) == 2 and all(c["accepted"] for c in parks)
    sup = Supervisor(world)
    assert any(_on(parks[0]["detail"]["goals"], sup, UNSEEN))
    assert not any(_on(parks[1]["detail"]["goals"], sup, UNSEEN))
    assert res["success"] and res["collisions"] == []


def test_a_goto_is_checked_on_the_known_map_not_the_scenarios_obstacles():
    """With sensing on, a goto is judged on what the operator knows, as a park is: the crate no
    scan has seen is not known (the goto is taken), the seen one is refused with the reason,
    and a refused goto leaves the skid on its previous order."""
    sup = Supervisor(build_world(_scenario(park_at=30.0)))
    on_unseen = sup.command("goto", {"robot": "a2", "pose": [12.2, 1.7, 90]})
    assert on_unseen.accepted, on_unseen
    ok = sup.command("goto", {"robot": "a1", "pose": [3.0, 2.0, 0]})
    assert ok.accepted
    before = sup.command("goto", {"robot": "a1", "pose": [5.2, 1.7, 90]})
    assert before.accepted  # no scan yet: the map alone does not show the crate
    sup.command("goto", {"robot": "a1", "pose": [3.0, 2.0, 0]})
    _run_until(sup, 1.0)
    reason = (
        "goto.pose: robot 'a1' would overlap a wall or a detected obstacle of the known map "
        "at [5.2, 1.7, 90.0]"
    )
    assert_goto_refused(sup, "a1", [5.2, 1.7, 90], reason, kept=[3.0, 2.0, 0.0])
    wall = sup.command("goto", {"robot": "a1", "pose": [8.0, 7.5, 0]})
    assert not wall.accepted and "overlap a wall" in wall.reason
    off = sup.command("goto", {"robot": "a1", "pose": [15.9, 4.0, 0]})
    assert not off.accepted
    assert off.reason == "goto.pose: robot 'a1' would reach outside the map at [15.9, 4.0, 0.0]"
