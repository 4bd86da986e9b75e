"""Operator commands in one place: per command its payload schema, its handler and its API
route.

:data:`COMMANDS` lists every command the supervisor takes (park, goto, formation, stop,
estop, resume, teleop, release). The scenario's timed commands and the operator API both go
through it (:meth:`Supervisor.command <swarmpark.supervisor.core.Supervisor.command>`), and
the server generates ``POST /api/<name>`` for every entry with ``route=True`` from it
(teleop and release keep hand-written routes: the server keeps a teleop alive between
requests). A name that is not in the registry is refused with the list of known ones.

The request models here are the API bodies; park, goto and formation *are* the scenario's
:class:`~swarmpark.world.scenario.ParkCmd`, :class:`~swarmpark.world.scenario.GotoCmd` and
:class:`~swarmpark.world.scenario.FormationCmd`, so a command that works in a scenario file
works over the API too.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator

from swarmpark.core.registry import Registry
from swarmpark.world.scenario import (
    COMMAND_KINDS,
    FormationCmd,
    GotoCmd,
    ParkCmd,
    RobotList,
    RobotRef,
)

if TYPE_CHECKING:
    from swarmpark.supervisor.commands import Outcome

__all__ = [
    "CommandDef",
    "COMMANDS",
    "ParkRequest",
    "GotoRequest",
    "FormationRequest",
    "RobotsRequest",
    "TeleopRequest",
    "ReleaseRequest",
]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class ParkRequest(ParkCmd):
    """Park ``robots`` inside ``boundary`` (``[[x, y], ...]``, metres, at least 3 vertices).

    ``heading_deg`` is the parked yaw in degrees (or ``"auto"``), ``method`` a layout method
    and ``assignment`` a robot-to-goal cost, both as listed by ``GET /api/meta`` (from their
    registries); ``margin_m`` the clearance between skids and to the boundary.
    """

    @field_validator("robots")
    @classmethod
    def _unique_robots(cls, robots: list[str]) -> list[str]:
        seen: set[str] = set()
        for name in robots:
            if name in seen:
                raise ValueError(f"robot {name!r} listed twice")
            seen.add(name)
        return robots

    @field_validator("boundary")
    @classmethod
    def _three_vertices(cls, boundary: list[list[float]]) -> list[list[float]]:
        if len(boundary) < 3:
            raise ValueError(f"a boundary needs at least 3 vertices (got {len(boundary)})")
        return boundary


class GotoRequest(GotoCmd):
    """Send one robot to ``pose`` = ``[x_m, y_m, heading_deg]`` (a new goal while moving too)."""


class FormationRequest(FormationCmd):
    """Move ``robots`` along ``paths`` holding a formation (the scenario's ``formation``)."""


class RobotsRequest(_Strict):
    """Robots to stop or resume: a list of ids, or ``"all"``."""

    robots: RobotList | Literal["all"]


class TeleopRequest(_Strict):
    """A velocity command for one robot taken over by the operator (REP-103: v forward,
    omega counter-clockwise). The simulator clips it to the robot's limits. The server keeps
    applying the last command while the operator keeps sending it (a dead-man of
    ``TELEOP_DEADMAN_S`` wall seconds); then the skid stops and waits in teleop."""

    robot: RobotRef
    v_mps: Annotated[float, Field(allow_inf_nan=False, ge=-100.0, le=100.0)]
    omega_radps: Annotated[float, Field(allow_inf_nan=False, ge=-100.0, le=100.0)]


class ReleaseRequest(_Strict):
    """Hand a teleoperated robot back to autonomy."""

    robot: RobotRef


@dataclass(frozen=True)
class CommandDef:
    """One operator command.

    Attributes
    ----------
    name
        The command's name: the scenario key, the API path ``/api/<name>``, the log entry.
    handler
        ``handler(supervisor, payload) -> Outcome``; ``payload`` is the scenario value or the
        API request model.
    summary, doc
        One line and the longer description (the API's summary and description).
    request
        The API body model (``None``: no body).
    scenario
        Whether a scenario's ``commands`` may use it (a key of ``CommandSpec``).
    route
        Whether the server generates ``POST /api/<name>`` from this entry.
    needs_token
        Whether the route needs the control token (the e-stop does not, on purpose).
    """

    name: str
    handler: Callable[[Any, Any], Outcome]
    summary: str
    doc: str = ""
    request: type[BaseModel] | None = None
    scenario: bool = True
    route: bool = True
    needs_token: bool = True


#: Every operator command by name (a :class:`~swarmpark.core.registry.Registry` of
#: :class:`CommandDef`, in the order the API lists them).
COMMANDS: Registry[CommandDef] = Registry("command", "command")


def _add(spec: CommandDef) -> None:
    COMMANDS.add(spec.name, spec, spec.summary)


def _names(payload: Any) -> Any:
    """Stop/resume take a list of ids or 'all', in a scenario or as ``{"robots": ...}``."""
    return payload.robots if isinstance(payload, RobotsRequest) else payload


_add(
    CommandDef(
        "park",
        lambda sup, p: sup.park(p),
        "Park robots inside a boundary",
        "Lay out goals inside ``boundary`` with ``method`` and send the robots there.\n\n"
        "All or nothing: if the skids do not fit, a robot is unknown or under teleop, the "
        "command is refused (409) with the reason and no robot's orders change.",
        request=ParkRequest,
    )
)
_add(
    CommandDef(
        "goto",
        lambda sup, p: sup.goto(p),
        "Send one robot to a pose (also a new goal while it moves)",
        "``pose`` is ``[x_m, y_m, heading_deg]``. The robot leaves any park group it was in.",
        request=GotoRequest,
    )
)
_add(
    CommandDef(
        "formation",
        lambda sup, p: sup.formation(p),
        "Move robots along paths holding a formation",
        "Liu, Sun, Zhu 2010: velocity profiles along given paths that keep the shape and a "
        "safe distance; the group docks with the navigation stack when the plan ends. A plan "
        "that cannot be made is refused (409) with the reason.",
        request=FormationRequest,
    )
)
_add(
    CommandDef(
        "stop",
        lambda sup, p: sup.stop(_names(p)),
        "Stop robots (they keep their goals; resume them later)",
        request=RobotsRequest,
    )
)
_add(
    CommandDef(
        "estop",
        lambda sup, p: sup.estop(),
        "Emergency stop: every robot halts at the next tick (latched)",
        "Needs no token, on purpose: like the red button on every console, any viewer may stop "
        'the swarm. Releasing it (``POST /api/resume`` with ``"all"``) needs the token.',
        needs_token=False,
    )
)
_add(
    CommandDef(
        "resume",
        lambda sup, p: sup.resume(_names(p)),
        "Resume stopped robots; 'all' also releases the e-stop",
        request=RobotsRequest,
    )
)
_add(
    CommandDef(
        "teleop",
        lambda sup, p: sup.set_teleop(p.robot, p.v_mps, p.omega_radps),
        "Drive one robot directly: v (m/s) and omega (rad/s)",
        request=TeleopRequest,
        scenario=False,
        route=False,  # the server keeps a teleop alive between requests (routers/commands.py)
    )
)
_add(
    CommandDef(
        "release",
        lambda sup, p: sup.release(p.robot),
        "Hand a teleoperated robot back to autonomy",
        request=ReleaseRequest,
        scenario=False,
        route=False,
    )
)

# The scenario schema cannot import the supervisor; its keys must be the scenario commands.
if set(COMMAND_KINDS) != {e.name for e in COMMANDS.entries() if e.item.scenario}:
    raise RuntimeError(f"scenario command keys {COMMAND_KINDS} differ from the registry's")
