"""The simulator: deterministic kinematics, exact footprint contacts, people walking."""

from swarmpark.sim.simulator import (
    CLEARANCE_RANGE_M,
    Contact,
    Simulator,
    StepResult,
)

__all__ = [
    "Simulator",
    "Contact",
    "StepResult",
    "CLEARANCE_RANGE_M",
]
