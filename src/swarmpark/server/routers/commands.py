"""Operator commands: park (and its preview), goto, formation, stop, resume, e-stop, teleop,
release.

The routes of park, goto, formation, stop, estop and resume are generated from the command
registry (:data:`swarmpark.supervisor.registry.COMMANDS`: body schema, handler, summary);
the park preview, teleop and release are written here (the session keeps a teleop alive).

Every command is validated twice: the request schema (unknown keys and bad values are a 422
naming the field), then the supervisor (a command it cannot carry out is refused with the
reason: HTTP 409 with ``accepted: false``, and the swarm keeps its previous orders).
Accepted commands answer 200 with ``accepted: true``.
"""

from __future__ import annotations

import inspect

import numpy as np
from fastapi import APIRouter, Depends
from fastapi.responses import JSONResponse

from swarmpark.core.geometry import GeometryError
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


def _endpoint(spec: CommandDef):
    """``POST /api/<name>`` for a registered command: the body is ``spec.request`` (none for
    the e-stop) and the supervisor carries it out through the registry."""

    async def endpoint(session, req=None):
        return _answer(session.command(session.sup.command(spec.name, req)))

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
    try:
        idx, _, lay = sup.plan_layout(cmd)
    except (ValueError, GeometryError) as exc:
        out = Outcome(False, "park.preview", str(exc), sup.t)
        return JSONResponse(status_code=409, content=CommandResult(**out.as_dict()).model_dump())
    poses = np.asarray(lay.poses, float)
    goals = np.column_stack([poses[:, :2], np.rad2deg(poses[:, 2])])
    return PreviewResult(
        robots=[sup.ids[i] for i in idx],
        method=lay.method,
        goals=np.round(goals, 4).tolist(),
        fill_order=[int(k) for k in lay.fill_order],
        report=jsonable(dict(lay.report)),
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
    return _answer(session.teleop(req.robot, req.v_mps, req.omega_radps))


@router.post(
    "/release",
    response_model=CommandResult,
    responses={**REFUSED, **NEEDS_TOKEN},
    dependencies=[Depends(require_control)],
    summary="Hand a teleoperated robot back to autonomy",
)
async def release(req: ReleaseRequest, session: SessionDep):
    return _answer(session.release(req.robot))
