"""What a controller may report each skid doing on purpose, shared by the controllers (which
report it) and the run's metrics (which add up the time lost to each)."""

from __future__ import annotations

__all__ = ["ACTIVITIES"]

#: Codes into this tuple (0: nothing in particular, it drives), as a controller's
#: ``activity`` ``(N,)``. The run result adds up the time each skid loses against its full
#: speed under these and two the recorder tells itself, ``parking`` (within 2 m of its
#: goal) and ``in_traffic`` (another skid within 2 m).
ACTIVITIES = (
    "driving",
    "fill_order",  # held back by the fill order, standing at its stop
    "queued",  # waiting for its turn at a bottleneck
    "manoeuvring",  # driving a planned manoeuvre
    "monitor",  # held still by the collision monitor
    "making_room",  # standing aside for another skid
)
