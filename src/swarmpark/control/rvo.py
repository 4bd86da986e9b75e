"""Moved to :mod:`swarmpark.control.orca.kernel`; this alias goes in the next release."""

from swarmpark._moved import alias

alias(__name__)
