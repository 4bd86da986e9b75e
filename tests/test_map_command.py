"""`swarmpark map`: a skid builds a map with its LIDAR while it drives; map_server output."""

import json
from pathlib import Path

from swarmpark.cli import main
from swarmpark.gridmap import load_map_yaml

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"


def test_map_command_writes_a_map_that_agrees_with_the_hangar(tmp_path, capsys):
    out = tmp_path / "built.yaml"
    assert (
        main(["map", str(SCENARIOS / "map-hangar.yaml"), "--robot", "m1", "--out", str(out)]) == 0
    )
    summary = json.loads(capsys.readouterr().out)
    grid = load_map_yaml(out)
    assert grid.shape == (400, 600) and grid.occupied.any()
    agree = summary["map_agreement"]
    # Measured: 99 % of the observed cells right, 87 % of the observable cells observed. Walls
    # are the weak part (drift that scan matching does not remove in an open hangar).
    assert agree["share_correct"] > 0.97
    assert agree["share_observed"] > 0.8
    assert summary["scans"] > 1000


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
