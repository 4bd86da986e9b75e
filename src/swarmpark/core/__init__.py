"""Core math shared by every layer: geometry, occupancy grids, paths. Imports nothing else of swarmpark."""
