"""Request and response schemas of the operator API (pydantic), kept apart from the core.

Poses at this edge are ``[x_m, y_m, heading_deg]`` as in the scenario schema, and the park,
goto and formation requests *are* the scenario's commands (they are defined with the command
registry, :mod:`swarmpark.supervisor.registry`): a command that works in a scenario file
works here.
Every model forbids unknown keys, so a misspelt field is a 422 naming it, never ignored.
"""

from __future__ import annotations

from typing import Annotated, Any

from pydantic import BaseModel, ConfigDict, Field

# The command bodies live with the command registry (one place per command).
from swarmpark.supervisor.registry import (
    FormationRequest,
    GotoRequest,
    ParkRequest,
    ReleaseRequest,
    RobotsRequest,
    TeleopRequest,
)

__all__ = [
    "ParkRequest",
    "GotoRequest",
    "FormationRequest",
    "RobotsRequest",
    "TeleopRequest",
    "ReleaseRequest",
    "SimControlRequest",
    "StepRequest",
    "ScenarioRequest",
    "CommandResult",
    "PreviewResult",
    "SimStatus",
    "ScenarioList",
    "AuthStatus",
    "MAX_SPEED_FACTOR",
    "MIN_SPEED_FACTOR",
]

#: Simulation speed factor bounds (sim seconds per wall second).
MIN_SPEED_FACTOR = 0.05
MAX_SPEED_FACTOR = 100.0
#: Largest number of ticks one POST /api/sim/step may run (keeps the server responsive).
MAX_STEP_TICKS = 2000


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class SimControlRequest(_Strict):
    """Pause or run the simulation and set its speed factor (omitted fields keep their value)."""

    paused: bool | None = None
    speed: Annotated[float, Field(ge=MIN_SPEED_FACTOR, le=MAX_SPEED_FACTOR)] | None = None


class StepRequest(_Strict):
    """Run ``ticks`` fixed steps now (for a paused simulation; tests and single-stepping)."""

    ticks: Annotated[int, Field(ge=1, le=MAX_STEP_TICKS)] = 1


class ScenarioRequest(_Strict):
    """Load a scenario by file name from the scenarios directory (see GET /api/scenarios).

    ``scripted=False`` drops the scenario's own timed commands, so the operator gives them.
    """

    name: Annotated[str, Field(min_length=1, pattern=r"^[A-Za-z0-9_.\-]+\.ya?ml$")]
    scripted: bool = True


class CommandResult(BaseModel):
    """What the supervisor said about a command. Refused commands come with HTTP 409."""

    accepted: bool
    command: str
    reason: str = ""
    t_s: float
    detail: dict[str, Any] = {}


class PreviewResult(BaseModel):
    """Goal poses a park command would lay out (nothing is committed)."""

    robots: list[str]
    method: str
    goals: list[list[float]]  # [x_m, y_m, heading_deg]
    fill_order: list[int]
    report: dict[str, Any]


class SimStatus(BaseModel):
    scenario: str
    file: str
    scripted: bool
    rev: int
    t_s: float
    dt_s: float
    paused: bool
    speed: float
    ticks: int
    error: str | None = None


class ScenarioList(BaseModel):
    directory: str
    current: str
    scenarios: list[str]


class AuthStatus(BaseModel):
    token_required: bool
    control: bool
