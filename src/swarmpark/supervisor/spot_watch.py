"""Spots found blocked: a park laid out on the sensed map is laid out again when a scan shows
something standing on one of its spots.

With onboard sensing a park is laid out on the map the skids know
(:mod:`swarmpark.supervisor.known_map`): an obstacle the map lacks and no scan has seen yet can
get a spot, and the skid sent there finds it on arrival. The fleet's obstacle layer then holds
cells inside that spot; :class:`SpotWatch` notices (the same spot blocked at two checks
:data:`CHECK_PERIOD_S` apart, so a person crossing the spot does not count, and never by a
tracked person) and the supervisor lays the group out again on what is known now, and
re-assigns it: the new layout keeps off the obstacle.
"""

from __future__ import annotations

import numpy as np

__all__ = ["CHECK_PERIOD_S", "MAX_RELAYOUTS", "PERSON_CLEAR_M", "SpotWatch", "blocked_goals"]

#: Spots are checked against the fleet's detections this often (s).
CHECK_PERIOD_S = 1.0
#: A group is laid out again at most this many times (a layout that keeps failing is left).
MAX_RELAYOUTS = 3
#: Detections within this distance of a tracked person are the person, not a blocked spot.
PERSON_CLEAR_M = 0.5


def blocked_goals(goals: np.ndarray, corners_body: np.ndarray, points: np.ndarray) -> np.ndarray:
    """``(G,)`` bool: which goal footprints hold at least one of ``points`` ``(M, 2)``.

    ``goals`` ``(G, 3)`` pivot poses; ``corners_body`` ``(G, 4, 2)`` the body-frame corners of
    the footprint laid out at each (an axis-aligned rectangle in the body frame).
    """
    goals = np.asarray(goals, float).reshape(-1, 3)
    points = np.asarray(points, float).reshape(-1, 2)
    if not len(goals) or not len(points):
        return np.zeros(len(goals), dtype=bool)
    lo, hi = corners_body.min(axis=1), corners_body.max(axis=1)  # (G, 2)
    d = points[None, :, :] - goals[:, None, :2]  # (G, M, 2)
    c, s = np.cos(goals[:, 2])[:, None], np.sin(goals[:, 2])[:, None]
    bx = c * d[..., 0] + s * d[..., 1]
    by = -s * d[..., 0] + c * d[..., 1]
    inside = (
        (bx >= lo[:, None, 0])
        & (bx <= hi[:, None, 0])
        & (by >= lo[:, None, 1])
        & (by <= hi[:, None, 1])
    )
    return inside.any(axis=1)


class SpotWatch:
    """Which parking groups to lay out again (see the module docstring). The count of
    layouts and of checks that found a group blocked live on the group
    (``ParkGroup.relayouts``, ``ParkGroup.blocked_checks``)."""

    def __init__(self) -> None:
        self._last_t = -np.inf

    def due(self, t: float, groups, corners_body, points: np.ndarray, people_xy: np.ndarray):
        """The groups to lay out again at time ``t``: an assigned spot of theirs held
        detected ``points`` ``(M, 2)`` (those near ``people_xy`` ``(P, 2)`` dropped) at this
        check and the last. ``corners_body`` ``(N, 4, 2)``: every skid's body corners."""
        if t - self._last_t < CHECK_PERIOD_S - 1e-9:
            return []
        self._last_t = t
        points = np.asarray(points, float).reshape(-1, 2)
        people_xy = np.asarray(people_xy, float).reshape(-1, 2)
        if len(points) and len(people_xy):
            d = np.linalg.norm(points[:, None, :] - people_xy[None, :, :], axis=2)
            points = points[d.min(axis=1) > PERSON_CLEAR_M]
        out = []
        for g in groups:
            if g.command is None or g.relayouts >= MAX_RELAYOUTS or not len(g.robots):
                continue
            hit = blocked_goals(g.goals[g.goal_of], corners_body[g.robots], points).any()
            g.blocked_checks = g.blocked_checks + 1 if hit else 0
            if g.blocked_checks >= 2:
                out.append(g)
        return out
