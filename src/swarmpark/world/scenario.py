"""Scenario schema (pydantic), YAML loading, and validation against the map with clear errors.

The YAML is only the serialized form of :class:`Scenario`. Angles are in degrees here (the
user's edge) and converted to radians when the world is built. Every error is a
:class:`ScenarioError` whose message starts with the field path and names the value.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator
from shapely.geometry import Polygon

from swarmpark.assign import ASSIGNMENT_COSTS as _COSTS
from swarmpark.control.modes import AVOIDANCE_MODES
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
from swarmpark.layout.methods import LAYOUT_METHODS as _METHODS

__all__ = [
    "Scenario",
    "ScenarioError",
    "World",
    "RobotConfig",
    "Person",
    "KidnapSpec",
    "load_scenario",
    "parse_scenario",
    "build_world",
    "LAYOUT_METHODS",
    "ASSIGNMENT_COSTS",
]

# The choices of methods, costs and avoidance live in their registries; names at import:
LAYOUT_METHODS = _METHODS.names()
COMMAND_KINDS = ("park", "goto", "formation", "stop", "estop", "resume")
ASSIGNMENT_COSTS = _COSTS.names()

Point = Annotated[list[float], Field(min_length=2, max_length=2)]
PoseDeg = Annotated[list[float], Field(min_length=3, max_length=3)]
PositiveFloat = Annotated[float, Field(gt=0, allow_inf_nan=False)]
NonNegFloat = Annotated[float, Field(ge=0, allow_inf_nan=False)]


class ScenarioError(ValueError):
    """Bad scenario input. The message starts with the field path and names the value."""


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, strict=False)


class FootprintSpec(_Model):
    length_m: PositiveFloat
    width_m: PositiveFloat
    pivot_from_rear_m: NonNegFloat | None = None

    def build(self, field: str) -> Footprint:
        try:
            return Footprint(self.length_m, self.width_m, self.pivot_from_rear_m)
        except GeometryError as exc:
            raise ScenarioError(f"{field}: {exc}") from exc


class RobotDefaults(_Model):
    footprint: FootprintSpec = FootprintSpec(length_m=1.2, width_m=0.8, pivot_from_rear_m=0.6)
    max_speed_mps: PositiveFloat = 0.5
    max_accel_mps2: PositiveFloat = 0.5
    max_yaw_rate_radps: PositiveFloat = 1.0
    max_yaw_accel_radps2: PositiveFloat = 2.0


class RobotSpec(_Model):
    id: Annotated[str, Field(min_length=1, pattern=r"^[A-Za-z0-9_.\-]+$")]
    pose: PoseDeg
    priority: NonNegFloat = 1.0
    footprint: FootprintSpec | None = None
    max_speed_mps: PositiveFloat | None = None
    max_accel_mps2: PositiveFloat | None = None
    max_yaw_rate_radps: PositiveFloat | None = None
    max_yaw_accel_radps2: PositiveFloat | None = None


class MapSpec(_Model):
    yaml: str | None = None
    size_m: Point | None = None
    resolution_m: PositiveFloat = 0.05
    walls: list[list[Point]] = []

    @model_validator(mode="after")
    def _one_form(self) -> MapSpec:
        if (self.yaml is None) == (self.size_m is None):
            raise ValueError("give either 'yaml' (a map_server file) or 'size_m' (+ walls)")
        if self.yaml is not None and self.walls:
            raise ValueError("'walls' go with 'size_m', not with a map_server 'yaml'")
        return self


class StaticObstacleSpec(_Model):
    polygon: list[Point]


class PersonSpec(_Model):
    id: str | None = None
    radius_m: PositiveFloat = 0.3
    waypoints: Annotated[list[Point], Field(min_length=2)]
    speed_mps: PositiveFloat = 1.2
    start_s: NonNegFloat = 0.0
    loop: bool = False
    #: Seconds the person stands at each waypoint before walking on (one per waypoint).
    waits_s: list[NonNegFloat] | None = None

    @model_validator(mode="after")
    def _one_wait_per_waypoint(self) -> PersonSpec:
        if self.waits_s is not None and len(self.waits_s) != len(self.waypoints):
            raise ValueError(
                f"waits_s: need one wait per waypoint ({len(self.waypoints)}), "
                f"got {len(self.waits_s)}"
            )
        return self


class ParkCmd(_Model):
    robots: Annotated[list[str], Field(min_length=1)]
    boundary: list[Point]
    heading_deg: float | Literal["auto"] = 0.0
    method: Annotated[str, _METHODS.as_field()] = "stacking"
    margin_m: NonNegFloat = 0.3
    assignment: Annotated[str, _COSTS.as_field()] = "formation"


class GotoCmd(_Model):
    robot: str
    pose: PoseDeg
    priority: NonNegFloat | None = None


class FormationCmd(_Model):
    """Move a group along given paths holding a formation (Liu, Sun, Zhu 2010).

    ``paths`` has one list of waypoints per robot, or only the leader's, in which case each
    follower's path is the leader's carried at its offset (a robot's position is put in front
    of its waypoints when the first waypoint is not it). ``offsets_m`` gives, for every follower, its desired
    position in the leader's frame (x forward, y left), either one ``[dx, dy]`` or one per
    keypoint in ``offset_at`` (fractions of the leader's path); by default the group holds the
    shape it starts in. The leader is the first robot.
    """

    robots: Annotated[list[str], Field(min_length=2)]
    paths: list[Annotated[list[Point], Field(min_length=2)]]
    method: Literal["formation", "no_formation", "leader_follower"] = "formation"
    offsets_m: list[list[float]] | list[list[list[float]]] | None = None
    offset_at: list[float] | None = None
    dt_s: PositiveFloat = 1.0
    steps: Annotated[int, Field(ge=2, le=400)] | None = None
    d_safe_m: PositiveFloat | None = None


class CommandSpec(_Model):
    at_s: NonNegFloat = 0.0
    park: ParkCmd | None = None
    goto: GotoCmd | None = None
    formation: FormationCmd | None = None
    stop: list[str] | Literal["all"] | None = None
    estop: Literal[True] | None = None
    resume: list[str] | Literal["all"] | None = None

    @model_validator(mode="after")
    def _exactly_one(self) -> CommandSpec:
        given = [k for k in COMMAND_KINDS if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError(
                f"a command needs exactly one of {', '.join(COMMAND_KINDS)} (got {given})"
            )
        return self

    @property
    def kind(self) -> str:
        return next(k for k in COMMAND_KINDS if getattr(self, k) is not None)


class ExpectSpec(_Model):
    success: bool | None = None
    max_collisions: Annotated[int, Field(ge=0)] | None = None
    min_clearance_m: float | None = None
    max_time_to_park_s: PositiveFloat | None = None
    #: With ``sensing.localization: amcl``: bound on the run's mean localization error.
    max_mean_localization_error_m: PositiveFloat | None = None
    #: With kidnappings: every kidnapped skid is found again within this many seconds.
    max_recovery_s: PositiveFloat | None = None


class NavigationSpec(_Model):
    """Navigation options: ``avoidance`` between skids is ``monitor`` (collision monitor with
    right of way at bottlenecks, the default) or ``rvo`` (ORCA with priorities)."""

    avoidance: Annotated[str, AVOIDANCE_MODES.as_field()] = "monitor"


class KidnapSpec(_Model):
    """At ``at_s`` a skid is carried (by hand, without its odometry noticing) to ``pose``
    (x, y, heading in degrees); its filter must find it again."""

    robot: str
    at_s: NonNegFloat
    pose: PoseDeg


class SensingSpec(_Model):
    """Onboard sensing. ``localization: amcl`` makes every skid localize with its own LIDAR
    and drifting odometry (particle filter against the map); control then uses the estimates
    and the run result reports the localization error. ``truth`` uses the true poses.
    ``recovery`` turns on augmented MCL (injected particles when the scans stop fitting,
    which finds a kidnapped skid); ``kidnap`` moves skids during the run to test it."""

    localization: Literal["truth", "amcl"] = "truth"
    #: The map the skids localize and plan in (map_server YAML, e.g. one built by
    #: ``swarmpark map``); by default the scenario's map. The simulator always uses the
    #: scenario's map as the true world.
    map: str | None = None
    lidar_beams: Annotated[int, Field(ge=8, le=4000)] = 1000
    lidar_range_m: PositiveFloat = 5.0
    range_noise_std_m: NonNegFloat = 0.01
    dropout_prob: Annotated[float, Field(ge=0, lt=1)] = 0.0
    recovery: bool = False
    kidnap: list[KidnapSpec] = []


class Scenario(_Model):
    name: str
    seed: int = 0
    dt_s: Annotated[float, Field(gt=0, le=0.5)] = 0.05
    duration_s: PositiveFloat = 180.0
    map: MapSpec
    robot_defaults: RobotDefaults = RobotDefaults()
    robots: Annotated[list[RobotSpec], Field(min_length=1)]
    obstacles: list[StaticObstacleSpec | PersonSpec] = []
    commands: list[CommandSpec] = []
    navigation: NavigationSpec = NavigationSpec()
    sensing: SensingSpec = SensingSpec()
    expect: ExpectSpec = ExpectSpec()


# ----------------------------------------------------------------------------- loading


def _loc(loc: tuple[Any, ...]) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        elif part in ("StaticObstacleSpec", "PersonSpec") or "[" in str(part):
            continue  # union branch names add nothing for the reader
        else:
            out += ("." if out else "") + str(part)
    return out or "scenario"


def _format_validation(exc: ValidationError) -> str:
    errs = exc.errors()
    # A union (static obstacle or person) reports every branch; show the closest one.
    err = min(errs, key=lambda e: (e["type"] == "extra_forbidden" and len(errs) > 1, len(e["loc"])))
    field = _loc(err["loc"])
    if err["type"] == "extra_forbidden":
        return f"{field}: unknown key (value {err['input']!r})"
    msg = err["msg"].removeprefix("Value error, ")
    value = err.get("input")
    shown = repr(value) if not isinstance(value, dict) else "{" + ", ".join(map(str, value)) + "}"
    extra = f" ({len(errs) - 1} more error(s))" if len(errs) > 1 else ""
    return f"{field}: {msg} (got {shown}){extra}"


def parse_scenario(data: Any, base_dir: str | Path = ".") -> Scenario:
    """Validate a parsed YAML mapping into a :class:`Scenario` (schema only, no map checks)."""
    if not isinstance(data, dict):
        raise ScenarioError(f"scenario: must be a mapping of keys (got {type(data).__name__})")
    try:
        scn = Scenario.model_validate(data)
    except ValidationError as exc:
        raise ScenarioError(_format_validation(exc)) from None
    if scn.map.yaml is not None and not Path(scn.map.yaml).is_absolute():
        new_map = scn.map.model_copy(update={"yaml": str(Path(base_dir) / scn.map.yaml)})
        scn = scn.model_copy(update={"map": new_map})
    if scn.sensing.map is not None and not Path(scn.sensing.map).is_absolute():
        new_sensing = scn.sensing.model_copy(update={"map": str(Path(base_dir) / scn.sensing.map)})
        scn = scn.model_copy(update={"sensing": new_sensing})
    return scn


def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a scenario YAML file (relative map paths resolve beside it)."""
    path = Path(path)
    if not path.is_file():
        raise ScenarioError(f"scenario: file not found: {str(path)!r}")
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise ScenarioError(f"scenario: {str(path)!r} is not valid YAML: {exc}") from None
    return parse_scenario(data, path.parent)


# ----------------------------------------------------------------------------- the world


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
    standing ``waits_s[i]`` seconds at waypoint ``i`` when given.

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

    def _route(self) -> tuple[np.ndarray, np.ndarray]:
        """Route points and the length of each leg (waits as legs that stay in place)."""
        pts = np.vstack([self.waypoints, self.waypoints[:1]]) if self.loop else self.waypoints
        seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
        if self.waits_s is None:
            return pts, seg
        stay = np.asarray(self.waits_s, float) * self.speed_mps  # (W,), one per waypoint
        vpts = np.repeat(pts, 2, axis=0)[:-1]  # p0 p0 p1 p1 ... pk: stand, then walk on
        vseg = np.empty(len(vpts) - 1)
        vseg[0::2] = stay[
            : len(seg)
        ]  # a loop stands at every waypoint, a route at all but the last
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
    _check_commands(world)
    _check_kidnaps(world)
    return world


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


def _check_start_poses(world: World) -> None:
    fps = [r.footprint for r in world.robots]
    poses = np.stack([r.start for r in world.robots])
    corners = footprint_corners(poses, body_corners(fps))
    pieces, owners = world.static_convex_pieces()
    n, p = len(corners), len(pieces)
    gaps = convex_gap(np.repeat(corners, p, axis=0), np.tile(pieces, (n, 1, 1))).reshape(n, p)
    for i, r in enumerate(world.robots):
        hit = np.flatnonzero(gaps[i] < 0)
        if len(hit):
            what = owners[hit[0]]
            where = "inside a wall" if what == "wall" else f"inside {what.replace(':', ' ')}"
            raise ScenarioError(
                f"robots[{i}].pose: robot {r.id!r} starts {where} at "
                f"{[float(v) for v in world.scenario.robots[i].pose]}"
            )
    iu, ju = np.triu_indices(n, 1)
    if len(iu):
        g = convex_gap(corners[iu], corners[ju])
        bad = np.flatnonzero(g < 0)
        if len(bad):
            a, b = world.robots[iu[bad[0]]], world.robots[ju[bad[0]]]
            raise ScenarioError(
                f"robots[{ju[bad[0]]}].pose: robot {b.id!r} overlaps robot {a.id!r} at start "
                f"(poses {world.scenario.robots[iu[bad[0]]].pose} and {world.scenario.robots[ju[bad[0]]].pose})"
            )
    for k, person in enumerate(world.people):
        if person.radius_m <= 0:
            raise ScenarioError(f"obstacles[{k}].radius_m: must be > 0 (got {person.radius_m})")


def _check_commands(world: World) -> None:
    ids = set(world.ids)
    for i, c in enumerate(world.scenario.commands):
        f = f"commands[{i}]"
        if c.park is not None:
            for name in c.park.robots:
                if name not in ids:
                    raise ScenarioError(f"{f}.park.robots: unknown robot {name!r}")
            if len(set(c.park.robots)) != len(c.park.robots):
                raise ScenarioError(f"{f}.park.robots: robot listed twice in {c.park.robots}")
            _polygon(c.park.boundary, f"{f}.park.boundary")
        elif c.goto is not None:
            if c.goto.robot not in ids:
                raise ScenarioError(f"{f}.goto.robot: unknown robot {c.goto.robot!r}")
        elif c.formation is not None:
            fc = c.formation
            for name in fc.robots:
                if name not in ids:
                    raise ScenarioError(f"{f}.formation.robots: unknown robot {name!r}")
            if len(set(fc.robots)) != len(fc.robots):
                raise ScenarioError(f"{f}.formation.robots: robot listed twice in {fc.robots}")
            if len(fc.paths) not in (1, len(fc.robots)):
                raise ScenarioError(
                    f"{f}.formation.paths: give the leader's path or one per robot "
                    f"({len(fc.robots)} robots, got {len(fc.paths)} paths)"
                )
        else:
            names = c.stop if c.stop is not None else c.resume
            if isinstance(names, list):
                for name in names:
                    if name not in ids:
                        raise ScenarioError(f"{f}.{c.kind}: unknown robot {name!r}")
        if c.at_s > world.scenario.duration_s:
            raise ScenarioError(
                f"{f}.at_s: {c.at_s} is after the end of the run (duration_s {world.scenario.duration_s})"
            )
