"""The served simulation's clock: ticks paced by real time, frames encoded once and offered
to every viewer.

:class:`Pacing` is the half of :class:`swarmpark.server.engine.Session` that runs in time:
the ticks (timed for the status panel; a tick that raises stops every skid), the frames
(encoded once, in the sim thread, then queued to the viewers) and the pacing task on the
event loop. The state it works on (the supervisor, the viewers, the timings) lives in the
session; see :mod:`swarmpark.server.engine` for the threads.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import time

import numpy as np

from swarmpark.server import viewers
from swarmpark.server.frames import FrameEncoder
from swarmpark.server.viewers import MAX_OVERFLOWS, perf_report

__all__ = ["Pacing", "FRAME_HZ", "MAX_TICKS_PER_FRAME", "MIN_YIELD_S"]

log = logging.getLogger("swarmpark.server")

#: State frames per wall second sent to the browsers.
FRAME_HZ = 20.0
#: Most ticks run between two frames; beyond that the simulation falls behind real time
#: (it slows down) instead of freezing the server to catch up.
MAX_TICKS_PER_FRAME = 40
#: Least time the pacing task sleeps per frame (s), even when it is behind.
MIN_YIELD_S = 0.003


class Pacing:
    """Ticking, frames and the pacing task of a :class:`~swarmpark.server.engine.Session`
    (state lives in the session)."""

    # ------------------------------------------------------------------ ticking

    def tick(self) -> None:
        """One fixed step of the core (timed for the status panel)."""
        self._keep_teleop_alive()
        t0, c0 = time.perf_counter(), time.process_time()
        step = self.sup.tick()
        self._ticks += 1
        if self._sync is not None:
            self._sync(self.sup)  # a real link's operator topics and visualization
        ms = (time.perf_counter() - t0) * 1e3
        if step is not None and step.new_contacts and self.sup.teleop.any():
            self._teleop_contacts(step.new_contacts)
        self.tick_ms.append(ms)
        self._tick_wall_ms += ms
        self._cpu_ms += (time.process_time() - c0) * 1e3
        for o in self.observers:
            o.on_tick(self.sup)

    def _teleop_contacts(self, contacts) -> None:
        """A contact of a teleoperated skid is an alarm (the monitor should have stopped it)."""
        driven = {self.sup.ids[i] for i in np.flatnonzero(self.sup.teleop)}
        for c in contacts:
            if c.a in driven or c.b in driven:
                self.alarm(
                    {
                        "kind": "teleop-contact",
                        "text": f"{c.kind} contact under teleop: {c.a} - {c.b}",
                        "robots": [r for r in (c.a, c.b) if r in self.sup.index],
                    }
                )

    def step(self, ticks: int) -> None:
        """Run ``ticks`` ticks now; a failing tick pauses the session with :attr:`error`."""
        try:
            for _ in range(ticks):
                self.tick()
        except Exception as exc:
            self._fail(exc)
        self.encoder.metrics_now = True

    def _fail(self, exc: Exception) -> None:
        # Keep serving: the operator must see what happened, and may still reset or load.
        # The skids are held on the link (a paused simulation does not move them either,
        # but a link to real robots would keep the last commands alive until their
        # dead-man); goals and groups are kept for a resume.
        log.exception("simulation tick failed")
        self.error = f"simulation stopped: {type(exc).__name__}: {exc}"
        self.paused = True
        with contextlib.suppress(Exception):
            self.sup.link.stop(list(self.sup.ids))
        self.alarm({"kind": "tick-error", "error": self.error})

    def due(self, wall_elapsed_s: float) -> int:
        """How many ticks are due after ``wall_elapsed_s`` more of wall time (consumed)."""
        if self.paused or self.error:
            self._budget_s = 0.0
            return 0
        dt = self.sup.info.dt_s
        self._budget_s += wall_elapsed_s * self.speed
        n = min(int((self._budget_s + 1e-9) // dt), MAX_TICKS_PER_FRAME)
        self._budget_s -= n * dt
        if n == MAX_TICKS_PER_FRAME:
            self._budget_s = min(self._budget_s, dt)  # fall behind rather than pile up
        return n

    def _carry(self, ticks: int, max_wall_s: float) -> None:
        """Put ``ticks`` back into the budget, keeping at most ``max_wall_s`` of backlog."""
        dt = self.sup.info.dt_s
        self._budget_s = min(self._budget_s + ticks * dt, max(max_wall_s * self.speed, dt))

    def advance(self, wall_elapsed_s: float) -> int:
        """Run the ticks due after ``wall_elapsed_s`` of wall time; returns how many ran."""
        n = self.due(wall_elapsed_s)
        for _ in range(n):
            self.tick()
        return n

    # ------------------------------------------------------------------ frames

    def sim_extra(self) -> dict:
        ticks = list(self.tick_ms)
        return {
            "rev": self.rev,
            "seq": self.seq,
            "sim": {
                "paused": self.paused,
                "speed": self.speed,
                "rate": round(self._rate, 2),
                "tick_ms": round(float(np.mean(ticks)), 2) if ticks else None,
                "error": self.error,
                "estop": bool(self.sup.estopped),
            },
            "alarms": list(self.alarms)[-10:],
        }

    def snapshot(self) -> dict:
        """A full frame without disturbing the change tracking of the broadcast."""
        enc = FrameEncoder(self.sup)
        _, full = enc.frame(self.sim_extra(), want_delta=False, want_full=True)
        return full  # type: ignore[return-value]

    def encode(self, want_full: bool) -> tuple[str, str | None]:
        """One frame as JSON text (the delta, and the full frame if asked); strict JSON."""
        t0, c0 = time.perf_counter(), time.process_time()
        self.seq += 1
        delta, full = self.encoder.frame(self.sim_extra(), want_full=want_full)
        d_msg = json.dumps(delta, separators=(",", ":"), allow_nan=False)
        f_msg = (
            json.dumps(full, separators=(",", ":"), allow_nan=False) if full is not None else None
        )
        self.frame_ms.append((time.perf_counter() - t0) * 1e3)
        self._cpu_ms += (time.process_time() - c0) * 1e3
        return d_msg, f_msg

    def offer(self, d_msg: str, f_msg: str | None) -> int:
        """Queue an encoded frame to every viewer (on the loop); returns the delta's bytes."""
        clients = list(self.clients)
        stride = -(-len(clients) // viewers.SENDS_PER_FRAME)
        slow = self.encoder.last_had_slow
        for c in clients:
            if stride > 1 and (self.seq + c.slot) % stride:
                # Not its turn. If this frame carries a slow part (goals, paths, ...), the
                # next frame it gets is whole; if not, the next delta is all it needs (the
                # fast parts are whole in every frame), a fraction of the bytes.
                if slow:
                    c.needs_full = True
                continue
            c.offer(d_msg, f_msg)
            if c.overflows > MAX_OVERFLOWS:
                c.close()
                self.clients.discard(c)
                log.warning("a viewer too slow for the frames was disconnected")
        self.last_message_bytes = len(d_msg)
        self.frames_sent += 1
        return len(d_msg)

    def broadcast(self) -> int:
        """Encode one frame and queue it to every client; returns the delta's size in bytes."""
        if not self.clients:
            return 0
        return self.offer(*self.encode(any(c.needs_full for c in self.clients)))

    def perf_report(self, frames: int | None = None) -> dict:
        """Server load over the last ``frames`` paced frames (:func:`.viewers.perf_report`)."""
        return perf_report(self, frames)

    # ------------------------------------------------------------------ the pacing task

    def _burst(self, n: int, period: float, want_frame: bool, want_full: bool):
        """In the sim thread: up to ``n`` due ticks within one frame period, then the frame.

        Returns ``(ticks run, delta message or None, full message or None)``."""
        t_start = time.perf_counter()
        self._tick_wall_ms = self._cpu_ms = 0.0
        ran = 0
        try:
            for k in range(n):
                if self.paused or self.error:
                    break
                if k and time.perf_counter() - t_start > period:
                    # Ticks slower than real time: send a frame first and run the rest
                    # later (the simulation falls behind, the view stays live).
                    self._carry(n - k, 5 * period)
                    break
                self.tick()
                ran += 1
        except Exception as exc:
            self._fail(exc)
        d_msg = f_msg = None
        if want_frame:
            try:
                d_msg, f_msg = self.encode(want_full)
            except Exception as exc:  # a frame that cannot be sent must not stop the loop
                self._fail(exc)
        return ran, d_msg, f_msg

    async def run(self) -> None:
        """Tick at the speed factor and broadcast at :data:`FRAME_HZ` until cancelled.

        The ticks and the frame run in the sim thread; this task only paces them and hands
        the frames to the viewers, so requests are answered while a tick runs."""
        loop = asyncio.get_running_loop()
        period = 1.0 / FRAME_HZ
        last = loop.time()
        next_frame = last
        rate_t, rate_sim = last, self.sup.t
        while True:
            now = loop.time()
            elapsed, last = now - last, now
            # After a stall (a laptop lid, a long plan) do not race to catch up.
            n = self.due(min(elapsed, 5 * period))
            clients = list(self.clients)
            want_full = any(c.needs_full for c in clients)
            ran, d_msg, f_msg = await self.on_sim(self._burst, n, period, bool(clients), want_full)
            if now - rate_t >= 1.0:
                sim_dt = self.sup.t - rate_sim
                self._rate = sim_dt / (now - rate_t) if sim_dt >= 0 else 0.0
                rate_t, rate_sim = now, self.sup.t
            nbytes = self.offer(d_msg, f_msg) if d_msg is not None else 0
            self.perf.append(
                (
                    ran,
                    self._cpu_ms,
                    nbytes,
                    self._tick_wall_ms,
                    self.frame_ms[-1] if nbytes and self.frame_ms else 0.0,
                )
            )
            self.frames_paced += 1
            next_frame += period
            delay = next_frame - loop.time()
            if delay < MIN_YIELD_S:
                # Behind: still give the loop a few milliseconds for I/O (the viewers).
                next_frame, delay = loop.time(), MIN_YIELD_S
            await asyncio.sleep(delay)
