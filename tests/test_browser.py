"""End-to-end tests of the operator interface in headless chromium (Playwright).

The server runs with uvicorn on a free localhost port in a background thread (test harness
only: the core still ticks on the server's event loop). The browser is Debian's chromium at
/usr/bin/chromium; nothing is downloaded. Screenshots go to test-artifacts/.
"""

from __future__ import annotations

import os
from pathlib import Path

import liveserver
import pytest
from helpers import DATA, ROOT
from liveserver import BROWSER_MARKS, chromium

SMALL = DATA / "ui-small.yaml"
ARTIFACTS = ROOT / "test-artifacts"
TOKEN = "browser-token"
ROBOTS = ["s1", "s2", "s3", "s4"]
BOX = [(6.5, 2.0), (10.5, 2.0), (10.5, 6.0), (6.5, 6.0)]
#: Simulated seconds per wall second: parking the four skids takes ~15 s simulated.
SPEED = 8.0
DT_S = 0.05

pytestmark = BROWSER_MARKS


class LiveServer(liveserver.LiveServer):
    """The small UI scenario served live; ``call`` sends ``token`` as a bearer token."""

    def __init__(self, **kwargs) -> None:
        from swarmpark.server import create_app

        super().__init__(create_app(SMALL, scenarios_dir=DATA, speed=SPEED, **kwargs))

    def call(self, method: str, path: str, body=None, token: str | None = None) -> dict:
        headers = {"Authorization": f"Bearer {token}"} if token else None
        return super().call(method, path, body, headers=headers, timeout=10)


@pytest.fixture(scope="module")
def server():
    with LiveServer() as s:
        yield s


@pytest.fixture(scope="module")
def browser():
    with chromium() as b:
        yield b


@pytest.fixture
def page(browser, server):
    server.call("POST", "/api/scenario", {"name": "ui-small.yaml"})  # a fresh start
    server.call("POST", "/api/sim", {"paused": False, "speed": SPEED})
    pg = browser.new_page(viewport={"width": 1400, "height": 850})
    errors: list[str] = []
    pg.on("pageerror", lambda e: errors.append(str(e)))
    pg.goto(server.url + "/")
    pg.wait_for_function(
        "document.querySelectorAll('#status-table tbody tr[data-state]').length === 4"
    )
    yield pg
    pg.close()
    assert not errors, errors


def shot(pg, name: str) -> Path:
    ARTIFACTS.mkdir(exist_ok=True)
    path = ARTIFACTS / name
    pg.screenshot(path=str(path))
    return path


def screen(pg, x: float, y: float) -> tuple[float, float]:
    """Page coordinates of a world point (the UI's own view transform)."""
    box = pg.locator("#map").bounding_box()
    sx, sy = pg.evaluate("([x, y]) => window.swarmpark.toScreen(x, y)", [x, y])
    return box["x"] + sx, box["y"] + sy


def px_m(pg) -> float:
    return pg.evaluate("window.swarmpark.S.view.scale")


def table_states(pg) -> dict[str, str]:
    return pg.evaluate(
        "Object.fromEntries([...document.querySelectorAll('#status-table tbody tr')]"
        ".map(r => [r.dataset.robot, r.dataset.state]))"
    )


def drag(pg, a, b, steps=8) -> None:
    pg.mouse.move(*a)
    pg.mouse.down()
    pg.mouse.move(*b, steps=steps)
    pg.mouse.up()


def box_select_all(pg) -> None:
    drag(pg, screen(pg, 1.0, 1.2), screen(pg, 3.5, 7.2))
    pg.wait_for_function("document.getElementById('sel-count').textContent === '(4)'")


def set_speed(server, speed: float) -> None:
    # Slower where the test must see a skid while it is on its way (the machine may be busy).
    server.call("POST", "/api/sim", {"speed": speed})


def moving_rows(pg) -> int:
    return pg.evaluate(
        "[...document.querySelectorAll('#status-table tbody tr')]"
        ".filter(r => r.dataset.state === 'moving').length"
    )


def test_drag_box_draw_boundary_park_and_see_them_parked(page, server):
    pg = page
    set_speed(server, 4.0)
    box_select_all(pg)
    assert pg.inner_text("#sel-list").split() == ROBOTS

    # The boundary as a polygon: click the vertices, double-click the last one to close.
    pg.click("#tool-polygon")
    for v in BOX[:-1]:
        pg.mouse.click(*screen(pg, *v))
    pg.mouse.dblclick(*screen(pg, *BOX[-1]))
    drawn = pg.evaluate("window.swarmpark.S.boundary")
    tol = 2.0 / px_m(pg)  # two pixels
    assert len(drawn) == 4
    for (x, y), (bx, by) in zip(drawn, BOX, strict=True):
        assert abs(x - bx) < tol and abs(y - by) < tol

    pg.wait_for_function(
        "document.getElementById('park-status').textContent.startsWith('Preview: 4 goals')"
    )
    preview = pg.evaluate("window.swarmpark.S.preview")
    assert preview["robots"] == ROBOTS and len(preview["goals"]) == 4
    for gx, gy, _ in preview["goals"]:
        assert 6.5 < gx < 10.5 and 2.0 < gy < 6.0
    assert server.call("GET", "/api/state")["goals"] == [None] * 4  # a preview commits nothing
    shot(pg, "ui-preview.png")

    pg.click("#park-confirm")
    pg.wait_for_function(
        "window.swarmpark.S.frame.robots.filter(r => Math.abs(r[4]) > 0.2).length >= 3"
    )
    if moving_rows(pg) >= 3:  # on the way, with their paths (the picture in docs/ui.md)
        shot(pg, "ui-parking.png")
    pg.wait_for_function(
        "[...document.querySelectorAll('#status-table tbody tr')].every(r => r.dataset.state === 'parked')",
        timeout=60000,
    )
    shot(pg, "ui-parked.png")

    st = server.call("GET", "/api/state")
    group = st["groups"][0]
    assert sorted(group["robots"]) == ROBOTS and group["method"] == "stacking"
    for x, y, _, _, _ in st["robots"]:
        assert 6.5 < x < 10.5 and 2.0 < y < 6.0
    log = [o for o in st["log"] if o["command"] == "park"]
    assert log and log[-1]["accepted"]


def test_rectangle_boundary_with_another_method_and_heading(page, server):
    pg = page
    box_select_all(pg)
    pg.select_option("#park-method", "convex")
    pg.fill("#park-heading", "90")
    pg.click("#tool-rect")
    drag(pg, screen(pg, 6.5, 1.5), screen(pg, 11.0, 6.5))
    pg.wait_for_function(
        "document.getElementById('park-status').textContent.startsWith('Preview:')"
        " || document.getElementById('park-status').classList.contains('bad')"
    )
    status = pg.inner_text("#park-status")
    preview = pg.evaluate("window.swarmpark.S.preview")
    if "goals" in preview:
        assert "convex" in status and all(abs(g[2] - 90) < 1e-6 for g in preview["goals"])
    else:  # a layout the method cannot make is refused with the reason, shown to the operator
        assert status == preview["error"] and status.startswith("refused:")
        assert pg.is_disabled("#park-confirm")


def options(pg, sel: str) -> list[dict]:
    return pg.evaluate(
        f"[...document.querySelectorAll('{sel} option')]"
        ".map(o => ({name: o.value, description: o.title}))"
    )


def test_park_choices_and_limits_are_read_from_the_api(browser, server):
    """The method and assignment selects list what GET /api/meta lists (a method registered
    on the server shows up without touching the page), and the inputs take its limits."""
    from swarmpark.layout import LAYOUT_METHODS
    from swarmpark.layout.methods import LayoutMethod, Stacking

    class Rows(LayoutMethod):  # registered by subclassing, as a plugin would be
        name = "test-rows"
        description = "stacking by rows (registered by a test)"
        solve = Stacking.solve
        fill = Stacking.fill

    try:
        meta = server.call("GET", "/api/meta")
        pg = browser.new_page(viewport={"width": 1400, "height": 850})
        pg.goto(server.url + "/")
        pg.wait_for_function("document.querySelectorAll('#park-method option').length > 0")
        assert options(pg, "#park-method") == meta["layout_methods"]
        assert [m["name"] for m in meta["layout_methods"]][-1] == "test-rows"
        assert options(pg, "#park-assign") == meta["assignment_costs"]
        assert pg.input_value("#park-method") == meta["defaults"]["method"] == "stacking"
        assert pg.input_value("#park-assign") == meta["defaults"]["assignment"]
        margin = meta["limits"]["margin_m"]
        assert float(pg.get_attribute("#park-margin", "min")) == margin["min"] == 0.0
        assert float(pg.input_value("#park-margin")) == margin["default"]
        pg.select_option("#park-method", "test-rows")
        assert pg.input_value("#park-method") == "test-rows"
        pg.close()
    finally:
        LAYOUT_METHODS.remove("test-rows")


def test_refused_preview_shows_the_reason_and_confirm_stays_off(page, server):
    pg = page
    box_select_all(pg)
    pg.click("#tool-rect")
    drag(pg, screen(pg, 7.0, 3.0), screen(pg, 8.0, 4.0))  # room for one skid, not four
    pg.wait_for_function("document.getElementById('park-status').classList.contains('bad')")
    assert "fit" in pg.inner_text("#park-status")
    assert pg.is_disabled("#park-confirm")
    assert server.call("GET", "/api/state")["goals"] == [None] * 4


def test_estop_key_halts_every_skid_within_one_tick(page, server):
    pg = page
    set_speed(server, 2.0)
    server.call("POST", "/api/park", {"robots": ROBOTS, "boundary": [list(v) for v in BOX]})
    pg.wait_for_function("window.swarmpark.S.frame.robots.every(r => Math.abs(r[4]) > 0.05)")
    # Space is the e-stop wherever the focus is, even on a button (which must not "click").
    pg.focus("#zoom-in")
    scale = px_m(pg)
    pg.keyboard.press("Space")
    pg.wait_for_function("window.swarmpark.S.frame.estop === true")
    assert px_m(pg) == scale
    pg.wait_for_timeout(1000)
    frame = pg.evaluate("window.swarmpark.S.frame")
    frames = pg.evaluate("window.swarmpark.S.frames")
    t_stop = [o["t_s"] for o in frame["log"] if o["command"] == "estop" and o["accepted"]][-1]
    after = [f for f in frames if f["t_s"] >= t_stop + DT_S - 1e-6]
    assert len(after) >= 5
    # From the first tick after the e-stop on, nothing moves: zero speed, identical poses.
    for f in after:
        assert all(r[4] == 0 for r in f["robots"]), f
        assert [r[:3] for r in f["robots"]] == [r[:3] for r in after[0]["robots"]]
    assert set(table_states(pg).values()) == {"estopped"}
    assert pg.is_visible("#estop-banner")
    shot(pg, "ui-estop.png")

    pg.click("#resume-all")
    pg.wait_for_function("window.swarmpark.S.frame.estop === false")
    pg.wait_for_function("window.swarmpark.S.frame.robots.some(r => Math.abs(r[4]) > 0)")
    assert "estopped" not in table_states(pg).values()


def test_stop_and_resume_one_skid_and_a_manual_goal_with_heading(page, server):
    pg = page
    set_speed(server, 1.0)
    pg.click("#status-table tbody tr[data-robot='s4']")
    assert pg.inner_text("#sel-list") == "s4"
    pg.click("#tool-goal")
    start, end = screen(pg, 6.0, 6.5), screen(pg, 6.0, 7.5)  # dragged north: 90 degrees
    drag(pg, start, end)
    pg.wait_for_function("window.swarmpark.S.frame.goals && window.swarmpark.S.frame.goals[3]")
    gx, gy, gh = server.call("GET", "/api/state")["goals"][3]
    tol = 2.0 / px_m(pg)
    assert abs(gx - 6.0) < tol and abs(gy - 6.5) < tol and abs(gh - 90.0) < 1.0
    pg.wait_for_function("Math.abs(window.swarmpark.S.frame.robots[3][4]) > 0.05")
    pg.click("#btn-stop")
    pg.wait_for_function(
        "document.querySelector(\"tr[data-robot='s4']\").dataset.state === 'stopped'"
    )
    pg.click("#btn-resume")
    pg.wait_for_function(
        "document.querySelector(\"tr[data-robot='s4']\").dataset.state === 'moving'"
    )
    # A new goal while it moves, by clicking on the map again (no drag: keeps its heading).
    pg.click("#tool-goal")
    pg.mouse.click(*screen(pg, 4.0, 7.0))
    pg.wait_for_function(
        "(g => g && Math.abs(g[0] - 4.0) < 0.1)(window.swarmpark.S.frame.goals[3])"
    )


def test_teleop_with_arrow_keys_and_release(page, server):
    pg = page
    x0, y0 = server.call("GET", "/api/state")["robots"][0][:2]
    pg.mouse.click(*screen(pg, 2.0, 2.0))  # click on s1 in the map
    assert pg.inner_text("#sel-list") == "s1"
    pg.click("#btn-teleop")
    pg.wait_for_selector("#teleop-box:not(.hidden)")
    pg.keyboard.down("ArrowUp")
    pg.wait_for_function("window.swarmpark.S.frame.robots[0][0] > %f" % (x0 + 0.5), timeout=20000)
    pg.keyboard.up("ArrowUp")
    assert table_states(pg)["s1"] == "teleop"
    x, y = server.call("GET", "/api/state")["robots"][0][:2]
    assert x > x0 + 0.5 and abs(y - y0) < 0.05  # straight ahead along +x
    pg.click("#btn-release")
    pg.wait_for_function("document.querySelector(\"tr[data-robot='s1']\").dataset.state === 'idle'")


def test_sim_controls_pause_speed_reset(page, server):
    pg = page
    pg.click("#sim-pause")
    pg.wait_for_function("window.swarmpark.S.frame.sim.paused === true")
    t = pg.evaluate("window.swarmpark.S.frame.t_s")
    pg.wait_for_timeout(500)
    assert pg.evaluate("window.swarmpark.S.frame.t_s") == t
    pg.click("#sim-faster")
    pg.wait_for_function(f"window.swarmpark.S.frame.sim.speed === {SPEED * 2}")
    pg.click("#sim-slower")
    pg.wait_for_function(f"window.swarmpark.S.frame.sim.speed === {SPEED}")
    pg.click("#sim-slower")
    pg.wait_for_function(f"window.swarmpark.S.frame.sim.speed === {SPEED / 2}")
    pg.click("#sim-pause")
    pg.wait_for_function(f"window.swarmpark.S.frame.t_s > {t + 0.5}")
    pg.click("#sim-reset")
    pg.wait_for_function(f"window.swarmpark.S.frame.t_s < {t}")
    assert pg.input_value("#scenario-select") == "ui-small.yaml"


def test_read_only_viewer_and_token_unlock(browser):
    with LiveServer(token=TOKEN) as srv:
        pg = browser.new_page(viewport={"width": 1400, "height": 850})
        pg.goto(srv.url + "/")
        pg.wait_for_function("document.getElementById('auth-badge').textContent === 'read-only'")
        for sel in ("#park-confirm", "#tool-polygon", "#sim-pause", "#resume-all"):
            assert pg.is_disabled(sel), sel
        assert pg.is_enabled("#estop")  # any console may stop the swarm
        pg.click("#estop")
        pg.wait_for_function("window.swarmpark.S.frame && window.swarmpark.S.frame.estop === true")
        pg.fill("#token-input", TOKEN)
        pg.click("#token-apply")
        pg.wait_for_function("document.getElementById('auth-badge').textContent === 'control'")
        assert pg.is_enabled("#resume-all")
        pg.click("#resume-all")
        pg.wait_for_function("window.swarmpark.S.frame.estop === false")
        pg.close()


def test_click_shift_click_pan_and_zoom(page, server):
    pg = page
    pg.mouse.click(*screen(pg, 2.0, 2.0))
    pg.keyboard.down("Shift")
    pg.mouse.click(*screen(pg, 2.0, 4.8))
    pg.mouse.click(*screen(pg, 2.0, 6.2))
    pg.mouse.click(*screen(pg, 2.0, 2.0))  # shift-click again takes it out
    pg.keyboard.up("Shift")
    assert pg.inner_text("#sel-list").split() == ["s3", "s4"]
    pg.mouse.click(*screen(pg, 5.0, 7.5))  # a click on empty floor clears the selection
    assert pg.text_content("#sel-count") == "(none)"
    scale = px_m(pg)
    pg.mouse.move(*screen(pg, 6.0, 4.0))
    pg.mouse.wheel(0, -400)  # zoom in about the cursor: the point under it stays put
    pg.wait_for_function(f"window.swarmpark.S.view.scale > {scale * 1.5}")
    box = pg.locator("#map").bounding_box()
    x, y = screen(pg, 6.0, 4.0)
    here = pg.evaluate("([x, y]) => window.swarmpark.toWorld(x, y)", [x - box["x"], y - box["y"]])
    assert abs(here[0] - 6.0) < 1e-6 and abs(here[1] - 4.0) < 1e-6
    a = screen(pg, 6.0, 4.0)
    pg.mouse.move(*a)
    pg.mouse.down(button="right")
    pg.mouse.move(a[0] + 100, a[1] + 50, steps=4)
    pg.mouse.up(button="right")
    b = screen(pg, 6.0, 4.0)
    assert abs(b[0] - a[0] - 100) < 1 and abs(b[1] - a[1] - 50) < 1  # the map moved with it
    pg.click("#zoom-fit")
    assert abs(px_m(pg) - scale) < 1e-6


# ----------------------------------------------------------------------------- operator safety


DOCS_IMG = ROOT / "docs" / "img"


@pytest.mark.parametrize("width", [800, 1024, 1366])
def test_estop_is_pinned_and_visible_at_any_width_even_with_a_token(browser, width):
    with LiveServer(token=TOKEN) as srv:
        pg = browser.new_page(viewport={"width": width, "height": 768})
        pg.goto(srv.url + "/")
        pg.wait_for_function("document.getElementById('auth-badge').textContent === 'read-only'")
        box = pg.locator("#estop").bounding_box()
        assert box["x"] >= 0 and box["x"] + box["width"] <= width, box
        assert box["y"] >= 0 and box["y"] + box["height"] <= 768, box
        # Nothing is drawn over it: the element at its centre is the button itself.
        hit = pg.evaluate(
            "([x, y]) => document.elementFromPoint(x, y).closest('#estop') !== null",
            [box["x"] + box["width"] / 2, box["y"] + box["height"] / 2],
        )
        assert hit
        assert "token" in pg.inner_text("#ro-banner")
        pg.close()


def test_estop_shows_sent_acknowledged_then_applied_and_the_ui_at_1024(browser, server, tmp_path):
    server.call("POST", "/api/scenario", {"name": "ui-small.yaml"})
    server.call("POST", "/api/sim", {"paused": False, "speed": 2.0})
    pg = browser.new_page(viewport={"width": 1024, "height": 768})
    pg.goto(server.url + "/")
    pg.wait_for_function(
        "document.querySelectorAll('#status-table tbody tr[data-state]').length === 4"
    )
    server.call("POST", "/api/park/preview", {"robots": ROBOTS, "boundary": [list(v) for v in BOX]})
    server.call("POST", "/api/park", {"robots": ROBOTS, "boundary": [list(v) for v in BOX]})
    pg.wait_for_function("window.swarmpark.S.frame.robots.every(r => Math.abs(r[4]) > 0.05)")
    # The docs' picture is refreshed only when asked (the suite leaves the checkout as it is).
    out = DOCS_IMG if os.environ.get("SWARMPARK_UPDATE_DOCS_IMG") else tmp_path
    out.mkdir(parents=True, exist_ok=True)
    pg.screenshot(path=str(out / "ui-1024x768.png"))
    assert (out / "ui-1024x768.png").stat().st_size > 10_000
    pg.keyboard.press("Space")
    pg.wait_for_function("document.getElementById('estop-state').className === 'applied'")
    assert pg.inner_text("#estop-state").startswith("applied")
    assert "estop" in pg.inner_text("#log")
    park_line = [t for t in pg.inner_text("#log").splitlines() if "park" in t][0]
    assert "s1" in park_line  # the log names the skids a command applied to
    pg.click("#resume-all")
    pg.wait_for_function("window.swarmpark.S.frame.estop === false")
    pg.close()


def test_stale_link_banner_when_frames_stop(browser):
    srv = LiveServer()
    srv.__enter__()
    try:
        pg = browser.new_page(viewport={"width": 1024, "height": 768})
        pg.goto(srv.url + "/")
        pg.wait_for_function("window.swarmpark.S.frame !== null")
        assert pg.is_hidden("#stale-banner")
    finally:
        srv.__exit__(None, None, None)
    pg.wait_for_function("!document.getElementById('stale-banner').classList.contains('hidden')")
    assert "stale" in pg.inner_text("#stale-banner")
    pg.close()


def test_secret_from_the_url_gives_control_and_without_it_the_page_says_read_only(browser):
    with LiveServer(secret="page-secret") as srv:
        pg = browser.new_page(viewport={"width": 1024, "height": 768})
        pg.goto(srv.url + "/")
        pg.wait_for_function("document.getElementById('ro-banner').textContent.includes('URL')")
        assert pg.is_disabled("#sim-pause")
        pg.close()
        pg = browser.new_page(viewport={"width": 1024, "height": 768})
        pg.goto(srv.url + "/?secret=page-secret")
        pg.wait_for_function("!document.getElementById('sim-pause').disabled")
        assert "secret" not in pg.url  # taken from the URL and hidden
        pg.click("#sim-pause")
        # (The first frame may come after the click: a null frame is not yet a failure.)
        pg.wait_for_function("window.swarmpark.S.frame?.sim.paused === true")
        pg.close()


def test_a_page_of_another_origin_cannot_command_or_watch(browser, server):
    rev = server.call("GET", "/api/sim")["rev"]
    with LiveServer() as other:  # another port: another origin
        pg = browser.new_page()
        pg.goto(other.url + "/static/style.css")
        result = pg.evaluate(
            """async (target) => {
                let post = "sent";
                try { await fetch(target + "/api/sim/reset", {method: "POST", mode: "no-cors"}); }
                catch (e) { post = "error"; }
                const ws = await new Promise((resolve) => {
                    const s = new WebSocket(target.replace("http", "ws") + "/api/ws");
                    s.onmessage = () => resolve("frame");
                    s.onclose = () => resolve("closed");
                    setTimeout(() => resolve("timeout"), 5000);
                });
                return {post, ws};
            }""",
            server.url,
        )
        pg.close()
    assert result["ws"] == "closed", result
    assert server.call("GET", "/api/sim")["rev"] == rev  # the reset was refused
