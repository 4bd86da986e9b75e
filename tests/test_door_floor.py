"""scripts/door_floor.py: the single-file floor of a park through a door."""

from __future__ import annotations

import pytest
from helpers import load_script

from swarmpark.apps.generate import generate, write_scenario
from swarmpark.world.scenario import build_world, load_scenario


def test_the_floor_spaces_the_crossings_and_sends_the_first_through_farthest():
    floor = load_script("door_floor").single_file_floor
    # Three skids 1 m from the door, 1 m long, 1 m/s: they pass at 1, 2 and 3 s; the first
    # through takes the spot 3 m beyond, the last the one 1 m beyond.
    assert floor([1.0, 1.0, 1.0], [1.0, 3.0, 2.0], 1.0, 1.0, 0.0) == pytest.approx(4.0)
    # A gap of 0.5 m spaces them 1.5 s apart: 1, 2.5, 4 s.
    assert floor([1.0, 1.0, 1.0], [1.0, 3.0, 2.0], 1.0, 1.0, 0.5) == pytest.approx(5.0)
    # A skid that reaches the door late passes when it gets there, not before.
    assert floor([1.0, 5.0, 5.0], [3.0, 2.0, 1.0], 1.0, 1.0, 0.0) == pytest.approx(7.0)
    # Half the speed, twice the time.
    assert floor([1.0, 5.0, 5.0], [3.0, 2.0, 1.0], 1.0, 0.5, 0.0) == pytest.approx(14.0)


def test_a_generated_door_has_a_floor_and_a_hangar_has_no_door(tmp_path):
    mod = load_script("door_floor")
    path = write_scenario(generate("door", 1000, robots=4), tmp_path / "d.yaml")
    door = mod.site(path, 0.0)
    robots = build_world(load_scenario(path)).robots
    shortest = min(r.footprint.length_m for r in robots)
    fastest = max(r.max_speed_mps for r in robots)
    assert door["skids"] == 4
    assert 1.4 <= door["door_m"] <= 2.9  # the generator's doors: a skid plus margins
    # The three behind the first pass the door a body length apart at top speed, at least.
    assert door["floor_s"] > 3 * shortest / fastest
    hangar = write_scenario(generate("hangar", 1000, robots=4), tmp_path / "h.yaml")
    assert mod.site(hangar, 0.0) is None


def test_bad_arguments_exit_2_naming_them(tmp_path, capsys):
    mod = load_script("door_floor")
    with pytest.raises(SystemExit) as e:
        mod.main([str(tmp_path / "nope.yaml")])
    assert e.value.code == 2 and "nope.yaml" in capsys.readouterr().err
    path = write_scenario(generate("door", 1000, robots=4), tmp_path / "d.yaml")
    with pytest.raises(SystemExit) as e:
        mod.main([str(path), "--gap", "-1"])
    assert e.value.code == 2 and "--gap must be at least 0 (got -1.0)" in capsys.readouterr().err
