"""State for viewers (no token needed): the static world, the map image, the current frame,
and the WebSocket that streams frames."""

from __future__ import annotations

import json
from typing import Annotated

from fastapi import APIRouter, Query, Request, WebSocket
from fastapi.responses import Response

from swarmpark.core.limits import MAX_VIEWERS
from swarmpark.server.deps import SessionDep, has_control, has_secret
from swarmpark.server.engine import Client, Session
from swarmpark.server.schemas import AuthStatus
from swarmpark.server.viewers import pump

__all__ = ["router"]

router = APIRouter(prefix="/api", tags=["state"])


@router.get("/world", summary="What does not change while a scenario runs")
async def world(session: SessionDep) -> dict:
    """Robot ids and footprints, the state names (frames send their index), the map geometry
    (the image is ``GET /api/map``), exact walls and obstacles, and ``rev``, which changes
    when a scenario is loaded or reset."""
    return session.world_info()


@router.get(
    "/map",
    summary="The occupancy map as a PNG (one pixel per cell, north up)",
    response_class=Response,
    responses={200: {"content": {"image/png": {}}}},
)
async def map_image(session: SessionDep):
    """Free cells white, occupied dark grey, unknown light grey. ``GET /api/world`` gives
    its placement: ``map.bounds_m`` = ``[xmin, ymin, xmax, ymax]``."""
    return Response(
        session.map_png(), media_type="image/png", headers={"Cache-Control": "no-cache"}
    )


@router.get("/state", summary="The current state as one full frame")
async def state(session: SessionDep) -> dict:
    """Same content as a full WebSocket frame (see docs/ui.md for the fields)."""
    return await session.on_sim(session.snapshot)


@router.get("/perf", summary="Server load: CPU per tick, frame sizes, tick times")
async def perf(
    session: SessionDep, frames: Annotated[int | None, Query(ge=1, le=2000)] = None
) -> dict:
    """Over the last ``frames`` (default and most: 2000) paced frames: CPU (process time) of
    the ticks plus the broadcast, per tick and per frame; the mean and largest delta message;
    ``process_cpu_s`` is the server process's CPU time so far (sample it twice for the whole
    server's load, WebSocket sends included)."""
    return session.perf_report(frames)


@router.get("/auth", response_model=AuthStatus, summary="Does this client hold the token?")
async def auth(request: Request):
    token = request.app.state.token
    secret = getattr(request.app.state, "secret", None)
    return AuthStatus(
        token_required=token is not None,
        control=has_control(request) and (token is not None or has_secret(request)),
        secret_required=token is None and secret is not None,
    )


@router.websocket("/ws")
async def stream(ws: WebSocket):
    """Frames as JSON text at 20 Hz: a full one first, then deltas (see docs/ui.md).

    The stream is read-only; commands go through the REST endpoints.
    """
    session: Session = ws.app.state.session
    if len(session.clients) >= MAX_VIEWERS:
        # Refused before it costs anything (1013: try again later).
        await ws.close(code=1013, reason=f"viewers: {MAX_VIEWERS} already connected")
        return
    await ws.accept()
    client = Client()
    session.clients.add(client)
    # A viewer that joins while nothing runs (a paused sim, no pacing task) sees the state.
    # (A fresh encoder: the broadcast's change tracking stays as the other viewers saw it.)
    first = await session.on_sim(session.snapshot)
    await ws.send_text(json.dumps(first, separators=(",", ":"), allow_nan=False))
    client.needs_full = False

    async def sender() -> None:
        # A viewer too slow to drain its queue is dropped from the broadcast by the session
        # (client.closed) and its connection closed here.
        # (No timeout around the wait: Client.close wakes it with a None.)
        while not client.closed:
            msg = await client.queue.get()
            if msg is None:
                break
            await ws.send_text(msg)
            client.overflows = 0  # it keeps up

    await pump(ws, client, session.clients, sender)
