"""The navigation modes and the avoidance modes between skids, by name: the values
``navigation.mode`` and ``navigation.avoidance`` take.

The scenario schema and the operator API validate the names against
:data:`NAVIGATION_MODES` and :data:`AVOIDANCE_MODES` and list their descriptions. The
navigator branches on the avoidance name itself (``NavParams.avoidance``); the navigation
mode picks the controller (:func:`swarmpark.control.nav.stack.make_controller`). A new mode
is registered here and handled there.
"""

from __future__ import annotations

from swarmpark.core.registry import Registry

__all__ = ["AVOIDANCE_MODES", "DEFAULT_AVOIDANCE", "NAVIGATION_MODES", "DEFAULT_NAVIGATION"]

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

#: Navigation modes by name (the item is the name: control/nav/stack.py builds the controller).
NAVIGATION_MODES: Registry[str] = Registry("navigation mode", "navigation.mode")
NAVIGATION_MODES.add(
    "planner",
    "planner",
    "least-cost path on the costmap, followed by the potential field, docking, avoidance and "
    "recovery (2018 paper, Sect. 3.4; the default)",
)
NAVIGATION_MODES.add(
    "pure-pf",
    "pure-pf",
    "the potential field alone, attracted straight to the goal, no planner and no recovery "
    "(2015 paper, Sect. 3.2: the baseline that stops in local minima)",
)

#: The navigation mode used when a scenario does not choose one.
DEFAULT_NAVIGATION = "planner"
