"""Simulation control: pause, speed, single steps, reset, and the scenario picker."""

from __future__ import annotations

from pathlib import Path

from fastapi import APIRouter, Depends, HTTPException, Request

from swarmpark.server.deps import SessionDep, require_control
from swarmpark.server.schemas import (
    ScenarioList,
    ScenarioRequest,
    SimControlRequest,
    SimStatus,
    StepRequest,
)
from swarmpark.world.scenario import ScenarioError

__all__ = ["router", "list_scenarios"]

NEEDS_TOKEN = {401: {"description": "The server has a token and the request did not carry it"}}

router = APIRouter(prefix="/api", tags=["simulation"])


def list_scenarios(directory: Path) -> list[str]:
    """Scenario file names (``*.yaml``, ``*.yml``) directly inside ``directory``, sorted."""
    if not directory.is_dir():
        return []
    return sorted(p.name for p in directory.iterdir() if p.suffix in (".yaml", ".yml"))


@router.get("/sim", response_model=SimStatus, summary="Scenario, clock, pause and speed")
async def get_sim(session: SessionDep):
    return session.status()


@router.post(
    "/sim",
    response_model=SimStatus,
    responses=NEEDS_TOKEN,
    dependencies=[Depends(require_control)],
    summary="Pause or run, and set the speed factor (sim seconds per wall second)",
)
async def set_sim(req: SimControlRequest, session: SessionDep):
    if req.paused is not None:
        session.paused = req.paused
        if not req.paused:
            session.error = None  # running again clears a stopped-on-error notice
    if req.speed is not None:
        session.speed = req.speed
    return session.status()


@router.post(
    "/sim/step",
    response_model=SimStatus,
    responses=NEEDS_TOKEN,
    dependencies=[Depends(require_control)],
    summary="Run a number of fixed ticks now (single-stepping a paused simulation)",
)
async def step(req: StepRequest, session: SessionDep):
    """A tick that fails pauses the simulation: 500 with the error (also in GET /api/sim)."""
    await session.on_sim(session.step, req.ticks)
    if session.error:
        raise HTTPException(500, session.error)
    return session.status()


@router.post(
    "/sim/reset",
    response_model=SimStatus,
    responses=NEEDS_TOKEN,
    dependencies=[Depends(require_control)],
    summary="Start the current scenario over",
)
async def reset(session: SessionDep):
    await session.on_sim(session.reset)
    return session.status()


@router.get("/scenarios", response_model=ScenarioList, summary="Scenarios that can be loaded")
async def scenarios(request: Request, session: SessionDep):
    directory: Path = request.app.state.scenarios_dir
    return ScenarioList(
        directory=str(directory), current=session.path.name, scenarios=list_scenarios(directory)
    )


@router.post(
    "/scenario",
    response_model=SimStatus,
    responses={
        **NEEDS_TOKEN,
        404: {"description": "No such scenario in the scenarios directory"},
        409: {"description": "The scenario file is invalid (the reason); nothing changed"},
    },
    dependencies=[Depends(require_control)],
    summary="Load a scenario from the scenarios directory by file name",
)
async def load(req: ScenarioRequest, request: Request, session: SessionDep):
    directory: Path = request.app.state.scenarios_dir
    # Only names listed in the directory: never a path from the network.
    if req.name not in list_scenarios(directory):
        raise HTTPException(404, f"name: no scenario {req.name!r} in {str(directory)!r}")
    try:
        built = await session.off_loop(session.build, directory / req.name, scripted=req.scripted)
    except ScenarioError as exc:
        raise HTTPException(409, f"{req.name}: {exc}") from None
    await session.on_sim(session.install, *built)
    return session.status()
