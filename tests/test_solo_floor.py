"""scripts/solo_floor.py: each skid of a park run alone against its lower bound."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml
from helpers import hall_walls, load_script

solo = load_script("solo_floor")


def _scenario():
    return {
        "name": "two-into-a-box",
        "seed": 0,
        "dt_s": 0.05,
        "duration_s": 60,
        "map": {"size_m": [12, 8], "walls": hall_walls(12, 8)},
        "robots": [{"id": "a", "pose": [2.0, 2.5, 0.0]}, {"id": "b", "pose": [2.0, 5.5, 90.0]}],
        "commands": [
            {
                "at_s": 0,
                "park": {"robots": ["a", "b"], "boundary": [[7, 2], [10, 2], [10, 6], [7, 6]]},
            }
        ],
        "expect": {"success": True},
    }


def test_each_skid_parks_alone_no_faster_than_its_bound(tmp_path):
    rows = solo.solo_runs(_scenario(), tmp_path)
    assert [r["robot"] for r in rows] == ["a", "b"]
    for r in rows:
        assert r["time_to_park_s"] is not None  # alone in an open hall, each parks
        assert 1.0 <= r["ratio"] < 2.0
        assert r["path_m"] > 4.0
        # The way to the docking's reach and the final approach make up the time to park
        # (the park command is given at 0 s); the way there takes at least the path beyond
        # that reach at top speed (0.5 m/s).
        assert r["approach_s"] + r["final_s"] == pytest.approx(r["time_to_park_s"], abs=0.06)
        assert r["approach_s"] >= (r["path_m"] - solo.NEAR_M) / 0.5
        assert 0 < r["final_s"] < r["approach_s"]
    # One skid only, with its own spot: the other skid and its goal are gone.
    one = solo.alone(_scenario(), "b")
    assert [r["id"] for r in one["robots"]] == ["b"]
    assert one["commands"][0]["park"]["robots"] == ["b"] and "expect" not in one


def test_several_scenarios_are_summed_up_and_written(tmp_path, capsys):
    one, two = tmp_path / "one.yaml", tmp_path / "two.yaml"
    one.write_text(yaml.safe_dump(_scenario()))
    two.write_text(yaml.safe_dump(_scenario()))
    out = tmp_path / "rows.json"
    solo.main([str(one), str(two), "--robots", "a", "--json", str(out)])
    rows = json.loads(out.read_text())
    assert [(Path(r["scenario"]).name, r["robot"]) for r in rows] == [
        ("one.yaml", "a"),
        ("two.yaml", "a"),
    ]
    assert rows[0]["ratio"] == rows[1]["ratio"]  # the same site: the same lone run
    s = solo.summary(rows)
    assert s["skids"] == s["parked"] == 2
    assert s["ratio_p50"] == s["ratio_max"] == pytest.approx(rows[0]["ratio"])
    assert "all: 2 of 2 skids parked alone" in capsys.readouterr().out
    # A skid that did not park counts among the skids, not in the ratios.
    s = solo.summary(rows + [{**rows[0], "ratio": None, "final_s": None}])
    assert (s["skids"], s["parked"]) == (3, 2)


def test_a_skid_outside_the_park_or_a_scenario_without_one_is_refused(tmp_path, capsys):
    with pytest.raises(ValueError, match="robots: 'c' is not in the first park command"):
        solo.alone(_scenario(), "c")
    data = _scenario()
    data["commands"] = []
    with pytest.raises(ValueError, match="commands: the scenario has no park command"):
        solo.solo_runs(data, tmp_path)
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump(_scenario()))
    with pytest.raises(SystemExit) as exc:
        solo.main([str(path), "--robots", "a,c"])
    assert exc.value.code == 2
    assert "'c' is not in the first park command" in capsys.readouterr().err
    # A bad skid in the last of several files is refused before any run: nothing printed.
    other = dict(_scenario(), robots=[{"id": "a", "pose": [2.0, 2.5, 0.0]}])
    other["commands"] = [
        {"at_s": 0, "park": {**_scenario()["commands"][0]["park"], "robots": ["a"]}}
    ]
    last = tmp_path / "t.yaml"
    last.write_text(yaml.safe_dump(other))
    with pytest.raises(SystemExit) as exc:
        solo.main([str(path), str(last), "--robots", "b"])
    assert exc.value.code == 2
    out = capsys.readouterr()
    assert "t.yaml: robots: 'b' is not in the first park command" in out.err and out.out == ""
