"""The 2015 pure potential-field baseline (``navigation: {mode: pure-pf}``): selectable,
validated, parks in the open, and stops in the local minimum of a U-shaped crate where the
default stack (planner + field) parks (issue 21 item 3, issue 15 item 1)."""

from pathlib import Path

import numpy as np
import pytest
import yaml
from helpers import SCENARIOS

from swarmpark.apps.run import run_world
from swarmpark.control.modes import NAVIGATION_MODES
from swarmpark.control.nav.navigator import Navigator
from swarmpark.control.nav.params import NavParams
from swarmpark.control.nav.pure_pf import PurePotentialField
from swarmpark.control.nav.stack import FACTORIES, make_controller
from swarmpark.core.registry import UnknownNameError
from swarmpark.supervisor.core import Supervisor
from swarmpark.world.scenario import ScenarioError, build_world, load_scenario, parse_scenario

U_TRAP = SCENARIOS / "u-trap-2015.yaml"
U_TRAP_PF = SCENARIOS / "experimental" / "u-trap-2015-pure-pf.yaml"


def _with_navigation(path: Path, **nav):
    scn = load_scenario(path)
    return scn.model_copy(update={"navigation": scn.navigation.model_copy(update=nav)})


def test_every_navigation_mode_has_a_controller():
    assert set(NAVIGATION_MODES.names()) == set(FACTORIES)
    assert isinstance(make_controller(), Navigator)
    assert isinstance(make_controller("pure-pf"), PurePotentialField)
    with pytest.raises(UnknownNameError, match="navigation.mode: unknown navigation mode 'bug2'"):
        make_controller("bug2")
    with pytest.raises(ValueError, match="avoidance must be 'monitor'"):
        PurePotentialField(NavParams(avoidance="rvo"))


def test_scenario_selects_the_mode_default_unchanged():
    scn = load_scenario(U_TRAP)
    assert scn.navigation.mode == "planner"
    assert isinstance(Supervisor(build_world(scn)).controller, Navigator)
    pf = load_scenario(U_TRAP_PF)
    assert pf.navigation.mode == "pure-pf"
    assert isinstance(Supervisor(build_world(pf)).controller, PurePotentialField)


@pytest.mark.parametrize(
    ("nav", "message"),
    [
        ({"mode": "bug2"}, "navigation.mode"),
        ({"mode": "pure-pf", "avoidance": "rvo"}, "avoidance 'rvo' needs mode 'planner'"),
    ],
)
def test_bad_navigation_is_refused_naming_the_field(nav, message):
    data = yaml.safe_load(U_TRAP.read_text())
    data["navigation"] = nav
    with pytest.raises(ScenarioError, match=message):
        parse_scenario(data)


def test_pure_pf_parks_in_the_open():
    """Without the crate the 2015 field alone parks the skid: the failure below is the local
    minimum, not a controller that cannot park."""
    scn = _with_navigation(U_TRAP, mode="pure-pf").model_copy(
        update={"obstacles": [], "duration_s": 60.0}
    )
    r = run_world(build_world(scn)).result
    assert r["success"] and r["collisions"] == []
    assert r["robots"]["r1"]["final_position_error_m"] <= 0.10


@pytest.mark.slow
def test_u_trap_pure_pf_stops_where_the_planner_parks():
    planned = run_world(build_world(load_scenario(U_TRAP))).result
    assert planned["success"] and planned["collisions"] == []
    pure = run_world(build_world(load_scenario(U_TRAP_PF))).result
    assert not pure["success"] and pure["collisions"] == []
    assert pure["expect_met"]
    # It stopped inside the U (between the arms, before the bottom at x = 9 m) and stayed:
    # a deadlock episode that never ended.
    x, y, _ = pure["robots"]["r1"]["final_pose"]
    assert 6.0 < x < 9.0 and 3.7 < y < 6.3
    assert pure["robots"]["r1"]["final_position_error_m"] > 4.0
    assert any(d["robot"] == "r1" and d["end_s"] is None for d in pure["deadlocks"])
    # The same scenario with only the mode switched back parks again.
    again = run_world(build_world(_with_navigation(U_TRAP_PF, mode="planner"))).result
    assert again["success"]
    assert np.isclose(again["time_to_park_s"], planned["time_to_park_s"])
