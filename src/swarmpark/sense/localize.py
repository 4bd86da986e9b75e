"""Moved to :mod:`swarmpark.sense.amcl` (``OdometryDrift`` to :mod:`swarmpark.sim.odometry`);
this alias goes in the next release."""

from swarmpark._moved import alias

alias(__name__)
