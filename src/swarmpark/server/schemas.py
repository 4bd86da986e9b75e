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
    "Choice",
    "Range",
    "HeadingLimits",
    "TeleopLimits",
    "Limits",
    "Meta",
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
    #: Per robot (in ``robots`` order), the index of the goal it would take.
    goal_of: list[int] = []


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
    """Whether this client may command: ``control`` is true if it holds the token (with
    one) or the server's secret (without a token, when the server has one)."""

    token_required: bool
    control: bool
    #: The server has a per-server secret (no token): the page must send it.
    secret_required: bool = False


# ----------------------------------------------------------------------------- GET /api/meta


class Choice(BaseModel):
    """One registered name (layout method, assignment cost, avoidance mode)."""

    name: str
    description: str


class Range(BaseModel):
    """Bounds of a number (``None``: unbounded on that side), its default and the step the
    UI's spinner uses."""

    min: float | None = None
    max: float | None = None
    default: float | None = None
    step: float | None = None


class HeadingLimits(Range):
    """The parked heading in degrees; ``special`` lists the words accepted instead of a
    number (``"auto"``: the heading with the most room)."""

    special: list[str] = []


class TeleopLimits(BaseModel):
    """Teleoperation: the server keeps applying the last command for ``deadman_s`` wall
    seconds after it arrived, so a client sends every ``send_period_s``. Speeds are clipped
    to each robot's own limits (``GET /api/world``: ``max_speed_mps``,
    ``max_yaw_rate_radps``)."""

    deadman_s: float
    send_period_s: float


class Limits(BaseModel):
    """What a request may ask for."""

    margin_m: Range
    heading_deg: HeadingLimits
    robots_per_park: Range
    sim_speed: Range
    step_ticks: Range
    teleop: TeleopLimits


class Meta(BaseModel):
    """The choices and limits of the operator API, read from the registries and schemas:
    the UI builds its controls from this instead of copying them."""

    layout_methods: list[Choice]
    assignment_costs: list[Choice]
    avoidance_modes: list[Choice]
    #: The park request's default ``method`` and ``assignment``.
    defaults: dict[str, Any]
    limits: Limits
