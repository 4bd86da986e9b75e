"""Recording cost: the recorder's time per tick against the tick, and the file size per minute.

50 skids in the server-load hangar (all driving, a person walking), with onboard sensing
(AMCL on 1000-beam scans, so ``/<id>/scan`` is recorded) and without. Each run carries two
recorders writing to two files: the default rates (poses 10 Hz, scans 5 Hz) and every tick
(20 Hz, scans too), so both are measured on the same ticks. The overhead is the recorder's
``on_tick`` wall time (serialization, MCAP chunking and zstd compression included) over the
supervisor's tick time; the file size includes the closing summary.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from swarmpark.apps.bench import register

N_SKIDS = 50


class _Timed:
    """Wraps an observer and keeps the wall and CPU time of its calls."""

    def __init__(self, inner) -> None:
        self.inner = inner
        self.tick_s: list[float] = []
        self.cpu_s: list[float] = []
        self.end_s = 0.0

    def on_start(self, sup) -> None:
        self.inner.on_start(sup)

    def on_tick(self, sup) -> None:
        t0, c0 = time.perf_counter(), time.process_time()
        self.inner.on_tick(sup)
        self.tick_s.append(time.perf_counter() - t0)
        self.cpu_s.append(time.process_time() - c0)

    def on_end(self, sup, result=None) -> None:
        t0 = time.perf_counter()
        self.inner.on_end(sup, result)
        self.end_s = time.perf_counter() - t0


class _TickCpu:
    """First and last observer: the CPU time between the last observer of one tick and the
    first of the next is the tick's (on a busy machine CPU time is steadier than wall)."""

    def __init__(self) -> None:
        self.mark: float | None = None
        self.ticks: list[float] = []

    def on_start(self, sup) -> None:
        self.mark = None

    def first(self, sup) -> None:
        if self.mark is not None:
            self.ticks.append(time.process_time() - self.mark)

    def last(self, sup) -> None:
        self.mark = time.process_time()

    def on_end(self, sup, result=None) -> None:
        pass


class _Hook:
    def __init__(self, fn) -> None:
        self.on_tick = fn

    def on_start(self, sup) -> None:
        pass

    def on_end(self, sup, result=None) -> None:
        pass


def _world(sensing: bool, duration_s: float):
    from swarmpark.apps.bench.server import load_scenario
    from swarmpark.world.scenario import Scenario, build_world

    spec = load_scenario(N_SKIDS)
    spec["duration_s"] = duration_s
    if sensing:
        spec["sensing"] = {"localization": "amcl"}
    return build_world(Scenario.model_validate(spec))


def _case(sensing: bool, duration_s: float, tmp: Path) -> list[dict]:
    from swarmpark.apps.run import run_world
    from swarmpark.record import RecordConfig, Recorder
    from swarmpark.record.sinks import McapSink

    configs = {
        "poses 10 Hz, scans 5 Hz (default)": RecordConfig(),
        "every tick (20 Hz)": RecordConfig(rate_hz=None, scan_rate_hz=None),
    }
    timed, files = [], []
    for k, cfg in enumerate(configs.values()):
        path = tmp / f"{'scan' if sensing else 'truth'}-{k}.mcap"
        files.append(path)
        timed.append(_Timed(Recorder([McapSink(path)], cfg)))
    cpu = _TickCpu()
    observers = [_Hook(cpu.first), *timed, _Hook(cpu.last)]
    out = run_world(_world(sensing, duration_s), observers=observers)
    tick_ms = float(np.mean(out.supervisor.metrics.tick_ms))
    tick_cpu_ms = 1e3 * float(np.mean(cpu.ticks))
    sim_s = out.supervisor.t
    rows = []
    for (name, _), tm, path in zip(configs.items(), timed, files, strict=True):
        rec_ms = 1e3 * float(np.mean(tm.tick_s))
        size = path.stat().st_size
        rows.append(
            {
                "case": f"{N_SKIDS} skids, {'scans (AMCL)' if sensing else 'no sensing'}",
                "record": name,
                "sim_s": round(sim_s, 2),
                "tick_ms": round(tick_ms, 2),
                "record_ms_per_tick": round(rec_ms, 3),
                "record_p99_ms": round(1e3 * float(np.percentile(tm.tick_s, 99)), 2),
                "overhead_pct": round(100 * rec_ms / tick_ms, 1),
                "tick_cpu_ms": round(tick_cpu_ms, 2),
                "record_cpu_ms": round(1e3 * float(np.mean(tm.cpu_s)), 3),
                "overhead_cpu_pct": round(100 * float(np.mean(tm.cpu_s)) * 1e3 / tick_cpu_ms, 1),
                "close_ms": round(1e3 * tm.end_s, 1),
                "file_mb": round(size / 1e6, 2),
                "mb_per_min": round(size / 1e6 / sim_s * 60.0, 1),
            }
        )
    return rows


@register(
    "record",
    "MCAP recording at 50 skids: recorder time per tick vs the tick, file size per minute",
    target="< 10 % of the tick at 50 skids with scans (default rates)",
)
def bench_record(quick: bool) -> list[dict]:
    duration = 3.0 if quick else 10.0
    with tempfile.TemporaryDirectory(prefix="swarmpark-bench-record-") as d:
        return _case(True, duration, Path(d)) + _case(False, duration, Path(d))
