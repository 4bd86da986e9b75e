"""One router per resource: simulation control, operator commands, state."""
