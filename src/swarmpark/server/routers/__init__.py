"""One router per resource: simulation control, operator commands, state, meta (choices and
limits)."""
