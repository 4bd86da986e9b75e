"""Operator-server load: N skids ticking at 20 Hz with three browsers' WebSockets connected.

The server is the real thing (``swarmpark serve`` with uvicorn) in a child process, so its
CPU time is its own; three WebSocket clients in this process read every frame. Reported:
the server's CPU per tick (``time.process_time`` around tick + frame encoding, and the
whole process including WebSocket sends), tick and encoding times, and message sizes.
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request
from pathlib import Path

import numpy as np
import yaml

from swarmpark.apps.bench import register

#: The acceptance target of the issue: 100 skids at 20 Hz with three browsers.
TARGET_N, TARGET_HZ, CLIENTS = 100, 20.0, 3
#: The gotos are given at 0.5 s; the skids drive and turn about until about 8 s.
WARMUP_SIM_S = 1.5
#: Pillars between the lattice rows and columns (the skids sit at x = 2 + 2c, y = 1.5 + 1.5r).
PILLARS = [
    [[12.8, 11.05], [13.2, 11.05], [13.2, 11.45], [12.8, 11.45]],
    [[24.8, 20.05], [25.2, 20.05], [25.2, 20.45], [24.8, 20.45]],
]


def load_scenario(n: int, *, goto_at_s: float = 0.5) -> dict:
    """``n`` skids on a 2.0 x 1.5 m lattice in a 50 x 40 m hangar, a person walking a loop,
    and at ``goto_at_s`` every skid sent 1 m ahead to turn about (all of them move)."""
    cols = int(np.ceil(np.sqrt(n * 1.5)))
    robots, commands = [], []
    for k in range(n):
        r, c = divmod(k, cols)
        x, y = 2.0 + 2.0 * c, 1.5 + 1.5 * r
        robots.append({"id": f"s{k}", "pose": [x, y, 0.0]})
        commands.append(
            {"at_s": goto_at_s, "goto": {"robot": f"s{k}", "pose": [x + 1.0, y, 180.0]}}
        )
    return {
        "name": f"server-load-{n}",
        "dt_s": 1.0 / TARGET_HZ,
        "duration_s": 3600,
        "map": {"size_m": [50, 40], "resolution_m": 0.05, "walls": PILLARS},
        "robots": robots,
        "obstacles": [{"radius_m": 0.3, "waypoints": [[1.0, 39.0], [49.0, 39.0]], "loop": True}],
        "commands": commands,
    }


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _get(url: str) -> dict:
    with urllib.request.urlopen(url, timeout=30) as r:
        return json.loads(r.read())


class _Viewer(threading.Thread):
    """A WebSocket client that reads every frame and counts bytes (one browser)."""

    def __init__(self, url: str) -> None:
        super().__init__(daemon=True)
        self.url = url
        self.sizes: list[int] = []
        self.times: list[float] = []
        self.first_bytes = 0
        self.stop = threading.Event()
        self.error: str | None = None

    def run(self) -> None:
        from websockets.sync.client import connect

        try:
            with connect(self.url, max_size=None) as ws:
                self.first_bytes = len(ws.recv())
                while not self.stop.is_set():
                    try:
                        msg = ws.recv(timeout=1.0)
                    except TimeoutError:
                        continue
                    self.sizes.append(len(msg))
                    self.times.append(time.monotonic())
        except Exception as exc:  # reported in the row, not hidden
            self.error = f"{type(exc).__name__}: {exc}"


def measure(n: int, seconds: float) -> dict:
    """Serve ``n`` skids, connect :data:`CLIENTS` viewers, measure ``seconds`` of steady state."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"load-{n}.yaml"
        path.write_text(yaml.safe_dump(load_scenario(n)))
        port = _free_port()
        base = f"http://127.0.0.1:{port}"
        code = (
            "import sys; from swarmpark.server.cli import serve_command; "
            f"sys.exit(serve_command([{str(path)!r}, '--port', '{port}', '--scenarios-dir', {tmp!r}]))"
        )
        proc = subprocess.Popen(
            [sys.executable, "-c", code],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            env={**os.environ, "PYTHONUNBUFFERED": "1"},
        )
        viewers: list[_Viewer] = []
        try:
            deadline = time.monotonic() + 120
            while True:
                try:
                    _get(base + "/api/sim")
                    break
                except OSError:
                    if proc.poll() is not None or time.monotonic() > deadline:
                        raise RuntimeError(
                            proc.stderr.read().decode() if proc.stderr else ""
                        ) from None
                    time.sleep(0.2)
            viewers = [_Viewer(f"ws://127.0.0.1:{port}/api/ws") for _ in range(CLIENTS)]
            for v in viewers:
                v.start()
            # Warm up past the gotos: the first tick after them plans every skid's path (a
            # stall of seconds at N = 100, reported as plan_stall_ms); then all of them drive.
            while _get(base + "/api/sim")["t_s"] < WARMUP_SIM_S:
                time.sleep(0.2)
            p0 = _get(base + "/api/perf")
            stall = p0["cpu_ms_per_frame_max"]
            time.sleep(seconds)
            p1 = _get(base + "/api/perf")
            # Rates from the server's own stamps (CLOCK_MONOTONIC, shared by both processes):
            # a late answer must not stretch or shrink the window.
            w0, wall = p0["monotonic_s"], p1["monotonic_s"] - p0["monotonic_s"]
            frames = max(p1["frames_paced"] - p0["frames_paced"], 1)
            window = _get(base + f"/api/perf?frames={min(frames, 2000)}")
            state = _get(base + "/api/state")
            # The operator's e-stop under this load: request to answer, then to a halted frame.
            t_e = time.monotonic()
            req = urllib.request.Request(base + "/api/estop", data=b"", method="POST")
            with urllib.request.urlopen(req, timeout=30) as r:
                r.read()
            estop_rtt = (time.monotonic() - t_e) * 1e3
            while any(abs(row[4]) > 0 for row in _get(base + "/api/state")["robots"]):
                time.sleep(0.005)
            estop_halt = (time.monotonic() - t_e) * 1e3
        finally:
            for v in viewers:
                v.stop.set()
            for v in viewers:
                v.join(5)
            proc.terminate()
            try:
                proc.wait(10)
            except subprocess.TimeoutExpired:
                proc.kill()
    ticks = p1["ticks_total"] - p0["ticks_total"]
    moving = sum(1 for r in state["robots"] if abs(r[4]) > 1e-3)
    sizes = [s for v in viewers for s in v.sizes if v.times and s > 0]
    recv_hz = [sum(1 for t in v.times if w0 <= t <= w0 + wall) / wall for v in viewers if v.times]
    errors = [v.error for v in viewers if v.error]
    server_cpu = (p1["process_cpu_s"] - p0["process_cpu_s"]) * 1e3
    return {
        "N": n,
        "clients": CLIENTS,
        "measured_s": round(wall, 2),
        "ticks_per_s": round(ticks / wall, 2),
        "frames_per_s": round((p1["frames_sent"] - p0["frames_sent"]) / wall, 2),
        "sim_rate": round((p1["sim_t_s"] - p0["sim_t_s"]) / wall, 3),
        "moving_at_end": moving,
        "plan_stall_ms": stall,
        "cpu_ms_per_tick": window["cpu_ms_per_tick"],
        "server_cpu_ms_per_tick": round(server_cpu / ticks, 3) if ticks else None,
        "server_cpu_pct": round(100 * server_cpu / 1e3 / wall, 1),
        "tick_wall_ms": window["tick_wall_ms_mean"],
        "encode_wall_ms": window["encode_wall_ms_mean"],
        "estop_rtt_ms": round(estop_rtt, 1),
        "estop_to_halt_ms": round(estop_halt, 1),
        "msg_bytes_mean": round(float(np.mean(sizes)), 1) if sizes else None,
        "msg_bytes_max": max(sizes) if sizes else None,
        "full_frame_bytes": max((v.first_bytes for v in viewers), default=None),
        "recv_hz_per_client": round(float(np.mean(recv_hz)), 2) if recv_hz else None,
        "meets_target": None
        if n != TARGET_N
        else (
            ticks / wall >= 0.95 * TARGET_HZ
            and bool(recv_hz)
            and min(recv_hz) >= 0.9 * TARGET_HZ
            and not errors
        ),
        "errors": "; ".join(errors) or None,
    }


@register(
    "server.load",
    "operator server: ticks, frame sizes and CPU with 3 WebSocket viewers",
    target=f"{TARGET_N} skids at {TARGET_HZ:g} Hz with {CLIENTS} browsers",
)
def bench_server_load(quick: bool) -> list[dict]:
    if quick:
        return [measure(TARGET_N, 2.0)]
    return [measure(n, 5.0) for n in (10, TARGET_N)]
