"""Action-point potential field for rectangular non-holonomic skids (2015 paper Sect. 3.2,
after Seki et al. 2008).

Each skid has two action points on its body x axis: the front one at the front edge and the
rear one at the rear edge. The goal attracts one of them (whichever end has the shorter arc
to the goal, extension 1 of the 2015 paper) along the tangent of the circle that passes
through it and meets the goal's action point at the goal heading. Obstacle points push the
front action point when they lie ahead of the pivot and the rear one when behind (the
navigator splits each push between the two as a lever instead: ``repulsion(lever=True)``),
with a force falling as 1/d^3 from the footprint. A force F at an action point at body-x ``x_a``
contributes ``v = F_x`` and ``omega = F_y / x_a`` (eq. 12); a force on the rear point thus
turns the skid the other way, which is the paper's "rear forces inverted and added at the
front".

All functions are batched over robots (and over robot-obstacle pairs) with numpy.
"""

from __future__ import annotations

import numpy as np

from swarmpark.core.geometry import wrap_angle

__all__ = [
    "arc_direction",
    "arc_length",
    "attraction",
    "repulsion",
    "forces_to_command",
    "rect_nearest_points",
    "turn_throttle",
]


def arc_direction(p: np.ndarray, g: np.ndarray, goal_heading: np.ndarray) -> np.ndarray:
    """Direction (rad) at ``p`` of the circle through ``p`` tangent to ``goal_heading`` at ``g``.

    The tangents at the two ends of a circular arc are mirror images about the chord, so the
    direction at ``p`` is ``2 * bearing(p -> g) - goal_heading``.

    >>> float(arc_direction(np.array([[0.0, 0.0]]), np.array([[1.0, 1.0]]), np.array([np.pi / 2]))[0])
    0.0
    """
    d = g - p
    phi = np.arctan2(d[:, 1], d[:, 0])
    return wrap_angle(2.0 * phi - goal_heading)


def arc_length(p: np.ndarray, g: np.ndarray, goal_heading: np.ndarray) -> np.ndarray:
    """Length of that arc from ``p`` to ``g`` (the chord when it is straight).

    >>> round(float(arc_length(np.array([[0.0, 0.0]]), np.array([[1.0, 1.0]]), np.array([np.pi / 2]))[0]), 4)
    1.5708
    """
    d = g - p
    chord = np.linalg.norm(d, axis=1)
    phi = np.arctan2(d[:, 1], d[:, 0])
    half_turn = np.abs(wrap_angle(goal_heading - phi))  # half the turning angle of the arc
    ratio = np.where(half_turn < 1e-9, 1.0, half_turn / np.maximum(np.sin(half_turn), 1e-9))
    # Beyond a half turn the "arc" wraps around behind the goal: penalize it as a full circle.
    return np.where(half_turn < np.pi / 2, chord * ratio, chord * (np.pi / 2 + half_turn))


def attraction(
    poses: np.ndarray,
    goals: np.ndarray,
    x_front: np.ndarray,
    x_rear: np.ndarray,
    reverse: np.ndarray,
    magnitude: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Goal force in the body frame ``(N, 2)`` and its action point body-x ``(N,)``.

    ``reverse`` selects the rear action point (the skid backs toward the goal); the goal's
    rear action point is then attracted with the goal heading flipped. ``magnitude`` is the
    goal force weight (the 2015 paper's distance weighting, in m/s).
    """
    th = poses[:, 2]
    x_a = np.where(reverse, x_rear, x_front)
    c, s = np.cos(th), np.sin(th)
    cg, sg = np.cos(goals[:, 2]), np.sin(goals[:, 2])
    p = poses[:, :2] + x_a[:, None] * np.column_stack([c, s])
    g = goals[:, :2] + x_a[:, None] * np.column_stack([cg, sg])
    travel = np.where(reverse, goals[:, 2] + np.pi, goals[:, 2])  # direction the point moves in
    direction = arc_direction(p, g, travel)
    rel = direction - th  # into the body frame
    return magnitude[:, None] * np.column_stack([np.cos(rel), np.sin(rel)]), x_a


def rect_nearest_points(
    pts_body: np.ndarray, x_min: np.ndarray, x_max: np.ndarray, half_w: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Nearest points on axis-aligned body rectangles to points ``(M, 2)`` (body frames), and
    their distances (0 for a point inside)."""
    nx = np.clip(pts_body[:, 0], x_min, x_max)
    ny = np.clip(pts_body[:, 1], -half_w, half_w)
    near = np.column_stack([nx, ny])
    return near, np.linalg.norm(pts_body - near, axis=1)


def repulsion(
    robot: np.ndarray,
    pts_body: np.ndarray,
    gain: np.ndarray,
    x_min: np.ndarray,
    x_max: np.ndarray,
    half_w: np.ndarray,
    influence_m: np.ndarray,
    lever: bool = False,
    min_distance_m: float = 0.02,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Obstacle forces for robot-point pairs.

    Parameters
    ----------
    robot
        ``(M,)`` robot index of each pair.
    pts_body
        ``(M, 2)`` obstacle points in that robot's body frame (pivot at the origin).
    gain, influence_m
        ``(M,)`` force gain (m^4/s: the force is in m/s) and distance beyond which the point
        exerts nothing. The force is ``gain * (1/d^3 - 1/influence^3)``, pointing from the
        obstacle point to the nearest point of the body.
    x_min, x_max, half_w
        ``(M,)`` the robot's body rectangle (rear edge, front edge, half width); the edges
        are also the rear and front action points.
    lever
        Split a point's force between the two action points as a lever does (the statically
        equivalent pair: shares ``(x - x_min) / (x_max - x_min)`` at the front and the rest at
        the rear, with ``x`` the body-x of the nearest body point), instead of the paper's rule
        (all of it at the front when the point is ahead of the pivot, else at the rear). The
        paper's rule flips the turn when a point beside the pivot crosses it, so a skid with a
        neighbour alongside chatters in place; with the lever a push at the pivot of a skid
        whose pivot is centred turns it not at all.

    Returns
    -------
    front, rear
        ``(N_robots, 2)`` summed body-frame forces on the front and rear action points, where
        ``N_robots = robot.max() + 1``.
    d
        ``(M,)`` distances of the points from the body.
    """
    near, d = rect_nearest_points(pts_body, x_min, x_max, half_w)
    away = near - pts_body
    inside = d < 1e-9
    # A point inside the body (should not happen) pushes straight out along body y.
    away[inside] = np.column_stack([np.zeros(inside.sum()), -np.sign(pts_body[inside, 1] + 1e-12)])
    unit = away / np.maximum(np.linalg.norm(away, axis=1, keepdims=True), 1e-12)
    dd = np.maximum(d, min_distance_m)
    mag = gain * np.clip(1.0 / dd**3 - 1.0 / influence_m**3, 0.0, None)
    f = unit * mag[:, None]
    n = int(robot.max()) + 1 if len(robot) else 0
    front = np.zeros((n, 2))
    rear = np.zeros((n, 2))
    if lever:
        share = ((near[:, 0] - x_min) / np.maximum(x_max - x_min, 1e-9))[:, None]
        np.add.at(front, robot, f * share)
        np.add.at(rear, robot, f * (1.0 - share))
        return front, rear, d
    ahead = pts_body[:, 0] >= 0.0
    np.add.at(front, robot[ahead], f[ahead])
    np.add.at(rear, robot[~ahead], f[~ahead])
    return front, rear, d


def forces_to_command(
    f_goal: np.ndarray,
    x_goal: np.ndarray,
    f_front: np.ndarray,
    f_rear: np.ndarray,
    x_front: np.ndarray,
    x_rear: np.ndarray,
) -> np.ndarray:
    """Eq. 12 summed over action points: ``v = sum F_x``, ``omega = sum F_y / x_a``."""
    v = f_goal[:, 0] + f_front[:, 0] + f_rear[:, 0]
    w = f_goal[:, 1] / x_goal + f_front[:, 1] / x_front + f_rear[:, 1] / x_rear
    return np.column_stack([v, w])


def turn_throttle(
    f_goal: np.ndarray, x_goal: np.ndarray, w_net: np.ndarray, *, follow_turn: bool = True
) -> np.ndarray:
    """Share ``(N,)`` of the field's speed to keep while turning: ``cos^2`` of the angle
    between the goal force and the body axis (turn before driving; the skid can spin in
    place). With ``follow_turn`` the speed is cut only as far as the skid does turn the way
    the goal force wants (``w_net``, the summed command, against the goal's own turn
    ``F_y / x_a``): a skid whose turn the repulsion holds back, a neighbour at the corner that
    would swing, drives on as the summed forces say instead of standing in a local minimum.

    >>> float(turn_throttle(np.array([[0.0, 1.0]]), np.array([0.5]), np.array([2.0]))[0])
    0.0
    >>> float(turn_throttle(np.array([[0.0, 1.0]]), np.array([0.5]), np.array([0.0]))[0])
    1.0
    """
    rel = np.arctan2(f_goal[:, 1], np.abs(f_goal[:, 0]))
    throttle = np.clip(np.cos(rel), 0.0, 1.0) ** 2
    if not follow_turn:
        return throttle
    w_goal = f_goal[:, 1] / x_goal
    wants = np.abs(w_goal) > 1e-9
    turning = np.ones(len(w_goal))
    turning[wants] = np.clip(w_net[wants] / w_goal[wants], 0.0, 1.0)
    return 1.0 - turning * (1.0 - throttle)
