"""Moved to :mod:`swarmpark.world.scenario`; this alias goes in the next release."""

from swarmpark._moved import alias

alias(__name__)
