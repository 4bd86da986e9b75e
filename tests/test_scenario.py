"""Scenario schema: every bad input named in the issue gives one clear message and exit code 2."""

import numpy as np
import pytest
import yaml
from helpers import ROOT

from swarmpark.apps.cli import main
from swarmpark.world.scenario import ScenarioError, build_world, load_scenario, parse_scenario

BASE = {
    "name": "t",
    "map": {
        "size_m": [10, 6],
        "resolution_m": 0.05,
        "walls": [[[4, 0], [4.5, 0], [4.5, 3], [4, 3]]],
    },
    "robots": [{"id": "a", "pose": [2.0, 3.0, 0.0]}, {"id": "b", "pose": [2.0, 5.0, 90.0]}],
}


def with_(**kw):
    d = {k: v for k, v in BASE.items()}
    d.update(kw)
    return d


def error_of(data, base_dir="."):
    with pytest.raises(ScenarioError) as e:
        build_world(parse_scenario(data, base_dir))
    return str(e.value)


def test_valid_scenario_builds_with_radians_and_defaults():
    w = build_world(parse_scenario(BASE))
    assert w.ids == ["a", "b"]
    assert w.robots[1].start[2] == pytest.approx(np.pi / 2)
    assert w.robots[0].footprint.length_m == 1.2 and w.robots[0].max_speed_mps == 0.5
    assert w.grid.shape == (120, 200)


def test_unknown_key_is_named():
    msg = error_of(with_(robots=[{"id": "a", "pose": [2, 3, 0], "colour": "red"}]))
    assert msg.startswith("robots[0].colour: unknown key")
    assert "'red'" in msg


@pytest.mark.parametrize(
    "overrides, message",
    [
        ({"duration": 10}, "duration: unknown key (value 10); did you mean 'duration_s'?"),
        (
            {"robots": [{"id": "a", "pose": [2, 3, 0], "max_speed": 1}]},
            "robots[0].max_speed: unknown key (value 1); did you mean 'max_speed_mps'?",
        ),
        (
            {"navigation": {"avoidence": "rvo"}},
            "navigation.avoidence: unknown key (value 'rvo'); did you mean 'avoidance'?",
        ),
        (
            {"people": [{"waypoints": [[1, 1], [2, 2]]}]},
            "people: unknown key (value [{'waypoints': [[1, 1], [2, 2]]}]); "
            "people walk as `obstacles` entries with `waypoints`",
        ),
        # A person with a misspelt key is reported as a person, not as a polygon missing.
        (
            {"obstacles": [{"waypoints": [[1, 1], [2, 2]], "speed": 1}]},
            "obstacles[0].speed: unknown key (value 1); did you mean 'speed_mps'?",
        ),
        (
            {"obstacles": [{"waypoints": [[1, 1], [2, 2]], "speed_mps": -1}]},
            "obstacles[0].speed_mps: Input should be greater than 0 (got -1)",
        ),
        ({"colour": "red"}, "colour: unknown key (value 'red')"),
    ],
)
def test_unknown_key_says_what_was_meant(overrides, message):
    assert error_of(with_(**overrides)) == message


def test_wrong_type_names_field_and_value():
    msg = error_of(with_(dt_s="fast"))
    assert msg.startswith("dt_s:") and "'fast'" in msg
    msg = error_of(with_(robots=[{"id": "a", "pose": [2, 3]}]))
    assert msg.startswith("robots[0].pose:") and "[2, 3]" in msg


def test_robot_inside_a_wall():
    msg = error_of(with_(robots=[{"id": "a", "pose": [4.2, 1.0, 0]}]))
    assert msg == "robots[0].pose: robot 'a' starts inside a wall at [4.2, 1.0, 0.0]"


def test_robot_off_the_map_counts_as_inside_a_wall():
    msg = error_of(with_(robots=[{"id": "a", "pose": [0.2, 3.0, 0]}]))
    assert "robot 'a' starts inside a wall" in msg


def test_robot_inside_a_static_obstacle():
    msg = error_of(with_(obstacles=[{"polygon": [[1.5, 2.5], [2.5, 2.5], [2.5, 3.5], [1.5, 3.5]]}]))
    assert msg.startswith("robots[0].pose: robot 'a' starts inside obstacle 0")


def test_overlapping_robots():
    msg = error_of(
        with_(robots=[{"id": "a", "pose": [2, 3, 0]}, {"id": "b", "pose": [2.5, 3.2, 30]}])
    )
    assert msg.startswith("robots[1].pose: robot 'b' overlaps robot 'a' at start")


def test_boundary_not_a_simple_polygon():
    cmd = {"at_s": 0, "park": {"robots": ["a"], "boundary": [[6, 1], [9, 5], [9, 1], [6, 5]]}}
    msg = error_of(with_(commands=[cmd]))
    assert msg.startswith("commands[0].park.boundary: not a simple polygon (Self-intersection")


def test_command_naming_unknown_robot():
    msg = error_of(with_(commands=[{"at_s": 1, "goto": {"robot": "zz", "pose": [8, 3, 0]}}]))
    assert msg == "commands[0].goto.robot: unknown robot 'zz'"
    msg = error_of(with_(commands=[{"at_s": 1, "stop": ["a", "zz"]}]))
    assert msg == "commands[0].stop: unknown robot 'zz'"


def test_command_with_two_actions_is_refused():
    msg = error_of(with_(commands=[{"at_s": 1, "estop": True, "resume": "all"}]))
    assert msg.startswith(
        "commands[0]: a command needs exactly one of park, goto, formation, stop, estop, resume"
    )


def test_missing_map_image(tmp_path):
    (tmp_path / "m.yaml").write_text(
        yaml.safe_dump({"image": "nope.pgm", "resolution": 0.05, "origin": [0, 0, 0]})
    )
    msg = error_of(with_(map={"yaml": "m.yaml"}), tmp_path)
    assert msg.startswith("map.yaml: image file not found:") and "nope.pgm" in msg


def test_missing_map_yaml(tmp_path):
    msg = error_of(with_(map={"yaml": "absent.yaml"}), tmp_path)
    assert msg.startswith("map.yaml: file not found:") and "absent.yaml" in msg


def test_duplicate_ids():
    msg = error_of(with_(robots=[{"id": "a", "pose": [2, 3, 0]}, {"id": "a", "pose": [2, 5, 0]}]))
    assert msg == "robots[1].id: duplicate robot id 'a'"


def test_cli_exits_2_with_one_line_and_no_traceback(tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump(with_(robots=[{"id": "a", "pose": [4.2, 1.0, 0]}])))
    assert main(["run", str(bad), "--json"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert "robots[0].pose: robot 'a' starts inside a wall" in err
    assert "Traceback" not in err


def test_cli_exit_2_for_missing_file(capsys):
    assert main(["run", "/nonexistent/scn.yaml"]) == 2
    assert "scenario: file not found" in capsys.readouterr().err


def test_shipped_scenarios_load():
    root = ROOT / "scenarios"
    files = sorted(root.glob("*.yaml"))
    assert files, "no scenarios shipped"
    for f in files:
        build_world(load_scenario(f))


AMCL = {"localization": "amcl", "recovery": True}


@pytest.mark.parametrize(
    "sensing, message",
    [
        (
            {"kidnap": [{"robot": "a", "at_s": 1, "pose": [5, 3, 0]}]},
            "sensing.kidnap: needs sensing.localization 'amcl' (got 'truth')",
        ),
        (
            {**AMCL, "kidnap": [{"robot": "zz", "at_s": 1, "pose": [5, 3, 0]}]},
            "sensing.kidnap[0].robot: unknown robot (got 'zz')",
        ),
        (
            {**AMCL, "kidnap": [{"robot": "a", "at_s": 99, "pose": [5, 3, 0]}]},
            "sensing.kidnap[0].at_s: after the end of the run, duration_s 20.0 (got 99.0)",
        ),
        (
            {**AMCL, "kidnap": [{"robot": "a", "at_s": 1, "pose": [0.1, 3, 0]}]},
            "sensing.kidnap[0].pose: robot 'a' would be inside a wall (got [0.1, 3.0, 0.0])",
        ),
        (
            {**AMCL, "kidnap": [{"robot": "a", "at_s": 1, "pose": [5, 3]}]},
            "sensing.kidnap[0].pose: List should have at least 3 items",
        ),
        (
            {**AMCL, "kidnap": [{"robot": "a", "at_s": 1, "pose": [5, 3, 0], "when": 2}]},
            "sensing.kidnap[0].when: unknown key (value 2)",
        ),
    ],
)
def test_bad_kidnap_names_the_field_and_value(sensing, message):
    assert error_of(with_(sensing=sensing, duration_s=20)).startswith(message)


def test_person_waits_at_waypoints():
    from swarmpark.world.scenario import Person

    p = Person(
        "w",
        0.3,
        np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0]]),
        1.0,
        0.0,
        False,
        np.array([1.0, 2.0, 0.0]),
    )
    assert p.route_length_m == pytest.approx(7.0)  # 4 m walked, 3 s standing at 1 m/s
    at = {s: p.position_at(s).tolist() for s in (0.5, 1.0, 2.0, 3.5, 4.5, 6.0, 7.0, 9.0)}
    assert at == {
        0.5: [0, 0],
        1.0: [0, 0],
        2.0: [1, 0],
        3.5: [2, 0],
        4.5: [2, 0],
        6.0: [2, 1],
        7.0: [2, 2],
        9.0: [2, 2],
    }
    # Without waits the route is the old one, to the bit.
    q = Person("w", 0.3, p.waypoints, 1.0, 0.0, False)
    assert q.route_length_m == 4.0 and q.position_at(3.0).tolist() == [2.0, 1.0]


def test_person_waits_need_one_per_waypoint():
    with pytest.raises(
        ScenarioError, match=r"obstacles\[0\].*waits_s: need one wait per waypoint \(2\), got 3"
    ):
        from helpers import make_world

        make_world(obstacles=[{"waypoints": [[1, 1], [3, 1]], "waits_s": [0, 1, 2]}])
