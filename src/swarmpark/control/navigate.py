"""Moved to :mod:`swarmpark.control.nav.navigator`; this alias goes in the next release."""

from swarmpark._moved import alias

alias(__name__)
