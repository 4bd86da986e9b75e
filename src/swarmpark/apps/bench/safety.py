"""Operator safety under load (issue 16): 100 skids served to 200 WebSocket viewers.

The server is the real thing (``swarmpark serve`` with uvicorn) in a child process; the 200
viewers are asyncio WebSocket clients in one thread of this process, each reading every
frame. Reported: the simulation rate (simulated seconds per wall second, from the server's
own clock stamps), frames received per viewer, and the e-stop round trip (request to
answer) over repeated presses, with its 99th percentile, plus the time to a halted frame.
Targets: sim rate >= 0.95 with 200 viewers; e-stop round trip p99 <= 100 ms.
"""

from __future__ import annotations

import asyncio
import os
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
from swarmpark.apps.bench.server import TARGET_N, _free_port, _get, load_scenario

#: The issue's targets.
VIEWERS = 200
MIN_SIM_RATE = 0.95
MAX_ESTOP_P99_MS = 100.0
#: E-stop presses timed, and the pause between them (s).
ESTOP_PRESSES = 60
ESTOP_GAP_S = 0.03


class _Viewers(threading.Thread):
    """``n`` WebSocket viewers on one asyncio loop, counting the frames each receives."""

    def __init__(self, url: str, n: int) -> None:
        super().__init__(daemon=True)
        self.url, self.n = url, n
        self.counts = [0] * n
        self.connected = 0
        self.errors: list[str] = []
        self.stop = threading.Event()

    async def _one(self, k: int) -> None:
        from websockets.asyncio.client import connect

        try:
            async with connect(self.url, max_size=None, open_timeout=60) as ws:
                self.connected += 1
                while not self.stop.is_set():
                    try:
                        await asyncio.wait_for(ws.recv(), 1.0)
                    except TimeoutError:
                        continue
                    self.counts[k] += 1
        except Exception as exc:  # reported in the row, not hidden
            self.errors.append(f"{type(exc).__name__}: {exc}")

    def run(self) -> None:
        async def main() -> None:
            await asyncio.gather(*(self._one(k) for k in range(self.n)))

        asyncio.run(main())


def _estop_ms(base: str) -> float:
    t0 = time.monotonic()
    req = urllib.request.Request(base + "/api/estop", data=b"", method="POST")
    with urllib.request.urlopen(req, timeout=30) as r:
        r.read()
    return (time.monotonic() - t0) * 1e3


def _start(path: Path, tmp: str, port: int) -> subprocess.Popen:
    code = (
        "import sys; from swarmpark.server.cli import serve_command; "
        f"sys.exit(serve_command([{str(path)!r}, '--port', '{port}', '--scenarios-dir', "
        f"{tmp!r}, '--audit', {str(Path(tmp) / 'audit.jsonl')!r}]))"
    )
    return subprocess.Popen(
        [sys.executable, "-c", code],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )


def _wait_up(base: str, proc: subprocess.Popen) -> None:
    deadline = time.monotonic() + 120
    while True:
        try:
            _get(base + "/api/sim")
            return
        except OSError:
            if proc.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(proc.stderr.read().decode() if proc.stderr else "") from None
            time.sleep(0.2)


def measure(n: int, viewers: int, seconds: float) -> dict:
    """Serve ``n`` skids to ``viewers`` viewers; measure ``seconds`` of steady state, then
    the e-stop round trip under that load."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"safety-{n}.yaml"
        path.write_text(yaml.safe_dump(load_scenario(n)))
        port = _free_port()
        base = f"http://127.0.0.1:{port}"
        proc = _start(path, tmp, port)
        crowd = _Viewers(f"ws://127.0.0.1:{port}/api/ws", viewers)
        try:
            _wait_up(base, proc)
            crowd.start()
            deadline = time.monotonic() + 120
            while crowd.connected + len(crowd.errors) < viewers and time.monotonic() < deadline:
                time.sleep(0.2)
            # Past the first plans (the gotos at 0.5 s), then steady driving.
            while _get(base + "/api/sim")["t_s"] < 1.5:
                time.sleep(0.2)
            p0, c0 = _get(base + "/api/perf"), list(crowd.counts)
            time.sleep(seconds)
            p1, c1 = _get(base + "/api/perf"), list(crowd.counts)
            wall = p1["monotonic_s"] - p0["monotonic_s"]
            # One press, then the time until a frame shows every skid at zero speed.
            t_first = time.monotonic()
            rtts = [_estop_ms(base)]
            halted = None
            while halted is None and time.monotonic() - t_first < 30:
                if all(abs(r[4]) == 0 for r in _get(base + "/api/state")["robots"]):
                    halted = (time.monotonic() - t_first) * 1e3
            # Then the round trip of repeated presses (the e-stop is latched: idempotent).
            for _ in range(ESTOP_PRESSES - 1):
                time.sleep(ESTOP_GAP_S)
                rtts.append(_estop_ms(base))
        finally:
            crowd.stop.set()
            crowd.join(10)
            proc.terminate()
            try:
                proc.wait(10)
            except subprocess.TimeoutExpired:
                proc.kill()
    rate = (p1["sim_t_s"] - p0["sim_t_s"]) / wall
    hz = [(b - a) / wall for a, b in zip(c0, c1, strict=True)]
    p99 = float(np.percentile(rtts, 99))
    return {
        "N": n,
        "viewers": viewers,
        "connected": crowd.connected,
        "measured_s": round(wall, 2),
        "sim_rate": round(rate, 3),
        "recv_hz_mean": round(float(np.mean(hz)), 2),
        "recv_hz_min": round(float(np.min(hz)), 2),
        "estop_rtt_ms_p50": round(float(np.percentile(rtts, 50)), 1),
        "estop_rtt_ms_p99": round(p99, 1),
        "estop_rtt_ms_max": round(max(rtts), 1),
        "estop_to_halt_ms": round(halted, 1) if halted is not None else None,
        "meets_target": bool(
            rate >= MIN_SIM_RATE and p99 <= MAX_ESTOP_P99_MS and crowd.connected == viewers
        ),
        "errors": "; ".join(sorted(set(crowd.errors)))[:300] or None,
    }


@register(
    "server.safety",
    "operator safety: sim rate with 200 viewers, e-stop round trip p99",
    target=f"{TARGET_N} skids, {VIEWERS} viewers: sim >= {MIN_SIM_RATE}x real time, "
    f"e-stop p99 <= {MAX_ESTOP_P99_MS:g} ms",
)
def bench_server_safety(quick: bool) -> list[dict]:
    if quick:
        return [measure(TARGET_N, VIEWERS, 3.0)]
    # Three viewers first: what the machine gives the server without the crowd.
    return [measure(TARGET_N, 3, 10.0), measure(TARGET_N, VIEWERS, 10.0)]
