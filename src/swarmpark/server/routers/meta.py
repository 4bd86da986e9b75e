"""What the operator may choose and within which limits (``GET /api/meta``), read from the
registries (layout methods, assignment costs, avoidance modes) and the request schemas, so
the UI fills its controls from the server instead of copying the lists."""

from __future__ import annotations

from fastapi import APIRouter

from swarmpark.assign import ASSIGNMENT_COSTS
from swarmpark.control.modes import AVOIDANCE_MODES
from swarmpark.core.registry import Registry
from swarmpark.layout import LAYOUT_METHODS
from swarmpark.server.deps import SessionDep
from swarmpark.server.engine import TELEOP_DEADMAN_S
from swarmpark.server.schemas import (
    MAX_SPEED_FACTOR,
    MAX_STEP_TICKS,
    MIN_SPEED_FACTOR,
    Choice,
    HeadingLimits,
    Limits,
    Meta,
    ParkRequest,
    Range,
    StepRequest,
    TeleopLimits,
)

__all__ = ["router", "meta", "MARGIN_STEP_M", "HEADING_STEP_DEG", "TELEOP_SENDS_PER_DEADMAN"]

router = APIRouter(prefix="/api", tags=["state"])

#: Spinner steps the UI offers (any value in range is accepted).
MARGIN_STEP_M = 0.05
HEADING_STEP_DEG = 15.0
#: A teleop client sends this many commands per dead-man period, so one lost message
#: does not stop the skid.
TELEOP_SENDS_PER_DEADMAN = 5


def _choices(registry: Registry) -> list[Choice]:
    return [Choice(name=e.name, description=e.description) for e in registry.entries()]


def _park_field(name: str) -> dict:
    """A field of the park request as its JSON schema (bounds and default live there)."""
    return ParkRequest.model_json_schema()["properties"][name]


def _heading() -> HeadingLimits:
    field = _park_field("heading_deg")
    special = [b["const"] for b in field.get("anyOf", []) if "const" in b]
    special += [v for b in field.get("anyOf", []) for v in b.get("enum", [])]
    return HeadingLimits(default=field.get("default"), step=HEADING_STEP_DEG, special=special)


def meta(robots: int) -> Meta:
    """The choices and limits, for a scenario with ``robots`` skids."""
    margin = _park_field("margin_m")
    defaults = {name: ParkRequest.model_fields[name].default for name in ("method", "assignment")}
    return Meta(
        layout_methods=_choices(LAYOUT_METHODS),
        assignment_costs=_choices(ASSIGNMENT_COSTS),
        avoidance_modes=_choices(AVOIDANCE_MODES),
        defaults=defaults,
        limits=Limits(
            margin_m=Range(
                min=margin.get("minimum", margin.get("exclusiveMinimum")),
                max=margin.get("maximum"),
                default=margin.get("default"),
                step=MARGIN_STEP_M,
            ),
            heading_deg=_heading(),
            robots_per_park=Range(min=_park_field("robots").get("minItems", 1), max=robots),
            sim_speed=Range(min=MIN_SPEED_FACTOR, max=MAX_SPEED_FACTOR),
            step_ticks=Range(
                min=1, max=MAX_STEP_TICKS, default=StepRequest.model_fields["ticks"].default
            ),
            teleop=TeleopLimits(
                deadman_s=TELEOP_DEADMAN_S,
                send_period_s=TELEOP_DEADMAN_S / TELEOP_SENDS_PER_DEADMAN,
            ),
        ),
    )


@router.get("/meta", response_model=Meta, summary="Methods, costs, modes and limits the UI offers")
async def get_meta(session: SessionDep):
    """Layout methods, assignment costs and avoidance modes (name and description, from
    their registries), the park request's defaults, and the limits of the requests
    (``robots_per_park.max`` is the number of skids in the current scenario)."""
    return meta(len(session.world_info()["robots"]))
