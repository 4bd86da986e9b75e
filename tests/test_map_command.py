"""`swarmpark map`: a skid builds a map with its LIDAR while it drives; map_server output."""

import json

import numpy as np
import pytest
import yaml
from helpers import SCENARIOS

from swarmpark.apps.cli import main
from swarmpark.apps.run import run_world
from swarmpark.core.gridmap import load_map_yaml
from swarmpark.world.scenario import build_world, load_scenario, parse_scenario


def test_map_command_writes_a_map_that_agrees_with_the_hangar(tmp_path, capsys):
    out = tmp_path / "built.yaml"
    assert (
        main(["map", str(SCENARIOS / "map-hangar.yaml"), "--robot", "m1", "--out", str(out)]) == 0
    )
    summary = json.loads(capsys.readouterr().out)
    grid = load_map_yaml(out)
    assert grid.shape == (400, 600) and grid.occupied.any()
    # The committed map that hangar-park-amcl-built parks in is this run's output, to within
    # a few cells: the same code gives the same map on one machine every time, but not
    # bit for bit on every machine (on an AMD EPYC, 2 occupied and 2 unknown cells of
    # 240 000 differ from the map committed from another, presumably in the last bits of
    # the floating point).
    committed = load_map_yaml(SCENARIOS / "maps" / "hangar-built.yaml")
    assert np.count_nonzero(grid.occupied != committed.occupied) <= 10
    assert np.count_nonzero(grid.unknown != committed.unknown) <= 10
    agree = summary["map_agreement"]
    # Measured (the loop and the two legs through the middle): every observed cell right, all
    # the observable cells observed, wall precision 1.00 and recall 1.00; after the loop
    # closures the keyframes are at most 0.06 m off while the odometry drifts 2.0 m (without
    # loop closure: 0.33 m, recall 0.97; before keyframes: wall precision 0.63 on the loop).
    assert agree["share_correct"] > 0.99
    assert agree["share_observed"] > 0.95
    assert agree["wall_precision"] > 0.95
    assert agree["wall_recall"] > 0.9
    assert summary["keyframe_error_max_m"] < 0.12
    assert summary["slam_error_final_m"] < 0.05
    assert summary["odometry_drift_final_m"] > 0.5  # there was drift to remove
    assert summary["scans"] > 1000
    # The route comes back to places it mapped: the pose graph finds the loop closures (46)
    # and is optimized when they show drift (3 times). (The drive since 2026-12-04 brings no
    # candidate that pairs the racks' opposite faces; the facing gate that refuses those is
    # tested on a rack of its own, tests/test_slam.py.)
    graph = summary["pose_graph"]
    assert graph["keyframes"] == summary["keyframes"] > 200
    assert graph["loop_closures"] > 20
    assert graph["optimizations"] >= 1


@pytest.mark.slow
def test_a_second_run_localizes_and_parks_in_the_map_the_first_built(tmp_path, capsys):
    """Hing 2018, Sect. 3.5.2: m1 maps the room (from scratch, in its own start frame); then
    three skids localize with AMCL in that map -- built here, not a committed file -- plan in
    it and park."""
    built = tmp_path / "room.yaml"
    assert (
        main(["map", str(SCENARIOS / "map-room.yaml"), "--robot", "m1", "--out", str(built)]) == 0
    )
    summary = json.loads(capsys.readouterr().out)
    # Measured: wall precision 1.00, recall 0.88, 98 % observed; mapping error under 2 cm.
    assert summary["map_agreement"]["wall_precision"] > 0.95
    assert summary["map_agreement"]["share_observed"] > 0.9
    assert summary["slam_error_max_m"] < 0.05

    data = yaml.safe_load((SCENARIOS / "room-park-built.yaml").read_text())
    data["sensing"]["map"] = str(built)
    world = build_world(parse_scenario(data, SCENARIOS))
    r = run_world(world).result
    assert r["expect_met"], r["expect_failures"]
    assert r["collisions"] == []
    for rid, s in r["robots"].items():
        assert s["final_position_error_m"] <= 0.10, rid
        assert s["final_heading_error_deg"] <= 5.0, rid
    loc = r["localization"]
    # Measured: mean 0.033 m, max 0.094 m.
    assert loc["mean_error_m"] < 0.05
    assert loc["max_error_m"] < 0.15
    assert loc["map_agreement"]["wall_precision"] > 0.95


def test_map_command_unknown_robot_exits_2(tmp_path, capsys):
    code = main(
        [
            "map",
            str(SCENARIOS / "map-hangar.yaml"),
            "--robot",
            "zz",
            "--out",
            str(tmp_path / "m.yaml"),
        ]
    )
    assert code == 2
    assert "map --robot: unknown robot 'zz'" in capsys.readouterr().err


@pytest.mark.slow
def test_the_hangar_fleet_localizes_and_parks_in_the_map_map_hangar_built():
    """Hing 2018, Sect. 3.5.2 in the staging bay: six skids localize with AMCL in the map m1
    built (scenarios/maps/hangar-built.yaml, checked above to be `swarmpark map`'s output),
    plan in it and park."""
    world = build_world(load_scenario(SCENARIOS / "hangar-park-amcl-built.yaml"))
    r = run_world(world).result
    assert r["expect_met"], r["expect_failures"]
    assert r["collisions"] == []
    for rid, s in r["robots"].items():
        assert s["final_position_error_m"] <= 0.10, rid
        assert s["final_heading_error_deg"] <= 5.0, rid
    loc = r["localization"]
    # Measured: mean 0.029 m, max 0.143 m; the believed map has every wall face in it.
    assert loc["mean_error_m"] < 0.05
    assert loc["max_error_m"] < 0.25
    assert loc["map_agreement"]["wall_precision"] > 0.95
    assert loc["map_agreement"]["wall_recall"] > 0.9
