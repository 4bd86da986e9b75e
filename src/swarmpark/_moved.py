"""Aliases for modules moved in the round-2 package layout; each goes in the next release."""

from __future__ import annotations

import importlib
import sys
import warnings

#: old module -> new module (docs/architecture.md has the layout).
MOVED = {
    "swarmpark.geometry": "swarmpark.core.geometry",
    "swarmpark.gridmap": "swarmpark.core.gridmap",
    "swarmpark.paths": "swarmpark.core.paths",
    "swarmpark.scenario": "swarmpark.world.scenario",
    "swarmpark.run": "swarmpark.apps.run",
    "swarmpark.cli": "swarmpark.apps.cli",
    "swarmpark.cli_layout": "swarmpark.apps.cli_layout",
    "swarmpark.compare": "swarmpark.apps.compare",
    "swarmpark.mapping_run": "swarmpark.apps.mapping_run",
    "swarmpark.plot": "swarmpark.apps.plot",
    "swarmpark.control.rvo": "swarmpark.control.orca.kernel",
    "swarmpark.control.apf": "swarmpark.control.nav.apf",
    "swarmpark.control.navigate": "swarmpark.control.nav.navigator",
    "swarmpark.control.formation_paper": "swarmpark.control.formation.paper",
    "swarmpark.control.formation_run": "swarmpark.control.formation.run",
    "swarmpark.sense.localize": "swarmpark.sense.amcl",
}


def alias(old: str) -> None:
    """Make ``old`` the module it moved to, with a DeprecationWarning naming the new path."""
    new = MOVED[old]
    warnings.warn(f"{old} moved to {new}", DeprecationWarning, stacklevel=3)
    sys.modules[old] = importlib.import_module(new)
