"""The default navigation stack, one module per component: planner, path follower, potential
field, docking, collision monitor, ORCA adapter, make-room and recoveries, composed by the
:class:`Navigator`; their parameters are in :mod:`.params`."""

from swarmpark.control.nav.navigator import Navigator, RobotNav
from swarmpark.control.nav.params import AVOIDANCE_MODES, NavParams

__all__ = [
    "AVOIDANCE_MODES",
    "NavParams",
    "Navigator",
    "RobotNav",
]
