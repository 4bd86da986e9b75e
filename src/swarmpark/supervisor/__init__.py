"""The supervisor: operator commands, per-robot state and the tick that holds the loop together.

``core`` (the tick, over a robot link), ``commands`` (handlers) and ``registry`` (the command
table: schema, handler, route), ``fill_order`` (which goals wait for which), ``sensing``
(AMCL and detection on what the link reports), ``reports`` (localization summary, snapshot).
"""

from swarmpark.supervisor.core import (
    ROBOT_STATES,
    Outcome,
    Supervisor,
)
from swarmpark.supervisor.registry import COMMANDS

__all__ = [
    "Supervisor",
    "Outcome",
    "ROBOT_STATES",
    "COMMANDS",
]
