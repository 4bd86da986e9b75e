"""Moved to :mod:`swarmpark.apps.mapping_run`; this alias goes in the next release."""

from swarmpark._moved import alias

alias(__name__)
