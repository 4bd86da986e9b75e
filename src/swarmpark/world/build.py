"""The world a scenario describes, in SI units, and its validation against the map.

:func:`build_world` turns a schema-valid :class:`~swarmpark.world.scenario.Scenario` into a
:class:`World` (map, walls, robots, static obstacles, people) and checks it: robots inside
walls or overlapping, commands naming unknown robots, kidnaps into walls. Errors are
:class:`~swarmpark.world.scenario.ScenarioError` naming the field and the value.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace

import numpy as np
from shapely.geometry import Polygon

from swarmpark.core.geometry import (
    Footprint,
    GeometryError,
    as_simple_polygon,
    body_corners,
    convex_gap,
    footprint_corners,
    pad_polygons,
    triangulate,
)
from swarmpark.core.gridmap import MapError, OccupancyGrid, grid_from_walls, load_map_yaml
from swarmpark.world.scenario import Scenario, ScenarioError, StaticObstacleSpec

__all__ = ["World", "RobotConfig", "Person", "build_world"]


@dataclass(frozen=True)
class RobotConfig:
    id: str
    footprint: Footprint
    start: np.ndarray  # (3,) pivot pose, radians
    priority: float
    max_speed_mps: float
    max_accel_mps2: float
    max_yaw_rate_radps: float
    max_yaw_accel_radps2: float


@dataclass(frozen=True)
class Person:
    """A moving obstacle: a disc walking a polyline at constant speed from ``start_s``,
    standing ``waits_s[i]`` seconds at waypoint ``i`` when given. A person who ``reacts``
    stops short of a skid in the way, waits and may back off (:mod:`swarmpark.sim.people`).

    The walked distance ``s`` counts a wait as ``speed * wait`` metres spent in place, so the
    simulator advances every person the same way whether it walks or stands.
    """

    id: str
    radius_m: float
    waypoints: np.ndarray  # (W, 2)
    speed_mps: float
    start_s: float
    loop: bool
    waits_s: np.ndarray | None = None  # (W,)
    reacts: bool = True

    def _route(self) -> tuple[np.ndarray, np.ndarray]:
        """Route points and the length of each leg (waits as legs that stay in place)."""
        pts = np.vstack([self.waypoints, self.waypoints[:1]]) if self.loop else self.waypoints
        seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
        if self.waits_s is None:
            return pts, seg
        stay = np.asarray(self.waits_s, float) * self.speed_mps  # (W,), one per waypoint
        vpts = np.repeat(pts, 2, axis=0)[:-1]  # p0 p0 p1 p1 ... pk: stand, then walk on
        vseg = np.empty(len(vpts) - 1)
        # A loop stands at every waypoint, a route at all but the last.
        vseg[0::2] = stay[: len(seg)]
        vseg[1::2] = seg
        if not self.loop and stay[-1] > 0:  # stand at the end, then the route is done
            vpts = np.vstack([vpts, pts[-1:]])
            vseg = np.append(vseg, stay[-1])
        return vpts, vseg

    @property
    def route_length_m(self) -> float:
        return float(self._route()[1].sum())

    def position_at(self, s_m: float) -> np.ndarray:
        """Position after walking ``s_m`` metres along the route."""
        pts, seg = self._route()
        total = seg.sum()
        s = s_m % total if self.loop and total > 0 else min(s_m, total)
        cum = np.concatenate([[0.0], np.cumsum(seg)])
        i = int(np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(seg) - 1))
        f = 0.0 if seg[i] == 0 else (s - cum[i]) / seg[i]
        return pts[i] + f * (pts[i + 1] - pts[i])


@dataclass(frozen=True)
class World:
    """A validated scenario turned into SI-unit objects the simulator and supervisor use."""

    scenario: Scenario
    grid: OccupancyGrid
    wall_polygons: tuple[Polygon, ...]  # exact walls when the map was given as polygons
    robots: tuple[RobotConfig, ...]
    static_obstacles: tuple[Polygon, ...]
    people: tuple[Person, ...]
    #: The map the skids believe in (``sensing.map``), when it is not the true one.
    believed_grid: OccupancyGrid | None = None

    @property
    def ids(self) -> list[str]:
        return [r.id for r in self.robots]

    def off_map_or_in_cells(self, corners: np.ndarray) -> np.ndarray:
        """Bool ``(N,)``: the footprints ``corners`` ``(N, 4, 2)`` reach outside the map or,
        on a map_server image, overlap an occupied cell (exactly: a block's interior counts,
        not only its outline). Polygon walls are tested exactly by the convex pieces."""
        grid = self.grid
        mask = np.zeros_like(grid.occupied) if self.wall_polygons else None
        return grid.footprint_hits(corners, mask)

    def static_convex_pieces(self) -> tuple[np.ndarray, list[str]]:
        """Every static solid as convex pieces padded to 4 vertices, and who owns each piece.

        Polygon walls and static obstacles are triangulated exactly; a map image contributes
        its boundary cells as squares; the map's outer edge is a wall too.
        """
        pieces: list[np.ndarray] = []
        owners: list[str] = []
        if self.wall_polygons:
            for poly in self.wall_polygons:
                tris = triangulate(poly)
                pieces.extend(tris)
                owners.extend(["wall"] * len(tris))
        else:
            rc = self.grid.boundary_cells()
            sq = self.grid.cell_squares(rc)
            pieces.extend(sq)
            owners.extend(["wall"] * len(sq))
        for k, poly in enumerate(self.static_obstacles):
            tris = triangulate(poly)
            pieces.extend(tris)
            owners.extend([f"obstacle:{k}"] * len(tris))
        xmin, ymin, xmax, ymax = self.grid.bounds
        t = 1.0  # the edge walls are 1 m thick, just outside the map
        for x0, y0, x1, y1 in (
            (xmin - t, ymin - t, xmax + t, ymin),
            (xmin - t, ymax, xmax + t, ymax + t),
            (xmin - t, ymin, xmin, ymax),
            (xmax, ymin, xmax + t, ymax),
        ):
            pieces.append(np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], float))
            owners.append("wall")
        return pad_polygons(pieces, 4), owners


def _polygon(points: list[list[float]], field: str) -> Polygon:
    try:
        return as_simple_polygon(points, field)
    except GeometryError as exc:
        raise ScenarioError(str(exc)) from None


def build_world(scn: Scenario) -> World:
    """Turn a schema-valid scenario into a :class:`World`, checking it against the map.

    Raises :class:`ScenarioError` for a map file that does not exist, a wall or obstacle that
    is not a simple polygon, a robot starting inside a wall or obstacle or overlapping another
    robot, a duplicate robot id, and a command naming an unknown robot or a bad boundary.
    """
    # Map.
    walls: list[Polygon] = []
    try:
        if scn.map.yaml is not None:
            grid = load_map_yaml(scn.map.yaml)
        else:
            walls = [_polygon(w, f"map.walls[{i}]") for i, w in enumerate(scn.map.walls)]
            grid = grid_from_walls(tuple(scn.map.size_m), scn.map.resolution_m, walls)  # type: ignore[arg-type]
    except MapError as exc:
        raise ScenarioError(str(exc).replace("map.yaml:", "map.yaml:", 1)) from None

    # Robots.
    d = scn.robot_defaults
    robots: list[RobotConfig] = []
    seen: set[str] = set()
    for i, r in enumerate(scn.robots):
        if r.id in seen:
            raise ScenarioError(f"robots[{i}].id: duplicate robot id {r.id!r}")
        seen.add(r.id)
        fp_spec = r.footprint or d.footprint
        robots.append(
            RobotConfig(
                id=r.id,
                footprint=fp_spec.build(f"robots[{i}].footprint"),
                start=np.array([r.pose[0], r.pose[1], np.deg2rad(r.pose[2])], float),
                priority=r.priority,
                max_speed_mps=r.max_speed_mps or d.max_speed_mps,
                max_accel_mps2=r.max_accel_mps2 or d.max_accel_mps2,
                max_yaw_rate_radps=r.max_yaw_rate_radps or d.max_yaw_rate_radps,
                max_yaw_accel_radps2=r.max_yaw_accel_radps2 or d.max_yaw_accel_radps2,
            )
        )

    # The fleet's order is the robots' ids in natural order, whatever order the file lists
    # them in: every tie later on (assignment, fill order, right of way) is broken by id, so a
    # reordered robot list gives the same run.
    if scn.perturb.shuffle:  # a shuffled list must give the same run (the sort below)
        order = np.random.default_rng([scn.seed, PERTURB_STREAM, 1]).permutation(len(robots))
        robots = [robots[k] for k in order]
    robots.sort(key=lambda r: robot_order_key(r.id))

    # Obstacles and people.
    statics: list[Polygon] = []
    people: list[Person] = []
    for i, o in enumerate(scn.obstacles):
        if isinstance(o, StaticObstacleSpec):
            statics.append(_polygon(o.polygon, f"obstacles[{i}].polygon"))
        else:
            wp = np.asarray(o.waypoints, float)
            if np.any(np.linalg.norm(np.diff(wp, axis=0), axis=1) == 0):
                raise ScenarioError(f"obstacles[{i}].waypoints: repeated waypoint in {o.waypoints}")
            people.append(
                Person(
                    o.id or f"person{len(people)}",
                    o.radius_m,
                    wp,
                    o.speed_mps,
                    o.start_s,
                    o.loop,
                    None if o.waits_s is None else np.asarray(o.waits_s, float),
                    o.reacts,
                )
            )
    pid = [p.id for p in people]
    if len(set(pid)) != len(pid):
        raise ScenarioError(f"obstacles: duplicate person id in {pid}")

    believed = None
    if scn.sensing.map is not None:
        try:
            believed = load_map_yaml(scn.sensing.map)
        except MapError as exc:
            raise ScenarioError(str(exc).replace("map.yaml:", "sensing.map:", 1)) from None
    world = World(
        scn,
        grid,
        tuple(walls),
        tuple(robots),
        tuple(statics),
        tuple(people),
        believed_grid=believed,
    )
    _check_start_poses(world)
    if scn.perturb.start_m > 0 or scn.perturb.start_deg > 0:
        world = replace(world, robots=_perturbed_starts(world))
    _check_commands(world)
    _check_kidnaps(world)
    _check_faults(world)
    return world


#: A perturbed start that lands in a wall or on another skid is drawn again this many times.
PERTURB_TRIES = 50


def _perturbed_starts(world: World) -> tuple[RobotConfig, ...]:
    """The robots with their starts moved as ``scenario.perturb`` says, drawn from the
    scenario's seed (and ``perturb.draw``) in the fleet's order; each start keeps clear of
    walls, obstacles and the skids already placed."""
    spec = world.scenario.perturb
    key = [world.scenario.seed, PERTURB_STREAM]
    # Sub-stream 1 is the shuffle's; draws other than 0 take sub-stream 2 (draw 0 keeps the
    # stream of the runs made before draws existed).
    rng = np.random.default_rng(key + [2, spec.draw] if spec.draw else key)
    pieces, _ = world.static_convex_pieces()
    bounds = np.array([spec.start_m, spec.start_m, np.deg2rad(spec.start_deg)])
    placed: list[np.ndarray] = []  # corners of the skids placed so far
    out = []
    for r in world.robots:
        body = body_corners([r.footprint])
        for _ in range(PERTURB_TRIES):
            pose = r.start + rng.uniform(-1.0, 1.0, 3) * bounds
            corners = footprint_corners(pose[None], body)
            others = np.concatenate([pieces, *(c[None] for c in placed)]) if placed else pieces
            gaps = convex_gap(np.repeat(corners, len(others), axis=0), others)
            if np.all(gaps >= 0):
                break
        else:
            raise ScenarioError(
                f"perturb: no free start within {spec.start_m} m / {spec.start_deg} deg of "
                f"robot {r.id!r} after {PERTURB_TRIES} draws"
            )
        placed.append(pad_polygons([corners[0]], 4)[0])
        out.append(replace(r, start=pose))
    return tuple(out)


#: The random stream of the start perturbations (independent of the sensing streams).
PERTURB_STREAM = 0x7E27


def robot_order_key(robot_id: str) -> tuple:
    """Natural order of robot ids: ``s2`` before ``s10``, then text order.

    >>> sorted(["s10", "b", "s2", "a1"], key=robot_order_key)
    ['a1', 'b', 's2', 's10']
    """
    parts = re.split(r"(\d+)", robot_id)
    return tuple((0, int(t), "") if t.isdigit() else (1, 0, t) for t in parts if t), robot_id


def _check_faults(world: World) -> None:
    ids = world.ids
    for k, fault in enumerate(world.scenario.faults):
        if fault.robot not in ids:
            raise ScenarioError(f"faults[{k}].robot: unknown robot (got {fault.robot!r})")


def _check_kidnaps(world: World) -> None:
    sensing = world.scenario.sensing
    if sensing.kidnap and sensing.localization != "amcl":
        raise ScenarioError(
            f"sensing.kidnap: needs sensing.localization 'amcl' (got {sensing.localization!r})"
        )
    ids = world.ids
    pieces, owners = world.static_convex_pieces()
    for k, kid in enumerate(sensing.kidnap):
        f = f"sensing.kidnap[{k}]"
        if kid.robot not in ids:
            raise ScenarioError(f"{f}.robot: unknown robot (got {kid.robot!r})")
        if kid.at_s > world.scenario.duration_s:
            raise ScenarioError(
                f"{f}.at_s: after the end of the run, duration_s {world.scenario.duration_s} "
                f"(got {kid.at_s})"
            )
        pose = np.array([kid.pose[0], kid.pose[1], np.deg2rad(kid.pose[2])], float)
        fp = world.robots[ids.index(kid.robot)].footprint
        corners = footprint_corners(pose[None], body_corners([fp]))
        gap = convex_gap(np.repeat(corners, len(pieces), axis=0), pieces)
        if np.any(gap < 0):
            what = owners[int(np.argmin(gap))].replace(":", " ")
            where = "a wall" if what == "wall" else what
            raise ScenarioError(
                f"{f}.pose: robot {kid.robot!r} would be inside {where} (got {kid.pose})"
            )
        if world.off_map_or_in_cells(corners)[0]:
            raise ScenarioError(
                f"{f}.pose: robot {kid.robot!r} would be in an occupied cell of the map or "
                f"outside it (got {kid.pose})"
            )


def _check_start_poses(world: World) -> None:
    listed = {r.id: k for k, r in enumerate(world.scenario.robots)}  # index in the file
    fps = [r.footprint for r in world.robots]
    poses = np.stack([r.start for r in world.robots])
    corners = footprint_corners(poses, body_corners(fps))
    pieces, owners = world.static_convex_pieces()
    n, p = len(corners), len(pieces)
    # Only a skid and a piece whose boxes meet can overlap: the exact gap is left for those
    # (every pair of a 500-skid site took 2.8 s). Others count as apart (+inf).
    lo, hi = corners.min(axis=1), corners.max(axis=1)
    meet = np.ones((n, 0), bool)
    if p:
        plo, phi = pieces.min(axis=1), pieces.max(axis=1)
        meet = np.all((lo[:, None] <= phi[None]) & (hi[:, None] >= plo[None]), axis=2)
    gaps = np.full((n, p), np.inf)
    ri, pi = np.nonzero(meet)
    if len(ri):
        gaps[ri, pi] = convex_gap(corners[ri], pieces[pi])
    off = world.off_map_or_in_cells(corners)
    for i, r in enumerate(world.robots):
        hit = np.flatnonzero(gaps[i] < 0)
        if len(hit):
            what = owners[hit[0]]
            where = "inside a wall" if what == "wall" else f"inside {what.replace(':', ' ')}"
            raise ScenarioError(
                f"robots[{listed[r.id]}].pose: robot {r.id!r} starts {where} at "
                f"{[float(v) for v in world.scenario.robots[listed[r.id]].pose]}"
            )
        if off[i]:  # past the walls: off the map, or inside a block of a map image
            raise ScenarioError(
                f"robots[{listed[r.id]}].pose: robot {r.id!r} starts "
                f"{'in an occupied cell of the map or ' if not world.wall_polygons else ''}"
                f"outside the map at {[float(v) for v in world.scenario.robots[listed[r.id]].pose]}"
            )
    # Pairs of skids whose boxes meet, in the order of np.triu_indices (the first overlap
    # reported is the same as checking every pair).
    iu, ju = np.triu_indices(n, 1) if n <= 64 else _meeting_pairs(lo, hi)
    if len(iu):
        g = convex_gap(corners[iu], corners[ju])
        bad = np.flatnonzero(g < 0)
        if len(bad):
            a, b = world.robots[iu[bad[0]]], world.robots[ju[bad[0]]]
            pa, pb = (world.scenario.robots[listed[r.id]].pose for r in (a, b))
            raise ScenarioError(
                f"robots[{listed[b.id]}].pose: robot {b.id!r} overlaps robot {a.id!r} at start "
                f"(poses {pa} and {pb})"
            )
    for k, person in enumerate(world.people):
        if person.radius_m <= 0:
            raise ScenarioError(f"obstacles[{k}].radius_m: must be > 0 (got {person.radius_m})")


def _meeting_pairs(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pairs ``i < j`` (sorted) of boxes ``lo``/``hi`` ``(N, 2)`` that meet: a sweep along x."""
    order = np.argsort(lo[:, 0], kind="stable")
    # For each box (in x order), the boxes starting before its end in x are candidates.
    end = np.searchsorted(lo[order, 0], hi[order, 0], side="right")
    counts = end - np.arange(len(order)) - 1
    a = np.repeat(np.arange(len(order)), np.maximum(counts, 0))
    b = a + 1 + (np.arange(len(a)) - np.repeat(np.cumsum(counts) - counts, np.maximum(counts, 0)))
    i, j = order[a], order[b]
    ok = np.all((lo[i] <= hi[j]) & (hi[i] >= lo[j]), axis=1)
    i, j = np.minimum(i[ok], j[ok]), np.maximum(i[ok], j[ok])
    k = np.lexsort((j, i))
    return i[k], j[k]


def _check_robot_list(names, ids: set[str], field: str, *, unique: bool = True) -> None:
    """Every name in ``names`` is a robot of the world (and, if ``unique``, listed once)."""
    for name in names:
        if name not in ids:
            raise ScenarioError(f"{field}: unknown robot {name!r}")
    if unique and len(set(names)) != len(names):
        raise ScenarioError(f"{field}: robot listed twice in {names}")


def _check_command(c, ids: set[str], f: str) -> None:
    """One scenario command's robots (and park boundary, formation paths) against the world."""
    if c.park is not None:
        _check_robot_list(c.park.robots, ids, f"{f}.park.robots")
        _polygon(c.park.boundary, f"{f}.park.boundary")
    elif c.goto is not None:
        if c.goto.robot not in ids:
            raise ScenarioError(f"{f}.goto.robot: unknown robot {c.goto.robot!r}")
    elif c.formation is not None:
        fc = c.formation
        _check_robot_list(fc.robots, ids, f"{f}.formation.robots")
        if len(fc.paths) not in (1, len(fc.robots)):
            raise ScenarioError(
                f"{f}.formation.paths: give the leader's path or one per robot "
                f"({len(fc.robots)} robots, got {len(fc.paths)} paths)"
            )
    else:
        names = c.stop if c.stop is not None else c.resume
        if isinstance(names, list):
            _check_robot_list(names, ids, f"{f}.{c.kind}", unique=False)


def _check_commands(world: World) -> None:
    ids = set(world.ids)
    for i, c in enumerate(world.scenario.commands):
        f = f"commands[{i}]"
        _check_command(c, ids, f)
        if c.at_s > world.scenario.duration_s:
            raise ScenarioError(
                f"{f}.at_s: {c.at_s} is after the end of the run (duration_s {world.scenario.duration_s})"
            )
