"""Moving a group along paths while holding a formation (Liu, Sun and Zhu 2010).

:mod:`.problem` (the problem and its plan), :mod:`.planner` (velocity planning by CasADi/IPOPT
and the no-formation baseline), :mod:`.leader_follower` (the leader-follower baseline),
:mod:`.metrics` (formation error), :mod:`.tracking` (reference sampling and unicycle tracking),
:mod:`.online` (online modification for a moving obstacle), :mod:`.paper` (the paper's
problems and figures), :mod:`.run` (a formation driven in the simulator).
"""

from swarmpark.control.formation.metrics import (
    FormationMetrics,
    blend_offsets,
    desired_offsets,
    formation_error,
    formation_metrics,
    pair_errors,
)
from swarmpark.control.formation.online import (
    ObstacleAdjustment,
    OnlineAdjuster,
    adjust_for_obstacle,
    predict_obstacle,
)
from swarmpark.control.formation.planner import METHODS, plan_velocities
from swarmpark.control.formation.problem import FormationPlan, FormationProblem, nominal_profile
from swarmpark.control.formation.tracking import (
    Reference,
    TrackingGains,
    sample_reference,
    track_unicycle,
)

__all__ = [
    "FormationProblem",
    "FormationPlan",
    "FormationMetrics",
    "Reference",
    "TrackingGains",
    "ObstacleAdjustment",
    "OnlineAdjuster",
    "METHODS",
    "plan_velocities",
    "nominal_profile",
    "blend_offsets",
    "desired_offsets",
    "pair_errors",
    "formation_metrics",
    "formation_error",
    "sample_reference",
    "track_unicycle",
    "predict_obstacle",
    "adjust_for_obstacle",
]
