"""A seeded mutation fuzzer over the suite's scenarios (issue 16): every mutated file either
loads, builds and runs a few ticks, or is refused with one clean ScenarioError line naming
the field (and, through ``swarmpark run``, exit code 2). No other exception, no hang past a
per-case limit, and grids over the cell budget are refused before anything is allocated.

The mutations are the ones that broke the loader before: non-finite numbers (``nan``,
``-inf``, the string ``'NaN'``), huge and tiny numbers, wrong types, deleted keys, long
strings, huge lists and YAML nested thousands deep.
"""

from __future__ import annotations

import copy
import io
import math
import random
import signal
import time
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path

import pytest
import yaml
from helpers import ROOT

from swarmpark.world.scenario import ScenarioError, build_world, load_scenario

#: The suite's scenarios (the experimental ones included); heavy sensing ones run fewer ticks.
SOURCES = sorted((ROOT / "scenarios").glob("*.yaml"))
SEED = 20261201
CASES = 300
TICKS = 2
#: Wall seconds one case may take (load, build, a few ticks) before it counts as a hang.
CASE_LIMIT_S = 30.0
#: The whole fuzz run stops adding cases after this long (CI time stays bounded).
RUN_BUDGET_S = 60.0

SPECIAL = [
    math.nan,
    math.inf,
    -math.inf,
    "NaN",
    "inf",
    1e20,
    -1e20,
    1e-300,
    0,
    -1,
    1e9,
    True,
    None,
    "",
    "x" * 5000,
    [],
    {},
    [[1e20, 1e20]] * 3,
    list(range(20_000)),
]


def _paths(node, prefix=()):
    """Every (path, value) in a parsed YAML tree."""
    yield prefix, node
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _paths(v, (*prefix, k))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _paths(v, (*prefix, i))


def _set(tree, path, value):
    node = tree
    for p in path[:-1]:
        node = node[p]
    node[path[-1]] = value


def _delete(tree, path):
    node = tree
    for p in path[:-1]:
        node = node[p]
    del node[path[-1]]


def _mutate(rng: random.Random, data: dict) -> tuple[str, object]:
    """One mutated copy of ``data`` as YAML text (or raw text), and what was done."""
    tree = copy.deepcopy(data)
    paths = [p for p, _ in _paths(tree) if p]
    kind = rng.random()
    if kind < 0.03:
        depth = rng.choice([500, 2_000, 10_000])
        return "a: " + "[" * depth + "]" * depth + "\n", f"nested {depth}"
    if kind < 0.05:
        return "\xff\xfe not utf-8 \x00", "binary"
    path = rng.choice(paths)
    if kind < 0.15 and len(path) > 0:
        _delete(tree, path)
        what = ("delete", path)
    elif kind < 0.25:
        n = rng.choice([3, 3000, 30_000])
        _set(tree, path, [[rng.uniform(-50, 50), rng.uniform(-50, 50)] for _ in range(n)])
        what = ("polygon", path, n)
    else:
        value = rng.choice(SPECIAL)
        _set(tree, path, value)
        what = ("set", path, repr(value)[:30])
    # PyYAML writes nan/inf as .nan/.inf, as a person would.
    dumper = getattr(yaml, "CSafeDumper", yaml.SafeDumper)
    return yaml.dump(tree, Dumper=dumper, sort_keys=False), what


class _Hang(Exception):
    pass


def _alarm(signum, frame):
    raise _Hang


def _run_case(path: Path, ticks: int) -> str:
    """'ok' after load, build and ``ticks`` ticks; the ScenarioError message if refused."""
    from swarmpark.supervisor.core import Supervisor

    try:
        scn = load_scenario(path)
        build_world(scn)
        # The ticks run without the timed commands (their first tick plans every park:
        # seconds each; the slow scenario tests cover those); the commands were validated.
        sup = Supervisor(build_world(scn.model_copy(update={"commands": []})))
        for _ in range(ticks):
            sup.tick()
    except ScenarioError as exc:
        return f"refused: {exc}"
    except ValueError as exc:
        # Supervisor refusals of a world the loader accepted must be ScenarioErrors too.
        raise AssertionError(f"{type(exc).__name__} escaped the loader: {exc}") from exc
    return "ok"


def test_mutated_scenarios_load_and_run_or_are_refused_in_one_clean_line(tmp_path):
    rng = random.Random(SEED)
    sources = [(p, yaml.safe_load(p.read_text())) for p in SOURCES]
    outcomes = {"ok": 0, "refused": 0}
    start = time.monotonic()
    old = signal.signal(signal.SIGALRM, _alarm)
    try:
        for case in range(CASES):
            if time.monotonic() - start > RUN_BUDGET_S:
                break
            src, data = rng.choice(sources)
            text, what = _mutate(rng, data)
            path = tmp_path / f"case{case}.yaml"
            path.write_text(text, encoding="utf-8", errors="surrogateescape")
            # The map files next to the scenario resolve as they do in the suite.
            if not (tmp_path / "maps").exists():
                (tmp_path / "maps").symlink_to(ROOT / "scenarios" / "maps")
            t0 = time.monotonic()
            signal.setitimer(signal.ITIMER_REAL, CASE_LIMIT_S)
            try:
                result = _run_case(path, TICKS)
            except _Hang:
                pytest.fail(f"case {case} from {src.name} ({what}) hung past {CASE_LIMIT_S} s")
            except AssertionError:
                raise
            except BaseException as exc:  # noqa: BLE001 - any other exception is the bug
                pytest.fail(
                    f"case {case} from {src.name} ({what}): {type(exc).__name__}: {str(exc)[:200]}"
                )
            finally:
                signal.setitimer(signal.ITIMER_REAL, 0)
            took = time.monotonic() - t0
            assert took < CASE_LIMIT_S
            if result != "ok":
                msg = result.removeprefix("refused: ")
                assert "\n" not in msg and len(msg) < 1000, (what, msg)
                assert ":" in msg, (what, msg)  # "field: what (got value)"
                outcomes["refused"] += 1
            else:
                outcomes["ok"] += 1
    finally:
        signal.signal(signal.SIGALRM, old)
    done = outcomes["ok"] + outcomes["refused"]
    assert done >= 100, outcomes  # the budget allowed a real sample
    assert outcomes["refused"] >= 20 and outcomes["ok"] >= 5, outcomes


def test_a_refused_scenario_exits_2_with_one_line_through_the_cli(tmp_path):
    from swarmpark.apps.cli import main

    for text, field in (
        ("a: " + "[" * 5000 + "]" * 5000 + "\n", "name"),
        (
            (ROOT / "scenarios" / "hangar-park.yaml")
            .read_text()
            .replace("dt_s: 0.05", "dt_s: 1.0e-300"),
            "dt_s",
        ),
        (
            (ROOT / "tests" / "data" / "ui-small.yaml")
            .read_text()
            .replace("size_m: [12, 8]", "size_m: [9000, 9000]"),
            "map",
        ),
        (
            (ROOT / "tests" / "data" / "ui-small.yaml")
            .read_text()
            .replace("pose: [2.0, 2.0, 0.0]", "pose: [.nan, 2.0, 0.0]"),
            "robots[0].pose",
        ),
    ):
        path = tmp_path / "bad.yaml"
        path.write_text(text)
        err, out = io.StringIO(), io.StringIO()
        with redirect_stderr(err), redirect_stdout(out):
            code = main(["run", str(path)])
        lines = err.getvalue().strip().splitlines()
        assert code == 2 and len(lines) == 1 and field in lines[0], (field, err.getvalue())
