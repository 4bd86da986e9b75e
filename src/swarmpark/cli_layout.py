"""Moved to :mod:`swarmpark.apps.cli_layout`; this alias goes in the next release."""

from swarmpark._moved import alias

alias(__name__)
