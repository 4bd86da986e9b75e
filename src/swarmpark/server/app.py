"""The FastAPI application: app factory, static UI, validation errors that name the field.

Layering: the server imports the core (scenario, supervisor, layout); the core never imports
the server. All endpoints that touch the supervisor are coroutines on the event loop that
also runs the pacing task, so commands are applied between ticks.
"""

from __future__ import annotations

import contextlib
from collections.abc import Sequence
from pathlib import Path

from fastapi import FastAPI, Request
from fastapi.encoders import jsonable_encoder
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, JSONResponse
from fastapi.staticfiles import StaticFiles

from swarmpark.server.engine import Session
from swarmpark.server.frames import jsonable
from swarmpark.server.guard import GuardMiddleware
from swarmpark.server.routers import commands, meta, sim, state

__all__ = [
    "create_app",
    "default_scenarios_dir",
    "default_scenario",
    "STATIC_DIR",
    "DEFAULT_SCENARIO",
]

STATIC_DIR = Path(__file__).parent / "static"
DEFAULT_SCENARIO = "hangar-park.yaml"

API_DESCRIPTION = """\
Operator interface of swarmpark (Hing et al. 2018, Figs. 2-3): select skids, draw a parking
boundary, preview and confirm a park, give manual goals, stop/resume, e-stop, teleoperate.

* Poses are `[x_m, y_m, heading_deg]` (degrees, as in the scenario files); velocities SI.
* A command the supervisor refuses answers **HTTP 409** with `accepted: false` and the
  `reason`; nothing changes. Accepted commands answer 200 with `accepted: true`.
* A malformed request answers **422**; `message` names the field (unknown keys included).
* With a token, every POST needs `Authorization: Bearer <token>` (401 otherwise) except
  `POST /api/estop`; GETs and the WebSocket `/api/ws` are open (read-only viewers).
  Without a token, `swarmpark serve` still generates a per-server secret: every POST but
  the e-stop needs `X-Swarmpark-Secret: <secret>` (403 otherwise).
* Requests from another site (an `Origin` that is not this server's) and a `Host` that
  names another server are refused (403 / 400); bodies over 256 kB get 413.
"""


def default_scenarios_dir() -> Path:
    """Where scenarios are looked for: ``./scenarios`` if it exists, else the ``scenarios/``
    of the repository checkout this package runs from, else ``swarmpark/data/scenarios``
    inside the installed package (the last one is returned even if missing)."""
    here = Path(__file__).resolve()
    candidates = [
        Path.cwd() / "scenarios",
        here.parents[3] / "scenarios",  # src/swarmpark/server/app.py -> repository root
        here.parents[1] / "data" / "scenarios",
    ]
    for c in candidates:
        if c.is_dir():
            return c
    return candidates[-1]


def default_scenario(scenarios_dir: Path) -> Path:
    """``hangar-park.yaml`` in ``scenarios_dir``; raises FileNotFoundError naming it."""
    path = scenarios_dir / DEFAULT_SCENARIO
    if not path.is_file():
        raise FileNotFoundError(
            f"scenario: none given and the default {str(path)!r} does not exist"
        )
    return path


def _field(loc) -> str:
    parts = [str(p) for p in loc]
    if parts and parts[0] in ("body", "query", "path", "header"):
        parts = parts[1:]
    out = ""
    for p in parts:
        out += f"[{p}]" if p.isdigit() else ("." if out else "") + p
    return out or "body"


async def _validation_error(request: Request, exc: RequestValidationError) -> JSONResponse:
    """FastAPI's 422 body plus ``message``: the first error as ``field: what (got value)``."""
    errors = exc.errors()
    first = errors[0] if errors else {"loc": (), "msg": "invalid request", "type": ""}
    field = _field(first.get("loc", ()))
    msg = str(first.get("msg", "")).removeprefix("Value error, ")
    if first.get("type") == "extra_forbidden":
        msg = "unknown key"
    shown = _short(first.get("input"))
    more = f" ({len(errors) - 1} more error(s))" if len(errors) > 1 else ""
    message = f"{field}: {msg} (got {shown}){more}"
    # The inputs are echoed cut short: a 200 kB id must not come back (or into a log) whole.
    errors = [{**e, "input": _short(e.get("input"))} if "input" in e else e for e in errors[:10]]
    return JSONResponse(
        # (Non-finite inputs such as NaN become null: JSON has no NaN.)
        status_code=422,
        content={"message": message, "detail": jsonable(jsonable_encoder(errors))},
    )


def _short(value, limit: int = 120) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def create_app(
    scenario_path: str | Path | None = None,
    *,
    token: str | None = None,
    scenarios_dir: str | Path | None = None,
    speed: float = 1.0,
    autostart: bool = True,
    scripted: bool = True,
    observers: Sequence = (),
    link_factory=None,
    secret: str | None = None,
    allowed_hosts: Sequence[str] = (),
    allowed_origins: Sequence[str] = (),
) -> FastAPI:
    """Build the operator-interface app for one scenario.

    Parameters
    ----------
    scenario_path
        Scenario YAML; ``None`` loads ``hangar-park.yaml`` from ``scenarios_dir``.
    token
        If given, control commands need ``Authorization: Bearer <token>``; viewers without
        it are read-only (they may still press the e-stop).
    scenarios_dir
        Directory the scenario picker lists; ``None``: :func:`default_scenarios_dir`.
    speed
        Initial simulation speed factor.
    autostart
        Run the simulation as soon as the server starts; ``False`` starts it paused.
    scripted
        Run the scenario's own timed commands.
    observers
        Watchers of every run (:class:`swarmpark.record.live.LiveRecording`,
        :class:`swarmpark.record.audit.AuditLog`); with any, every ``POST /api/...`` is
        also passed to their ``on_command`` as an audit entry (client, token, answer).
    link_factory
        Builds the robots' link for a world (``None``: the simulator; ROS 2: see
        :func:`swarmpark.links.ros2.link_from_args`).
    secret
        Without a token, control commands need this in ``X-Swarmpark-Secret`` (``swarmpark
        serve`` always generates one); ``None``: open (tests, embedding).
    allowed_hosts, allowed_origins
        Host names and origins accepted besides the server's own (:mod:`.guard`).

    Raises
    ------
    swarmpark.world.scenario.ScenarioError
        The scenario is invalid. FileNotFoundError: no scenario given and no default.
    """
    sdir = Path(scenarios_dir) if scenarios_dir is not None else default_scenarios_dir()
    path = Path(scenario_path) if scenario_path is not None else default_scenario(sdir)
    if token is not None and not token.strip():
        raise ValueError("token: must not be empty")
    if secret is not None and not secret.strip():
        raise ValueError("secret: must not be empty")
    session = Session(
        path,
        speed=speed,
        running=autostart,
        scripted=scripted,
        observers=observers,
        link_factory=link_factory,
    )

    @contextlib.asynccontextmanager
    async def lifespan(app: FastAPI):
        session.start()
        try:
            yield
        finally:
            await session.stop()

    app = FastAPI(
        title="swarmpark operator interface",
        version="1",
        description=API_DESCRIPTION,
        lifespan=lifespan,
    )
    app.state.session = session
    app.state.token = token
    app.state.secret = secret
    app.state.scenarios_dir = sdir.resolve()
    app.add_exception_handler(RequestValidationError, _validation_error)  # type: ignore[arg-type]
    app.add_middleware(
        GuardMiddleware, allowed_hosts=allowed_hosts, allowed_origins=allowed_origins
    )
    if observers:  # outside the guard: refused requests are audited too
        from swarmpark.record.audit import AuditMiddleware

        app.add_middleware(AuditMiddleware)
    app.include_router(sim.router)
    app.include_router(commands.router)
    app.include_router(state.router)
    app.include_router(meta.router)

    @app.get("/", include_in_schema=False)
    async def index():
        return FileResponse(STATIC_DIR / "index.html", headers={"Cache-Control": "no-cache"})

    app.mount("/static", StaticFiles(directory=STATIC_DIR), name="static")
    return app
