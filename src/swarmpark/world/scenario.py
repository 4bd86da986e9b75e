"""Scenario schema (pydantic) and YAML loading with clear errors (the world: world/build.py).

The YAML is only the serialized form of :class:`Scenario`. Angles are in degrees here (the
user's edge) and converted to radians when the world is built. Every error is a
:class:`ScenarioError` whose message starts with the field path and names the value.
"""

from __future__ import annotations

import difflib
import typing
from pathlib import Path
from typing import Annotated, Any, Literal

import yaml
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    field_validator,
    model_validator,
)

from swarmpark.assign import ASSIGNMENT_COSTS as _COSTS
from swarmpark.control.modes import AVOIDANCE_MODES, NAVIGATION_MODES
from swarmpark.core.geometry import (
    Footprint,
    GeometryError,
)
from swarmpark.core.limits import (
    MAX_BOUNDARY_VERTICES,
    MAX_COORDINATE_M,
    MAX_DURATION_S,
    MAX_FOOTPRINT_M,
    MAX_HEADING_DEG,
    MAX_ID_LENGTH,
    MAX_POLYGON_VERTICES,
    MAX_ROBOTS,
    MAX_ROBOTS_PER_COMMAND,
    MAX_TICKS,
    MIN_DT_S,
    MIN_RESOLUTION_M,
    check_grid_cells,
)
from swarmpark.layout.methods import LAYOUT_METHODS as _METHODS

__all__ = [
    "Scenario",
    "ScenarioError",
    "World",
    "RobotConfig",
    "Person",
    "KidnapSpec",
    "FaultSpec",
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

# Every number at this edge is finite and bounded (core/limits.py): a NaN, an infinity or
# 1e300 never reaches the core. The API's request models reuse these types.
#: A coordinate in metres (map frame), within +-MAX_COORDINATE_M.
Coord = Annotated[float, Field(allow_inf_nan=False, ge=-MAX_COORDINATE_M, le=MAX_COORDINATE_M)]
#: A heading in degrees, within +-MAX_HEADING_DEG.
HeadingDeg = Annotated[float, Field(allow_inf_nan=False, ge=-MAX_HEADING_DEG, le=MAX_HEADING_DEG)]
Point = Annotated[list[Coord], Field(min_length=2, max_length=2)]
PoseDeg = Annotated[list[float], Field(min_length=3, max_length=3)]
#: A polygon (boundary, wall, obstacle) or a path: at most MAX_POLYGON_VERTICES points.
Polygon = Annotated[list[Point], Field(max_length=MAX_POLYGON_VERTICES)]
#: A park boundary: at most MAX_BOUNDARY_VERTICES points (a surveyed outline may be dense).
Boundary = Annotated[list[Point], Field(max_length=MAX_BOUNDARY_VERTICES)]
PositiveFloat = Annotated[float, Field(gt=0, allow_inf_nan=False, le=1e6)]
NonNegFloat = Annotated[float, Field(ge=0, allow_inf_nan=False, le=1e6)]
#: A robot or person id as referenced (commands, faults): bounded length.
RobotRef = Annotated[str, Field(min_length=1, max_length=MAX_ID_LENGTH)]
#: A list of robots in one command.
RobotList = Annotated[list[RobotRef], Field(min_length=1, max_length=MAX_ROBOTS_PER_COMMAND)]
FootprintSide = Annotated[float, Field(gt=0, le=MAX_FOOTPRINT_M, allow_inf_nan=False)]


def _pose(value: list[float]) -> list[float]:
    """``[x_m, y_m, heading_deg]``: finite, coordinates and heading within the limits."""
    x, y, h = value
    for k, (v, bound) in enumerate(
        ((x, MAX_COORDINATE_M), (y, MAX_COORDINATE_M), (h, MAX_HEADING_DEG))
    ):
        if v != v or v in (float("inf"), float("-inf")):
            raise ValueError(f"[{k}] must be a finite number (got {v})")
        if abs(v) > bound:
            raise ValueError(f"[{k}] must be within +-{bound:g} (got {v})")
    return value


#: Scenario files larger than this are refused unread (the suite's largest is a few kB).
MAX_SCENARIO_BYTES = 4 * 1024 * 1024


#: libyaml's safe loader when PyYAML has it (same documents, tens of times faster on a long
#: wall list), else the pure-Python one.
_SafeLoader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


class ScenarioError(ValueError):
    """Bad scenario input. The message starts with the field path and names the value."""


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, strict=False)


class FootprintSpec(_Model):
    length_m: FootprintSide
    width_m: FootprintSide
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
    id: Annotated[str, Field(min_length=1, max_length=MAX_ID_LENGTH, pattern=r"^[A-Za-z0-9_.\-]+$")]
    pose: PoseDeg
    priority: NonNegFloat = 1.0
    footprint: FootprintSpec | None = None
    max_speed_mps: PositiveFloat | None = None
    max_accel_mps2: PositiveFloat | None = None
    max_yaw_rate_radps: PositiveFloat | None = None
    max_yaw_accel_radps2: PositiveFloat | None = None

    _finite_pose = field_validator("pose")(classmethod(lambda cls, v: _pose(v)))


#: Walls of a ``size_m`` map, all polygons together: at most this many vertices.
MAX_WALL_VERTICES = 20 * MAX_POLYGON_VERTICES


class MapSpec(_Model):
    yaml: str | None = None
    size_m: (
        Annotated[
            list[Annotated[float, Field(gt=0, le=MAX_COORDINATE_M, allow_inf_nan=False)]],
            Field(min_length=2, max_length=2),
        ]
        | None
    ) = None
    resolution_m: Annotated[float, Field(ge=MIN_RESOLUTION_M, le=100.0, allow_inf_nan=False)] = 0.05
    walls: Annotated[list[Polygon], Field(max_length=MAX_POLYGON_VERTICES)] = []

    @model_validator(mode="after")
    def _one_form(self) -> MapSpec:
        if (self.yaml is None) == (self.size_m is None):
            raise ValueError("give either 'yaml' (a map_server file) or 'size_m' (+ walls)")
        if self.yaml is not None and self.walls:
            raise ValueError("'walls' go with 'size_m', not with a map_server 'yaml'")
        if self.size_m is not None:
            # Refuse a grid over the cell budget before anything is allocated.
            shape = tuple(int(round(s / self.resolution_m)) for s in self.size_m[::-1])
            check_grid_cells(shape, f"size_m {self.size_m} at resolution_m {self.resolution_m}")
        n = sum(len(w) for w in self.walls)
        if n > MAX_WALL_VERTICES:
            raise ValueError(f"walls have {n} vertices in all, more than {MAX_WALL_VERTICES}")
        return self


class StaticObstacleSpec(_Model):
    polygon: Polygon


class PersonSpec(_Model):
    id: Annotated[str, Field(max_length=MAX_ID_LENGTH)] | None = None
    radius_m: PositiveFloat = 0.3
    waypoints: Annotated[list[Point], Field(min_length=2, max_length=MAX_POLYGON_VERTICES)]
    speed_mps: PositiveFloat = 1.2
    start_s: NonNegFloat = 0.0
    loop: bool = False
    #: Seconds the person stands at each waypoint before walking on (one per waypoint).
    waits_s: list[NonNegFloat] | None = None
    #: The person stops short of a skid in their way and walks on once it has left (as people
    #: do); false keeps them walking their route into whatever stands there (adversarial tests).
    reacts: bool = True

    @model_validator(mode="after")
    def _one_wait_per_waypoint(self) -> PersonSpec:
        if self.waits_s is not None and len(self.waits_s) != len(self.waypoints):
            raise ValueError(
                f"waits_s: need one wait per waypoint ({len(self.waypoints)}), "
                f"got {len(self.waits_s)}"
            )
        return self


class ParkCmd(_Model):
    robots: RobotList
    boundary: Boundary
    heading_deg: HeadingDeg | Literal["auto"] = 0.0
    method: Annotated[str, _METHODS.as_field()] = "stacking"
    margin_m: NonNegFloat = 0.3
    assignment: Annotated[str, _COSTS.as_field()] = "formation"


class GotoCmd(_Model):
    robot: RobotRef
    pose: PoseDeg
    priority: NonNegFloat | None = None

    _finite_pose = field_validator("pose")(classmethod(lambda cls, v: _pose(v)))


class FormationCmd(_Model):
    """Move a group along given paths holding a formation (Liu, Sun, Zhu 2010).

    ``paths`` has one list of waypoints per robot, or only the leader's, in which case each
    follower's path is the leader's carried at its offset (a robot's position is put in front
    of its waypoints when the first waypoint is not it). ``offsets_m`` gives, for every follower, its desired
    position in the leader's frame (x forward, y left), either one ``[dx, dy]`` or one per
    keypoint in ``offset_at`` (fractions of the leader's path); by default the group holds the
    shape it starts in. The leader is the first robot.
    """

    robots: Annotated[list[RobotRef], Field(min_length=2, max_length=MAX_ROBOTS_PER_COMMAND)]
    paths: Annotated[
        list[Annotated[list[Point], Field(min_length=2, max_length=MAX_POLYGON_VERTICES)]],
        Field(max_length=MAX_ROBOTS_PER_COMMAND),
    ]
    method: Literal["formation", "no_formation", "leader_follower"] = "formation"
    offsets_m: list[list[Coord]] | list[list[list[Coord]]] | None = None
    offset_at: list[Annotated[float, Field(allow_inf_nan=False)]] | None = None
    dt_s: PositiveFloat = 1.0
    steps: Annotated[int, Field(ge=2, le=400)] | None = None
    d_safe_m: PositiveFloat | None = None


class CommandSpec(_Model):
    at_s: NonNegFloat = 0.0
    park: ParkCmd | None = None
    goto: GotoCmd | None = None
    formation: FormationCmd | None = None
    stop: RobotList | Literal["all"] | None = None
    estop: Literal[True] | None = None
    resume: RobotList | Literal["all"] | None = None

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
    #: Bound on time_to_park_s / lower_bound_s: a regression guard set a little above what
    #: the scenario achieves, so a slower park fails its test.
    max_time_ratio: Annotated[float, Field(ge=1.0)] | None = None
    #: With ``sensing.localization: amcl``: bound on the run's mean localization error.
    max_mean_localization_error_m: PositiveFloat | None = None
    #: With kidnappings: every kidnapped skid is found again within this many seconds.
    max_recovery_s: PositiveFloat | None = None


class NavigationSpec(_Model):
    """Navigation options: ``mode`` is ``planner`` (plan a path, follow it with the potential
    field, the default) or ``pure-pf`` (the 2015 paper's potential field straight to the goal,
    no planner: the baseline with local minima); ``avoidance`` between skids is ``monitor``
    (collision monitor with right of way at bottlenecks, the default) or ``rvo`` (ORCA with
    priorities, ``planner`` mode only)."""

    mode: Annotated[str, NAVIGATION_MODES.as_field()] = "planner"
    avoidance: Annotated[str, AVOIDANCE_MODES.as_field()] = "monitor"

    @model_validator(mode="after")
    def _avoidance_of_mode(self) -> NavigationSpec:
        if self.mode == "pure-pf" and self.avoidance != "monitor":
            raise ValueError(
                f"avoidance {self.avoidance!r} needs mode 'planner' (pure-pf: skids repel "
                "each other in the field, with the collision monitor as the safety layer)"
            )
        return self


class KidnapSpec(_Model):
    """At ``at_s`` a skid is carried (by hand, without its odometry noticing) to ``pose``
    (x, y, heading in degrees); its filter must find it again."""

    robot: RobotRef
    at_s: NonNegFloat
    pose: PoseDeg

    _finite_pose = field_validator("pose")(classmethod(lambda cls, v: _pose(v)))


class SensingSpec(_Model):
    """Onboard sensing. ``localization: amcl`` makes every skid localize with its own LIDAR
    and drifting odometry (particle filter against the map); control then uses the estimates
    and the run result reports the localization error. ``truth`` uses the true poses.
    ``recovery`` turns on augmented MCL (injected particles when the scans stop fitting,
    which finds a kidnapped skid); ``kidnap`` moves skids during the run to test it.
    ``cooperative`` (the default) makes each skid's filter use the neighbours it sees in its
    scan as landmarks at their estimates (cooperative localization,
    :mod:`swarmpark.sense.amcl.coop`); ``false`` only masks their returns."""

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
    cooperative: bool = True
    #: With ``localization: amcl``, each metre of path out of sight of every wall costs this
    #: many metres more (coastal navigation; 0: shortest paths).
    coastal_weight: NonNegFloat = 0.5
    kidnap: list[KidnapSpec] = []


class FaultSpec(_Model):
    """A fault injected on the simulator's link to one robot (not in the robot itself), from
    ``from_s`` to ``to_s``: ``drop`` loses every message to and from it, ``delay_s`` delivers
    them that late (so they may arrive out of order), ``noise_m`` / ``noise_deg`` add Gaussian
    noise (standard deviations) to the poses it reports. The e-stop is not affected."""

    robot: RobotRef
    from_s: NonNegFloat
    to_s: PositiveFloat
    drop: bool = False
    delay_s: NonNegFloat = 0.0
    noise_m: NonNegFloat = 0.0
    noise_deg: NonNegFloat = 0.0

    @model_validator(mode="after")
    def _window_and_effect(self) -> FaultSpec:
        if self.to_s <= self.from_s:
            raise ValueError(f"to_s must be after from_s {self.from_s} (got {self.to_s})")
        if not (self.drop or self.delay_s > 0 or self.noise_m > 0 or self.noise_deg > 0):
            raise ValueError("a fault needs drop, delay_s, noise_m or noise_deg")
        return self


class PerturbSpec(_Model):
    """Perturbations of the start, drawn from the scenario's ``seed`` (for sweeps: the same
    site from slightly different starts). Each start moves uniformly within ``start_m`` in x
    and y and ``start_deg`` in heading, redrawn (up to :data:`PERTURB_TRIES` times) while it
    would start in a wall or on another skid; ``shuffle`` lists the robots in a random order
    (which must not change the outcome: robots are ordered by id, see world.build).
    ``draw`` picks another draw of the start moves for the same seed: a generated site is
    made from the seed, so sweeps run one site from several starts with ``draw: [1, 2, 3]``
    (0: the seed's own draw)."""

    start_m: Annotated[float, Field(ge=0, le=2.0)] = 0.0
    start_deg: Annotated[float, Field(ge=0, le=180.0)] = 0.0
    shuffle: bool = False
    draw: Annotated[int, Field(ge=0, le=1_000_000)] = 0


class Scenario(_Model):
    name: str
    #: Drives everything random in a run: the sensor noise and odometry drift of onboard
    #: sensing (``sensing``) and the start perturbations (``perturb``). Without either, the
    #: run is the same for every seed.
    seed: int = 0
    dt_s: Annotated[float, Field(ge=MIN_DT_S, le=0.5, allow_inf_nan=False)] = 0.05
    duration_s: Annotated[float, Field(gt=0, le=MAX_DURATION_S, allow_inf_nan=False)] = 180.0
    map: MapSpec
    robot_defaults: RobotDefaults = RobotDefaults()
    robots: Annotated[list[RobotSpec], Field(min_length=1, max_length=MAX_ROBOTS)]
    obstacles: Annotated[
        list[StaticObstacleSpec | PersonSpec], Field(max_length=MAX_POLYGON_VERTICES)
    ] = []
    commands: Annotated[list[CommandSpec], Field(max_length=10_000)] = []
    navigation: NavigationSpec = NavigationSpec()
    sensing: SensingSpec = SensingSpec()
    #: Faults injected on the simulator's robot link (drops, delays, noise).
    faults: list[FaultSpec] = []
    perturb: PerturbSpec = PerturbSpec()
    expect: ExpectSpec = ExpectSpec()

    @model_validator(mode="after")
    def _run_ends(self) -> Scenario:
        ticks = self.duration_s / self.dt_s
        if ticks > MAX_TICKS:
            raise ValueError(
                f"duration_s {self.duration_s} at dt_s {self.dt_s} is {ticks:.3g} ticks, "
                f"more than {MAX_TICKS}"
            )
        return self


# ----------------------------------------------------------------------------- loading


def _loc(loc: tuple[Any, ...]) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        elif _is_branch(part):
            continue  # union branch names add nothing for the reader
        else:
            out += ("." if out else "") + str(part)
    return out or "scenario"


#: Keys a new user may well write for something the schema has under another name.
_PEOPLE_HINT = "people walk as `obstacles` entries with `waypoints`"
_KEY_HINTS = {
    "people": _PEOPLE_HINT,
    "persons": _PEOPLE_HINT,
    "humans": _PEOPLE_HINT,
    "walls": "walls belong under `map`",
    "footprint": "give it per robot or under `robot_defaults`",
    "goals": "goals come from `commands` (`park`, `goto`)",
}


def _models_in(annotation: Any) -> list[type[BaseModel]]:
    """The pydantic models an annotation can hold (through lists, unions and Annotated)."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return [annotation]
    return [m for arg in typing.get_args(annotation) for m in _models_in(arg)]


def _keys_at(loc: tuple[Any, ...]) -> list[str]:
    """The keys the schema allows beside the unknown key at ``loc`` (empty if unresolved)."""
    models: list[type[BaseModel]] = [Scenario]
    for part in loc[:-1]:
        if isinstance(part, int):
            continue
        if _is_branch(part):  # a union's branch: its name, or its validator's that ends in it
            models = [m for m in models if str(part).rstrip("]").endswith(m.__name__)]
            continue
        models = [
            sub
            for m in models
            if part in m.model_fields
            for sub in _models_in(m.model_fields[part].annotation)
        ]
        if not models:
            return []
    return sorted({k for m in models for k in m.model_fields})


def _unknown_key_hint(loc: tuple[Any, ...]) -> str:
    """What the user may have meant by the unknown key at ``loc``."""
    key = str(loc[-1]) if loc else ""
    if key in _KEY_HINTS:
        return f"; {_KEY_HINTS[key]}"
    close = difflib.get_close_matches(key, _keys_at(loc), n=1, cutoff=0.6)
    return f"; did you mean {close[0]!r}?" if close else ""


def _is_branch(part: Any) -> bool:
    """Whether a location part names a union's branch (a static obstacle or a person)."""
    return isinstance(part, str) and (part in ("StaticObstacleSpec", "PersonSpec") or "[" in part)


def _closest_branch(errs: list[Any]) -> list[Any]:
    """The errors of a union's branch with the fewest (the one the user meant), per union."""
    by_union: dict[tuple[Any, ...], dict[Any, list[Any]]] = {}
    plain = []
    for e in errs:
        cut = next((i for i, part in enumerate(e["loc"]) if _is_branch(part)), None)
        if cut is None:
            plain.append(e)
        else:
            by_union.setdefault(e["loc"][:cut], {}).setdefault(e["loc"][cut], []).append(e)
    return plain + [e for b in by_union.values() for e in min(b.values(), key=len)]


def _format_validation(exc: ValidationError) -> str:
    errs = _closest_branch(exc.errors())
    # Of the rest, a missing or wrong value reads better than an unknown key beside it.
    err = min(errs, key=lambda e: (e["type"] == "extra_forbidden" and len(errs) > 1, len(e["loc"])))
    field = _loc(err["loc"])
    if err["type"] == "extra_forbidden":
        shown = repr(err["input"])
        shown = shown if len(shown) <= 120 else shown[:117] + "..."
        return f"{field}: unknown key (value {shown}){_unknown_key_hint(err['loc'])}"
    msg = err["msg"].removeprefix("Value error, ")
    value = err.get("input")
    shown = repr(value) if not isinstance(value, dict) else "{" + ", ".join(map(str, value)) + "}"
    if len(shown) > 120:  # one readable line, whatever the file holds
        shown = shown[:117] + "..."
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
    size = path.stat().st_size
    if size > MAX_SCENARIO_BYTES:
        raise ScenarioError(
            f"scenario: {str(path)!r} is {size} bytes, more than {MAX_SCENARIO_BYTES}"
        )
    try:
        data = yaml.load(path.read_bytes().decode("utf-8"), Loader=_SafeLoader)
    except UnicodeDecodeError as exc:
        raise ScenarioError(f"scenario: {str(path)!r} is not UTF-8 text ({exc})") from None
    except yaml.YAMLError as exc:
        where = " ".join(str(exc).split())  # one line
        raise ScenarioError(f"scenario: {str(path)!r} is not valid YAML: {where}") from None
    except RecursionError:
        raise ScenarioError(f"scenario: {str(path)!r} is nested too deeply") from None
    try:
        return parse_scenario(data, path.parent)
    except RecursionError:
        raise ScenarioError(f"scenario: {str(path)!r} is nested too deeply") from None


# The world built from a scenario lives in world/build.py; its names stay importable from here.
from swarmpark.world.build import Person, RobotConfig, World, build_world  # noqa: E402
