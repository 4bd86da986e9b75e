"""Fill order: skids held back wait outside their parking boundary (moving away stays allowed)."""

from __future__ import annotations

import numpy as np
import shapely

from swarmpark.control.base import ControlView
from swarmpark.control.nav.params import HoldParams
from swarmpark.core.geometry import footprint_corners

__all__ = ["hold_outside"]


def hold_outside(view: ControlView, idx: np.ndarray, cmd: np.ndarray, p: HoldParams) -> None:
    """Stop (in place on ``cmd``) the held skids among ``idx`` whose command, held for
    ``lookahead_s``, would bring them within ``gap_m`` of their parking boundary."""
    if view.hold is None or not view.hold[idx].any():
        return
    for i in idx[view.hold[idx]]:
        zone = view.hold_zones[i] if i < len(view.hold_zones) else None
        if zone is None:
            continue
        body = view.footprints[i].corners_body()[None]
        now = shapely.Polygon(footprint_corners(view.poses[i][None], body)[0])
        if now.intersects(zone):
            continue  # already inside: never freeze in the middle of the formation
        v, w = cmd[i]
        th = view.poses[i, 2]
        ahead = view.poses[i] + np.array([v * np.cos(th), v * np.sin(th), w]) * p.lookahead_s
        nxt = shapely.Polygon(footprint_corners(ahead[None], body)[0])
        d_now, d_next = now.distance(zone), nxt.distance(zone)
        if d_next < p.gap_m and d_next <= d_now:
            cmd[i] = 0.0
