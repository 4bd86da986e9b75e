"""How well a built occupancy map agrees with the ground truth (:func:`map_agreement`): the
score of a mapping run, cell by cell over what a scanner could observe."""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from swarmpark.core.gridmap import OccupancyGrid

__all__ = ["map_agreement"]


def map_agreement(
    estimate: OccupancyGrid, truth: OccupancyGrid, *, tolerance_cells: int = 0
) -> dict[str, float]:
    """How well a built map agrees with the ground truth, cell by cell.

    Only cells a scanner could observe count: the truth's free cells and its occupied cells
    next to free space (wall faces; the inside of a thick wall is never seen).

    Parameters
    ----------
    estimate, truth
        Grids of the same shape, resolution and origin.
    tolerance_cells
        A cell of the estimate is right when the truth has the same label within this many
        cells (Chebyshev distance); 0 is a strict cell-by-cell comparison.

    Returns
    -------
    dict
        ``share_correct`` (right among observable cells the estimate knows),
        ``share_observed`` (observable cells the estimate knows), ``wall_precision`` (estimate's
        occupied cells that are walls), ``wall_recall`` (wall faces the estimate has occupied)
        and ``cells_observable``.
    """
    if estimate.shape != truth.shape:
        raise ValueError(
            f"map_agreement: estimate shape {estimate.shape} != truth shape {truth.shape}"
        )
    if not np.isclose(estimate.resolution_m, truth.resolution_m) or not np.allclose(
        estimate.origin, truth.origin
    ):
        raise ValueError(
            "map_agreement: estimate and truth must share resolution and origin (got "
            f"{estimate.resolution_m} at {estimate.origin} vs {truth.resolution_m} at "
            f"{truth.origin})"
        )
    t_occ = truth.occupied
    t_free = ~truth.occupied & ~truth.unknown
    near_free = ndimage.binary_dilation(t_free, structure=np.ones((3, 3), dtype=bool))
    faces = t_occ & near_free
    observable = t_free | faces
    e_occ = estimate.occupied
    e_known = ~estimate.unknown | e_occ
    e_free = e_known & ~e_occ
    if tolerance_cells > 0:
        st = np.ones((2 * tolerance_cells + 1,) * 2, dtype=bool)
        occ_ok = ndimage.binary_dilation(t_occ, structure=st)
        free_ok = ndimage.binary_dilation(t_free, structure=st)
        e_occ_near = ndimage.binary_dilation(e_occ, structure=st)
    else:
        occ_ok, free_ok, e_occ_near = t_occ, t_free, e_occ
    right = (e_occ & occ_ok) | (e_free & free_ok)
    known_obs = e_known & observable
    n_known = int(known_obs.sum())
    n_obs = int(observable.sum())
    n_e_occ = int((e_occ & observable).sum())
    return {
        "share_correct": float((right & known_obs).sum() / n_known) if n_known else 0.0,
        "share_observed": float(n_known / n_obs) if n_obs else 0.0,
        "wall_precision": float((e_occ & occ_ok & observable).sum() / n_e_occ) if n_e_occ else 0.0,
        "wall_recall": float((faces & e_occ_near).sum() / max(int(faces.sum()), 1)),
        "cells_observable": float(n_obs),
    }
