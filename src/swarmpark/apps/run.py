"""Headless runs: drive a supervisor to the end of a scenario, collect the result, write outputs.

This is the application layer around the deterministic core: it alone reads the wall clock
(to report ``tick_ms``), shows progress, and writes files.
"""

from __future__ import annotations

import json
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Protocol

import numpy as np

from swarmpark.supervisor.core import Supervisor
from swarmpark.world.scenario import World

__all__ = ["run_world", "check_expect", "write_outputs", "RunOutput", "RunObserver"]

#: A run ends early once everything is settled for this long (and nothing is pending).
SETTLE_S = 1.0


class RunObserver(Protocol):
    """Watches a run from outside the tick (a recorder): called after the supervisor is made,
    after every tick, and once at the end with the result. It may read the supervisor and
    must not change it. (A server also calls ``on_command`` and ``on_alarm``.)"""

    def on_start(self, sup: Supervisor) -> None: ...

    def on_tick(self, sup: Supervisor) -> None: ...

    def on_end(self, sup: Supervisor, result: dict | None = None) -> None: ...


class RunOutput:
    """Everything a run produced: the result dict and the trajectories."""

    def __init__(
        self,
        result: dict,
        times: np.ndarray,
        poses: np.ndarray,
        people: np.ndarray,
        supervisor: Supervisor,
    ) -> None:
        self.result = result
        self.times = times  # (T,)
        self.poses = poses  # (T, N, 3)
        self.people = people  # (T, P, 2)
        self.supervisor = supervisor


def run_world(
    world: World,
    *,
    controller=None,
    progress: Callable[[float, float], None] | None = None,
    record_every: int = 1,
    observers: Sequence[RunObserver] = (),
    link=None,
    health=None,
) -> RunOutput:
    """Run ``world`` until ``duration_s`` or until settled; returns the result and trajectories.

    ``observers`` (e.g. a :class:`swarmpark.record.Recorder`) see the start, every tick
    (outside the timed part, so ``tick_ms`` is the core's alone) and the result.
    ``link`` is the robots (default: the simulator); over a link with no simulator behind it
    (ROS 2) the poses recorded are the ones the robots report and collisions are not seen.
    A link with a ``sync(supervisor)`` method is called after every tick (operator topics,
    visualization).
    """
    sup = Supervisor(world, controller=controller, link=link, health=health)
    for o in observers:
        o.on_start(sup)
    scn = world.scenario
    n_ticks = int(round(scn.duration_s / scn.dt_s))
    sync = getattr(sup.link, "sync", None)
    times, poses, people = [0.0], [sup.truth_poses().copy()], [_people(sup)]
    settled_since = None
    last_report = -np.inf
    for k in range(n_ticks):
        t0 = time.perf_counter()
        sup.tick()
        sup.metrics.tick_ms.append((time.perf_counter() - t0) * 1e3)
        for o in observers:
            o.on_tick(sup)
        if sync is not None:
            sync(sup)
        if (k + 1) % record_every == 0:
            times.append(sup.t)
            poses.append(sup.truth_poses().copy())
            people.append(_people(sup))
        if progress is not None and sup.t - last_report >= 1.0:
            progress(sup.t, scn.duration_s)
            last_report = sup.t
        if sup.settled():
            settled_since = sup.t if settled_since is None else settled_since
            if sup.t - settled_since >= SETTLE_S:
                break
        else:
            settled_since = None
    result = sup.metrics.result(sup.t, sup.truth_poses(), sup.goals, sup.has_goal)
    recoveries = getattr(sup.controller, "recoveries", None)
    if recoveries is not None:
        # Deadlock recoveries the navigator applied (RVO): who, when, what, time to clear
        # (None: still stuck at the end).
        result["recoveries"] = [
            {**r, "robot": sup.ids[r["robot"]], "cleared_after_s": r.get("cleared_after_s")}
            for r in recoveries
        ]
    result = {
        "scenario": scn.name,
        "seed": scn.seed,
        **result,
        "commands": [o.as_dict() for o in sup.outcomes],
        "assignment_switches": int(sum(g.switches for g in sup.groups)),
    }
    if sup.localizer is not None:
        result["localization"] = sup.localization_summary()
    if sup.formations:
        result["formation_error"] = [
            {"robots": [sup.ids[i] for i in f.idx], **f.metrics()} for f in sup.formations
        ]
    if sup.health.events:
        # Robots lost (stale odometry) or not following their commands, and when.
        result["link_faults"] = list(sup.health.events)
    result["expect"] = scn.expect.model_dump(exclude_none=True)
    result["expect_met"], result["expect_failures"] = check_expect(result, scn.expect)
    for o in observers:
        o.on_end(sup, result)
    return RunOutput(result, np.asarray(times), np.stack(poses), np.stack(people), sup)


def _people(sup) -> np.ndarray:
    return sup.sim.person_positions() if sup.sim is not None else np.zeros((0, 2))


def check_expect(result: dict, expect) -> tuple[bool, list[str]]:
    """Compare a result with the scenario's ``expect`` block; returns (met, reasons)."""
    fails = []
    if expect.success is not None and result["success"] != expect.success:
        fails.append(f"success is {result['success']}, expected {expect.success}")
    if expect.max_collisions is not None and len(result["collisions"]) > expect.max_collisions:
        fails.append(f"{len(result['collisions'])} collisions > {expect.max_collisions}")
    if expect.min_clearance_m is not None:
        c = result["min_clearance_m"]
        if c is None or c < expect.min_clearance_m:
            fails.append(f"min_clearance_m {c} < {expect.min_clearance_m}")
    if expect.max_time_to_park_s is not None:
        tp = result["time_to_park_s"]
        if tp is None or tp > expect.max_time_to_park_s:
            fails.append(f"time_to_park_s {tp} > {expect.max_time_to_park_s}")
    if expect.max_time_ratio is not None:
        tp, lb = result["time_to_park_s"], result.get("lower_bound_s")
        ratio = None if tp is None or not lb else tp / lb
        if ratio is None or ratio > expect.max_time_ratio:
            shown = "none" if ratio is None else f"{ratio:.3f}"
            fails.append(f"time_to_park_s / lower_bound_s {shown} > {expect.max_time_ratio}")
    loc = result.get("localization") or {}
    if expect.max_mean_localization_error_m is not None:
        e = loc.get("mean_error_m")
        if e is None or e > expect.max_mean_localization_error_m:
            fails.append(f"localization mean_error_m {e} > {expect.max_mean_localization_error_m}")
    if expect.max_recovery_s is not None:
        for k in loc.get("kidnaps", []):
            rs = k["recovered_after_s"]
            if rs is None or rs > expect.max_recovery_s:
                fails.append(
                    f"kidnapped {k['robot']} at {k['at_s']} s: recovered_after_s {rs} "
                    f"> {expect.max_recovery_s}"
                )
    return not fails, fails


def terminal_progress(t: float, total: float) -> None:
    """A one-line progress bar on stderr."""
    width = 30
    frac = min(t / total, 1.0) if total > 0 else 1.0
    bar = "#" * int(frac * width)
    sys.stderr.write(f"\r  [{bar:<{width}}] {t:7.1f} / {total:.0f} s simulated")
    sys.stderr.flush()


def write_outputs(out: RunOutput, out_dir: str | Path) -> dict[str, Path]:
    """Write result.json, trajectories.npz and a PNG of the run into ``out_dir``."""
    from swarmpark.apps.plot import plot_run

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = {
        "result": out_dir / "result.json",
        "trajectories": out_dir / "trajectories.npz",
        "png": out_dir / "run.png",
    }
    paths["result"].write_text(json.dumps(out.result, indent=2) + "\n")
    sup = out.supervisor
    # With AMCL: each tick's position error of every skid's estimate (m), and its time.
    loc = (
        {"loc_t_s": np.asarray(sup.loc_times), "loc_error_m": np.stack(sup.loc_errors)}
        if sup.loc_errors
        else {}
    )
    np.savez_compressed(
        paths["trajectories"],
        t_s=out.times,
        poses=out.poses,
        people_xy=out.people,
        robot_ids=np.array(sup.ids),
        **loc,
    )
    plot_run(out, paths["png"])
    return paths
