"""The operator interface's sensing layers and per-skid panel in headless chromium (issue 16):
obstacles detected by onboard sensing and the people the fleet tracks (with velocity arrows)
are drawn, and a click on a skid shows its state, achieved speed, goal, localization error,
last velocity command and last order with the values the server has.

As in test_browser.py: uvicorn on a free loopback port in a background thread (test harness
only), Debian's chromium at /usr/bin/chromium, nothing downloaded.
"""

from __future__ import annotations

import math
import os
import time

import pytest
from helpers import DATA, ROOT
from liveserver import BROWSER_MARKS, LiveServer, chromium

ARTIFACTS = ROOT / "test-artifacts"
DOC_IMG = ROOT / "docs" / "img" / "ui-sensing-1024x768.png"
#: The colours app.js draws the layers in (DETECTED_COLOUR, TRACKED_COLOUR).
DETECTED_RGB = (208, 64, 255)
TRACKED_RGB = (255, 210, 60)

pytestmark = BROWSER_MARKS


@pytest.fixture(scope="module")
def server():
    from swarmpark.server import create_app

    with LiveServer(create_app(DATA / "ui-people.yaml", scenarios_dir=DATA, speed=2.0)) as s:
        yield s


@pytest.fixture(scope="module")
def browser():
    with chromium() as b:
        yield b


def _open(browser, server, scenario: str, n_robots: int):
    server.call("POST", "/api/scenario", {"name": scenario})
    pg = browser.new_page(viewport={"width": 1400, "height": 850})
    errors: list[str] = []
    pg.on("pageerror", lambda e: errors.append(str(e)))
    pg.goto(server.url + "/")
    pg.wait_for_function(
        f"document.querySelectorAll('#status-table tbody tr[data-state]').length === {n_robots}"
    )
    return pg, errors


def _pause_and_settle(pg, server) -> dict:
    """Pause, wait until the page shows the paused state, return the server's full frame."""
    server.call("POST", "/api/sim", {"paused": True})
    time.sleep(0.3)  # a tick under way when the pause came still finishes
    t = server.call("GET", "/api/sim")["t_s"]
    pg.wait_for_function(
        f"(() => {{ const f = window.swarmpark.S.frame; return f && f.sim.paused && "
        f"Math.abs(f.t_s - {t}) < 1e-6 && f.robot_info; }})()",
        timeout=10_000,
    )
    # The heavy layers (robot_info, detected) go out twice a second: wait for one more.
    time.sleep(0.8)
    return server.call("GET", "/api/state")


def _click_robot(pg, frame: dict, i: int) -> None:
    x, y = frame["robots"][i][:2]
    box = pg.locator("#map").bounding_box()
    sx, sy = pg.evaluate("([x, y]) => window.swarmpark.toScreen(x, y)", [x, y])
    pg.mouse.click(box["x"] + sx, box["y"] + sy)


def _canvas_has_colour(pg, x: float, y: float, rgb, half: int = 2, tol: int = 40) -> bool:
    """Whether a pixel of the map canvas within ``half`` px of world point (x, y) has ``rgb``."""
    return pg.evaluate(
        """([x, y, rgb, half, tol]) => {
            const c = document.getElementById("map"), dpr = window.devicePixelRatio || 1;
            const [sx, sy] = window.swarmpark.toScreen(x, y);
            const px = Math.round(sx * dpr), py = Math.round(sy * dpr), n = 2 * half + 1;
            const d = c.getContext("2d").getImageData(px - half, py - half, n, n).data;
            for (let k = 0; k < d.length; k += 4)
                if (Math.abs(d[k] - rgb[0]) < tol && Math.abs(d[k + 1] - rgb[1]) < tol &&
                    Math.abs(d[k + 2] - rgb[2]) < tol) return true;
            return false;
        }""",
        [x, y, list(rgb), half, tol],
    )


def _panel(pg) -> dict[str, str]:
    keys = ("id", "state", "speed", "goal", "loc", "cmd", "order")
    return {k: pg.locator(f"#rp-{k}").text_content() for k in keys}


def test_detected_obstacles_and_the_panel_of_a_skid_localizing_onboard(browser, server):
    pg, errors = _open(browser, server, "ui-sensing.yaml", 2)
    server.call("POST", "/api/sim", {"paused": False, "speed": 2.0})
    # The scripted park starts at 0 s; the crate is in view of the scans from the start.
    pg.wait_for_function(
        "(() => { const f = window.swarmpark.S.frame; return f && f.t_s > 3 && "
        "f.detected && f.detected.total > 20 && window.swarmpark.S.drawn.detected > 20; })()",
        timeout=30_000,
    )
    full = _pause_and_settle(pg, server)
    assert pg.evaluate("window.swarmpark.S.world.sensing") is True
    assert pg.locator("#robot-box").is_hidden()
    _click_robot(pg, full, 0)
    pg.wait_for_function("!document.getElementById('robot-box').classList.contains('hidden')")
    ARTIFACTS.mkdir(exist_ok=True)
    pg.screenshot(path=str(ARTIFACTS / "layers-sensing.png"))

    frame = pg.evaluate("window.swarmpark.S.frame")
    # The page holds what the server has now (paused: nothing moves).
    assert frame["robots"] == full["robots"]
    assert frame["detected"] == full["detected"]
    assert frame["robot_info"] == full["robot_info"]
    info = full["robot_info"]
    x, y, hd, state, v = full["robots"][0]
    goal = full["goals"][0]
    panel = _panel(pg)
    assert panel["id"] == "d1"
    assert panel["state"] == pg.evaluate(f"window.swarmpark.S.world.states[{state}]")
    assert panel["speed"] == f"{v:.2f} m/s"
    assert panel["goal"] == f"{goal[0]:.2f}, {goal[1]:.2f}, {goal[2]:.0f}°"
    err = info["loc_err_m"][0]
    assert 0.0 <= err < 0.5  # a skid localizing well, and the panel shows that number
    assert panel["loc"] == f"{100 * err:.1f} cm"
    cmd = info["cmd"][0]
    assert panel["cmd"] == f"v {cmd[0]:.2f} m/s, ω {cmd[1]:.2f} rad/s"
    assert full["orders"][0] == ["park", 0.0] and panel["order"] == "park at 0.0 s"

    # Every detected square is drawn (up to the cap), in the detection colour where it is.
    det = full["detected"]
    assert pg.evaluate("window.swarmpark.S.drawn.detected") == len(det["squares"]) // 2
    side = pg.evaluate("window.swarmpark.S.world.detection_square_m")
    sq = det["squares"]
    # A square of the crate's west face (x 6.5 m), away from the skids' labels.
    crate = [
        (sq[k], sq[k + 1])
        for k in range(0, len(sq), 2)
        if 6.3 <= sq[k] * side <= 6.7 and 5.0 <= sq[k + 1] * side <= 6.8
    ]
    assert crate, "the crate was not detected"
    i, j = crate[len(crate) // 2]
    assert _canvas_has_colour(pg, (i + 0.5) * side, (j + 0.5) * side, DETECTED_RGB)
    # and not where nothing was detected (open floor south of the crate)
    assert not _canvas_has_colour(pg, 8.0, 1.5, DETECTED_RGB)
    pg.close()
    assert not errors, errors


def test_tracked_people_with_velocity_arrows_and_the_panel_after_a_goto(browser, server):
    pg, errors = _open(browser, server, "ui-people.yaml", 4)
    assert server.call("POST", "/api/goto", {"robot": "s2", "pose": [6.0, 3.4, 90.0]})["accepted"]
    server.call("POST", "/api/sim", {"paused": False, "speed": 2.0})
    pg.wait_for_function(
        "(() => { const f = window.swarmpark.S.frame; return f && f.t_s > 2 && f.tracked && "
        "f.robots[1][4] > 0.1; })()",
        timeout=30_000,
    )
    full = _pause_and_settle(pg, server)
    _click_robot(pg, full, 1)
    pg.wait_for_function("document.getElementById('rp-id').textContent === 's2'")
    ARTIFACTS.mkdir(exist_ok=True)
    pg.screenshot(path=str(ARTIFACTS / "layers-people.png"))

    # The walker (0.8 m/s up and down x = 11 m) as the fleet tracks it.
    assert len(full["tracked"]) == 1
    tx, ty, vx, vy = full["tracked"][0]
    assert abs(tx - 11.0) < 0.05 and abs(math.hypot(vx, vy) - 0.8) < 0.02 and abs(vx) < 0.02
    assert pg.evaluate("window.swarmpark.S.drawn.tracked") == 1
    assert pg.evaluate("window.swarmpark.S.drawn.people") == 1
    # The arrow: drawn from the person along the velocity, one second long (0.8 m); its
    # head (filled) just short of the tip is in the tracked colour.
    speed = math.hypot(vx, vy)
    scale = pg.evaluate("window.swarmpark.S.view.scale")
    back = 4.0 / scale  # 4 px back from the tip, inside the head
    tip = (tx + vx * (1 - back / speed), ty + vy * (1 - back / speed))
    assert _canvas_has_colour(pg, *tip, TRACKED_RGB)
    behind = (tx - vx * 1.2, ty - vy * 1.2)  # nothing drawn behind the walker
    assert not _canvas_has_colour(pg, *behind, TRACKED_RGB)

    # The panel of s2 shows what the server has for it.
    x, y, hd, state, v = full["robots"][1]
    panel = _panel(pg)
    assert panel["state"] == "moving" and v > 0.1
    assert panel["speed"] == f"{v:.2f} m/s"
    assert panel["goal"] == "6.00, 3.40, 90°"
    assert panel["loc"] == "not localizing onboard"
    cmd = full["robot_info"]["cmd"][1]
    assert cmd[0] > 0.0  # it was driving when paused
    assert panel["cmd"] == f"v {cmd[0]:.2f} m/s, ω {cmd[1]:.2f} rad/s"
    assert panel["order"] == f"goto at {full['orders'][1][1]:.1f} s"
    assert full["orders"][0] is None  # s1 was never commanded
    # A stop of s2 becomes its last order.
    server.call("POST", "/api/stop", {"robots": ["s2"]})
    pg.wait_for_function("document.getElementById('rp-order').textContent.startsWith('stop at')")
    pg.close()
    assert not errors, errors


def test_the_skid_panel_and_the_layers_fit_at_1024_by_768(browser, server):
    """At 1024 x 768 the panel of a clicked skid is on screen without scrolling, next to the
    E-STOP and the map with its detections. With ``SWARMPARK_DOC_SHOTS=1`` the screenshot
    also goes to docs/img/ui-sensing-1024x768.png."""
    server.call("POST", "/api/scenario", {"name": "ui-sensing.yaml"})
    server.call("POST", "/api/sim", {"paused": False, "speed": 2.0})
    pg = browser.new_page(viewport={"width": 1024, "height": 768})
    errors: list[str] = []
    pg.on("pageerror", lambda e: errors.append(str(e)))
    pg.goto(server.url + "/")
    pg.wait_for_function(
        "(() => { const f = window.swarmpark.S.frame; return f && f.t_s > 6 && f.robot_info && "
        "window.swarmpark.S.drawn.detected > 20; })()",
        timeout=30_000,
    )
    full = _pause_and_settle(pg, server)
    _click_robot(pg, full, 0)
    pg.wait_for_function("document.getElementById('rp-id').textContent === 'd1'")
    for sel in ("#robot-box", "#estop"):
        box = pg.locator(sel).bounding_box()
        assert box is not None and box["y"] >= 0 and box["y"] + box["height"] <= 768, (sel, box)
        assert box["x"] >= 0 and box["x"] + box["width"] <= 1024, (sel, box)
    assert pg.locator("#rp-loc").text_content().endswith(" cm")
    # The link badge and "Resume all" are on screen beside the pinned e-stop, not under it
    # or scrolled off the top bar.
    estop_left = pg.locator("#estop-box").bounding_box()["x"]
    for sel in ("#conn", "#resume-all", "#sim-time"):
        box = pg.locator(sel).bounding_box()
        assert box["x"] >= 0 and box["x"] + box["width"] <= estop_left, (sel, box, estop_left)
    ARTIFACTS.mkdir(exist_ok=True)
    pg.screenshot(path=str(ARTIFACTS / "ui-sensing-1024x768.png"))
    if os.environ.get("SWARMPARK_DOC_SHOTS") == "1":
        DOC_IMG.parent.mkdir(parents=True, exist_ok=True)
        pg.screenshot(path=str(DOC_IMG))
    pg.close()
    assert not errors, errors
