"""Experiment sweeps: scenario files or generated sites x seeds x parameter overrides, on Dask.

``swarmpark sweep SPEC.yaml`` expands the spec (:func:`load_spec`) into jobs. Each job is one
``swarmpark run ... --json`` in its own subprocess with a timeout, so a crash or a hang costs
one row, never the sweep; a generated site is first written by its own
``swarmpark generate`` subprocess (one task per site, the runs depend on it). Jobs go to a
``dask.distributed`` cluster: a ``LocalCluster(processes=False)`` with one single-threaded
worker per core by default (threads are enough: the work is in the subprocesses), or an
existing scheduler (``--scheduler tcp://HOST:8786``; the workers must see the same paths).

Every finished job leaves ``records/<job>.json`` in the output directory; a re-run of the
same spec into the same directory skips the jobs that have a record without an error. At the
end the records become ``results.parquet`` and ``summary.md`` (see
:mod:`swarmpark.apps.sweep_report`). The spec format is documented in ``docs/sweeps.md``.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import os
import subprocess
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import yaml

__all__ = ["SpecError", "Job", "Spec", "load_spec", "expand_jobs", "run_job", "run_sweep"]

#: Keys a spec may have; anything else is a typo and an error.
SPEC_KEYS = ("name", "scenarios", "generate", "seeds", "params", "duration_s", "timeout_s")
#: Seconds a job may take unless the command line or the spec says otherwise.
DEFAULT_TIMEOUT_S = 1800.0
#: Characters of a failed job's stderr kept in its ``error``.
ERROR_TAIL_CHARS = 2000


class SpecError(ValueError):
    """A bad sweep spec; the message names the field and the value."""


@dataclass(frozen=True)
class Job:
    """One run: a scenario file or a generated site, a seed and parameter overrides."""

    job_id: str
    kind: str  # the generator kind, or the scenario file's stem
    source: str  # the scenario file, or "generate:KIND"
    seed: int
    robots: int | None = None
    params: dict = field(default_factory=dict)
    duration_s: float | None = None
    timeout_s: float | None = None
    site: str = ""  # the scenario file the run starts from (for generated sites: written)


@dataclass(frozen=True)
class Spec:
    name: str
    jobs: tuple[Job, ...]
    timeout_s: float | None


def _seeds(value) -> list[int]:
    if isinstance(value, int) and not isinstance(value, bool):
        value = [value]
    if isinstance(value, dict):
        if set(value) != {"range"} or not isinstance(value["range"], list):
            raise SpecError(f"seeds: use a list or {{range: [start, stop]}} (got {value!r})")
        value = list(range(*value["range"]))
    if not isinstance(value, list) or not value:
        raise SpecError(f"seeds: a non-empty list of integers >= 0 (got {value!r})")
    for s in value:
        if isinstance(s, bool) or not isinstance(s, int) or s < 0:
            raise SpecError(f"seeds: every seed is an integer >= 0 (got {s!r})")
    return value


def _set_path(data: dict, dotted: str, value) -> None:
    """Set ``a.b.c`` in a nested mapping; ``park.X`` sets X of every park command."""
    if dotted.startswith("park."):
        for c in data.get("commands", []):
            if "park" in c:
                c["park"][dotted[5:]] = value
        return
    *head, last = dotted.split(".")
    node = data
    for k in head:
        node = node.setdefault(k, {})
        if not isinstance(node, dict):
            raise SpecError(f"params.{dotted}: {k!r} is not a mapping in the scenario")
    node[last] = value


def _check_params(params) -> dict[str, list]:
    """Every override is tried on a minimal scenario so a bad key or value fails now."""
    from swarmpark.world.scenario import ScenarioError, parse_scenario

    if params is None:
        return {}
    if not isinstance(params, dict):
        raise SpecError(f"params: a mapping of dotted keys to value lists (got {params!r})")
    out = {}
    for key, values in params.items():
        values = values if isinstance(values, list) else [values]
        if not values:
            raise SpecError(f"params.{key}: give at least one value (got [])")
        for v in values:
            probe = {
                "name": "probe",
                "map": {"size_m": [10, 10]},
                "robots": [{"id": "a", "pose": [2, 2, 0]}],
                "commands": [{"park": {"robots": ["a"], "boundary": [[5, 5], [9, 5], [9, 9]]}}],
            }
            try:
                _set_path(probe, str(key), v)
                parse_scenario(probe)
            except ScenarioError as exc:
                raise SpecError(f"params.{key}: bad value {v!r} ({exc})") from None
        out[str(key)] = values
    return out


def _sources(raw: dict, base: Path) -> list[dict]:
    """(kind, source, site path, robots, duration, timeout) of every scenario or site kind."""
    from swarmpark.apps.generate import KINDS

    out = []
    for i, entry in enumerate(raw.get("scenarios") or []):
        entry = {"path": entry} if isinstance(entry, str) else entry
        if not isinstance(entry, dict) or not isinstance(entry.get("path"), str):
            raise SpecError(f"scenarios[{i}]: a file path or {{path: ...}} (got {entry!r})")
        extra = set(entry) - {"path", "duration_s", "timeout_s"}
        if extra:
            raise SpecError(f"scenarios[{i}]: unknown key {sorted(extra)[0]!r}")
        path = (base / entry["path"]).resolve()
        if not path.is_file():
            raise SpecError(f"scenarios[{i}]: file not found: {entry['path']!r}")
        out.append({"kind": path.stem, "source": str(path), "site": str(path), "robots": None,
                    "duration_s": entry.get("duration_s"), "timeout_s": entry.get("timeout_s")})  # fmt: skip
    gen = raw.get("generate")
    if gen is not None:
        if not isinstance(gen, dict) or set(gen) - {"kinds", "robots"}:
            raise SpecError(f"generate: a mapping with 'kinds' and optional 'robots' (got {gen!r})")
        kinds = gen.get("kinds", "all")
        kinds = list(KINDS) if kinds == "all" else kinds
        if not isinstance(kinds, list) or not kinds:
            raise SpecError(f"generate.kinds: a list of kinds or 'all' (got {kinds!r})")
        for k in kinds:
            if k not in KINDS:
                raise SpecError(f"generate.kinds: unknown kind {k!r} (known: {', '.join(KINDS)})")
        robots = gen.get("robots", [None])
        robots = robots if isinstance(robots, list) else [robots]
        for n in robots:
            if n is not None and (isinstance(n, bool) or not isinstance(n, int) or n < 2):
                raise SpecError(f"generate.robots: integers >= 2 or null (got {n!r})")
        for k, n in itertools.product(kinds, robots):
            out.append({"kind": k, "source": f"generate:{k}", "site": "", "robots": n,
                        "duration_s": None, "timeout_s": None})  # fmt: skip
    if not out:
        raise SpecError("scenarios: give scenario files and/or generate.kinds (got neither)")
    return out


def _positive_or_none(raw: dict, key: str) -> float | None:
    v = raw.get(key)
    if v is None:
        return None
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not v > 0:
        raise SpecError(f"{key}: a number > 0 (got {v!r})")
    return float(v)


def load_spec(path: str | Path) -> Spec:
    """Read and check a sweep spec; raises :class:`SpecError` naming the field and value."""
    path = Path(path)
    if not path.is_file():
        raise SpecError(f"spec: file not found: {str(path)!r}")
    try:
        raw = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise SpecError(f"spec: {str(path)!r} is not valid YAML: {exc}") from None
    if not isinstance(raw, dict):
        raise SpecError(f"spec: a mapping of keys (got {type(raw).__name__})")
    unknown = [k for k in raw if k not in SPEC_KEYS]
    if unknown:
        raise SpecError(f"{unknown[0]}: unknown key (known: {', '.join(SPEC_KEYS)})")
    name = str(raw.get("name") or path.stem)
    seeds = _seeds(raw.get("seeds", [0]))
    params = _check_params(raw.get("params"))
    duration = _positive_or_none(raw, "duration_s")
    timeout = _positive_or_none(raw, "timeout_s")
    jobs = expand_jobs(_sources(raw, path.parent), seeds, params, duration)
    return Spec(name, tuple(jobs), timeout)


def expand_jobs(sources: list[dict], seeds: list[int], params: dict, duration) -> list[Job]:
    """The cartesian product seeds x sources x parameter values, with stable job ids.

    Seed-major order: a sweep stopped half way has covered every source and parameter.
    """
    keys = list(params)
    combos = list(itertools.product(*(params[k] for k in keys))) or [()]
    jobs = []
    for seed, src, combo in itertools.product(seeds, sources, combos):
        p = dict(zip(keys, combo, strict=True))
        dur = src["duration_s"] if src["duration_s"] is not None else duration
        ident = json.dumps([src["source"], src["robots"], seed, p, dur], sort_keys=True)
        digest = hashlib.sha1(ident.encode()).hexdigest()[:10]
        n = f"-n{src['robots']}" if src["robots"] is not None else ""
        job_id = f"{src['kind']}{n}-s{seed}-{digest}"
        jobs.append(Job(job_id, src["kind"], src["source"], seed, src["robots"], p, dur,
                        src["timeout_s"], src["site"]))  # fmt: skip
    return jobs


# ----------------------------------------------------------------------------- one job


def _cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "swarmpark.apps.cli", *args]


def _tail(text: str) -> str:
    text = text.strip()
    return text[-ERROR_TAIL_CHARS:]


def site_path(out_dir: Path, job: Job) -> str:
    """The scenario file a job starts from (generated sites live in ``out_dir/sites``)."""
    return job.site or str(out_dir / "sites" / f"{job.kind}-n{job.robots}-s{job.seed}.yaml")


def make_site(kind: str, seed: int, robots: int | None, out: str, timeout_s: float) -> str:
    """Write a generated site with ``swarmpark generate`` (skipped if it exists); '' or error."""
    if Path(out).is_file():
        return ""
    cmd = _cli("generate", kind, "--seed", str(seed), "--out", out)
    if robots is not None:
        cmd += ["--robots", str(robots)]
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s)
    except subprocess.TimeoutExpired:
        return f"generate: timeout after {timeout_s:g} s"
    return "" if p.returncode == 0 else f"generate: exit {p.returncode}: {_tail(p.stderr)}"


def _variant(job: Job, site: str, out_dir: Path) -> Path:
    """The job's scenario file: the site with the overrides (relative map paths made absolute)."""
    data = yaml.safe_load(Path(site).read_text())
    base = Path(site).parent
    for holder, key in ((data.get("map") or {}, "yaml"), (data.get("sensing") or {}, "map")):
        if isinstance(holder.get(key), str) and not Path(holder[key]).is_absolute():
            holder[key] = str((base / holder[key]).resolve())
    for k, v in job.params.items():
        _set_path(data, k, v)
    path = out_dir / "jobs" / f"{job.job_id}.yaml"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def _run_once(job: Job, site: str, out_dir: Path, timeout_s: float) -> tuple[dict | None, str]:
    cmd = _cli(
        "run", str(_variant(job, site, out_dir)), "--json", "--quiet", "--seed", str(job.seed)
    )
    if job.duration_s is not None:
        cmd += ["--duration", str(job.duration_s)]
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s)
    except subprocess.TimeoutExpired:
        return None, f"timeout after {timeout_s:g} s"
    if p.returncode in (0, 1):  # 1: the run finished but did not meet expect, a result too
        try:
            return json.loads(p.stdout), ""
        except json.JSONDecodeError:
            return None, f"exit {p.returncode} without a JSON result: {_tail(p.stdout + p.stderr)}"
    return None, f"exit {p.returncode}: {_tail(p.stderr)}"


def run_job(job: Job, out_dir: str, timeout_s: float, retries: int, site_error: str = "") -> dict:
    """Run one job (with retries on error) and write its record; never raises."""
    out = Path(out_dir)
    t0 = time.perf_counter()
    result, error, attempts = None, site_error, 0
    site = site_path(out, job)
    while not site_error and attempts <= retries:
        attempts += 1
        try:
            result, error = _run_once(job, site, out, job.timeout_s or timeout_s)
        except Exception as exc:  # a bad site file, a full disk: this job's error, not the sweep's
            result, error = None, f"{type(exc).__name__}: {exc}"
        if not error:
            break
    record = {
        "job": asdict(job) | {"site": site},
        "error": error or None,
        "wall_s": round(time.perf_counter() - t0, 3),
        "attempts": attempts,
        "result": result,
    }
    path = out / "records" / f"{job.job_id}.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(record) + "\n")
    os.replace(tmp, path)  # a record is there whole or not at all (resume reads them)
    return record


# ----------------------------------------------------------------------------- the sweep


def finished_jobs(out_dir: Path) -> set[str]:
    """Ids of jobs with a record and no error (a resumed sweep skips them)."""
    done = set()
    for p in (out_dir / "records").glob("*.json"):
        try:
            rec = json.loads(p.read_text())
        except (OSError, json.JSONDecodeError):
            continue
        if not rec.get("error"):
            done.add(p.stem)
    return done


def _client(scheduler: str | None, workers: int | None):
    from dask.distributed import Client, LocalCluster

    if scheduler:
        return Client(scheduler), None
    n = workers or os.cpu_count() or 1
    # In-process workers talk over inproc://; the scheduler's and the workers' dashboards
    # listen on loopback only (the workers' default is every interface), any free port (a
    # second sweep on the same machine must not collide on 8787).
    cluster = LocalCluster(
        processes=False,
        n_workers=n,
        threads_per_worker=1,
        dashboard_address="127.0.0.1:0",
        worker_dashboard_address="127.0.0.1:0",
    )
    return Client(cluster), cluster


def run_sweep(
    spec: Spec,
    out_dir: str | Path,
    *,
    scheduler: str | None = None,
    workers: int | None = None,
    retries: int = 0,
    timeout_s: float | None = None,
    progress: bool = True,
    run: bool = True,
) -> dict:
    """Run the jobs of ``spec`` not yet finished in ``out_dir``; return counts and paths.

    ``timeout_s`` (per job) wins over the spec's, which wins over :data:`DEFAULT_TIMEOUT_S`;
    a scenario entry's own ``timeout_s`` wins over all. ``run=False`` only rewrites the table
    and summary from the records already there (e.g. of a sweep still running, or stopped).
    """
    from dask.distributed import as_completed

    from swarmpark.apps.sweep_report import write_report

    out = Path(out_dir).resolve()
    (out / "sites").mkdir(parents=True, exist_ok=True)
    timeout_s = timeout_s or spec.timeout_s or DEFAULT_TIMEOUT_S
    done = finished_jobs(out)
    todo = [j for j in spec.jobs if j.job_id not in done] if run else []
    t0 = time.perf_counter()
    if todo:
        client, cluster = _client(scheduler, workers)
        try:
            futures = _submit(client, todo, out, timeout_s, retries)
            _collect(as_completed(futures), len(todo), progress)
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
    report = write_report(out, [j.job_id for j in spec.jobs], spec.name)
    report.update({"ran": len(todo), "skipped": len(done & {j.job_id for j in spec.jobs})})
    report["wall_s"] = round(time.perf_counter() - t0, 2)
    return report


def _submit(client, todo: list[Job], out: Path, timeout_s: float, retries: int) -> list:
    sites = {}
    futures = []
    for j in todo:
        site_err = ""
        if not j.site:
            key = (j.kind, j.seed, j.robots)
            if key not in sites:
                sites[key] = client.submit(
                    make_site, j.kind, j.seed, j.robots, site_path(out, j), timeout_s, pure=False
                )
            site_err = sites[key]
        futures.append(
            client.submit(run_job, j, str(out), timeout_s, retries, site_err, pure=False)
        )
    return futures


def _collect(completed, total: int, progress: bool) -> None:
    from tqdm import tqdm

    with tqdm(total=total, unit="job", disable=not progress, file=sys.stderr,
              mininterval=1.0 if sys.stderr.isatty() else 30.0) as bar:  # fmt: skip
        for fut in completed:
            rec = fut.result()
            bar.set_postfix_str(f"{rec['job']['job_id']}: {_status(rec)}", refresh=False)
            bar.update(1)


def _status(rec: dict) -> str:
    if rec["error"]:
        return "error"
    return "parked" if rec["result"]["success"] else "not parked"


def run_sweep_cli(args) -> int:
    """The ``swarmpark sweep`` command (see :mod:`swarmpark.apps.cli`)."""
    from swarmpark.apps.sweep_report import print_summary

    spec = load_spec(args.spec)
    if args.retries < 0:
        raise SpecError(f"--retries: an integer >= 0 (got {args.retries})")
    if args.workers is not None and args.workers < 1:
        raise SpecError(f"--workers: an integer >= 1 (got {args.workers})")
    out = Path(args.out) if args.out else Path("sweeps") / "out" / spec.name
    rep = run_sweep(
        spec, out, scheduler=args.scheduler, workers=args.workers, retries=args.retries,
        timeout_s=args.timeout, run=not args.no_run,
    )  # fmt: skip
    print_summary(rep)
    return 0
