"""The map a park command is laid out, assigned and checked on: what the operator knows.

A park command needs the solids inside its boundary (the layout keeps its spots off them), a
grid for the manoeuvre check of the spots (:mod:`swarmpark.plan.spot_reach`) and for path-length
assignment costs. Where they come from depends on whether the skids sense:

- :class:`OperatorMap` (sensing off): the scenario's map (exact wall polygons, or the map
  image's occupied cells) and the static obstacles the scenario places, which the operator is
  taken to know; the check and the path costs run on the scenario's map.
- :class:`SensedMap` (``sensing.localization: amcl``): the prior map the skids localize in
  (``sensing.map``, e.g. one a skid built, else the scenario's map) plus what the fleet has
  detected (the merged obstacle layer, :class:`~swarmpark.sense.costmap.FleetLayer`) and,
  for the layout, the cells behind those detections no scan saw free
  (:mod:`swarmpark.sense.shadow`); never the scenario's obstacles: an obstacle the map lacks
  and no scan has seen is not known, and a spot may be laid on it (docs/sensing.md says what
  the skid does then).

Both answer the same two questions (:class:`KnownMap`), so the command handlers do not
branch on sensing.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

from shapely.geometry import Polygon
from shapely.ops import unary_union

from swarmpark.core.gridmap import OccupancyGrid

if TYPE_CHECKING:
    from swarmpark.supervisor.sensing import OnboardSensing
    from swarmpark.world.build import World

__all__ = ["KnownMap", "OperatorMap", "SensedMap"]


class KnownMap(Protocol):
    """What a park command is laid out on."""

    def solids(self, region: Polygon):
        """The known walls and obstacles touching ``region``, as one shapely geometry, or
        ``None`` when there are none."""

    def grid(self) -> OccupancyGrid:
        """The known map as a grid, now (for the spot check and path costs)."""


def _union(parts: list):
    parts = [p for p in parts if not p.is_empty]
    return unary_union(parts) if parts else None


class OperatorMap:
    """Sensing off: the scenario's map and its static obstacles (the operator's knowledge)."""

    def __init__(self, world: World) -> None:
        self.world = world

    def solids(self, region: Polygon):
        w = self.world
        parts = [p for p in w.wall_polygons if p.intersects(region)]
        if not w.wall_polygons:
            parts.append(w.grid.occupied_geometry(region))
        parts += [p for p in w.static_obstacles if p.intersects(region)]
        return _union(parts)

    def grid(self) -> OccupancyGrid:
        # The scenario's map without the static obstacles: the spot check has always run on it.
        return self.world.grid


class SensedMap:
    """Sensing on: the prior map merged with the fleet's detections, nothing from the truth.

    Parameters
    ----------
    world
        The scenario's world: only its map (when the skids believe it, ``sensing.map`` unset)
        and ``believed_grid`` are read, never its obstacles or people.
    sensing
        The skids' onboard stacks; :meth:`OnboardSensing.detected_mask` is the fleet's layer
        after the last scans.
    """

    def __init__(self, world: World, sensing: OnboardSensing) -> None:
        self.world = world
        self.sensing = sensing

    @property
    def prior(self) -> OccupancyGrid:
        """The map the skids were given (a built one, or the scenario's)."""
        w = self.world
        return w.believed_grid if w.believed_grid is not None else w.grid

    def solids(self, region: Polygon):
        w, prior = self.world, self.prior
        if w.believed_grid is None and w.wall_polygons:
            # The skids were given the scenario's polygon map: its walls are exact.
            parts = [p for p in w.wall_polygons if p.intersects(region)]
        else:
            parts = [prior.occupied_geometry(region)]
        # What the scans showed, and what lies behind it unseen (a crate's face is seen, not
        # its depth).
        mask = self.sensing.detected_mask()
        if mask.any():
            mask |= self.sensing.shadowed_mask()
            seen = OccupancyGrid(mask, prior.resolution_m, prior.origin)
            parts.append(seen.occupied_geometry(region))
        return _union(parts)

    def grid(self) -> OccupancyGrid:
        mask = self.sensing.detected_mask()
        return self.sensing.with_detections(mask) if mask.any() else self.prior
