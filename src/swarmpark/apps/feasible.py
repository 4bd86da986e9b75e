"""Is a scenario feasible in its static map? The check every generated site passes.

Feasible here means what a planner can promise before anything moves: the file validates and
builds (:func:`~swarmpark.world.scenario.build_world` checks the starts against the walls and
each other), every park command's layout fits (the same :func:`swarmpark.layout.layout` call
the supervisor makes) and every goal can be reached from every start in the static map (one
Dijkstra per goal on the costmap of the widest skid, :mod:`swarmpark.plan.grid`). Whether the
fleet then parks without a collision is what a run measures.
"""

from __future__ import annotations

import math

import numpy as np
from shapely.geometry import LineString, Point
from shapely.ops import nearest_points, unary_union

from swarmpark.core.geometry import GeometryError, as_simple_polygon, footprint_polygon
from swarmpark.layout import LayoutError, LayoutResult, layout
from swarmpark.plan.grid import build_costmap, path_length_matrix
from swarmpark.world.scenario import ScenarioError, World, build_world, parse_scenario

__all__ = ["FeasibilityError", "check_feasible", "park_layout", "duration_for"]

#: Seconds a run gets beyond the travel-time estimate: start-up, docking, settling.
BASE_DURATION_S = 60.0
#: Travel time is estimated as this many times the longest start-goal path at full speed.
TRAVEL_FACTOR = 2.5
#: Extra seconds per skid (they queue at doors and in the bay).
PER_ROBOT_S = 2.0
WALKER_RADIUS_M = 0.25
#: A walker's route keeps this far from every parked footprint and wall (beyond its radius).
WALKER_CLEARANCE_M = 0.15


class FeasibilityError(ValueError):
    """The scenario cannot be carried out even in principle (names the field and value)."""


def park_layout(world: World, park, starts: np.ndarray) -> LayoutResult:
    """A park command's layout with one spot per skid at its own size. The supervisor lays a
    park of several sizes out at the largest size where that fits
    (:func:`swarmpark.supervisor.commands.uniform_spots`); the generator's check keeps the
    layout it was written with, so the generated sites (and their durations) stay as they
    were; a run's goals may then lie elsewhere than these."""
    idx = [world.ids.index(r) for r in park.robots]
    boundary = as_simple_polygon(park.boundary, "park.boundary")
    heading = park.heading_deg if park.heading_deg == "auto" else math.radians(park.heading_deg)
    solids = [p for p in world.wall_polygons if p.intersects(boundary)]
    solids += [p for p in world.static_obstacles if p.intersects(boundary)]
    opening = nearest_points(boundary.exterior, Point(starts[idx, :2].mean(axis=0)))[0]
    return layout(
        boundary,
        [world.robots[i].footprint for i in idx],
        heading=heading,
        method=park.method,
        margin_m=park.margin_m,
        obstacles=unary_union(solids) if solids else None,
        opening=(opening.x, opening.y),
    )


def duration_for(longest_path_m: float, n: int, speed_mps: float) -> float:
    """A run's duration from the site: generous, so a slow but working fleet still parks."""
    raw = BASE_DURATION_S + TRAVEL_FACTOR * longest_path_m / speed_mps + PER_ROBOT_S * n
    return float(10 * math.ceil(raw / 10))


def _goals(world: World, starts: np.ndarray) -> list[tuple[list[int], np.ndarray, str]]:
    """(robot indices, goal poses (K, 3), field) for every park and goto command."""
    out = []
    for k, c in enumerate(world.scenario.commands):
        f = f"commands[{k}]"
        if c.park is not None:
            try:
                lay = park_layout(world, c.park, starts)
            except (LayoutError, GeometryError) as exc:
                raise FeasibilityError(f"{f}.park: {exc}") from None
            out.append(([world.ids.index(r) for r in c.park.robots], lay.poses, f"{f}.park"))
        elif c.goto is not None:
            g = c.goto.pose
            pose = np.array([[g[0], g[1], math.radians(g[2])]])
            i = world.ids.index(c.goto.robot)
            body = footprint_polygon(pose[0], world.robots[i].footprint)
            if any(body.intersects(w) for w in world.wall_polygons):
                raise FeasibilityError(f"{f}.goto.pose: inside a wall (got {g})")
            out.append(([i], pose, f"{f}.goto"))
    return out


def _reach(world: World, starts: np.ndarray, goals) -> float:
    """Longest start-to-goal path (m); raises if a goal cannot be reached by its robots."""
    wmax = max(r.footprint.width_m for r in world.robots)
    cm = build_costmap(world.grid, wmax / 2, wmax / 2)
    longest = 0.0
    for idx, poses, f in goals:
        lengths = path_length_matrix(cm, starts[idx, :2], poses[:, :2])
        bad = np.argwhere(~np.isfinite(lengths))
        if len(bad):
            r, g = bad[0]
            raise FeasibilityError(
                f"{f}: goal {int(g)} at {np.round(poses[g, :2], 2).tolist()} cannot be reached "
                f"from robot {world.ids[idx[r]]!r}"
            )
        longest = max(longest, float(lengths.max(initial=0.0)))
    return longest


def _walker_routes(world: World, goals, count: int, rng: np.random.Generator) -> list[dict]:
    """Straight routes through the parking area's aisles: clear of every goal and wall."""
    parked = [
        footprint_polygon(p, world.robots[i].footprint)
        for idx, poses, _ in goals
        for i, p in zip(idx, poses, strict=True)
    ]
    if not parked:
        return []
    blocked = unary_union(parked + list(world.wall_polygons))
    keep = WALKER_RADIUS_M + WALKER_CLEARANCE_M
    x0, y0, x1, y1 = unary_union(parked).bounds
    w, h = world.grid.size_m
    edge = 0.3 + keep + 0.3
    cands = [LineString([(x, edge), (x, h - edge)]) for x in np.arange(x0, x1, 0.1)]
    cands += [LineString([(max(x0 - 3, edge), y), (w - edge, y)]) for y in np.arange(y0, y1, 0.1)]
    ok = [c for c in cands if c.distance(blocked) > keep]
    if not ok:  # no aisle wide enough: walk past the parking area's east side
        x = min(x1 + 1.0, w - edge)
        ok = [c for c in [LineString([(x, edge), (x, h - edge)])] if c.distance(blocked) > keep]
    routes = []
    for k in range(min(count, len(ok))):
        line = ok[int(rng.integers(len(ok)))]
        pts = [[round(float(a), 3), round(float(b), 3)] for a, b in line.coords]
        if rng.random() < 0.5:
            pts.reverse()
        routes.append(
            {
                "id": f"walker{k + 1}",
                "radius_m": WALKER_RADIUS_M,
                "waypoints": pts,
                "speed_mps": round(float(rng.uniform(0.8, 1.4)), 2),
                "start_s": round(float(rng.uniform(0.0, 40.0)), 1),
            }
        )
    return routes


def check_feasible(data: dict, *, walkers: int = 0, rng: np.random.Generator | None = None) -> dict:
    """Check ``data`` (a scenario mapping); return ``duration_s`` and ``obstacles`` for it.

    ``walkers`` people are routed through the parking area's aisles (added to the returned
    ``obstacles``). Raises :class:`FeasibilityError` naming the failing field.
    """
    rng = np.random.default_rng(rng)
    try:
        world = build_world(parse_scenario(data))
    except ScenarioError as exc:
        raise FeasibilityError(str(exc)) from None
    starts = np.stack([r.start for r in world.robots])
    goals = _goals(world, starts)
    longest = _reach(world, starts, goals)
    speed = min(r.max_speed_mps for r in world.robots)
    duration = duration_for(longest, len(world.robots), speed)
    obstacles = list(data.get("obstacles") or [])
    routes = _walker_routes(world, goals, walkers, rng) if walkers else []
    if walkers and not routes:
        raise FeasibilityError("obstacles: no walker route clear of the parking goals")
    for p in routes:
        walk = LineString(p["waypoints"]).length / p["speed_mps"]
        duration = max(duration, 10 * math.ceil((p["start_s"] + walk + 30) / 10))
    obstacles += routes
    if routes:  # the people must be valid scenario input too
        try:
            build_world(parse_scenario({**data, "obstacles": obstacles, "duration_s": duration}))
        except ScenarioError as exc:
            raise FeasibilityError(str(exc)) from None
    return {"duration_s": float(duration), "obstacles": obstacles, "longest_path_m": longest}
