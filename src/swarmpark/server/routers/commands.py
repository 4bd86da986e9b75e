"""Operator commands: park (and its preview), goto, stop, resume, e-stop, teleop, release.

Every command is validated twice: the request schema (unknown keys and bad values are a 422
naming the field), then the supervisor (a command it cannot carry out is refused with the
reason: HTTP 409 with ``accepted: false``, and the swarm keeps its previous orders).
Accepted commands answer 200 with ``accepted: true``.
"""

from __future__ import annotations

import numpy as np
from fastapi import APIRouter, Depends
from fastapi.responses import JSONResponse

from swarmpark.core.geometry import GeometryError
from swarmpark.server.deps import SessionDep, require_control
from swarmpark.server.frames import jsonable
from swarmpark.server.schemas import (
    CommandResult,
    GotoRequest,
    ParkRequest,
    PreviewResult,
    ReleaseRequest,
    RobotsRequest,
    TeleopRequest,
)
from swarmpark.supervisor.core import Outcome

__all__ = ["router"]

REFUSED = {409: {"model": CommandResult, "description": "Refused: the reason; nothing changed"}}
NEEDS_TOKEN = {401: {"description": "The server has a token and the request did not carry it"}}

router = APIRouter(prefix="/api", tags=["commands"])


def _answer(out: Outcome):
    body = CommandResult(**{**out.as_dict(), "detail": jsonable(out.detail)})
    if out.accepted:
        return body
    return JSONResponse(status_code=409, content=body.model_dump())


@router.post(
    "/park",
    response_model=CommandResult,
    responses={**REFUSED, **NEEDS_TOKEN},
    dependencies=[Depends(require_control)],
    summary="Park robots inside a boundary",
)
async def park(cmd: ParkRequest, session: SessionDep):
    """Lay out goals inside ``boundary`` with ``method`` and send the robots there.

    All or nothing: if the skids do not fit, a robot is unknown or under teleop, the command
    is refused (409) with the reason and no robot's orders change.
    """
    return _answer(session.command(session.sup.park(cmd)))


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
    "/goto",
    response_model=CommandResult,
    responses={**REFUSED, **NEEDS_TOKEN},
    dependencies=[Depends(require_control)],
    summary="Send one robot to a pose (also a new goal while it moves)",
)
async def goto(cmd: GotoRequest, session: SessionDep):
    """``pose`` is ``[x_m, y_m, heading_deg]``. The robot leaves any park group it was in."""
    return _answer(session.command(session.sup.goto(cmd)))


@router.post(
    "/stop",
    response_model=CommandResult,
    responses={**REFUSED, **NEEDS_TOKEN},
    dependencies=[Depends(require_control)],
    summary="Stop robots (they keep their goals; resume them later)",
)
async def stop(req: RobotsRequest, session: SessionDep):
    return _answer(session.command(session.sup.stop(req.robots)))


@router.post(
    "/resume",
    response_model=CommandResult,
    responses={**REFUSED, **NEEDS_TOKEN},
    dependencies=[Depends(require_control)],
    summary="Resume stopped robots; 'all' also releases the e-stop",
)
async def resume(req: RobotsRequest, session: SessionDep):
    return _answer(session.command(session.sup.resume(req.robots)))


@router.post(
    "/estop",
    response_model=CommandResult,
    summary="Emergency stop: every robot halts at the next tick (latched)",
)
async def estop(session: SessionDep):
    """Needs no token, on purpose: like the red button on every console, any viewer may stop
    the swarm. Releasing it (``POST /api/resume`` with ``"all"``) needs the token."""
    return _answer(session.command(session.sup.estop()))


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
