"""Registry of timing and quality benchmarks run by ``swarmpark bench``.

A benchmark is a function registered with :func:`register` in a module of this package; it
takes ``quick`` (bool: smaller sizes and fewer repeats, for smoke runs) and returns a list of
rows (flat dicts of numbers and strings). The runner imports every module here, runs the
selected benchmarks, prints one table per benchmark and writes all rows as JSON.
Timing uses ``time.perf_counter`` here, never inside the core.

>>> @register("example", "a doc example", target="none")
... def _example(quick: bool) -> list[dict]:
...     return [{"case": "n=1", "value": 1.0}]
>>> REGISTRY.pop("example").fn(True)
[{'case': 'n=1', 'value': 1.0}]
"""

from __future__ import annotations

import importlib
import pkgutil
import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass

__all__ = ["Benchmark", "REGISTRY", "register", "discover", "time_call"]


@dataclass(frozen=True)
class Benchmark:
    name: str
    description: str
    target: str
    fn: Callable[[bool], list[dict]]


REGISTRY: dict[str, Benchmark] = {}


def register(name: str, description: str, *, target: str = ""):
    """Decorator that registers a benchmark under ``name`` (must be unique)."""

    def deco(fn: Callable[[bool], list[dict]]) -> Callable[[bool], list[dict]]:
        if name in REGISTRY:
            raise ValueError(f"benchmark {name!r} registered twice")
        REGISTRY[name] = Benchmark(name, description, target, fn)
        return fn

    return deco


def discover() -> dict[str, Benchmark]:
    """Import every benchmark module in this package and return the registry."""
    for mod in pkgutil.iter_modules(__path__):
        importlib.import_module(f"{__name__}.{mod.name}")
    return REGISTRY


def time_call(fn: Callable[[], object], repeat: int, warmup: int = 1) -> dict[str, float]:
    """Run ``fn`` ``warmup + repeat`` times; return mean, median and max wall time in ms."""
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append((time.perf_counter() - t0) * 1e3)
    return {
        "mean_ms": statistics.fmean(times),
        "median_ms": statistics.median(times),
        "max_ms": max(times),
    }
