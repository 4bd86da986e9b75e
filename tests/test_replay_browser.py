"""Replay of a recorded run in headless chromium: the timeline seeks, the skids are drawn
where the recording has them. With ``SWARMPARK_DOC_SHOTS=1`` it also refreshes the
screenshot in docs/img/replay.png."""

from __future__ import annotations

import os
import shutil
import time

import numpy as np
import pytest
from helpers import DATA, ROOT
from liveserver import BROWSER_MARKS, LiveServer, chromium

ARTIFACTS = ROOT / "test-artifacts"
DOC_IMG = ROOT / "docs" / "img" / "replay.png"

pytestmark = BROWSER_MARKS


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    from swarmpark.apps.run import run_world
    from swarmpark.record import Recorder
    from swarmpark.record.sinks import McapSink
    from swarmpark.world.scenario import build_world, load_scenario

    path = tmp_path_factory.mktemp("replay") / "run.mcap"
    world = build_world(load_scenario(DATA / "rec-small.yaml"))
    run_world(world, observers=[Recorder([McapSink(path)])])
    return path


@pytest.fixture(scope="module")
def replay_server(recording):
    from swarmpark.record.reader import load_recording
    from swarmpark.record.replay import create_replay_app

    rec = load_recording(recording)
    with LiveServer(create_replay_app(rec)) as srv:
        yield srv, rec


def test_replay_seeks_and_draws_the_recorded_poses(replay_server):
    srv, rec = replay_server
    with chromium() as browser:
        pg = browser.new_page(viewport={"width": 1400, "height": 850})
        errors: list[str] = []
        pg.on("pageerror", lambda e: errors.append(str(e)))
        pg.goto(srv.url + "/")
        pg.wait_for_function(
            "document.querySelectorAll('#status-table tbody tr[data-state]').length === 3"
        )
        assert pg.is_visible("#replay-bar") and not pg.is_visible("#estop")

        # Seek with the slider (as a user drags it) to 4.0 s.
        pg.eval_on_selector(
            "#replay-seek",
            "(e) => { e.value = '4.0'; e.dispatchEvent(new Event('input')); "
            "e.dispatchEvent(new Event('change')); }",
        )
        pg.wait_for_function("window.swarmpark.S.frame && window.swarmpark.S.frame.t_s === 4")
        pg.wait_for_function(
            "document.getElementById('replay-time').textContent.startsWith('4.0 / 6.0')"
        )
        k = rec.index_at(4.0)
        drawn = pg.evaluate("window.swarmpark.S.frame.robots")
        for row, pose in zip(drawn, rec.poses[k], strict=True):
            assert row[0] == pytest.approx(pose[0], abs=1e-3)
            assert row[1] == pytest.approx(pose[1], abs=1e-3)
            assert row[2] == pytest.approx(np.rad2deg(pose[2]), abs=0.1)
        # The skid is drawn at its recorded place: the canvas pixel there is the skid colour.
        box = pg.locator("#map").bounding_box()
        sx, sy = pg.evaluate(
            "([x, y]) => window.swarmpark.toScreen(x, y)", list(rec.poses[k, 0, :2])
        )
        pixel = pg.evaluate(
            "([x, y]) => { const c = document.getElementById('map'); const r = window.devicePixelRatio || 1;"
            " return Array.from(c.getContext('2d').getImageData(Math.round(x * r), Math.round(y * r), 1, 1).data); }",
            [sx, sy],
        )
        empty = pg.evaluate(
            "([x, y]) => { const c = document.getElementById('map'); const r = window.devicePixelRatio || 1;"
            " return Array.from(c.getContext('2d').getImageData(Math.round(x * r), Math.round(y * r), 1, 1).data); }",
            list(pg.evaluate("([x, y]) => window.swarmpark.toScreen(x, y)", [2.0, 6.9])),
        )
        assert box["width"] > 0 and pixel != empty
        # The goals and the command log at 4 s, as in the recording.
        assert pg.evaluate("window.swarmpark.S.frame.goals.every((g) => g !== null)")
        assert "goto s3" not in pg.inner_text("#log") and "refused" in pg.inner_text("#log")
        ARTIFACTS.mkdir(exist_ok=True)
        pg.screenshot(path=str(ARTIFACTS / "replay.png"))
        if os.environ.get("SWARMPARK_DOC_SHOTS"):  # refresh the picture in docs/
            shutil.copy(ARTIFACTS / "replay.png", DOC_IMG)

        # Seek back to the start: the skids are at their start poses; play runs the clock.
        pg.eval_on_selector(
            "#replay-seek",
            "(e) => { e.value = '0'; e.dispatchEvent(new Event('input')); e.dispatchEvent(new Event('change')); }",
        )
        pg.wait_for_function("window.swarmpark.S.frame.t_s === 0")
        assert pg.evaluate("window.swarmpark.S.frame.robots")[0][:2] == [2.0, 2.0]
        pg.select_option("#replay-speed", "4")
        pg.click("#replay-play")
        pg.wait_for_function("window.swarmpark.S.frame.t_s >= 1.0", timeout=10000)
        pg.click("#replay-play")  # pause
        pg.wait_for_function("window.swarmpark.S.frame.sim.paused === true")
        t = pg.evaluate("window.swarmpark.S.frame.t_s")
        time.sleep(0.3)
        assert pg.evaluate("window.swarmpark.S.frame.t_s") == t
        assert srv.call("POST", "/api/replay", {}, timeout=10)["speed"] == 4.0
    assert not errors, errors
