"""swarmpark: park a swarm of rectangular non-holonomic skids inside an operator-drawn boundary."""

__version__ = "0.1.0"
