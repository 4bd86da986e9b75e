"""Sweep overhead: the same tiny jobs through a Dask LocalCluster and in a plain loop.

Every job is one ``swarmpark run`` subprocess (a one-skid goto, 2 s simulated), so a job's
own cost is mostly the interpreter start and imports. The loop runs :func:`run_job` one after
the other; the cluster runs them with one worker (overhead per job = the difference, divided
by the job count) and with one worker per core (the speed-up a sweep gets).
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

import yaml

from swarmpark.apps.bench import register

TINY = {
    "name": "bench-tiny",
    "duration_s": 2,
    "map": {"size_m": [12, 8], "resolution_m": 0.1},
    "robots": [{"id": "a", "pose": [2, 4, 0]}],
    "commands": [{"goto": {"robot": "a", "pose": [4, 4, 0]}}],
}
TIMEOUT_S = 300.0


def _jobs(tmp: Path, k: int):
    from swarmpark.apps.sweep import expand_jobs

    path = tmp / "tiny.yaml"
    path.write_text(yaml.safe_dump(TINY))
    src = {"kind": "tiny", "source": str(path), "site": str(path), "robots": None,
           "duration_s": None, "timeout_s": None}  # fmt: skip
    return expand_jobs([src], list(range(k)), {}, None)


def _on_cluster(jobs, out: Path, workers: int) -> tuple[float, float, int]:
    """(cluster start-up s, wall s for all jobs, errors)."""
    from dask.distributed import as_completed

    from swarmpark.apps.sweep import _client, run_job

    t0 = time.perf_counter()
    client, cluster = _client(None, workers)
    t1 = time.perf_counter()
    try:
        futs = [client.submit(run_job, j, str(out), TIMEOUT_S, 0, pure=False) for j in jobs]
        errors = sum(bool(f.result()["error"]) for f in as_completed(futs))
    finally:
        client.close()
        cluster.close()
    return t1 - t0, time.perf_counter() - t1, errors


@register(
    "sweep.overhead",
    "per-job overhead of a Dask LocalCluster sweep against the same jobs in a loop",
    target="overhead per job well under a job's own time",
)
def bench_sweep_overhead(quick: bool) -> list[dict]:
    from swarmpark.apps.sweep import run_job

    k = 4 if quick else 10
    cores = os.cpu_count() or 1
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        jobs = _jobs(tmp, k)
        t0 = time.perf_counter()
        loop_err = sum(bool(run_job(j, str(tmp / "loop"), TIMEOUT_S, 0)["error"]) for j in jobs)
        loop_s = time.perf_counter() - t0
        rows = [{"engine": "loop", "workers": 1, "jobs": k, "startup_s": 0.0,
                 "wall_s": loop_s, "per_job_s": loop_s / k, "overhead_per_job_ms": 0.0,
                 "errors": loop_err}]  # fmt: skip
        for workers in sorted({1, cores}):
            start, wall, err = _on_cluster(jobs, tmp / f"dask{workers}", workers)
            rows.append(
                {
                    "engine": "dask LocalCluster",
                    "workers": workers,
                    "jobs": k,
                    "startup_s": start,
                    "wall_s": wall,
                    "per_job_s": wall / k,
                    # Only meaningful with one worker: same serial work as the loop.
                    "overhead_per_job_ms": (wall - loop_s) / k * 1e3 if workers == 1 else None,
                    "errors": err,
                }
            )
    return rows
