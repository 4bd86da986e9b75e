"""Particle-filter localization against a known map (AMCL style).

The filter follows Thrun, Burgard and Fox, *Probabilistic Robotics* (2005), as ROS ``amcl``
does: ``sample_motion_model_odometry`` (Table 5.6) for prediction (:mod:`.motion`), the
likelihood-field sensor model (Table 6.3, :mod:`.likelihood`) on a subsample of beams,
low-variance resampling (Table 4.4, :mod:`.resample`) when the effective sample size falls,
KLD-sampling for an adaptive particle count (Fox 2003) and augmented MCL (Table 8.3:
``w_slow``/``w_fast``) that injects uniform particles when the scans stop fitting, which
recovers a kidnapped robot (:mod:`.filter`, settings in :mod:`.config`). :mod:`.fleet` runs one
filter per skid; with :mod:`.coop` each filter also uses the neighbours it sees as landmarks
(cooperative localization, Fox, Burgard, Kruppa and Thrun 2000). The drifting wheel odometry a simulated skid reports is a robot model:
:class:`swarmpark.sim.odometry.OdometryDrift`.
"""

from __future__ import annotations

import warnings

from swarmpark.sense.amcl.config import RECOVERY, FilterConfig, PoseEstimate
from swarmpark.sense.amcl.coop import CoopConfig
from swarmpark.sense.amcl.filter import ParticleFilter
from swarmpark.sense.amcl.fleet import FleetLocalizer, RobotLocalizer, pose_error_summary
from swarmpark.sense.amcl.likelihood import LikelihoodField
from swarmpark.sense.amcl.motion import relative_motion
from swarmpark.sense.amcl.resample import kld_sample_count, low_variance_resample

__all__ = [
    "LikelihoodField",
    "FilterConfig",
    "CoopConfig",
    "RECOVERY",
    "PoseEstimate",
    "ParticleFilter",
    "FleetLocalizer",
    "RobotLocalizer",
    "pose_error_summary",
    "relative_motion",
    "low_variance_resample",
    "kld_sample_count",
]


def __getattr__(name: str):
    # For the swarmpark.sense.localize alias, which also exported OdometryDrift. Not imported at
    # the top: swarmpark.sim.odometry imports this package's motion model.
    if name == "OdometryDrift":
        warnings.warn(
            "OdometryDrift moved to swarmpark.sim.odometry", DeprecationWarning, stacklevel=2
        )
        from swarmpark.sim.odometry import OdometryDrift

        return OdometryDrift
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
