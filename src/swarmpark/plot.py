"""Moved to :mod:`swarmpark.apps.plot`; this alias goes in the next release."""

from swarmpark._moved import alias

alias(__name__)
