"""Planning: least-cost grid paths on the inflated costmap (Dijkstra fields)."""

from swarmpark.plan.grid import (
    Costmap,
    build_costmap,
    distance_field_from,
    path_length,
    paths_from,
    plan_path,
    shortcut,
)

__all__ = [
    "paths_from",
    "Costmap",
    "build_costmap",
    "plan_path",
    "distance_field_from",
    "path_length",
    "shortcut",
]
