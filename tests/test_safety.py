"""Operator safety at the server's edge (issue 16): an e-stop nothing delays, input refused
at the edge, cross-site requests refused, bounded bodies and viewers.

The e-stop and secret tests run uvicorn on a free loopback port in a background thread (the
test harness only) and talk to it over HTTP, as an operator's browser would.
"""

from __future__ import annotations

import json
import math
import time
import urllib.error
import urllib.request
import warnings
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest
from helpers import DATA
from liveserver import LiveServer
from starlette.websockets import WebSocketDisconnect

from swarmpark.core.limits import (
    MAX_BODY_BYTES,
    MAX_BOUNDARY_VERTICES,
    MAX_ID_LENGTH,
    MAX_PARK_BODY_BYTES,
)
from swarmpark.server import create_app
from swarmpark.server.deps import SECRET_HEADER
from swarmpark.server.engine import TELEOP_DEADMAN_S, Session

with warnings.catch_warnings():
    # starlette's TestClient prefers httpx2 (not installed here), as in test_server.py
    warnings.filterwarnings("ignore", message=".*httpx2.*")
    from fastapi.testclient import TestClient

SMALL = DATA / "ui-small.yaml"
ROBOTS = ["s1", "s2", "s3", "s4"]
BOX = [[6.5, 2.0], [10.5, 2.0], [10.5, 6.0], [6.5, 6.0]]
SECRET = "s3cret-for-tests"


def _circle(n: int, cx: float, cy: float, r: float) -> list[list[float]]:
    th = np.linspace(0.0, 2 * math.pi, n, endpoint=False)
    return np.column_stack([cx + r * np.cos(th), cy + r * np.sin(th)]).round(6).tolist()


# ----------------------------------------------------------------------------- the e-stop


def test_estop_during_heavy_previews_and_a_park_halts_every_skid_within_half_a_second():
    app = create_app(SMALL, scenarios_dir=DATA, speed=1.0)
    with LiveServer(app, log_level="error") as srv:
        for k, rid in enumerate(ROBOTS):
            code, _ = srv.status_call(
                "POST", "/api/goto", {"robot": rid, "pose": [9.0, 1.5 + 1.6 * k, 0]}
            )
            assert code == 200
        deadline = time.monotonic() + 10
        while True:  # wait until they drive
            _, st = srv.status_call("GET", "/api/state")
            if all(r[4] > 0.05 for r in st["robots"]):
                break
            assert time.monotonic() < deadline, "the skids never started"
            time.sleep(0.05)
        heavy = [
            ("/api/park/preview", {"robots": ROBOTS, "boundary": _circle(20_000, 6, 4, 3.5)}),
            ("/api/park/preview", {"robots": ROBOTS, "boundary": _circle(2_000, 6, 4, 3.5)}),
            ("/api/park/preview", {"robots": ROBOTS, "boundary": _circle(2_000, 6, 4, 3.4)}),
            ("/api/park", {"robots": ROBOTS, "boundary": _circle(2_000, 6, 4, 3.3)}),
        ]
        with ThreadPoolExecutor(len(heavy)) as pool:
            t_sent = time.monotonic()
            futures = [pool.submit(srv.status_call, "POST", p, b) for p, b in heavy]
            time.sleep(0.3)  # the bodies are read and the work is under way
            t0 = time.monotonic()
            code, out = srv.status_call("POST", "/api/estop")
            answered = time.monotonic() - t0
            assert code == 200 and out["accepted"]
            halted = None
            while time.monotonic() - t0 < 3.0:
                _, st = srv.status_call("GET", "/api/state")
                if all(r[4] == 0.0 for r in st["robots"]) and st["estop"]:
                    halted = time.monotonic() - t0
                    break
                time.sleep(0.01)
            busy = not futures[0].done()  # the 20,000-vertex preview is still being worked out
            codes = [f.result()[0] for f in futures]
            preview_s = time.monotonic() - t_sent
        print(
            f"estop answered {answered:.3f} s, halted {halted} s, previews took {preview_s:.2f} s"
        )
        assert answered < 0.5, answered
        assert halted is not None and halted <= 0.5, halted
        # Every preview and the park were worked out, the 20,000-vertex one included (its
        # body, about 440 kB, is under the park requests' cap), and it ran past the halt.
        assert codes == [200, 200, 200, 200], codes
        assert busy, f"the 20,000-vertex preview ended before the halt ({preview_s:.2f} s)"
        assert app.state.session.error is None


def test_a_failed_tick_holds_the_skids_raises_an_alarm_and_keeps_the_orders(monkeypatch):
    s = Session(SMALL, running=True)
    s.sup.command("goto", {"robot": "s1", "pose": [9.0, 2.0, 0.0]})
    s.step(10)
    goals = s.sup.goals.copy()

    def boom():
        raise FloatingPointError("injected")

    monkeypatch.setattr(s.sup, "tick", boom)
    s.step(1)
    assert s.paused and "injected" in s.error
    assert s.alarms[-1]["kind"] == "tick-error" and "injected" in s.alarms[-1]["text"]
    assert s.sup.link._hold.all()  # every skid held on the link
    assert np.array_equal(s.sup.goals, goals) and s.sup.has_goal[0]  # orders kept
    monkeypatch.undo()
    s.paused, s.error = False, None
    s.step(1)
    frame = s.snapshot()
    assert frame["alarms"][-1]["kind"] == "tick-error"


# ----------------------------------------------------------------------------- input at the edge


@pytest.fixture
def client():
    return TestClient(create_app(SMALL, autostart=False, scenarios_dir=DATA))


def _raw_post(client, path, text):
    return client.post(path, content=text, headers={"Content-Type": "application/json"})


@pytest.mark.parametrize(
    ("path", "body", "field"),
    [
        ("/api/goto", '{"robot": "s1", "pose": [NaN, 2, 0]}', "pose"),
        ("/api/goto", '{"robot": "s1", "pose": [5, 2, Infinity]}', "pose"),
        ("/api/goto", '{"robot": "s1", "pose": [1e9, 1e9, 0]}', "pose"),
        ("/api/goto", '{"robot": "s1", "pose": [50, 2, 0]}', "pose"),
        ("/api/goto", '{"robot": "s1", "pose": ["NaN", 2, 0]}', "pose"),
        ("/api/park", '{"robots": ["s1"], "boundary": [[-9, -9], [-5, -9], [-5, -5]]}', "boundary"),
        ("/api/park/preview", '{"robots": ["s1"], "boundary": [[1, 1], [2, NaN], [2, 2]]}', "boundary"),
        ("/api/park", '{"robots": ["s1"], "boundary": [[1, 1], [2, 1], [2, 2]], "heading_deg": NaN}', "heading_deg"),
        ("/api/teleop", '{"robot": "s1", "v_mps": NaN, "omega_radps": 0}', "v_mps"),
        ("/api/formation", '{"robots": ["s1", "s2"], "paths": [[[2, 2], [99, 2]]]}', "paths"),
    ],
)  # fmt: skip
def test_non_finite_and_off_map_input_is_a_422_and_the_simulation_keeps_running(
    client, path, body, field
):
    r = _raw_post(client, path, body)
    assert r.status_code == 422, r.text
    assert r.json()["message"].startswith(field), r.json()["message"]
    s = client.post("/api/sim/step", json={"ticks": 3})
    assert s.status_code == 200 and s.json()["error"] is None and s.json()["ticks"] == 3
    assert json.loads(client.get("/api/state").text)  # still strict JSON


def test_ids_robot_lists_and_polygons_are_capped(client):
    long_id = "x" * 200_000
    r = client.post("/api/goto", json={"robot": long_id, "pose": [5, 2, 0]})
    assert r.status_code == 422 and len(r.text) < 5_000
    assert f"at most {MAX_ID_LENGTH} characters" in r.json()["message"]
    r = client.post("/api/stop", json={"robots": ["s1"] * 6000})
    assert r.status_code == 422 and r.json()["message"].startswith("robots")
    # A park boundary may be a dense survey (up to MAX_BOUNDARY_VERTICES), not more.
    big = _circle(MAX_BOUNDARY_VERTICES + 1, 6, 4, 2)
    r = client.post("/api/park/preview", json={"robots": ROBOTS, "boundary": big})
    assert r.status_code == 422 and r.json()["message"].startswith("boundary")
    assert f"at most {MAX_BOUNDARY_VERTICES} items" in r.json()["message"], r.json()["message"]
    # Other polygons (a formation's paths) keep the general cap of 2,000.
    path = _circle(3000, 6, 4, 2)
    r = client.post("/api/formation", json={"robots": ["s1", "s2"], "paths": [path, path]})
    assert r.status_code == 422 and r.json()["message"].startswith("paths"), r.text[:300]
    # Nothing of it reached the log or the frames.
    assert long_id not in client.get("/api/state").text


def test_a_5_mb_body_is_refused_with_413_within_a_second():
    app = create_app(SMALL, autostart=False, scenarios_dir=DATA)
    with LiveServer(app, log_level="error") as srv:
        body = b'{"robot": "' + b"x" * 5_000_000 + b'", "pose": [1, 1, 0]}'
        req = urllib.request.Request(srv.url + "/api/goto", data=body, method="POST")
        req.add_header("Content-Type", "application/json")
        t0 = time.monotonic()
        with pytest.raises((urllib.error.HTTPError, ConnectionError, urllib.error.URLError)) as e:
            urllib.request.urlopen(req, timeout=5)
        took = time.monotonic() - t0
        if isinstance(e.value, urllib.error.HTTPError):
            assert e.value.code == 413
        assert took < 1.0, took
        # Under the cap, the same path still works.
        assert srv.status_call("POST", "/api/goto", {"robot": "s1", "pose": [5, 2, 0]})[0] == 200
    c = TestClient(create_app(SMALL, autostart=False, scenarios_dir=DATA))
    r = c.post("/api/goto", content=b"x" * (MAX_BODY_BYTES + 1))
    assert r.status_code == 413 and "over the limit" in r.json()["message"]
    # The park requests have their own, larger cap (a dense boundary); past it, 413 too.
    for path in ("/api/park", "/api/park/preview"):
        r = c.post(path, content=b"x" * (MAX_PARK_BODY_BYTES + 1))
        assert r.status_code == 413 and f"limit of {MAX_PARK_BODY_BYTES}" in r.json()["message"]
        r = c.post(path, content=b"x" * (MAX_BODY_BYTES + 1))
        assert r.status_code == 422  # read and parsed: not JSON, but not too big


# ----------------------------------------------------------------------------- origin, host, secret


def test_cross_origin_post_and_websocket_and_a_foreign_host_are_refused(client):
    rev = client.get("/api/sim").json()["rev"]
    for origin in ("http://evil.example", "null", "http://127.0.0.1:9"):
        r = client.post("/api/sim/reset", headers={"Origin": origin})
        assert r.status_code == 403 and "origin" in r.json()["message"], origin
        with pytest.raises(WebSocketDisconnect):
            with client.websocket_connect("/api/ws", headers={"Origin": origin}) as ws:
                ws.receive_json()
    assert client.get("/api/sim").json()["rev"] == rev  # nothing was reset
    r = client.get("/api/state", headers={"Host": "attacker.example"})
    assert r.status_code == 400 and "host" in r.json()["message"]
    # The server's own origin, an IP literal host and configured origins are accepted.
    assert client.post("/api/sim/reset", headers={"Origin": "http://testserver"}).status_code == 200
    assert client.get("/api/sim", headers={"Host": "10.1.2.3:8000"}).status_code == 200
    with client.websocket_connect("/api/ws", headers={"Origin": "http://testserver"}) as ws:
        assert ws.receive_json()["type"] == "state"
    other = TestClient(
        create_app(
            SMALL,
            autostart=False,
            scenarios_dir=DATA,
            allowed_origins=["https://console.example"],
            allowed_hosts=["ship.local"],
        )
    )
    assert (
        other.post("/api/estop", headers={"Origin": "https://console.example"}).status_code == 200
    )
    assert other.get("/api/sim", headers={"Host": "ship.local:8000"}).status_code == 200


def test_control_needs_the_per_server_secret_but_the_estop_does_not():
    app = create_app(SMALL, autostart=False, scenarios_dir=DATA, secret=SECRET)
    c = TestClient(app)
    assert c.get("/api/auth").json()["secret_required"] is True
    assert c.get("/api/auth").json()["control"] is False
    for path, body in (
        ("/api/sim/reset", None),
        ("/api/goto", {"robot": "s1", "pose": [5, 2, 0]}),
        ("/api/sim", {"paused": False}),
    ):
        r = c.post(path, json=body)
        assert r.status_code == 403 and SECRET_HEADER in r.json()["detail"], path
        r = c.post(path, json=body, headers={SECRET_HEADER: "wrong"})
        assert r.status_code == 403
        assert c.post(path, json=body, headers={SECRET_HEADER: SECRET}).status_code == 200
    assert c.get("/api/auth", headers={SECRET_HEADER: SECRET}).json()["control"] is True
    assert c.post("/api/estop").status_code == 200 and app.state.session.sup.estopped


def test_viewers_are_capped(monkeypatch):
    import swarmpark.server.routers.state as state_router

    monkeypatch.setattr(state_router, "MAX_VIEWERS", 2)
    c = TestClient(create_app(SMALL, autostart=False, scenarios_dir=DATA))
    with c.websocket_connect("/api/ws") as a, c.websocket_connect("/api/ws") as b:
        a.receive_json(), b.receive_json()
        with pytest.raises(WebSocketDisconnect) as e:
            with c.websocket_connect("/api/ws") as third:
                third.receive_json()
        assert e.value.code == 1013


def test_a_viewer_that_never_reads_is_dropped_from_the_broadcast():
    from swarmpark.server.engine import CLIENT_QUEUE, MAX_OVERFLOWS, Client

    s = Session(SMALL, running=False)
    slow = Client()
    s.clients.add(slow)
    for _ in range((CLIENT_QUEUE + 2) * (MAX_OVERFLOWS + 2)):  # it overflows every few frames
        s.broadcast()
    assert slow.closed and slow not in s.clients


# ----------------------------------------------------------------------------- teleop, release


class FakeClock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_release_is_final_for_teleop_requests_in_flight():
    clock = FakeClock()
    s = Session(SMALL, running=False, clock=clock)
    assert s.teleop("s1", 0.3, 0.0).accepted
    assert s.release("s1").accepted
    clock.t += 0.05  # a key-repeat request sent before the release arrives after it
    late = s.teleop("s1", 0.3, 0.0)
    assert not late.accepted and "released" in late.reason
    assert not s.sup.teleop[0]
    clock.t += TELEOP_DEADMAN_S  # a deliberate take-over later works
    assert s.teleop("s1", 0.3, 0.0).accepted and s.sup.teleop[0]


def test_teleop_goes_through_the_collision_monitor_and_stops_before_contact():
    clock = FakeClock()
    s = Session(SMALL, running=False, clock=clock)
    # s2 parks right in front of s1's nose, then the operator drives s1 straight at it.
    assert s.sup.command("goto", {"robot": "s2", "pose": [5.0, 2.0, 0.0]}).accepted
    s.step(400)
    assert np.hypot(*(s.sup.sim.poses[1, :2] - [5.0, 2.0])) < 0.2
    assert s.teleop("s1", 0.8, 0.0).accepted
    s.step(300)  # 15 s at 0.8 m/s would be 12 m: far past s2 without the monitor
    gap = s.sup.sim.poses[1, 0] - s.sup.sim.poses[0, 0]
    assert 1.2 < gap < 2.5, gap  # stopped short of s2 (skids are 1.2 m long), after moving
    assert s.sup.sim.vel[0, 0] == pytest.approx(0.0, abs=1e-6)
    assert s.sup.metrics.collisions == []
    assert not [a for a in s.alarms if a["kind"] == "teleop-contact"]


def test_a_crowd_of_viewers_gets_frames_in_turns(monkeypatch):
    from swarmpark.server import viewers
    from swarmpark.server.engine import Client

    monkeypatch.setattr(viewers, "SENDS_PER_FRAME", 2)
    s = Session(SMALL, running=False)
    crowd = [Client() for _ in range(4)]  # stride 2: every viewer gets every other frame
    s.clients.update(crowd)
    got = []
    held = [dict() for _ in crowd]  # what each viewer has merged, as the page does
    missed_slow = [False] * 4
    kinds = []
    for k in range(8):
        if k == 3:  # a new goal: the next frame carries a slow part (goals)
            s.sup.command("goto", {"robot": "s1", "pose": [9.0, 2.0, 0.0]})
        s.broadcast()
        got.append([c.queue.qsize() for c in crowd])
        slow = s.encoder.last_had_slow
        for j, c in enumerate(crowd):  # the viewers read what they got
            if c.queue.empty():
                missed_slow[j] |= slow
                continue
            msg = json.loads(c.queue.get_nowait())
            # Whole after a skipped frame that carried a slow part (or the first), else a
            # delta: the skipped frames changed nothing a delta would not carry.
            assert msg["full"] is (missed_slow[j] or not held[j]), (k, j, msg["full"])
            kinds.append(msg["full"])
            missed_slow[j] = False
            held[j] = msg if msg["full"] else {**held[j], **msg}
    assert True in kinds and False in kinds  # both happened
    full = s.snapshot()
    for h in held:  # every viewer holds the current goals
        assert h["goals"] == full["goals"]
    sent = np.array(got)
    assert sent.sum(axis=1).tolist() == [2] * 8  # two sends per frame, not four
    assert sent.sum(axis=0).tolist() == [4] * 4  # everyone gets half of the frames
