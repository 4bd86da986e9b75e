"""The supervisor: operator commands, per-robot state and the tick that holds the loop together."""

from swarmpark.supervisor.core import (
    ROBOT_STATES,
    Outcome,
    Supervisor,
)

__all__ = [
    "Supervisor",
    "Outcome",
    "ROBOT_STATES",
]
