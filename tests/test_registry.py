"""Registries of layout methods, assignment costs and avoidance modes: unknown names are
refused with the known ones listed, every consumer (layout, scenario schema, API) reads the
registry, and a method registered later is usable everywhere without other edits."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

with warnings.catch_warnings():
    warnings.filterwarnings("ignore", message=".*httpx2.*")
    from fastapi.testclient import TestClient

from helpers import DATA

from swarmpark.assign import ASSIGNMENT_COSTS, cost_matrix
from swarmpark.control.modes import AVOIDANCE_MODES
from swarmpark.core.geometry import Footprint
from swarmpark.core.registry import Registry, UnknownNameError
from swarmpark.layout import LAYOUT_METHODS, LayoutError, capacity, layout
from swarmpark.layout.methods import LayoutMethod, stack_best
from swarmpark.server import create_app
from swarmpark.server.engine import TELEOP_DEADMAN_S
from swarmpark.server.schemas import MAX_SPEED_FACTOR, MIN_SPEED_FACTOR
from swarmpark.world.scenario import ParkCmd, ScenarioError, parse_scenario

SQUARE = [[0, 0], [6, 0], [6, 4], [0, 4]]
SKID = Footprint(1.2, 0.8)


def minimal_scenario(**extra) -> dict:
    return {
        "name": "t",
        "map": {"size_m": [10, 10]},
        "robots": [{"id": "a", "pose": [1, 1, 0]}],
        **extra,
    }


# ----------------------------------------------------------------------------- the registry


def test_registry_refuses_unknown_and_duplicate_names():
    reg: Registry[int] = Registry("colour", "paint.colour")
    reg.add("red", 1, "warm")

    @reg.register("blue", "cold")
    def _blue():
        return 2

    assert reg.names() == ("red", "blue") and reg.get("blue")() == 2
    with pytest.raises(
        UnknownNameError, match=r"^paint.colour: unknown colour 'green' \(known: red, blue\)$"
    ):
        reg.get("green")
    with pytest.raises(ValueError, match="already registered"):
        reg.add("red", 3, "again")
    with pytest.raises(ValueError, match="needs a description"):
        reg.add("grey", 4, "")
    assert reg.remove("red") == 1 and reg.names() == ("blue",)


def test_the_builtin_choices_are_registered_in_order():
    assert LAYOUT_METHODS.names() == ("stacking", "potential", "convex")
    assert ASSIGNMENT_COSTS.names() == ("sequential", "euclidean", "formation", "path")
    assert AVOIDANCE_MODES.names() == ("monitor", "rvo")
    for reg in (LAYOUT_METHODS, ASSIGNMENT_COSTS, AVOIDANCE_MODES):
        assert all(e.description for e in reg.entries())


# ----------------------------------------------------------------------------- unknown names


def test_unknown_layout_method_lists_the_known_ones():
    with pytest.raises(
        LayoutError, match=r"park.method: .*'stacking', 'potential', 'convex'.*'best'"
    ):
        layout(SQUARE, [SKID], method="best")
    with pytest.raises(LayoutError, match=r"park.method: .*'best'"):
        capacity(SQUARE, SKID, method="best")


def test_unknown_assignment_cost_lists_the_known_ones():
    with pytest.raises(
        UnknownNameError,
        match=r"park.assignment: unknown assignment cost 'near'"
        r" \(known: sequential, euclidean, formation, path\)",
    ):
        cost_matrix(np.zeros((1, 2)), np.ones((1, 2)), "near")


@pytest.mark.parametrize(
    ("extra", "field", "value", "known"),
    [
        (
            {"commands": [{"park": {"robots": ["a"], "boundary": SQUARE, "method": "magic"}}]},
            "commands[0].park.method",
            "magic",
            "stacking, potential, convex",
        ),
        (
            {"commands": [{"park": {"robots": ["a"], "boundary": SQUARE, "assignment": "near"}}]},
            "commands[0].park.assignment",
            "near",
            "sequential, euclidean, formation, path",
        ),
        (
            {"navigation": {"avoidance": "telepathy"}},
            "navigation.avoidance",
            "telepathy",
            "monitor, rvo",
        ),
    ],
)
def test_scenario_refuses_unknown_names_naming_field_value_and_choices(extra, field, value, known):
    with pytest.raises(ScenarioError) as exc:
        parse_scenario(minimal_scenario(**extra))
    msg = str(exc.value)
    assert msg.startswith(f"{field}: unknown ") and f"(known: {known})" in msg
    assert msg.endswith(f"(got {value!r})")


def test_scenario_schema_still_lists_the_choices_as_an_enum():
    props = ParkCmd.model_json_schema()["properties"]
    assert props["method"]["enum"] == ["stacking", "potential", "convex"]
    assert props["assignment"]["enum"] == list(ASSIGNMENT_COSTS.names())


# ----------------------------------------------------------------------------- a new method


@pytest.fixture
def rows_method():
    """A layout method registered by subclassing: stacking scanned by rows."""

    class Rows(LayoutMethod):
        name = "test-rows"
        description = "stacking scanned by rows only (a test plugin)"

        @classmethod
        def solve(cls, region, skids):
            from swarmpark.layout import stacking

            st = stacking.stack(region, skids, order="rows", count=len(skids))
            if st.fits < len(skids):
                raise LayoutError("park.boundary: too small", fits=st.fits)
            return st.centres, {"iterations": 0, "notices": []}

        @classmethod
        def fill(cls, region, footprint, stacked):
            return stacked.centres[stacked.placed], {"iterations": 0, "notices": []}

    yield Rows
    LAYOUT_METHODS.remove("test-rows")


def test_a_registered_method_is_usable_everywhere(rows_method):
    res = layout(SQUARE, [SKID] * 6, method="test-rows", margin_m=0.3)
    assert res.method == "test-rows" and len(res.poses) == 6 and res.report["egress_ok"]
    cap = capacity(SQUARE, SKID, method="test-rows", margin_m=0.3)
    assert cap.report["capacity"] >= 6
    assert ParkCmd(robots=["a"], boundary=SQUARE, method="test-rows").method == "test-rows"
    app = create_app(DATA / "ui-small.yaml", autostart=False, scenarios_dir=DATA)
    with TestClient(app) as client:
        names = [m["name"] for m in client.get("/api/meta").json()["layout_methods"]]
        assert names[-1] == "test-rows"
        r = client.post(
            "/api/park/preview",
            json={
                "robots": ["s1", "s2"],
                "boundary": [[6.5, 2], [10.5, 2], [10.5, 6], [6.5, 6]],
                "method": "test-rows",
            },
        )
        assert r.status_code == 200, r.json()
        assert r.json()["method"] == "test-rows" and len(r.json()["goals"]) == 2


def test_a_removed_method_is_refused_again(rows_method):
    LAYOUT_METHODS.remove("test-rows")
    with pytest.raises(ScenarioError, match="unknown layout method"):
        parse_scenario(
            minimal_scenario(
                commands=[{"park": {"robots": ["a"], "boundary": SQUARE, "method": "test-rows"}}]
            )
        )
    LAYOUT_METHODS.add("test-rows", rows_method, rows_method.description)  # for the fixture


def test_stack_best_prefers_rows_only_when_they_fit_more():
    from swarmpark.layout.region import make_region, make_skids

    region = make_region(SQUARE, None, 0.0, 0.3)
    st = stack_best(region, make_skids([SKID] * 4), 4)
    assert st.order == "columns" and st.fits == 4


# ----------------------------------------------------------------------------- GET /api/meta


def test_meta_lists_the_registries_and_the_limits():
    app = create_app(DATA / "ui-small.yaml", autostart=False, scenarios_dir=DATA)
    with TestClient(app) as client:
        r = client.get("/api/meta")
        n_robots = len(client.get("/api/world").json()["robots"])
    assert r.status_code == 200
    m = r.json()
    for key, reg in (
        ("layout_methods", LAYOUT_METHODS),
        ("assignment_costs", ASSIGNMENT_COSTS),
        ("avoidance_modes", AVOIDANCE_MODES),
    ):
        assert m[key] == [{"name": e.name, "description": e.description} for e in reg.entries()]
    assert m["defaults"] == {"method": "stacking", "assignment": "formation"}
    lim = m["limits"]
    assert lim["margin_m"]["min"] == 0.0 and lim["margin_m"]["default"] == 0.3
    assert lim["heading_deg"]["special"] == ["auto"] and lim["heading_deg"]["default"] == 0.0
    assert lim["robots_per_park"] == {"min": 1, "max": n_robots, "default": None, "step": None}
    assert (lim["sim_speed"]["min"], lim["sim_speed"]["max"]) == (
        MIN_SPEED_FACTOR,
        MAX_SPEED_FACTOR,
    )
    assert lim["teleop"]["deadman_s"] == TELEOP_DEADMAN_S
    assert 0 < lim["teleop"]["send_period_s"] < TELEOP_DEADMAN_S
