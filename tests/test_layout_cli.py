"""Tests for the ``swarmpark layout`` subcommand (called in-process)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from PIL import Image
from shapely.geometry import box

from swarmpark.apps.cli_layout import layout_command
from swarmpark.core.geometry import Footprint, footprint_polygon
from swarmpark.core.gridmap import grid_from_walls, save_map_yaml

SQUARE = "[[0,0],[4,0],[4,4],[0,4]]"
ELEVATOR = "[[0,0],[7,0],[7,4],[0,4]]"


def run(capsys, *argv):
    code = layout_command(list(argv))
    out = capsys.readouterr()
    return code, out.out, out.err


def test_json_output_nine_in_square(capsys):
    code, out, err = run(
        capsys,
        "--boundary",
        SQUARE,
        "--count",
        "9",
        "--footprint",
        "1",
        "1",
        "--margin-m",
        "0.25",
        "--json",
    )
    assert code == 0 and err == ""
    d = json.loads(out)
    assert d["method"] == "stacking" and d["count"] == 9 and len(d["goals"]) == 9
    xs = sorted({round(g["x_m"], 6) for g in d["goals"]})
    assert xs == [0.75, 2.0, 3.25]
    assert all(g["yaw_deg"] == 0.0 for g in d["goals"])
    rep = d["report"]
    assert rep["min_spacing_m"] == pytest.approx(0.25)
    assert rep["solve_time_s"] > 0 and rep["egress_ok"] is True
    assert sorted(d["fill_order"]) == list(range(9))


def test_table_output_and_heading(capsys):
    code, out, _ = run(
        capsys,
        "--boundary",
        ELEVATOR,
        "--count",
        "4",
        "--footprint",
        "1.2",
        "0.8",
        "--heading-deg",
        "90",
        "--method",
        "convex",
    )
    assert code == 0
    assert out.startswith("method convex, heading 90.0 deg, 4 goals, margin 0.3 m")
    assert "min spacing" in out and "fill" in out


def test_capacity(capsys):
    code, out, _ = run(capsys, "--boundary", ELEVATOR, "--footprint", "1.2", "0.8", "--capacity")
    assert code == 0 and "12 skids fit" in out
    code, out, _ = run(
        capsys, "--boundary", ELEVATOR, "--footprint", "1.2", "0.8", "--capacity", "--json"
    )
    d = json.loads(out)
    assert d["count"] == 12 and d["report"]["capacity"] == 12


def test_mixed_footprints_and_auto_heading(capsys):
    code, out, _ = run(
        capsys,
        "--boundary",
        "[[0,0],[10,0],[10,6],[0,6]]",
        "--footprints",
        "[[1.2, 0.8], [2.0, 1.0, 0.4], [1.2, 0.8]]",
        "--heading-deg",
        "auto",
        "--method",
        "potential",
        "--json",
    )
    assert code == 0
    d = json.loads(out)
    assert d["count"] == 3 and "auto_heading" in d["report"]


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["--boundary", "[[0,0],[4,0"], "--boundary: not valid JSON"),
        (["--boundary", "[[0,0],[4,4],[4,0],[0,4]]"], "--boundary: not a simple polygon"),
        (["--boundary", SQUARE, "--margin-m", "-1"], "--margin-m: must be a finite number >= 0"),
        (["--boundary", SQUARE, "--heading-deg", "north"], "--heading-deg: a number of degrees"),
        (
            ["--boundary", SQUARE, "--count", "10", "--margin-m", "0.25"],
            "--boundary: only 9 of 10 skids (1 x 1 m, margin 0.25 m) fit with method 'stacking'",
        ),
        (["--boundary", SQUARE, "--count", "0"], "--count: must be >= 1 (got 0)"),
        (
            ["--boundary", SQUARE, "--count", "2", "--map", "/nonexistent/map.yaml"],
            "--map: file not found",
        ),
    ],
)
def test_bad_input_one_clear_message(capsys, argv, needle):
    if "--count" not in argv:
        argv = [*argv, "--count", "2"]
    code, out, err = run(capsys, *argv, "--footprint", "1", "1")
    assert code == 2 and out == ""
    assert err.startswith("swarmpark layout: error: ")
    assert needle in err
    assert "Traceback" not in err and err.count("\n") == 1


def test_footprint_required(capsys):
    code, _, err = run(capsys, "--boundary", SQUARE, "--count", "2")
    assert code == 2 and "--footprint: required" in err


def test_map_obstacles_are_avoided(tmp_path, capsys):
    wall = box(3.0, 0.0, 3.5, 3.0)
    grid = grid_from_walls((8.0, 5.0), 0.05, [wall])
    path = save_map_yaml(grid, tmp_path / "bay.yaml")
    code, out, err = run(
        capsys,
        "--boundary",
        "[[0.5,0.5],[7.5,0.5],[7.5,4.5],[0.5,4.5]]",
        "--count",
        "6",
        "--footprint",
        "1.2",
        "0.8",
        "--map",
        str(path),
        "--json",
    )
    assert code == 0, err
    fp = Footprint(1.2, 0.8)
    for g in json.loads(out)["goals"]:
        poly = footprint_polygon([g["x_m"], g["y_m"], np.radians(g["yaw_deg"])], fp)
        assert poly.distance(wall) >= 0.3 - 1e-6


def test_png_three_methods_side_by_side(tmp_path, capsys):
    png = tmp_path / "fig.png"
    code, out, _ = run(
        capsys,
        "--boundary",
        "[[0,0],[12,0],[12,4],[4,4],[4,10],[0,10]]",
        "--count",
        "12",
        "--footprint",
        "1.2",
        "0.8",
        "--png",
        str(png),
    )
    assert code == 0 and f"wrote {png}" in out
    with Image.open(png) as img:
        w, h = img.size
    assert w > 2.5 * h  # three panels in a row
    png1 = tmp_path / "one.png"
    code, _, _ = run(
        capsys,
        "--boundary",
        SQUARE,
        "--count",
        "4",
        "--footprint",
        "1",
        "1",
        "--method",
        "convex",
        "--png",
        str(png1),
    )
    with Image.open(png1) as img:
        w, h = img.size
    assert code == 0 and w < 1.5 * h  # one panel
