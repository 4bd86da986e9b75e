"""The avoidance modes between skids, by name: the values ``navigation.avoidance`` takes.

The scenario schema and the operator API validate the name against
:data:`AVOIDANCE_MODES` and list its descriptions; the navigator branches on the name
itself (``NavParams.avoidance``). A new mode is registered here and handled there.
"""

from __future__ import annotations

from swarmpark.core.registry import Registry

__all__ = ["AVOIDANCE_MODES", "DEFAULT_AVOIDANCE"]

#: Avoidance modes by name (the item is the name: the navigator owns the behaviour).
AVOIDANCE_MODES: Registry[str] = Registry("avoidance mode", "navigation.avoidance")
AVOIDANCE_MODES.add(
    "monitor",
    "monitor",
    "collision monitor: slow down or stop before a predicted contact; right of way at "
    "bottlenecks (the default)",
)
AVOIDANCE_MODES.add(
    "rvo", "rvo", "reciprocal velocity obstacles (ORCA) with priorities (2018 paper, Sect. 3.4.1)"
)

#: The mode used when a scenario does not choose one.
DEFAULT_AVOIDANCE = "monitor"
