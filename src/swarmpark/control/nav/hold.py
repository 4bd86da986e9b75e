"""Fill order: skids held back wait outside their parking boundary (moving away stays allowed)."""

from __future__ import annotations

import numpy as np
import shapely

from swarmpark.control.base import ControlView
from swarmpark.control.nav.params import HoldParams
from swarmpark.core.geometry import footprint_corners

__all__ = ["hold_outside", "stop_short"]


def stop_short(
    view: ControlView, i: int, cmd: np.ndarray, zone, gap_m: float, lookahead_s: float
) -> bool:
    """Stop skid ``i`` (in place on ``cmd``, rows of all skids) if its command, held for
    ``lookahead_s``, would bring it within ``gap_m`` of ``zone`` (a shapely geometry); moving
    away stays allowed. Returns False if it is already inside the zone (never frozen there),
    True if it is held outside."""
    return _stop_short(view, i, cmd, zone, gap_m, lookahead_s) > 0.0


def _stop_short(
    view: ControlView, i: int, cmd: np.ndarray, zone, gap_m: float, lookahead_s: float
) -> float:
    """:func:`stop_short`, returning the distance of skid ``i`` from ``zone`` before the
    check (0: inside, not held)."""
    body = view.footprints[i].corners_body()[None]
    now = shapely.Polygon(footprint_corners(view.poses[i][None], body)[0])
    d_now = now.distance(zone)
    if d_now <= 0.0:
        return 0.0
    v, w = cmd[i]
    th = view.poses[i, 2]
    ahead = view.poses[i] + np.array([v * np.cos(th), v * np.sin(th), w]) * lookahead_s
    d_next = shapely.Polygon(footprint_corners(ahead[None], body)[0]).distance(zone)
    if d_next < gap_m and d_next <= d_now:
        cmd[i] = 0.0
    return float(d_now)


def hold_outside(
    view: ControlView, idx: np.ndarray, cmd: np.ndarray, p: HoldParams
) -> tuple[np.ndarray, np.ndarray]:
    """Stop (in place on ``cmd``) the held skids among ``idx`` whose command, held for
    ``lookahead_s``, would bring them within ``gap_m`` of their parking boundary. Returns
    ``(held, at_stop)``, each ``(len(idx),)`` bool: which of ``idx`` are held outside (whether
    stopped this tick or not), and which of those stand where the hold stops them (within
    ``gap_m`` plus one lookahead at full speed of their zone). A held skid farther out is
    still on its way there, not waiting."""
    held = np.zeros(len(idx), dtype=bool)
    at_stop = np.zeros(len(idx), dtype=bool)
    if view.hold is None or not view.hold[idx].any():
        return held, at_stop
    for k in np.flatnonzero(view.hold[idx]).tolist():
        i = int(idx[k])
        zone = view.hold_zones[i] if i < len(view.hold_zones) else None
        if zone is not None:
            d = _stop_short(view, i, cmd, zone, p.gap_m, p.lookahead_s)
            held[k] = d > 0.0
            at_stop[k] = held[k] and d <= p.gap_m + view.max_speed[i] * p.lookahead_s
    return held, at_stop
