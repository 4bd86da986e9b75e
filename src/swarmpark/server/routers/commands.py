"""Operator commands: park (and its preview), goto, formation, stop, resume, e-stop, teleop,
release.

The routes of park, goto, formation, stop, estop and resume are generated from the command
registry (:data:`swarmpark.supervisor.registry.COMMANDS`: body schema, handler, summary);
the park preview, teleop and release are written here (the session keeps a teleop alive).

Every command is validated twice: the request schema (unknown keys and bad values are a 422
naming the field), then the supervisor (a command it cannot carry out is refused with the
reason: HTTP 409 with ``accepted: false``, and the swarm keeps its previous orders).
Accepted commands answer 200 with ``accepted: true``. Goals, boundaries and paths off the
map are a 422 naming the point.

Nothing here runs on the event loop for long: the e-stop and stops are applied at once
(:meth:`Session.estop_now`), heavy planning (previews, a park's layout) runs in the work
pool and everything that changes orders in the sim thread (:mod:`swarmpark.server.engine`).
"""

from __future__ import annotations

import inspect

import numpy as np
from fastapi import APIRouter, Depends
from fastapi.responses import JSONResponse

from swarmpark.core.limits import check_inside
from swarmpark.server.deps import SessionDep, require_control
from swarmpark.server.frames import jsonable
from swarmpark.server.schemas import (
    CommandResult,
    ParkRequest,
    PreviewResult,
    ReleaseRequest,
    TeleopRequest,
)
from swarmpark.supervisor.core import Outcome
from swarmpark.supervisor.registry import COMMANDS, CommandDef

__all__ = ["router"]

REFUSED = {409: {"model": CommandResult, "description": "Refused: the reason; nothing changed"}}
NEEDS_TOKEN = {401: {"description": "The server has a token and the request did not carry it"}}

router = APIRouter(prefix="/api", tags=["commands"])


def _answer(out: Outcome):
    body = CommandResult(**{**out.as_dict(), "detail": jsonable(out.detail)})
    if out.accepted:
        return body
    return JSONResponse(status_code=409, content=body.model_dump())


def _off_map(session, name: str, req) -> JSONResponse | None:
    """A 422 naming the first goal, boundary vertex or path point outside the map."""
    points: list = []
    field = name
    if name == "goto":
        points, field = [req.pose], "pose"
    elif name == "park":
        points, field = list(req.boundary), "boundary"
    elif name == "formation":
        points = [p for path in req.paths for p in path]
        field = "paths"
    if not points:
        return None
    try:
        check_inside(points, session.sup.world.grid.bounds, field)
    except ValueError as exc:
        return JSONResponse(status_code=422, content={"message": str(exc), "detail": []})
    return None


async def _park(session, req) -> Outcome:
    """Plan in the work pool (the ticks go on), commit in the sim thread."""
    sup = session.sup
    plan = await session.off_loop(sup.prepare_park, req)

    def commit() -> Outcome:
        if session.sup is not sup:
            return Outcome(False, "park", "park: the scenario was replaced while planning", 0.0)
        return session.command(sup.apply_park(plan))

    return await session.on_sim(commit)


async def _run(spec: CommandDef, session, req) -> Outcome:
    if spec.name == "estop":
        return session.estop_now()  # nothing queues in front of it
    if spec.name == "stop":
        return session.stop_now(req.robots)
    if spec.name == "park":
        return await _park(session, req)
    return await session.on_sim(lambda: session.command(session.sup.command(spec.name, req)))


def _endpoint(spec: CommandDef):
    """``POST /api/<name>`` for a registered command: the body is ``spec.request`` (none for
    the e-stop) and the supervisor carries it out through the registry."""

    async def endpoint(session, req=None):
        bad = _off_map(session, spec.name, req) if req is not None else None
        if bad is not None:
            return bad
        return _answer(await _run(spec, session, req))

    params = [inspect.Parameter("session", inspect.Parameter.KEYWORD_ONLY, annotation=SessionDep)]
    if spec.request is not None:
        params.append(
            inspect.Parameter("req", inspect.Parameter.KEYWORD_ONLY, annotation=spec.request)
        )
    endpoint.__signature__ = inspect.Signature(params)  # what FastAPI reads the body from
    endpoint.__name__ = spec.name
    endpoint.__doc__ = spec.doc or None
    return endpoint


for _spec in (e.item for e in COMMANDS.entries()):
    if _spec.route:
        router.add_api_route(
            f"/{_spec.name}",
            _endpoint(_spec),
            methods=["POST"],
            response_model=CommandResult,
            responses={**REFUSED, **NEEDS_TOKEN} if _spec.needs_token else {},
            dependencies=[Depends(require_control)] if _spec.needs_token else [],
            summary=_spec.summary,
            description=_spec.doc or None,
        )


@router.post(
    "/park/preview",
    response_model=PreviewResult,
    responses={**REFUSED, **NEEDS_TOKEN},
    dependencies=[Depends(require_control)],
    summary="Goal poses a park command would produce, without committing",
)
async def park_preview(cmd: ParkRequest, session: SessionDep):
    """The layout only: goals as ``[x_m, y_m, heading_deg]``. Nothing changes, nothing is
    logged; a layout that cannot be made is a 409 with the reason."""
    sup = session.sup
    bad = _off_map(session, "park", cmd)
    if bad is not None:
        return bad
    # The whole plan (layout, assignment, fill order) in the work pool: the ticks go on.
    plan = await session.off_loop(sup.prepare_park, cmd)
    if isinstance(plan, str):
        out = Outcome(False, "park.preview", plan, sup.t)
        return JSONResponse(status_code=409, content=CommandResult(**out.as_dict()).model_dump())
    g = plan.group
    goals = np.column_stack([g.goals[:, :2], np.rad2deg(g.goals[:, 2])])
    return PreviewResult(
        robots=[sup.ids[i] for i in g.robots],
        method=g.method,
        goals=np.round(goals, 4).tolist(),
        fill_order=[int(k) for k in g.fill_order],
        report=jsonable(dict(g.report)),
        goal_of=[int(k) for k in g.goal_of],
    )


@router.post(
    "/teleop",
    response_model=CommandResult,
    responses={**REFUSED, **NEEDS_TOKEN},
    dependencies=[Depends(require_control)],
    summary="Drive one robot directly: v (m/s) and omega (rad/s)",
)
async def teleop(req: TeleopRequest, session: SessionDep):
    """Takes the robot over from autonomy until ``/api/release``. Send it repeatedly while
    the operator holds the stick: the last command stays in force for
    ``TELEOP_DEADMAN_S`` = 0.5 wall seconds, then the skid stops (still in teleop)."""
    return _answer(await session.on_sim(session.teleop, req.robot, req.v_mps, req.omega_radps))


@router.post(
    "/release",
    response_model=CommandResult,
    responses={**REFUSED, **NEEDS_TOKEN},
    dependencies=[Depends(require_control)],
    summary="Hand a teleoperated robot back to autonomy",
)
async def release(req: ReleaseRequest, session: SessionDep):
    return _answer(await session.on_sim(session.release, req.robot))
