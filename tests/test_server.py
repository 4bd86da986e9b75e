"""API tests of the operator interface (FastAPI TestClient, no browser).

The app is built paused (``autostart=False``) and driven with ``POST /api/sim/step``, so every
test is deterministic: a command lands between two ticks exactly as in the paced server.
"""

from __future__ import annotations

import io
import math
import warnings

import numpy as np
import pytest

with warnings.catch_warnings():
    # starlette's TestClient warns that it prefers httpx2 (not installed here); the warning
    # is about the test transport, not about this project.
    warnings.filterwarnings("ignore", message=".*httpx2.*")
    from fastapi.testclient import TestClient

from helpers import DATA, ROOT

from swarmpark.server import create_app
from swarmpark.server.cli import serve_command
from swarmpark.server.engine import MAX_TICKS_PER_FRAME, TELEOP_DEADMAN_S, Session
from swarmpark.world.scenario import ScenarioError

SMALL = DATA / "ui-small.yaml"
TOKEN = "s3cret-token"
AUTH = {"Authorization": f"Bearer {TOKEN}"}
ROBOTS = ["s1", "s2", "s3", "s4"]
BOX = [[6.5, 2.0], [10.5, 2.0], [10.5, 6.0], [6.5, 6.0]]


@pytest.fixture
def app():
    return create_app(SMALL, autostart=False, scenarios_dir=DATA)


@pytest.fixture
def client(app):
    return TestClient(app)


def sup_of(app):
    return app.state.session.sup


def fingerprint(sup) -> tuple:
    """Everything a refused command must leave alone."""
    return (
        sup.goals.tobytes(),
        sup.has_goal.tobytes(),
        sup.stopped.tobytes(),
        sup.teleop.tobytes(),
        sup.priority.tobytes(),
        bool(sup.estopped),
        tuple((tuple(g.robots), g.goals.tobytes(), g.goal_of.tobytes()) for g in sup.groups),
        sup.sim.poses.tobytes(),
        sup.sim.vel.tobytes(),
        sup.t,
    )


def step(client, ticks=1, headers=None):
    r = client.post("/api/sim/step", json={"ticks": ticks}, headers=headers or {})
    assert r.status_code == 200, r.text
    return r.json()


def state(client) -> dict:
    r = client.get("/api/state")
    assert r.status_code == 200
    return r.json()


def states_by_id(client) -> dict[str, str]:
    s = state(client)
    names = client.get("/api/world").json()["states"]
    return {rid: names[row[3]] for rid, row in zip(ROBOTS, s["robots"], strict=True)}


# ----------------------------------------------------------------------------- schema, docs


def test_openapi_lists_every_endpoint_and_the_park_schema(client):
    spec = client.get("/openapi.json").json()
    paths = spec["paths"]
    for p in (
        "/api/park",
        "/api/park/preview",
        "/api/goto",
        "/api/stop",
        "/api/resume",
        "/api/estop",
        "/api/teleop",
        "/api/release",
        "/api/sim",
        "/api/sim/step",
        "/api/sim/reset",
        "/api/scenario",
        "/api/scenarios",
        "/api/state",
        "/api/world",
        "/api/map",
        "/api/perf",
    ):
        assert p in paths, p
    park = spec["components"]["schemas"]["ParkRequest"]
    assert {"robots", "boundary", "heading_deg", "method", "margin_m", "assignment"} <= set(
        park["properties"]
    )
    assert park.get("additionalProperties") is False
    assert "409" in paths["/api/park"]["post"]["responses"]


def test_index_and_static_files_are_served(client):
    r = client.get("/")
    assert r.status_code == 200 and "E-STOP" in r.text
    for name in ("app.js", "style.css"):
        assert client.get(f"/static/{name}").status_code == 200


def test_world_and_map_png_match_the_grid(client):
    from PIL import Image

    world = client.get("/api/world").json()
    assert [r["id"] for r in world["robots"]] == ROBOTS
    assert world["map"]["size_px"] == [240, 160]  # 12 x 8 m at 0.05 m
    assert world["map"]["bounds_m"] == [0.0, 0.0, 12.0, 8.0]
    r = client.get("/api/map")
    assert r.headers["content-type"] == "image/png"
    img = Image.open(io.BytesIO(r.content))
    assert img.size == (240, 160)


# ----------------------------------------------------------------------------- park


def test_park_is_accepted_and_its_goals_lie_in_the_boundary(app, client):
    r = client.post("/api/park", json={"robots": ROBOTS, "boundary": BOX, "heading_deg": 90})
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["accepted"] is True and body["command"] == "park"
    assert sorted(body["detail"]["robots"]) == ROBOTS
    s = state(client)
    assert len(s["goals"]) == 4
    for x, y, h in s["goals"]:
        assert 6.5 < x < 10.5 and 2.0 < y < 6.0
        assert h == pytest.approx(90.0)  # degrees at the edge
    assert np.allclose(sup_of(app).goals[:, 2], math.pi / 2)  # radians inside
    assert s["groups"][0]["boundary"] == BOX and s["groups"][0]["method"] == "stacking"


@pytest.mark.parametrize(
    ("body", "reason"),
    [
        ({"robots": ["s1", "zz"], "boundary": BOX}, "park.robots: unknown robot 'zz'"),
        (
            {"robots": ROBOTS, "boundary": [[6.5, 2], [7.5, 2], [7.5, 3], [6.5, 3]]},
            "fit",
        ),
        (
            {"robots": ROBOTS, "boundary": [[6, 2], [10, 6], [10, 2], [6, 6]]},
            "park.boundary",
        ),
    ],
    ids=["unknown-robot", "does-not-fit", "self-intersecting"],
)
def test_refused_park_says_why_and_changes_nothing(app, client, body, reason):
    before = fingerprint(sup_of(app))
    r = client.post("/api/park", json=body)
    assert r.status_code == 409
    out = r.json()
    assert out["accepted"] is False and out["command"] == "park"
    assert reason in out["reason"]
    assert fingerprint(sup_of(app)) == before
    # The refusal is in the command log the status panel shows.
    log = state(client)["log"]
    assert log[-1]["accepted"] is False and reason in log[-1]["reason"]


def test_park_of_a_teleoperated_skid_is_refused(app, client):
    assert (
        client.post("/api/teleop", json={"robot": "s2", "v_mps": 0, "omega_radps": 0}).status_code
        == 200
    )
    before = fingerprint(sup_of(app))
    r = client.post("/api/park", json={"robots": ROBOTS, "boundary": BOX})
    assert r.status_code == 409
    assert r.json()["reason"] == "park.robots: robot 's2' is under teleop"
    assert fingerprint(sup_of(app)) == before


def test_preview_returns_goals_and_changes_nothing(app, client):
    before = fingerprint(sup_of(app))
    n_out = len(sup_of(app).outcomes)
    body = {"robots": ROBOTS, "boundary": BOX, "heading_deg": 90, "margin_m": 0.3}
    r = client.post("/api/park/preview", json=body)
    assert r.status_code == 200, r.text
    prev = r.json()
    assert prev["robots"] == ROBOTS and prev["method"] == "stacking"
    goals = np.array(prev["goals"])
    assert goals.shape == (4, 3)
    assert np.allclose(goals[:, 2], 90.0)
    assert sorted(prev["fill_order"]) == [0, 1, 2, 3]
    assert prev["report"]["margin_m"] == 0.3
    assert fingerprint(sup_of(app)) == before
    assert len(sup_of(app).outcomes) == n_out  # a preview is not a command
    # The park that follows lays out the same goals.
    done = client.post("/api/park", json=body).json()
    assert sorted(map(tuple, np.round(done["detail"]["goals"], 3))) == sorted(
        (round(x, 3), round(y, 3), round(math.radians(h), 3)) for x, y, h in goals
    )


def test_preview_refusal_is_409_with_the_reason(app, client):
    before = fingerprint(sup_of(app))
    r = client.post(
        "/api/park/preview",
        json={"robots": ROBOTS, "boundary": [[6.5, 2], [7.5, 2], [7.5, 3], [6.5, 3]]},
    )
    assert r.status_code == 409
    assert r.json()["accepted"] is False and "fit" in r.json()["reason"]
    assert fingerprint(sup_of(app)) == before


# ----------------------------------------------------------------------------- validation (422)


@pytest.mark.parametrize(
    ("path", "body", "field"),
    [
        ("/api/park", {"robots": ROBOTS, "boundary": BOX, "colour": "red"}, "colour"),
        ("/api/park", {"robots": ROBOTS, "boundary": BOX, "method": "magic"}, "method"),
        ("/api/park", {"robots": ROBOTS, "boundary": BOX, "heading_deg": "north"}, "heading_deg"),
        ("/api/park", {"robots": ROBOTS, "boundary": BOX, "margin_m": -1}, "margin_m"),
        ("/api/park", {"robots": ["s1", "s1"], "boundary": BOX}, "robots"),
        ("/api/park", {"robots": ROBOTS, "boundary": [[0, 0], [1, 1]]}, "boundary"),
        ("/api/park", {"boundary": BOX}, "robots"),
        ("/api/goto", {"robot": "s1", "pose": [1, 2]}, "pose"),
        ("/api/goto", {"robot": "s1", "pose": [5, 4, 0], "speed": 2}, "speed"),
        ("/api/stop", {"robots": "some"}, "robots"),
        ("/api/teleop", {"robot": "s1", "v_mps": 0.2}, "omega_radps"),
        ("/api/sim", {"speed": 1000}, "speed"),
        ("/api/sim", {"pause": True}, "pause"),
        ("/api/sim/step", {"ticks": 0}, "ticks"),
        ("/api/scenario", {"name": "../etc/passwd.yaml"}, "name"),
    ],
)
def test_malformed_requests_are_422_naming_the_field(app, client, path, body, field):
    before = fingerprint(sup_of(app))
    r = client.post(path, json=body)
    assert r.status_code == 422, r.text
    out = r.json()
    assert out["message"].startswith(field), out["message"]
    assert any(field in [str(p) for p in e["loc"]] for e in out["detail"])
    assert fingerprint(sup_of(app)) == before


def test_unknown_key_message(client):
    r = client.post("/api/park", json={"robots": ROBOTS, "boundary": BOX, "colour": "red"})
    assert r.json()["message"] == "colour: unknown key (got 'red')"


def test_non_finite_teleop_is_rejected(app, client):
    before = fingerprint(sup_of(app))
    r = client.post(
        "/api/teleop",
        content='{"robot": "s1", "v_mps": NaN, "omega_radps": 0}',
        headers={"Content-Type": "application/json"},
    )
    assert r.status_code == 422 and r.json()["message"].startswith("v_mps")
    assert fingerprint(sup_of(app)) == before


# ----------------------------------------------------------------------------- goto, stop, resume


def test_goto_sets_the_goal_in_degrees_and_drives_there(app, client):
    r = client.post("/api/goto", json={"robot": "s1", "pose": [4.0, 1.5, 90.0]})
    assert r.status_code == 200 and r.json()["accepted"]
    assert np.allclose(sup_of(app).goals[0], [4.0, 1.5, math.pi / 2])
    step(client, 20)
    assert states_by_id(client)["s1"] == "moving"
    assert state(client)["goals"][0] == [4.0, 1.5, 90.0]


def test_new_goal_while_moving_replaces_the_old_one(app, client):
    client.post("/api/goto", json={"robot": "s1", "pose": [5.0, 1.5, 0.0]})
    step(client, 20)
    assert sup_of(app).sim.vel[0, 0] != 0.0
    r = client.post("/api/goto", json={"robot": "s1", "pose": [3.0, 1.2, 180.0]})
    assert r.status_code == 200
    step(client, 1)
    assert state(client)["goals"][0] == [3.0, 1.2, 180.0]
    assert states_by_id(client)["s1"] == "moving"


def test_new_goal_for_a_skid_of_a_park_group(app, client):
    client.post("/api/park", json={"robots": ROBOTS, "boundary": BOX})
    step(client, 10)
    assert (
        client.post("/api/goto", json={"robot": "s1", "pose": [3.0, 1.2, 0.0]}).status_code == 200
    )
    r = client.post("/api/sim/step", json={"ticks": 5})
    assert r.status_code == 200, r.text
    assert state(client)["goals"][0] == [3.0, 1.2, 0.0]


def test_goto_into_the_wall_is_refused(app, client):
    before = fingerprint(sup_of(app))
    r = client.post("/api/goto", json={"robot": "s1", "pose": [0.1, 4.0, 0.0]})
    assert r.status_code == 409
    assert r.json()["reason"].startswith("goto.pose: robot 's1' would overlap wall")
    assert fingerprint(sup_of(app)) == before


def test_goto_unknown_robot_is_refused(client):
    r = client.post("/api/goto", json={"robot": "x9", "pose": [5, 4, 0]})
    assert r.status_code == 409 and r.json()["reason"] == "goto.robot: unknown robot 'x9'"


def test_stop_and_resume_one_skid(app, client):
    client.post("/api/park", json={"robots": ROBOTS, "boundary": BOX})
    step(client, 20)
    r = client.post("/api/stop", json={"robots": ["s2"]})
    assert r.status_code == 200 and r.json()["detail"]["robots"] == ["s2"]
    step(client, 30)  # a stop brakes at the skid's deceleration limit (not an e-stop)
    assert sup_of(app).sim.vel[1, 0] == 0.0
    held = sup_of(app).sim.poses[1].copy()
    step(client, 20)
    st = states_by_id(client)
    assert st["s2"] == "stopped"
    assert np.allclose(sup_of(app).sim.poses[1], held)  # it waits where it stopped
    assert all(st[r] != "stopped" for r in ("s1", "s3", "s4"))
    assert client.post("/api/resume", json={"robots": ["s2"]}).status_code == 200
    step(client, 20)
    assert states_by_id(client)["s2"] == "moving"
    assert not np.allclose(sup_of(app).sim.poses[1], held)


def test_stop_unknown_robot_is_refused(app, client):
    before = fingerprint(sup_of(app))
    r = client.post("/api/stop", json={"robots": ["s1", "nobody"]})
    assert r.status_code == 409 and r.json()["reason"] == "stop: unknown robot 'nobody'"
    assert fingerprint(sup_of(app)) == before


# ----------------------------------------------------------------------------- e-stop


def test_estop_halts_every_skid_within_one_tick(app, client):
    sup = sup_of(app)
    client.post("/api/park", json={"robots": ROBOTS, "boundary": BOX})
    step(client, 30)
    assert np.all(np.abs(sup.sim.vel[:, 0]) > 0.05)  # all four are driving
    r = client.post("/api/estop")
    assert r.status_code == 200 and r.json()["accepted"]
    poses = sup.sim.poses.copy()
    step(client, 1)  # the very next tick
    assert np.all(sup.sim.vel == 0.0)
    assert np.array_equal(sup.sim.poses, poses)
    step(client, 20)
    assert np.array_equal(sup.sim.poses, poses)
    assert set(states_by_id(client).values()) == {"estopped"}
    assert state(client)["estop"] is True


def test_estop_is_latched_until_resume_all(app, client):
    client.post("/api/park", json={"robots": ROBOTS, "boundary": BOX})
    step(client, 10)
    client.post("/api/estop")
    before = fingerprint(sup_of(app))
    r = client.post("/api/resume", json={"robots": ["s1"]})
    assert r.status_code == 409 and "e-stop is latched" in r.json()["reason"]
    assert fingerprint(sup_of(app)) == before
    assert client.post("/api/resume", json={"robots": "all"}).status_code == 200
    step(client, 5)
    assert "estopped" not in states_by_id(client).values()
    assert np.any(sup_of(app).sim.vel[:, 0] != 0)


# ----------------------------------------------------------------------------- teleop


def test_teleop_drives_the_skid_and_release_hands_it_back(app, client):
    sup = sup_of(app)
    x0 = sup.sim.poses[0, 0]
    r = client.post("/api/teleop", json={"robot": "s1", "v_mps": 0.4, "omega_radps": 0.0})
    assert r.status_code == 200
    # Re-sent like a held stick (every 2 ticks = 0.1 s, as the browser does at speed 1).
    for _ in range(10):
        step(client, 2)
        client.post("/api/teleop", json={"robot": "s1", "v_mps": 0.4, "omega_radps": 0.0})
    assert states_by_id(client)["s1"] == "teleop"
    assert sup.sim.poses[0, 0] > x0 + 0.3  # drove forward along +x (heading 0)
    assert abs(sup.sim.poses[0, 1] - 2.0) < 1e-6
    r = client.post("/api/release", json={"robot": "s1"})
    assert r.status_code == 200
    step(client, 40)
    assert states_by_id(client)["s1"] == "idle"  # no goal: autonomy holds it
    assert sup.sim.vel[0, 0] == 0.0


def test_teleop_unknown_robot_is_refused(client):
    r = client.post("/api/teleop", json={"robot": "nope", "v_mps": 0.1, "omega_radps": 0})
    assert r.status_code == 409 and r.json()["reason"] == "teleop.robot: unknown robot 'nope'"


class FakeClock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_teleop_is_kept_alive_while_the_operator_sends_and_stops_after_the_deadman():
    clock = FakeClock()
    s = Session(SMALL, running=False, clock=clock)
    s.teleop("s1", 0.5, 0.0)
    # Two simulated seconds pass in no wall time (a high speed factor): the command holds.
    s.step(40)
    assert s.sup.sim.vel[0, 0] == pytest.approx(0.5)
    # The operator stops sending: after the dead-man the supervisor's timeout stops it.
    clock.t += TELEOP_DEADMAN_S + 0.01
    s.step(40)
    assert s.sup.sim.vel[0, 0] == 0.0
    assert s.sup.modes()[0] == "teleop"


# ----------------------------------------------------------------------------- token


@pytest.fixture
def guarded():
    return create_app(SMALL, autostart=False, scenarios_dir=DATA, token=TOKEN)


@pytest.mark.parametrize(
    ("path", "body"),
    [
        ("/api/park", {"robots": ROBOTS, "boundary": BOX}),
        ("/api/park/preview", {"robots": ROBOTS, "boundary": BOX}),
        ("/api/goto", {"robot": "s1", "pose": [5, 4, 0]}),
        ("/api/stop", {"robots": "all"}),
        ("/api/resume", {"robots": "all"}),
        ("/api/teleop", {"robot": "s1", "v_mps": 0.3, "omega_radps": 0}),
        ("/api/release", {"robot": "s1"}),
        ("/api/sim", {"paused": False}),
        ("/api/sim/step", {"ticks": 3}),
        ("/api/sim/reset", None),
        ("/api/scenario", {"name": "ui-small.yaml"}),
    ],
)
def test_control_needs_the_token(guarded, path, body):
    c = TestClient(guarded)
    before = fingerprint(sup_of(guarded))
    rev = guarded.state.session.rev
    for headers in ({}, {"Authorization": "Bearer wrong"}, {"Authorization": TOKEN}):
        r = c.post(path, json=body, headers=headers)
        assert r.status_code == 401, (path, headers)
        assert "read-only" in r.json()["detail"]
    assert fingerprint(sup_of(guarded)) == before
    assert guarded.state.session.rev == rev and guarded.state.session.paused
    r = c.post(path, json=body, headers=AUTH)
    assert r.status_code == 200, r.text


def test_viewers_without_the_token_can_read(guarded):
    c = TestClient(guarded)
    for path in (
        "/api/state",
        "/api/world",
        "/api/map",
        "/api/sim",
        "/api/scenarios",
        "/api/perf",
        "/",
    ):
        assert c.get(path).status_code == 200, path
    no = {"token_required": True, "control": False, "secret_required": False}
    assert c.get("/api/auth").json() == no
    assert c.get("/api/auth", headers=AUTH).json() == {**no, "control": True}
    with c.websocket_connect("/api/ws") as ws:
        frame = ws.receive_json()
    assert frame["type"] == "state" and len(frame["robots"]) == 4


def test_estop_needs_no_token_but_releasing_it_does(guarded):
    c = TestClient(guarded)
    assert c.post("/api/estop").status_code == 200
    assert sup_of(guarded).estopped
    assert c.post("/api/resume", json={"robots": "all"}).status_code == 401
    assert sup_of(guarded).estopped
    assert c.post("/api/resume", json={"robots": "all"}, headers=AUTH).status_code == 200
    assert not sup_of(guarded).estopped


def test_without_a_token_everything_is_open(client):
    assert client.get("/api/auth").json() == {
        "token_required": False,
        "control": True,
        "secret_required": False,
    }


# ----------------------------------------------------------------------------- sim control


def test_step_pause_speed_and_reset(app, client):
    s = step(client, 5)
    assert s["t_s"] == pytest.approx(0.25) and s["ticks"] == 5 and s["paused"]
    r = client.post("/api/sim", json={"speed": 8, "paused": False})
    assert r.json()["speed"] == 8 and r.json()["paused"] is False
    r = client.post("/api/sim", json={"paused": True})
    assert r.json()["speed"] == 8 and r.json()["paused"] is True
    client.post("/api/goto", json={"robot": "s1", "pose": [5, 2, 0]})
    step(client, 10)
    rev = client.get("/api/sim").json()["rev"]
    r = client.post("/api/sim/reset")
    assert r.status_code == 200
    assert r.json()["t_s"] == 0.0 and r.json()["rev"] == rev + 1
    assert np.allclose(sup_of(app).sim.poses[0], [2.0, 2.0, 0.0])
    assert not sup_of(app).has_goal.any()


def test_pacing_runs_the_ticks_due_at_the_speed_factor():
    s = Session(SMALL, running=True, speed=2.0)
    assert s.advance(0.5) == 20  # 0.5 wall s x 2 = 1 sim s = 20 ticks of 0.05 s
    assert s.advance(0.01) == 0  # 0.02 sim s: not a whole tick yet ...
    assert s.advance(0.02) == 1  # ... 0.06 sim s now
    s.paused = True
    assert s.advance(1.0) == 0
    s.paused = False
    s.speed = 100.0
    assert s.advance(1.0) == MAX_TICKS_PER_FRAME  # falls behind instead of freezing
    assert s.sup.sim.tick == 21 + MAX_TICKS_PER_FRAME


def test_scenario_picker_lists_and_loads(app, client):
    r = client.get("/api/scenarios").json()
    assert "ui-small.yaml" in r["scenarios"] and r["current"] == "ui-small.yaml"
    client.post("/api/goto", json={"robot": "s1", "pose": [5, 2, 0]})
    r = client.post("/api/scenario", json={"name": "ui-small.yaml", "scripted": False})
    assert r.status_code == 200 and r.json()["scripted"] is False
    assert not sup_of(app).has_goal.any()
    assert client.post("/api/scenario", json={"name": "nope.yaml"}).status_code == 404


def test_a_bad_scenario_file_is_refused_and_the_current_one_stays(tmp_path):
    good = tmp_path / "good.yaml"
    good.write_text(SMALL.read_text())
    (tmp_path / "bad.yaml").write_text(
        SMALL.read_text().replace("pose: [2.0, 3.4", "pose: [2.0, 2.2")
    )
    app = create_app(good, autostart=False, scenarios_dir=tmp_path)
    c = TestClient(app)
    before = fingerprint(sup_of(app))
    r = c.post("/api/scenario", json={"name": "bad.yaml"})
    assert r.status_code == 409
    assert "robots[1].pose: robot 's2' overlaps robot 's1'" in r.json()["detail"]
    assert c.get("/api/sim").json()["file"] == "good.yaml"
    assert fingerprint(sup_of(app)) == before


def test_scenario_scripted_commands_run(tmp_path):
    text = SMALL.read_text() + (
        "commands:\n  - at_s: 0.5\n    goto: {robot: s1, pose: [5.0, 2.0, 0.0]}\n"
    )
    path = tmp_path / "scripted.yaml"
    path.write_text(text)
    c = TestClient(create_app(path, autostart=False, scenarios_dir=tmp_path))
    step(c, 11)
    assert state(c)["goals"][0] == [5.0, 2.0, 0.0]
    c.post("/api/scenario", json={"name": "scripted.yaml", "scripted": False})
    step(c, 11)
    assert state(c)["goals"][0] is None


# ----------------------------------------------------------------------------- frames, websocket


def test_delta_frames_carry_slow_parts_only_when_they_change():
    s = Session(SMALL, running=False)
    d1, full = s.encoder.frame(s.sim_extra(), want_full=True)
    assert full["full"] is True
    assert {"goals", "paths", "groups", "log", "metrics"} <= set(full)
    d2, _ = s.encoder.frame(s.sim_extra())
    assert not {"goals", "paths", "groups", "log"} & set(d2)
    s.sup.goto(
        __import__("swarmpark.world.scenario", fromlist=["GotoCmd"]).GotoCmd(
            robot="s2", pose=[5, 4, 0]
        )
    )
    s.step(1)
    d3, _ = s.encoder.frame(s.sim_extra())
    assert d3["goals"][1] == [5.0, 4.0, 0.0] and d3["goals"][0] is None
    assert d3["paths"][1] is not None and len(d3["paths"][1]) % 2 == 0
    assert d3["log"][-1]["command"] == "goto"
    # Poses: x, y (mm), heading (degrees), state index, speed.
    assert len(d3["robots"][1]) == 5 and isinstance(d3["robots"][1][3], int)


def test_websocket_streams_a_full_frame_then_deltas(app):
    with TestClient(app) as c:  # runs the lifespan: the pacing task broadcasts (paused)
        with c.websocket_connect("/api/ws") as ws:
            first = ws.receive_json()
            assert first["full"] is True and first["sim"]["paused"] is True
            assert c.post("/api/park", json={"robots": ROBOTS, "boundary": BOX}).status_code == 200
            seen_goals = None
            for _ in range(40):
                f = ws.receive_json()
                assert f["type"] == "state"
                # (The first delta may still be the one from before the park.)
                if not f["full"] and f.get("groups"):
                    seen_goals = f["goals"]
                    assert f["groups"][0]["boundary"] == BOX
                    break
            assert seen_goals is not None and all(g is not None for g in seen_goals)


def test_client_that_falls_behind_gets_a_full_frame():
    from swarmpark.server.engine import CLIENT_QUEUE, Client

    c = Client(needs_full=False)
    for k in range(CLIENT_QUEUE):
        c.offer(f"d{k}", None)
    c.offer("d-late", "FULL")  # the queue is full: drop the backlog, send everything
    assert c.queue.qsize() == 1 and c.queue.get_nowait() == "FULL"
    assert c.dropped == CLIENT_QUEUE and c.needs_full is False


# ----------------------------------------------------------------------------- factory, CLI


def test_create_app_rejects_a_bad_scenario(tmp_path):
    bad = tmp_path / "x.yaml"
    bad.write_text("name: x\nmap: {size_m: [5, 5]}\nrobots: []\n")
    with pytest.raises(ScenarioError, match="robots"):
        create_app(bad)
    with pytest.raises(FileNotFoundError, match="hangar-park.yaml"):
        create_app(None, scenarios_dir=tmp_path)


def test_default_scenario_is_the_hangar_in_the_scenarios_directory():
    repo_scenarios = ROOT / "scenarios"
    app = create_app(None, scenarios_dir=repo_scenarios, autostart=False)
    assert app.state.session.path.name == "hangar-park.yaml"


@pytest.mark.parametrize(
    ("argv", "msg"),
    [
        (["--port", "0"], "--port must be 1..65535 (got 0)"),
        (["--speed", "0"], "--speed must be"),
        (["--speed", "fast"], "invalid float value: 'fast'"),
        (["--bogus"], "unrecognized arguments: --bogus"),
        (["no/such/scenario.yaml"], "scenario: file not found"),
        (["--token", " "], "--token must not be empty"),
    ],
)
def test_serve_command_bad_input_is_one_line_and_exit_2(capsys, argv, msg):
    assert serve_command(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and msg in err and err.startswith("swarmpark serve: error:")


def test_people_are_streamed_with_their_radius(tmp_path):
    text = SMALL.read_text() + (
        "obstacles:\n"
        "  - {id: walker, radius_m: 0.35, waypoints: [[5, 7.5], [11, 7.5]], speed_mps: 1.0}\n"
        "  - polygon: [[9, 0.5], [9.5, 0.5], [9.5, 1], [9, 1]]\n"
    )
    path = tmp_path / "people.yaml"
    path.write_text(text)
    c = TestClient(create_app(path, autostart=False, scenarios_dir=tmp_path))
    world = c.get("/api/world").json()
    assert world["people"] == [{"id": "walker", "radius_m": 0.35}]
    assert world["obstacles"] == [[[9.0, 0.5], [9.5, 0.5], [9.5, 1.0], [9.0, 1.0]]]
    assert state(c)["people"] == [[5.0, 7.5]]
    step(c, 20)  # 1 s at 1 m/s along +x
    assert state(c)["people"] == [[6.0, 7.5]]


# ----------------------------------------------------------------------------- formation


def test_formation_reaches_the_api(app, client):
    """POST /api/formation is generated from the command registry like park and goto."""
    body = {"robots": ["s1", "s3"], "paths": [[[2.0, 2.0], [8.0, 2.0]]]}
    r = client.post("/api/formation", json=body)
    assert r.status_code == 200, r.text
    assert r.json()["accepted"] and r.json()["command"] == "formation"
    assert np.allclose(sup_of(app).goals[0, :2], [8.0, 2.0])
    bad = client.post("/api/formation", json={**body, "robots": ["s1", "zz"]})
    assert bad.status_code == 409
    assert "formation.robots: unknown robot 'zz'" in bad.json()["reason"]
    typo = client.post("/api/formation", json={**body, "speed": 1})
    assert typo.status_code == 422 and "speed" in typo.text


def test_an_unknown_command_has_no_route(client):
    assert client.post("/api/dance", json={}).status_code in (404, 405)
