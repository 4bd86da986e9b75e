"""The served simulation: one supervisor, paced by real time, and the clients watching it.

The core stays deterministic: :class:`Session` calls :meth:`Supervisor.tick` at fixed steps;
pacing, the speed factor and pause live here (the ticking, the frames and the pacing task in
:mod:`swarmpark.server.pacing`, whose :class:`~swarmpark.server.pacing.Pacing` the session
extends).

Threads (the event loop must never wait on the simulation):

* **the sim thread** (one worker, :meth:`Session.on_sim`) owns the supervisor: ticks, frame
  encoding and every command that changes orders run there, one after the other, so a
  command still lands *between* two ticks and no two pieces of code change the supervisor at
  once;
* **the work pool** (:meth:`Session.off_loop`) runs heavy read-mostly work: layout previews,
  the layout and planning of a park, loading and building a scenario; its result is applied
  in the sim thread;
* **the event loop** answers requests and feeds the viewers. The e-stop and per-robot stops
  are applied from here at once (:meth:`Session.estop_now`): a latched flag and a hold on the
  robot link, which the tick reads; nothing queues in front of them.

A tick that raises stops every skid (link hold), pauses the session with :attr:`error`,
raises an alarm and keeps the orders (goals, groups) for a resume after the fix.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import time
from collections import deque
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from swarmpark.server.frames import FrameEncoder, map_png, world_info
from swarmpark.server.pacing import FRAME_HZ, MAX_TICKS_PER_FRAME, Pacing
from swarmpark.server.viewers import CLIENT_QUEUE, MAX_OVERFLOWS, Client
from swarmpark.supervisor.core import TELEOP_TIMEOUT_S, Outcome, Supervisor
from swarmpark.world.scenario import World, build_world, load_scenario

__all__ = [
    "Session",
    "Client",
    "FRAME_HZ",
    "MAX_TICKS_PER_FRAME",
    "TELEOP_DEADMAN_S",
    "CLIENT_QUEUE",
    "MAX_OVERFLOWS",
]

#: A teleop command is re-applied while the operator sent it within this many wall seconds
#: (the dead-man: a closed tab or a dropped link stops the skid).
TELEOP_DEADMAN_S = 0.5
#: Wall-clock tick timings kept for the status panel.
TICK_HISTORY = 200
#: Paced frames kept for GET /api/perf.
PERF_HISTORY = 2000
#: Alarms kept for the alarms panel (newest last).
ALARM_HISTORY = 50
#: Heavy work (previews, park plans, scenario loads) that may run at once, off the loop.
WORK_THREADS = 2


class Session(Pacing):
    """A scenario being served: the supervisor, the pacing, the frames and the viewers.

    Parameters
    ----------
    scenario_path
        Scenario YAML to load.
    speed
        Simulated seconds per wall second.
    running
        Start ticking as soon as the pacing task runs (else start paused).
    scripted
        Run the scenario's own timed commands (else the operator gives every command).
    clock
        Wall clock (seconds) for the teleop dead-man; injectable for tests.
    observers
        Watch every run of the session (:class:`swarmpark.apps.run.RunObserver`: a recorder,
        the audit log): ``on_start`` with each new supervisor (load, reset), ``on_tick``
        after each tick, ``on_end`` with the result when a run is replaced or the server
        stops; ``on_command``/``on_alarm`` where they have them.
    """

    def __init__(
        self,
        scenario_path: str | Path,
        *,
        speed: float = 1.0,
        running: bool = True,
        scripted: bool = True,
        clock: Callable[[], float] = time.monotonic,
        observers: Sequence = (),
        link_factory: Callable[[World], object] | None = None,
    ) -> None:
        self.observers = list(observers)
        #: Builds the robots' link for a world (``None``: the simulator); e.g. ROS 2.
        self.link_factory = link_factory
        self.sup: Supervisor | None = None
        self.speed = float(speed)
        self.clock = clock
        self.paused = not running
        self.rev = 0
        self.seq = 0
        self.error: str | None = None
        self.clients: set[Client] = set()
        self.tick_ms: deque[float] = deque(maxlen=TICK_HISTORY)
        self.frame_ms: deque[float] = deque(maxlen=TICK_HISTORY)
        #: Per paced frame: ticks run, CPU ms of ticks + broadcast, delta bytes, wall ms of
        #: the ticks, wall ms of encoding the frame.
        self.perf: deque[tuple[int, float, int, float, float]] = deque(maxlen=PERF_HISTORY)
        self.frames_sent = 0
        self.frames_paced = 0
        self.last_message_bytes = 0
        self._task: asyncio.Task | None = None
        self._budget_s = 0.0
        self._rate = 0.0
        self._tick_wall_ms = 0.0
        self._cpu_ms = 0.0
        #: Alarms raised (failed ticks, contacts under teleop): ``{"t_s", "kind", "text"}``.
        self.alarms: deque[dict] = deque(maxlen=ALARM_HISTORY)
        self.alarm_seq = 0
        #: Wall time (clock) each robot was released: a teleop request issued before the
        #: release may still arrive after it and must not take the skid back.
        self._released: dict[str, float] = {}
        self._sim_pool: ThreadPoolExecutor | None = None
        self._work_pool: ThreadPoolExecutor | None = None
        self.load(scenario_path, scripted=scripted)

    # ------------------------------------------------------------------ scenario

    def load(self, path: str | Path, *, scripted: bool = True) -> None:
        """Load a scenario (raises :class:`~swarmpark.world.scenario.ScenarioError`, changing
        nothing, if it is bad)."""
        self.install(*self.build(path, scripted=scripted))

    @staticmethod
    def build(path: str | Path, *, scripted: bool = True) -> tuple[Path, bool, World]:
        """Read and build a scenario (no state touched: safe in the work pool)."""
        path = Path(path)
        scn = load_scenario(path)
        if not scripted:
            scn = scn.model_copy(update={"commands": []})
        return path, scripted, build_world(scn)

    def install(self, path: Path, scripted: bool, world: World) -> None:
        """Serve a built world (in the sim thread, between ticks)."""
        self.path, self.scripted, self.world = path.resolve(), scripted, world
        self._start(world)

    def reset(self) -> None:
        """Start the current scenario over (same world, a fresh supervisor)."""
        self._start(self.world)

    def _start(self, world: World) -> None:
        self._end_observers()
        old = getattr(self.sup, "link", None)
        if old is not None and hasattr(old, "close"):
            old.close()  # the robots of a real link stop
        link = self.link_factory(world) if self.link_factory is not None else None
        self.sup = Supervisor(world, link=link)
        self._ticks = 0
        self._sync = getattr(self.sup.link, "sync", None)
        for o in self.observers:
            o.on_start(self.sup)
        self.encoder = FrameEncoder(self.sup)
        self.rev += 1
        self.error = None
        self._released = {}
        self._teleop: dict[str, tuple[float, float, float, float]] = {}
        self._budget_s = 0.0
        self._world_info = {"rev": self.rev, **self.describe(), **world_info(self.sup)}
        self._map_png: bytes | None = None
        for c in self.clients:
            c.needs_full = True

    def _end_observers(self) -> None:
        """Tell the observers the current run is over (with its result)."""
        sup = getattr(self, "sup", None)
        if sup is None or not self.observers or getattr(self, "_ended", None) is sup:
            return
        self._ended = sup
        result = {
            "scenario": sup.world.scenario.name,
            **sup.metrics.result(sup.t, sup.sim.poses, sup.goals, sup.has_goal),
            "commands": [o.as_dict() for o in sup.outcomes],
        }
        for o in self.observers:
            o.on_end(sup, result)

    def alarm(self, entry: dict) -> None:
        """Raise an alarm (shown in the alarms panel) and pass it to the observers that take
        them (e.g. a failed tick)."""
        self.alarm_seq += 1
        sup = getattr(self, "sup", None)
        self.alarms.append(
            {
                "id": self.alarm_seq,
                "t_s": round(sup.t, 3) if sup is not None else 0.0,
                "kind": entry.get("kind", "alarm"),
                "text": str(entry.get("error") or entry.get("text") or entry.get("kind")),
                **({"robots": list(entry["robots"])} if "robots" in entry else {}),
            }
        )
        for o in self.observers:
            fn = getattr(o, "on_alarm", None)
            if fn is not None:
                fn(entry)

    def describe(self) -> dict:
        scn = self.world.scenario
        return {
            "scenario": scn.name,
            "file": self.path.name,
            "scripted": self.scripted,
            "dt_s": scn.dt_s,
            "duration_s": scn.duration_s,
        }

    def world_info(self) -> dict:
        return self._world_info

    def map_png(self) -> bytes:
        if self._map_png is None:
            self._map_png = map_png(self.sup)
        return self._map_png

    def status(self) -> dict:
        return {
            **self.describe(),
            "rev": self.rev,
            "t_s": round(self.sup.t, 3),
            "paused": self.paused,
            "speed": self.speed,
            "ticks": self._ticks,
            "error": self.error,
        }

    # ------------------------------------------------------------------ commands

    def command(self, outcome: Outcome) -> Outcome:
        """Record that a command was applied (frames show its effect at once)."""
        self.encoder.metrics_now = True
        return outcome

    def teleop(self, robot: str, v: float, omega: float) -> Outcome:
        released = self._released.get(robot)
        if released is not None and self.clock() - released < TELEOP_DEADMAN_S:
            # Release is final for commands issued before it: a request of the held stick
            # still in flight when the operator let go must not take the skid back.
            return self.command(
                Outcome(
                    False,
                    "teleop",
                    f"teleop.robot: robot {robot!r} was released "
                    f"{self.clock() - released:.2f} s ago; take it over again after "
                    f"{TELEOP_DEADMAN_S} s",
                    self.sup.t,
                )
            )
        out = self.sup.set_teleop(robot, v, omega)
        if out.accepted:
            self._teleop[robot] = (v, omega, self.clock(), self.sup.t)
        return self.command(out)

    def release(self, robot: str) -> Outcome:
        self._teleop.pop(robot, None)
        out = self.sup.release(robot)
        if out.accepted:
            self._released[robot] = self.clock()
        return self.command(out)

    def estop_now(self) -> Outcome:
        """The e-stop, applied from any thread without waiting for the sim thread: the
        latched flag (every later tick commands zero and holds) and a hold on the link for
        every robot (the next step brakes them even if a tick is under way)."""
        sup = self.sup
        out = sup.estop()
        with contextlib.suppress(Exception):  # the flag is set; the link is a second path
            sup.link.stop(list(sup.ids))
        self.encoder.metrics_now = True
        return out

    def stop_now(self, names) -> Outcome:
        """Per-robot stop on the same unblocked path as the e-stop."""
        sup = self.sup
        out = sup.stop(names)
        if out.accepted:
            with contextlib.suppress(Exception):
                sup.link.stop(list(out.detail.get("robots", [])))
        self.encoder.metrics_now = True
        return out

    # ------------------------------------------------------------------ threads and lifecycle

    def _sim_executor(self) -> ThreadPoolExecutor:
        if self._sim_pool is None:
            self._sim_pool = ThreadPoolExecutor(1, thread_name_prefix="swarmpark-sim")
        return self._sim_pool

    def _work_executor(self) -> ThreadPoolExecutor:
        if self._work_pool is None:
            self._work_pool = ThreadPoolExecutor(WORK_THREADS, thread_name_prefix="swarmpark-work")
        return self._work_pool

    async def on_sim(self, fn: Callable, *args, **kwargs):
        """Run ``fn`` in the sim thread (between two ticks) and await its result."""
        loop = asyncio.get_running_loop()
        return await loop.run_in_executor(
            self._sim_executor(), functools.partial(fn, *args, **kwargs)
        )

    async def off_loop(self, fn: Callable, *args, **kwargs):
        """Run heavy ``fn`` in the work pool (neither the loop nor the ticks wait on it)."""
        loop = asyncio.get_running_loop()
        return await loop.run_in_executor(
            self._work_executor(), functools.partial(fn, *args, **kwargs)
        )

    def _keep_teleop_alive(self) -> None:
        """Re-send held teleop commands before the supervisor's own timeout (sim time) runs
        out, for as long as the operator keeps sending them (wall time): at a speed factor
        above one, sim time outruns the operator's key repeat."""
        now = self.clock()
        for robot, (v, w, wall, sim_t) in list(self._teleop.items()):
            if now - wall > TELEOP_DEADMAN_S or not self.sup.teleop[self.sup.index[robot]]:
                del self._teleop[robot]
            elif self.sup.t - sim_t >= 0.5 * TELEOP_TIMEOUT_S:
                self.sup.set_teleop(robot, v, w)
                self._teleop[robot] = (v, w, wall, self.sup.t)

    def start(self) -> None:
        if self._task is None:
            self._task = asyncio.get_running_loop().create_task(self.run(), name="swarmpark-sim")

    async def stop(self) -> None:
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
            self._task = None
        for pool in (self._sim_pool, self._work_pool):
            if pool is not None:
                pool.shutdown(wait=True, cancel_futures=True)
        self._sim_pool = self._work_pool = None
        self._end_observers()
        for o in self.observers:
            close = getattr(o, "close", None)
            if close is not None:
                close()
