"""scripts/single_file.py: a line of skids through a generated door."""

from __future__ import annotations

import numpy as np
import yaml
from helpers import load_script

from swarmpark.apps.generate import generate, write_scenario
from swarmpark.world.scenario import RobotDefaults


def test_crossings_are_the_first_pass_over_the_door_line():
    mod = load_script("single_file")
    times = np.arange(5) * 1.0
    # Skid 0 crosses x = 2 between t = 2 and 3, skid 1 never, skid 2 twice (first at t = 1).
    x = np.array(
        [[0.0, 0.0, 1.0], [1.0, 0.5, 2.5], [1.5, 1.0, 1.0], [2.5, 1.5, 3.0], [3.0, 1.9, 3.5]]
    )
    poses = np.stack([x, np.full_like(x, 4.0), np.zeros_like(x)], axis=-1)
    got = mod.crossings(poses, times, [2.0, 4.0], 0.0)
    assert got[0] == 3.0 and np.isnan(got[1]) and got[2] == 1.0


def test_a_line_of_four_crosses_a_generated_door_in_order_and_parks(tmp_path):
    mod = load_script("single_file")
    path = write_scenario(generate("door", 1000, robots=4), tmp_path / "door.yaml")
    data = yaml.safe_load(path.read_text())
    door = mod.door_centre(data, tmp_path)
    # The zone's centre is in the door: within the dividing wall's thickness, in its gap.
    width = data["map"]["size_m"][0]
    inner = [np.array(w) for w in data["map"]["walls"]]
    inner = [w for w in inner if w[:, 0].min() > 0.5 and w[:, 0].max() < width - 0.5]
    assert len(inner) == 2  # the dividing wall, above and below its door
    assert inner[0][:, 0].min() <= door[0] <= inner[0][:, 0].max()
    below, above = sorted(inner, key=lambda w: w[:, 1].min())
    assert below[:, 1].max() < door[1] < above[:, 1].min()
    line = mod.line_scenario(data, door, 0.0, 4, 0.4)
    first = np.array(line["robots"][0]["pose"][:2])
    assert door[0] - first[0] > 1.0  # the nose 1 m before the door
    result, cross = mod.run(path, 4, 0.4)
    assert result["success"] and result["collisions"] == []
    assert np.all(np.isfinite(cross)) and np.all(np.diff(cross) > 0)
    # A line passes the door in single file, so it takes no less than the single-file floor
    # of scripts/door_floor.py (straight runs at top speed, a body length apart at the door).
    starts = np.array([r["pose"][:2] for r in line["robots"]])
    spots = np.array([r["final_pose"][:2] for r in result["robots"].values()])
    floor = load_script("door_floor").single_file_floor(
        np.linalg.norm(starts - door, axis=1),
        np.linalg.norm(spots - door, axis=1),
        data["robot_defaults"]["footprint"]["length_m"],
        RobotDefaults().max_speed_mps,  # the line's skids set none
        0.0,
    )
    assert 0.0 < floor <= result["time_to_park_s"]
