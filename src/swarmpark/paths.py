"""Moved to :mod:`swarmpark.core.paths`; this alias goes in the next release."""

from swarmpark._moved import alias

alias(__name__)
