"""The viewers of a served session: a WebSocket client's frame queue (slow viewers are
dropped, never waited for) and the server-load report of ``GET /api/perf``."""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from swarmpark.server.engine import Session

__all__ = ["Client", "pump", "perf_report", "CLIENT_QUEUE", "MAX_OVERFLOWS", "SENDS_PER_FRAME"]

#: Frames a slow client may have queued before older ones are dropped.
CLIENT_QUEUE = 4
#: A viewer whose queue overflowed this many times without it taking a frame is
#: disconnected (a slow link must not cost the others, or the simulation, anything).
MAX_OVERFLOWS = 20
#: At most about this many viewers are sent each frame: with more, each viewer gets every
#: k-th frame in turn (k = ceil(viewers / SENDS_PER_FRAME); 200 viewers: 5 of the 20 frames/s),
#: so a crowd costs the server a bounded number of sends and never slows the simulation.
SENDS_PER_FRAME = 50

_slots = itertools.count()


@dataclass(eq=False)
class Client:
    """One WebSocket viewer: a small queue of encoded frames, and whether it needs a full one."""

    queue: asyncio.Queue = field(default_factory=lambda: asyncio.Queue(CLIENT_QUEUE))
    needs_full: bool = True
    dropped: int = 0
    #: Overflows since the viewer last took a frame (the sender resets it); past
    #: :data:`MAX_OVERFLOWS` the viewer is closed.
    overflows: int = 0
    #: Dropped for being too slow (the WebSocket handler closes it).
    closed: bool = False
    #: Its turn among the viewers when there are more than :data:`SENDS_PER_FRAME`.
    slot: int = field(default_factory=lambda: next(_slots))

    def close(self) -> None:
        """Drop the viewer: its sender ends after the frames queued (a ``None`` wakes it)."""
        self.closed = True
        with contextlib.suppress(asyncio.QueueFull):
            self.queue.put_nowait(None)

    def offer(self, delta: str, full: str | None) -> None:
        msg = full if self.needs_full else delta
        if msg is None:
            return
        if self.queue.full():
            # A dropped delta may have carried a slow part: resend everything next time.
            while not self.queue.empty():
                self.queue.get_nowait()
                self.dropped += 1
            self.needs_full = True
            self.overflows += 1
            if full is None:
                return
            msg = full
        self.queue.put_nowait(msg)
        if msg is full:
            self.needs_full = False


def perf_report(self: Session, frames: int | None = None) -> dict:
    """Server load over the last ``frames`` (at most :data:`PERF_HISTORY`) paced frames."""
    rows = list(self.perf)
    if frames is not None:
        rows = rows[-frames:] if frames > 0 else []
    ticks = sum(r[0] for r in rows)
    cpu = [r[1] for r in rows]
    sizes = [r[2] for r in rows if r[2] > 0]
    enc = [r[4] for r in rows if r[2] > 0]
    return {
        "frames": len(rows),
        "ticks": ticks,
        "clients": len(self.clients),
        "robots": self.sup.sim.n,
        "cpu_ms_per_tick": round(sum(cpu) / ticks, 3) if ticks else None,
        "cpu_ms_per_frame_mean": round(float(np.mean(cpu)), 3) if cpu else None,
        "cpu_ms_per_frame_p99": round(float(np.percentile(cpu, 99)), 3) if cpu else None,
        "cpu_ms_per_frame_max": round(max(cpu), 3) if cpu else None,
        "tick_wall_ms_mean": round(sum(r[3] for r in rows) / ticks, 3) if ticks else None,
        "encode_wall_ms_mean": round(float(np.mean(enc)), 3) if enc else None,
        "message_bytes_mean": round(float(np.mean(sizes)), 1) if sizes else None,
        "message_bytes_max": max(sizes) if sizes else None,
        "process_cpu_s": round(time.process_time(), 4),
        "frames_sent": self.frames_sent,
        "frames_paced": self.frames_paced,
        "sim_t_s": round(self.sup.t, 3),
        "ticks_total": self._ticks,
        "monotonic_s": round(time.monotonic(), 4),
    }


async def pump(ws, client: Client, clients: set, sender) -> None:
    """Serve one viewer's WebSocket: run ``sender()`` (which pushes its frames) beside a
    receiver that only notices the close; when either ends, drop ``client`` from ``clients``
    and stop both. Shared by the live server and replay."""
    from starlette.websockets import WebSocketDisconnect

    async def receiver() -> None:
        with contextlib.suppress(WebSocketDisconnect):
            while True:
                await ws.receive_text()  # nothing is expected; this notices the close

    tasks = [asyncio.ensure_future(sender()), asyncio.ensure_future(receiver())]
    try:
        await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
    finally:
        clients.discard(client)
        for t in tasks:
            t.cancel()
        for t in tasks:
            with contextlib.suppress(asyncio.CancelledError, WebSocketDisconnect, RuntimeError):
                await t
