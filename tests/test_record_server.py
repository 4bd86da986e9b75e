"""The served session's record: MCAP per run, the operator audit log, the live Foxglove view."""

from __future__ import annotations

import asyncio
import json
import struct
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

with warnings.catch_warnings():
    # starlette's TestClient prefers httpx2 (not installed here); as in test_server.py.
    warnings.filterwarnings("ignore", message=".*httpx2.*")
    from fastapi.testclient import TestClient

from helpers import DATA

from swarmpark.record import messages as m
from swarmpark.record.audit import AuditLog
from swarmpark.record.live import LiveRecording
from swarmpark.record.reader import load_recording
from swarmpark.server import create_app

TOKEN = "audit-token"
AUTH = {"Authorization": f"Bearer {TOKEN}"}


def _lines(path: Path) -> list[dict]:
    return [json.loads(x) for x in path.read_text().splitlines()]


def test_serve_records_every_run_and_audits_every_command(tmp_path):
    audit = AuditLog(tmp_path / "audit.jsonl")
    live = LiveRecording(directory=tmp_path)
    app = create_app(
        DATA / "ui-small.yaml", token=TOKEN, scenarios_dir=DATA, autostart=False,
        observers=[audit, live],
    )  # fmt: skip
    goto = {"robot": "s1", "pose": [5.0, 2.0, 0.0]}
    with TestClient(app) as c:
        assert c.post("/api/goto", json=goto).status_code == 401  # no token
        assert c.post("/api/goto", json=goto, headers=AUTH).status_code == 200
        bad = {"robot": "x9", "pose": [3.0, 2.0, 0.0]}  # no such skid: refused
        assert c.post("/api/goto", json=bad, headers=AUTH).status_code == 409
        assert c.post("/api/sim/step", json={"ticks": 20}, headers=AUTH).status_code == 200
        assert c.post("/api/estop").status_code == 200  # anyone may press it
        assert c.post("/api/sim/step", json={"ticks": 2}, headers=AUTH).status_code == 200
        assert c.post("/api/sim/reset", headers=AUTH).status_code == 200  # a second run
        assert c.post("/api/sim/step", json={"ticks": 4}, headers=AUTH).status_code == 200
        load = {"name": "rec-small.yaml"}  # a third, of another scenario
        assert c.post("/api/scenario", json=load, headers=AUTH).status_code == 200
    # The audit file: every request, who, token or not, the answer; the alarms.
    rows = _lines(tmp_path / "audit.jsonl")
    cmds = [r for r in rows if r["event"] == "command"]
    assert [(r["path"], r["status"], r["accepted"], r["token_holder"]) for r in cmds[:5]] == [
        ("/api/goto", 401, False, False),
        ("/api/goto", 200, True, True),
        ("/api/goto", 409, False, True),
        ("/api/sim/step", 200, True, True),
        ("/api/estop", 200, True, False),
    ]
    assert "token" in cmds[0]["reason"] and cmds[2]["reason"]
    assert all(r["client"] and r["time"] and r["token_required"] for r in cmds)
    assert cmds[1]["request"] == goto and cmds[1]["t_s"] == 0.0
    alarms = [r for r in rows if r["event"] == "alarm"]
    assert {"kind": "estop", "latched": True}.items() <= alarms[0].items()
    assert [r["event"] for r in rows].count("start") == 3
    # Three runs, three files; the first has the commands, the alarm and its result.
    assert len(live.files) == 3 and all(f.is_file() for f in live.files)
    assert "ui-small" in live.files[1].name and "rec-small" in live.files[2].name
    first = load_recording(live.files[0])
    assert [o["path"] for o in first.operator][:3] == ["/api/goto"] * 3
    assert first.operator[0]["accepted"] is False and first.operator[4]["path"] == "/api/estop"
    assert [(c["command"], c["accepted"]) for c in first.commands] == [
        ("goto", True),
        ("goto", False),
        ("estop", True),
    ]
    assert first.alarms[0]["kind"] == "estop" and first.estop[-1]
    assert first.result is not None and first.result["scenario"] == "ui-small"
    assert first.duration_s == pytest.approx(22 * 0.05)
    second = load_recording(live.files[1])
    assert second.duration_s == pytest.approx(4 * 0.05)
    assert second.result["scenario"] == "ui-small"  # (not the scenario loaded after it)
    assert second.operator[-1]["path"] == "/api/sim/step"
    third = load_recording(live.files[2])
    assert third.result["scenario"] == "rec-small" and "/s1/scan" in third.types


async def _foxglove_client(port: int, wanted: list[str], timeout_s: float) -> dict:
    import websockets

    async with websockets.connect(
        f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1"], max_size=None
    ) as ws:
        assert ws.subprotocol == "foxglove.sdk.v1"
        channels: dict[str, dict] = {}
        got: dict[str, list] = {}
        subs: dict[int, str] = {}
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline and not all(got.get(t) for t in wanted):
            try:
                raw = await asyncio.wait_for(
                    ws.recv(), timeout=max(deadline - time.monotonic(), 0.1)
                )
            except TimeoutError:
                break
            if isinstance(raw, str):
                msg = json.loads(raw)
                if msg["op"] == "advertise":
                    new = []
                    for ch in msg["channels"]:
                        channels[ch["topic"]] = ch
                        if ch["topic"] in wanted:
                            sid = len(subs) + 1
                            subs[sid] = ch["topic"]
                            new.append({"id": sid, "channelId": ch["id"]})
                    if new:
                        await ws.send(json.dumps({"op": "subscribe", "subscriptions": new}))
                continue
            if raw[0] != 1:  # message data
                continue
            sid, _ = struct.unpack_from("<IQ", raw, 1)
            topic = subs[sid]
            got.setdefault(topic, []).append(
                m.deserialize(bytes(raw[13:]), channels[topic]["schemaName"])
            )
        return {"channels": channels, "got": got}


def test_foxglove_client_receives_scans_and_poses():
    live = LiveRecording(foxglove_port=0)
    app = create_app(DATA / "rec-small.yaml", scenarios_dir=DATA, speed=2.0, observers=[live])
    wanted = ["/s1/scan", "/s2/odom", "/tf", "/map"]
    with TestClient(app):
        out = asyncio.run(_foxglove_client(live.foxglove_port, wanted, timeout_s=30))
    ch = out["channels"]
    assert ch["/s1/scan"]["encoding"] == "cdr" and ch["/s1/scan"]["schemaEncoding"] == "ros2msg"
    assert ch["/s1/scan"]["schemaName"] == "sensor_msgs/msg/LaserScan"
    got = out["got"]
    assert set(wanted) <= set(got), sorted(got)
    scan = got["/s1/scan"][-1]
    assert scan.header.frame_id == "s1/laser" and len(scan.ranges) == 180
    assert np.isfinite(scan.ranges).mean() > 0.5
    odom = got["/s2/odom"][-1]
    assert odom.child_frame_id == "s2/base_link" and odom.header.frame_id == "map"
    assert 1.0 < odom.pose.pose.position.x < 11.0
    assert {t.child_frame_id for t in got["/tf"][-1].transforms} == {
        "s1/base_link",
        "s2/base_link",
        "s3/base_link",
    }
    grid = got["/map"][0]  # sent to the late subscriber again (latched)
    assert (grid.info.width, grid.info.height) == (240, 160)


def test_foxglove_binds_loopback_by_default():
    live = LiveRecording(foxglove_port=0)
    try:
        import socket

        with socket.create_connection(("127.0.0.1", live.foxglove_port), timeout=2):
            pass
        assert live.fox.server.port == live.foxglove_port
    finally:
        live.close()


def test_serve_cli_rejects_bad_record_options(tmp_path, capsys):
    from swarmpark.server.cli import serve_command

    assert serve_command([str(DATA / "ui-small.yaml"), "--foxglove", "70000"]) == 2
    assert "--foxglove must be 0..65535" in capsys.readouterr().err
    assert serve_command([str(DATA / "ui-small.yaml"), "--record-rate", "-1"]) == 2
    assert "--record-rate must be >= 0 Hz" in capsys.readouterr().err


def test_serve_foxglove_port_in_use_is_one_line(capsys):
    from swarmpark.server.cli import serve_command

    live = LiveRecording(foxglove_port=0)
    try:
        rc = serve_command(
            [
                str(DATA / "ui-small.yaml"),
                "--foxglove",
                str(live.foxglove_port),
                "--audit",
                "/dev/null",
            ]
        )
    finally:
        live.close()
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and "--foxglove" in err and "in use" in err
