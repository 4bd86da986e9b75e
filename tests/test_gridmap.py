"""Occupancy grids: a small map checked by eye, map_server io, transforms."""

import numpy as np
import pytest
import yaml
from PIL import Image
from shapely.geometry import Polygon

from swarmpark.core.gridmap import (
    MapError,
    grid_from_walls,
    load_map_yaml,
    refine_occupancy,
    save_map_yaml,
)

# A 6 x 4 map at 1 m per cell; rows printed top (y = 3) to bottom (y = 0).
PICTURE = """
......
..##..
..#...
......
"""


def picture_grid():
    rows = [list(r) for r in PICTURE.strip().splitlines()]
    occ = np.flipud(np.array([[c == "#" for c in r] for r in rows]))
    from swarmpark.core.gridmap import OccupancyGrid

    return OccupancyGrid(occ, 1.0, (10.0, 20.0))


def test_world_cell_round_trip():
    g = picture_grid()
    assert g.world_to_cell([[12.5, 22.5]]).tolist() == [[2, 2]]
    assert g.is_occupied([[12.5, 22.5], [12.5, 21.5], [13.5, 21.5], [9.0, 20.0]]).tolist() == [
        True,
        True,
        False,
        True,
    ]  # off the map counts as occupied
    assert g.cell_to_world([[0, 0]]).tolist() == [[10.5, 20.5]]


def test_distance_field_by_hand():
    g = picture_grid()
    d = g.distance_field()
    assert d[1, 2] == 0.0  # occupied
    assert d[1, 3] == pytest.approx(0.5)  # neighbour: half a cell to the obstacle's edge
    assert d[0, 0] == pytest.approx(0.5)  # map edge counts as occupied


def test_walls_rasterize_cells_they_overlap_not_those_they_touch():
    g = grid_from_walls((2.0, 1.0), 0.1, [Polygon([(0, 0), (2, 0), (2, 0.1), (0, 0.1)])])
    assert g.occupied[0].all() and not g.occupied[1].any()


def test_map_server_round_trip(tmp_path):
    g = picture_grid()
    g.unknown[3, 5] = True
    path = save_map_yaml(g, tmp_path / "m.yaml")
    back = load_map_yaml(path)
    assert np.array_equal(back.occupied, g.occupied)
    assert np.array_equal(back.unknown, g.unknown)
    assert back.origin == (10.0, 20.0) and back.resolution_m == 1.0


def test_negate_and_thresholds(tmp_path):
    img = np.array([[0, 255], [128, 250]], dtype=np.uint8)  # first image row is the top (y = 1)
    Image.fromarray(img).save(tmp_path / "m.png")
    (tmp_path / "m.yaml").write_text(
        yaml.safe_dump(
            {
                "image": "m.png",
                "resolution": 0.5,
                "origin": [0, 0, 0],
                "negate": 1,
                "occupied_thresh": 0.65,
                "free_thresh": 0.196,
            }
        )
    )
    g = load_map_yaml(tmp_path / "m.yaml")
    # negate: p = value / 255, so white (255) is occupied and black free.
    assert g.occupied.tolist() == [[False, True], [False, True]]
    assert g.unknown.tolist() == [[True, False], [False, False]]


def test_bad_map_metadata_is_named(tmp_path):
    (tmp_path / "m.yaml").write_text(yaml.safe_dump({"image": "x.pgm", "resolution": 0.05}))
    with pytest.raises(MapError, match="has no 'origin' key"):
        load_map_yaml(tmp_path / "m.yaml")


def test_refine_occupancy_gives_back_the_free_part_of_a_wall_cell():
    """A wall from x = 1.06 m on a 10 cm grid takes the cell from 1.0 m; on 5 cm cells made
    from the wall itself only the half from 1.05 m stays occupied. A coarse cell no solid
    overlaps (a keep-out drawn on the map) stays occupied whole."""
    wall = np.array([[[1.06, 0.0], [2.0, 0.0], [2.0, 1.0], [1.06, 1.0]]])
    occ = np.zeros((10, 20), bool)
    occ[:, 10:] = True  # the wall, rasterized outwards
    occ[2, 3] = True  # a keep-out
    fine = refine_occupancy(occ, np.zeros(2), 0.1, 2, wall)
    assert fine.shape == (20, 40)
    assert not fine[:, 20].any() and fine[:, 21:].all()
    assert fine[4:6, 6:8].all() and fine.sum() == 20 * 19 + 4
    # Nothing changes without a split.
    assert np.array_equal(refine_occupancy(occ, np.zeros(2), 0.1, 1, wall), occ)
