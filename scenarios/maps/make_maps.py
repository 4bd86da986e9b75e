"""Regenerate the map_server maps used by the scenarios (run from anywhere).

The maps are drawn from polygons here so they can be checked by eye and rebuilt exactly.
"""

from pathlib import Path

from shapely.geometry import Polygon, box

from swarmpark.gridmap import grid_from_walls, save_map_yaml

HERE = Path(__file__).resolve().parent


def elevator() -> None:
    """A 20 x 14 m hangar bay with a 6 x 5 m elevator recess on the east side, reached
    through a 2.6 m door."""
    walls = [
        box(0, 0, 20, 0.3), box(0, 13.7, 20, 14), box(0, 0.3, 0.3, 13.7),  # bay
        box(14, 0.3, 14.3, 5.2), box(14, 7.8, 14.3, 13.7),  # east wall with the door
        box(14.3, 0.3, 20, 4.6), box(14.3, 9.6, 20, 13.7),  # around the elevator
        box(19.7, 4.6, 20, 9.6),  # elevator back wall
        Polygon([(6, 6), (7, 6), (7, 7), (6, 7)]),  # a stanchion
    ]
    save_map_yaml(grid_from_walls((20, 14), 0.05, walls), HERE / "elevator.yaml")


if __name__ == "__main__":
    elevator()
