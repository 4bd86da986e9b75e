"""The world: scenario schema (pydantic), loading and validation with clear errors."""
