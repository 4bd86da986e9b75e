"""The world: scenario schema (pydantic), loading and validation with clear errors.

``world.scenario`` is imported first: it re-exports the world built by ``world.build``, which
itself needs the schema, so importing ``world.build`` alone must find the schema complete.
"""

from swarmpark.world import scenario as _scenario  # noqa: F401  (import order, see above)
