"""``swarmpark replay FILE.mcap``: the operator interface on a recorded run, with a timeline.

The replay server answers the read-only part of the live API (``/api/world``, ``/api/map``,
``/api/auth``, ``/api/scenarios``, the ``/api/ws`` frame stream) from the recording, so the
live UI (``static/app.js``) draws a replay exactly as it draws a run; ``static/replay.js``
adds the timeline (play, pause, seek, speed) over ``/api/replay``. Nothing can be commanded.
Exit codes: 0 after a clean shutdown, 2 for a bad or truncated file (one line on stderr).
"""

from __future__ import annotations

import asyncio
import contextlib
import io
import json
import math
import sys
from collections import deque

import numpy as np
from fastapi import (
    APIRouter,
    FastAPI,
    HTTPException,
    Query,
    Request,
    WebSocket,
)
from fastapi.responses import HTMLResponse, Response
from fastapi.staticfiles import StaticFiles
from pydantic import BaseModel, ConfigDict, Field

from swarmpark.record.reader import Recording, RecordingError, load_recording

__all__ = ["Player", "create_replay_app", "replay_command", "SPEEDS"]

#: Frames per wall second sent while playing.
FRAME_HZ = 20.0
#: Playback speed factors offered (and accepted) by the timeline.
SPEEDS = (0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0)
LOG_LENGTH = 40
XY_DEC, DEG_DEC, V_DEC = 3, 1, 2
REPLAY_SCRIPT = '<script src="/static/replay.js"></script>'


def _latest(events: list, t: float):
    """The value of the last ``(t_s, value)`` event at or before ``t`` (``None`` if none)."""
    out = None
    for te, v in events:
        if te > t + 1e-9:
            break
        out = v
    return out


class Player:
    """The playback clock over a recording and the frames it shows (same format as live)."""

    def __init__(self, rec: Recording) -> None:
        self.rec = rec
        self.t = float(rec.times[0]) if len(rec.times) else 0.0
        self.playing = False
        self.speed = 1.0
        self.seq = 0
        self.clients: set = set()
        self.dirty = True
        self._states = rec.world["states"]
        self._parked = self._states.index("parked") if "parked" in self._states else -1

    # ------------------------------------------------------------------ control

    def seek(self, t: float) -> None:
        self.t = float(np.clip(t, 0.0, self.rec.duration_s))
        self.dirty = True

    def advance(self, wall_s: float) -> None:
        if not self.playing:
            return
        self.seek(self.t + wall_s * self.speed)
        if self.t >= self.rec.duration_s:
            self.playing = False

    def status(self) -> dict:
        return {
            "t_s": round(self.t, 3),
            "duration_s": self.rec.duration_s,
            "playing": self.playing,
            "speed": self.speed,
            "speeds": list(SPEEDS),
            "file": self.rec.path.name,
            "scenario": self.rec.world.get("scenario") or self.rec.run.get("scenario"),
        }

    # ------------------------------------------------------------------ frames

    def world_info(self) -> dict:
        r = self.rec
        return {
            **r.world,
            "rev": 1,
            "scenario": r.run.get("scenario", ""),
            "file": r.path.name,
            "scripted": True,
            "dt_s": float(r.run.get("dt_s", "0.05")),
            "duration_s": r.duration_s,
            "replay": True,
        }

    def map_png(self) -> bytes:
        from PIL import Image

        r = self.rec
        img = np.full(r.occupied.shape, 255, np.uint8)
        img[r.unknown] = 205
        img[r.occupied] = 60
        buf = io.BytesIO()
        Image.fromarray(np.flipud(img), mode="L").save(buf, format="PNG")
        return buf.getvalue()

    def frame(self) -> dict:
        """A full frame at the playback time (the format of the live ``/api/ws``)."""
        r, t = self.rec, self.t
        k = r.index_at(t)
        poses, vel, states = r.poses[k], r.vel[k], r.states[k]
        robots = [
            [round(float(x), XY_DEC), round(float(y), XY_DEC), round(math.degrees(h), DEG_DEC), int(s), round(float(v), V_DEC)]
            for (x, y, h), (v, _), s in zip(poses.tolist(), vel.tolist(), states.tolist(), strict=True)
        ]  # fmt: skip
        people = []
        if len(r.people_times):
            j = max(int(np.searchsorted(r.people_times, t + 1e-9, side="right")) - 1, 0)
            people = np.round(r.people_xy[j], 2).tolist()
        goals = _latest(r.goals, t)
        goal_rows = (
            [None if np.isnan(g[0]) else [round(g[0], XY_DEC), round(g[1], XY_DEC), round(math.degrees(g[2]), DEG_DEC)] for g in goals.tolist()]
            if goals is not None
            else [None] * len(r.ids)
        )  # fmt: skip
        paths = _latest(r.paths, t) or [None] * len(r.ids)
        groups = _latest(r.groups, t) or []
        self.seq += 1
        return {
            "type": "state",
            "rev": 1,
            "seq": self.seq,
            "t_s": round(float(r.times[k]), 3),
            "estop": bool(r.estop[k]),
            "robots": robots,
            "people": people,
            "sim": {
                "paused": not self.playing,
                "speed": self.speed,
                "rate": self.speed if self.playing else 0.0,
                "tick_ms": None,
                "error": None,
            },
            "replay": {"t_s": round(t, 3), "duration_s": r.duration_s},
            "full": True,
            "goals": goal_rows,
            "paths": paths,
            "groups": groups,
            "log": self._log(t),
            "metrics": self._metrics(t, states, goal_rows),
        }

    def _log(self, t: float) -> list[dict]:
        shown: deque = deque(maxlen=LOG_LENGTH)
        last_teleop = None
        for o in self.rec.commands:
            if o["t_s"] > t + 1e-9:
                break
            robot = (o.get("detail") or {}).get("robot")
            if o["accepted"] and o["command"] == "teleop":
                if last_teleop == robot:
                    continue
                last_teleop = robot
            elif o["command"] == "release":
                last_teleop = None
            shown.append(
                {
                    "accepted": o["accepted"],
                    "command": o["command"],
                    "reason": o["reason"],
                    "t_s": round(o["t_s"], 2),
                    **({"robot": robot} if robot else {}),
                }
            )
        return list(shown)

    def _metrics(self, t: float, states: np.ndarray, goals: list) -> dict:
        alarms = [a for a in self.rec.alarms if a["t_s"] <= t + 1e-9]
        res = self.rec.result or {}
        end = t >= self.rec.duration_s - 1e-9
        return {
            "success": res.get("success") if end else "-",
            "parked": int(np.sum(states == self._parked)),
            "commanded": sum(g is not None for g in goals),
            "time_to_park_s": res.get("time_to_park_s") if end else None,
            "lower_bound_s": res.get("lower_bound_s"),
            "collisions": sum(a["kind"] == "collision" for a in alarms),
            "min_clearance_m": res.get("min_clearance_m") if end else None,
            "deadlocks": sum(a["kind"] == "deadlock" for a in alarms),
            "path_length_m": None,
        }

    def broadcast(self) -> None:
        if not self.clients:
            return
        msg = json.dumps(self.frame(), separators=(",", ":"))
        for c in self.clients:
            c.offer(msg, msg)
        self.dirty = False

    async def run(self) -> None:
        loop = asyncio.get_running_loop()
        period = 1.0 / FRAME_HZ
        last = loop.time()
        while True:
            await asyncio.sleep(period)
            now = loop.time()
            self.advance(min(now - last, 5 * period))
            last = now
            if self.playing or self.dirty:
                self.broadcast()


class ReplayControl(BaseModel):
    """``POST /api/replay``: any of play/pause, speed factor, position (s)."""

    model_config = ConfigDict(extra="forbid")
    playing: bool | None = None
    speed: float | None = Field(None, gt=0, le=max(SPEEDS))
    seek_s: float | None = Field(None, ge=0)


#: The replay's read-only API (the player is ``app.state.player``).
router = APIRouter(prefix="/api")


def _player(request: Request) -> Player:
    return request.app.state.player


@router.get("/world")
async def world(request: Request):
    return _player(request).world_info()


@router.get("/map", response_class=Response)
async def map_image(request: Request, rev: int | None = Query(None)):
    return Response(_player(request).map_png(), media_type="image/png")


@router.get("/auth")
async def auth():
    """Nobody holds control in a replay: the UI shows itself read-only."""
    return {"token_required": False, "control": False}


@router.get("/meta")
async def meta(request: Request):
    """The live UI's choices and limits, from the live server's ``GET /api/meta`` where this
    version has one (the UI reads it when it loads; a replay commands nothing)."""
    try:
        from swarmpark.server.routers.meta import meta as live_meta
    except ImportError:
        raise HTTPException(404, "this version has no /api/meta") from None
    return live_meta(len(_player(request).rec.ids))


@router.get("/scenarios")
async def scenarios(request: Request):
    path = _player(request).rec.path
    return {"directory": str(path.parent), "current": path.name, "scenarios": [path.name]}


@router.get("/state")
async def state(request: Request):
    return _player(request).frame()


@router.get("/replay")
async def replay_status(request: Request):
    return _player(request).status()


@router.post("/replay")
async def replay_control(req: ReplayControl, request: Request):
    player = _player(request)
    if req.seek_s is not None:
        player.seek(req.seek_s)
    if req.speed is not None:
        player.speed = req.speed
    if req.playing is not None:
        if req.playing and player.t >= player.rec.duration_s - 1e-9:
            player.seek(0.0)  # play again from the start
        player.playing = req.playing
    player.dirty = True
    return player.status()


@router.get("/recording")
async def recording(request: Request):
    """What the file holds: channels with their types and message counts, metadata."""
    rec = _player(request).rec
    return {
        "file": rec.path.name,
        "run": rec.run,
        "result": rec.result,
        "channels": {t: {"type": rec.types[t], "messages": len(s)} for t, s in rec.stamps.items()},
        "operator": rec.operator,
        "alarms": rec.alarms,
    }


@router.websocket("/ws")
async def stream(ws: WebSocket):
    """Frames in the live format: one at once, then while playing or after a seek."""
    from swarmpark.server.engine import Client
    from swarmpark.server.viewers import pump

    player: Player = ws.app.state.player
    await ws.accept()
    client = Client()
    player.clients.add(client)
    await ws.send_text(json.dumps(player.frame(), separators=(",", ":")))
    client.needs_full = False

    async def sender():
        while True:
            await ws.send_text(await client.queue.get())

    await pump(ws, client, player.clients, sender)


def create_replay_app(rec: Recording, *, open_url: str | None = None) -> FastAPI:
    """The replay server for one recording (see the module docstring); ``open_url`` is
    opened in the user's browser once the server is up."""
    from swarmpark.server.app import STATIC_DIR

    player = Player(rec)

    @contextlib.asynccontextmanager
    async def lifespan(app):
        loop = asyncio.get_running_loop()
        task = loop.create_task(player.run(), name="swarmpark-replay")
        if open_url:
            import webbrowser

            loop.run_in_executor(None, webbrowser.open, open_url)
        try:
            yield
        finally:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task

    app = FastAPI(title=f"swarmpark replay: {rec.path.name}", lifespan=lifespan)
    app.state.player = player
    page = (STATIC_DIR / "index.html").read_text()
    page = page.replace(
        "<title>swarmpark operator</title>", f"<title>swarmpark replay: {rec.path.name}</title>"
    )
    page = page.replace("</body>", f"{REPLAY_SCRIPT}\n</body>")

    @app.get("/", include_in_schema=False)
    async def index():
        return HTMLResponse(page, headers={"Cache-Control": "no-cache"})

    app.include_router(router)
    app.mount("/static", StaticFiles(directory=STATIC_DIR), name="static")
    return app


def _summary_line(rec: Recording) -> str:
    n_scan = sum(len(s) for t, s in rec.stamps.items() if t.endswith("/scan"))
    return (
        f"{rec.path.name}: scenario {rec.run.get('scenario', '?')}, {len(rec.ids)} skids, "
        f"{rec.duration_s:.1f} s, {len(rec.times)} pose samples, {n_scan} scans, "
        f"{len(rec.commands)} commands, {len(rec.operator)} operator requests, "
        f"{len(rec.alarms)} alarms, result {'yes' if rec.result is not None else 'no'}"
    )


def replay_command(args) -> int:
    """``swarmpark replay`` (``args`` from the CLI parser): read the file, serve it."""
    if not 0 < args.port < 65536:
        sys.stderr.write(f"swarmpark replay: error: --port must be 1..65535 (got {args.port})\n")
        return 2
    try:
        rec = load_recording(args.file)
    except RecordingError as exc:
        sys.stderr.write(f"swarmpark replay: error: {exc}\n")
        return 2
    if args.check:
        print(_summary_line(rec))
        return 0
    import uvicorn

    url = f"http://{args.host}:{args.port}/"
    app = create_replay_app(rec, open_url=None if args.no_browser else url)
    sys.stderr.write(f"swarmpark replay: {_summary_line(rec)}\nswarmpark replay: on {url}\n")
    try:
        uvicorn.run(app, host=args.host, port=args.port, log_level="warning")
    except OSError as exc:
        sys.stderr.write(f"swarmpark replay: error: {exc}\n")
        return 2
    except SystemExit as exc:
        return 2 if exc.code else 0
    return 0
