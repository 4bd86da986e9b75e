"""Parameters of the navigation components: one frozen, validated object per component.

Every field carries its unit in its name and a comment saying why it has its value; bad values
raise :class:`ValueError` naming the field and the value (as :class:`~swarmpark.control.orca.
kernel.OrcaParams` does). :class:`NavParams` composes them and stays the one entry point of the
supervisor and the scenarios (``NavParams(avoidance="rvo")``).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields

import numpy as np

from swarmpark.control.modes import AVOIDANCE_MODES
from swarmpark.core.progress import NAV_HEADING_LEVER_M

__all__ = [
    "AVOIDANCE_MODES",
    "AvoidanceParams",
    "BackUpParams",
    "DeadlockParams",
    "DockingParams",
    "FieldParams",
    "FleetMapParams",
    "FollowerParams",
    "GiveWayParams",
    "HoldParams",
    "KeepRightParams",
    "MakeRoomParams",
    "ManoeuvreParams",
    "MonitorParams",
    "NavParams",
    "PeopleParams",
    "PlannerParams",
    "StallParams",
    "TrafficParams",
]


def _is_number(v) -> bool:
    return isinstance(v, int | float | np.integer | np.floating) and not isinstance(v, bool)


#: Validation rules of :func:`_check`: (test, what the message says the value must be).
_RULES = {
    ">0": (lambda v: _is_number(v) and np.isfinite(v) and v > 0, "a finite number > 0"),
    ">=0": (lambda v: _is_number(v) and np.isfinite(v) and v >= 0, "a finite number >= 0"),
    "int>0": (lambda v: isinstance(v, int | np.integer) and v > 0, "an integer > 0"),
    "share": (lambda v: _is_number(v) and 0 <= v <= 1, "a number in [0, 1]"),
    "half share": (lambda v: _is_number(v) and 0 <= v <= 0.5, "in [0, 0.5]"),
    "tuple>0": (
        lambda v: isinstance(v, tuple) and len(v) > 0 and all(_RULES[">0"][0](x) for x in v),
        "a non-empty tuple of finite numbers > 0",
    ),
    "tuple>=0": (
        lambda v: isinstance(v, tuple) and len(v) > 0 and all(_RULES[">=0"][0](x) for x in v),
        "a non-empty tuple of finite numbers >= 0",
    ),
}


def _check(obj, rules: dict[str, str]) -> None:
    """Validate ``obj``'s fields by the rules of :data:`_RULES` (ValueError names the field)."""
    cls = type(obj).__name__
    for name, rule in rules.items():
        value = getattr(obj, name)
        test, what = _RULES[rule]
        if not test(value):
            raise ValueError(f"{cls}.{name} must be {what} (got {value!r})")


def _order(obj, small: str, large: str) -> None:
    a, b = getattr(obj, small), getattr(obj, large)
    if not a < b:
        cls = type(obj).__name__
        raise ValueError(f"{cls}.{small} must be below {cls}.{large} (got {a!r} >= {b!r})")


@dataclass(frozen=True, kw_only=True)
class FollowerParams:
    """Path following (:mod:`.follower`)."""

    #: Lookahead along the path of the field's temporary goal (about two skid lengths).
    lookahead_m: float = 1.2
    #: Within this arc length of the path's end the field attracts the goal pose itself.
    approach_m: float = 2.0
    #: Switch driving end only if the other end's arc is shorter by this factor (hysteresis).
    switch_ratio: float = 0.75
    #: A fresh path is driven in reverse when the skid faces more than this away from its
    #: first stretch (below it turning in place to drive forwards is cheaper).
    face_away_rad: float = float(np.deg2rad(120.0))
    #: A path that turns onto the goal's axis at its staging point by more than this is
    #: driven to the staging point first (its final approach starts within
    #: ``stage_reach_m`` of it), braking there at ``stage_brake_share`` of the acceleration
    #: limit; a gentler corner is left to the docking law from ``approach_m`` out.
    stage_corner_rad: float = float(np.deg2rad(45.0))
    stage_reach_m: float = 0.25
    stage_brake_share: float = 0.5

    def __post_init__(self) -> None:
        _check(self, {"lookahead_m": ">0", "approach_m": ">0", "switch_ratio": "share"})
        _check(self, {"stage_corner_rad": ">=0", "stage_reach_m": ">=0"})
        _check(self, {"stage_brake_share": "share"})
        if not (_is_number(self.face_away_rad) and 0 <= self.face_away_rad <= np.pi):
            raise ValueError(
                f"FollowerParams.face_away_rad must be in [0, pi] (got {self.face_away_rad!r})"
            )


@dataclass(frozen=True, kw_only=True)
class PlannerParams:
    """Path planning (:mod:`.planner`)."""

    #: A failed plan is tried again this often (the way may have cleared).
    replan_period_s: float = 3.0
    #: At most this many paths are planned in one tick (a park command for a hundred skids
    #: must not stall the loop).
    max_plans_per_tick: int = 8
    #: And no more plans in a tick once their searches have expanded this many grid cells
    #: (the first plan of a tick always runs): a plan's work depends on the map and the way,
    #: so a park command for hundreds of skids on a large map must not stall the loop either
    #: (about 25 ms of search on one core; a suite plan expands a few thousand cells).
    max_plan_cells_per_tick: int = 150_000
    #: Paths are searched on the map coarsened to this resolution (conservatively); None
    #: searches at the map's own resolution. Coarser plans are faster (see the nav.plan
    #: benchmark) but narrow the passages by up to a cell, which costs time in tight spaces.
    plan_resolution_m: float | None = None
    #: Points checked along the straight run from a staging point to the goal (0.1 m apart
    #: at the default run-up).
    staging_check_points: int = 10
    #: Coastal navigation (:func:`~swarmpark.plan.grid.build_costmap`), for skids that
    #: localize with their LIDAR: cells farther than this from every wall are blind (None:
    #: no cell is). The supervisor sets it from the scenario's ``sensing``.
    seen_within_m: float | None = None
    #: Extra cost per metre through blind cells (0: paths ignore them).
    blind_weight: float = 0.0
    #: In the doors (the bottleneck zones of :mod:`.traffic` whose throat is at most
    #: ``door_throat_skids`` of the fleet's longest skid long) the costmap's inflation band
    #: reaches this much farther than the skid's circumscribed radius, so a path through a
    #: door keeps to its middle instead of grazing a jamb, where the walls' push on both
    #: ends of the skid cancels its turn and it crawls (0: as elsewhere).
    zone_band_m: float = 0.5
    #: A zone is a door, not a narrow corridor, when its throat is at most this many of the
    #: longest skid's lengths long (generated doors: 1.4-1.6 m; corridors: 6-14 m).
    door_throat_skids: float = 2.0

    def __post_init__(self) -> None:
        _check(self, {"replan_period_s": ">0", "max_plans_per_tick": "int>0"})
        _check(self, {"max_plan_cells_per_tick": "int>0"})
        _check(self, {"staging_check_points": "int>0", "blind_weight": ">=0"})
        _check(self, {"zone_band_m": ">=0", "door_throat_skids": ">=0"})
        if self.plan_resolution_m is not None:
            _check(self, {"plan_resolution_m": ">0"})
        if self.seen_within_m is not None:
            _check(self, {"seen_within_m": ">0"})


@dataclass(frozen=True, kw_only=True)
class FleetMapParams:
    """The fleet layers of each plan and the plan repairs (:mod:`.fleetmap`)."""

    #: Off: plans on the static map alone, no repairs (the behaviour before the fleet layers).
    enabled: bool = True

    #: Extra cost per metre inside another skid's goal spot while that skid is on its way
    #: (a path crossing a 1.2 m spot costs as much as this many times 1.2 m more of floor).
    #: Off by default: at 6 the repaired paths went round whole bays to keep off spots still
    #: empty when the skid passed (the suite's hangar-bay-12 no longer parked; a generated
    #: hangar took 76 s instead of 34 s).
    spot_cost: float = 0.0
    #: Cost band around a parked skid (beyond the lethal part): width and extra cost per metre.
    band_m: float = 0.3
    band_cost: float = 2.0
    #: A skid that has not shortened its remaining path by ``stuck_progress_m`` for this long
    #: is planned again, with the skids standing still around it as obstacles (tuned on the
    #: suite and generated training sites: 6 s made the suite's elevator slower, 74.7 -> 85 s).
    stuck_s: float = 10.0
    stuck_progress_m: float = 0.3
    #: A skid held still this long (its stall watch) counts as standing still for a repair.
    still_s: float = 2.0

    def __post_init__(self) -> None:
        _check(self, {"spot_cost": ">=0", "band_m": ">=0", "band_cost": ">=0"})
        _check(self, {"stuck_s": ">0", "stuck_progress_m": ">0", "still_s": ">=0"})


@dataclass(frozen=True, kw_only=True)
class ManoeuvreParams:
    """Manoeuvres for a stuck skid's rectangle (:mod:`.manoeuvre`, :mod:`swarmpark.plan.lattice`)."""

    #: Off: no manoeuvres (they are used with the monitor avoidance only: with RVO the
    #: deadlock ladder recovers).
    enabled: bool = True

    #: A skid whose remaining distance to its goal (position plus heading at the navigation
    #: lever) has not fallen by ``progress_m`` for ``stuck_s`` plans a manoeuvre (after a
    #: plan repair has had its chance; 8 s made the suite's elevator slower, 74.7 -> 100 s).
    stuck_s: float = 12.0
    progress_m: float = 0.15
    #: Within ``near_goal_m`` of its goal (parking, where no plan repair helps) it plans one
    #: after ``near_stuck_s`` already (training draws: 7.6 % faster on the runs parked
    #: either way, 247 deadlock episodes against 260).
    near_goal_m: float = 2.0
    near_stuck_s: float = 5.0
    #: A skid standing still that cannot turn on the spot to its path (its footprint, swept
    #: from its heading to the path's by more than ``cramped_rad``, hits the map) plans one
    #: after ``cramped_s`` without progress: the field cannot get it out, it only turned it
    #: against the wall (a new user's site: a skid nose to a wall, 5 cm off it, turned
    #: broadside to it and shuffled for 20 s before its manoeuvre). ``cramped`` off: as
    #: any other skid.
    cramped: bool = True
    cramped_s: float = 0.0
    cramped_rad: float = 0.2
    #: ... and has stayed within this distance of where it last got closer (a skid driving
    #: round an obstacle, away from its goal, is not stuck).
    roam_m: float = 1.0
    #: The planning window: the box around the skid and its goal grown by this, at most
    #: ``max_window_m`` on a side (farther goals are left to the path planner's repairs).
    window_margin_m: float = 2.5
    max_window_m: float = 14.0
    #: Where no manoeuvre is found in that window, one is searched for in a window grown by
    #: ``wide_margin_m`` before the skid counts as walled in by the parked skids (which then
    #: make room for it): a way round the back of a row, a few metres beyond the window,
    #: is a way in (a generated hangar: a skid whose spot was reached only round its
    #: column was taken for walled in, and the block that made room for it across its
    #: middle never closed again; 12 of 20 parked). At most ``window_margin_m``: off.
    wide_margin_m: float = 5.0
    #: A skid stuck farther from its goal than one window reaches plans a manoeuvre to a pose
    #: on its path instead: this far along it from where it stands (the first that is clear
    #: and reached), at the path's heading there (from its points ``via_tangent_m`` before
    #: and after).
    via_m: tuple[float, ...] = (4.0, 3.0, 5.0)
    via_tangent_m: float = 0.3
    #: The lattice's cells are the map's, split where the map is coarser than this.
    max_cell_m: float = 0.05
    #: Other skids are obstacles grown by this; people by ``person_margin_m``; the skid's own
    #: footprint is grown by ``grow_m`` (besides half a cell diagonal) for collision checks.
    skid_margin_m: float = 0.05
    person_margin_m: float = 0.3
    grow_m: float = 0.02
    #: After a manoeuvre the monitor held up (or one that overran), the next is planned with
    #: the footprint grown by these in turn (the monitor's margin plus the few cm a skid stops
    #: off a planned pose), at ``grow_m`` if none is found. Planning roomy every time made the
    #: training sites worse (17 of 28 parked against 19). The 5 cm step: a skid in an
    #: elevator's corner had room for neither 10 cm nor the monitor's margin (3 cm, 4.2 cm
    #: at a corner of the 1.2 x 0.8 m skid) once it stood 1.3 cm off the turn planned at 2 cm.
    roomy_grow_m: tuple[float, ...] = (0.10, 0.05)
    #: A wedged skid first looks for a clear pose straight behind or ahead of it, in these
    #: steps up to this far.
    escape_step_m: float = 0.15
    escape_max_m: float = 1.2
    #: Reverse moves cost this much more than forward ones; the search's expansion budget.
    reverse_cost: float = 1.5
    budget: int = 400_000
    #: When the walls alone leave no way to the goal's cell, one that ends this far from it
    #: at the goal's heading is searched for (half the parking tolerance; the docking closes
    #: it): :func:`swarmpark.plan.lattice.plan_manoeuvre`.
    goal_tol_m: float = 0.05
    #: Dropped when the monitor holds it still this long, or when a segment takes longer
    #: than ``timeout_factor`` times its time at the manoeuvre's speed plus ``timeout_s``;
    #: tried again after ``retry_s``.
    blocked_s: float = 3.0
    timeout_factor: float = 3.0
    timeout_s: float = 3.0
    retry_s: float = 4.0
    #: A manoeuvre that only goes the long way round skids on the move waits for them: where
    #: the one found takes more than ``detour_ratio`` times, and ``detour_s`` more than, the
    #: one found with the moving skids left out, the skid plans again after ``retry_s``, for
    #: at most ``detour_wait_s`` on the same goal (then it takes the long way). Found on a
    #: 10-skid elevator training site: a skid at the car's door, bound for the spot beside
    #: it, planned round a skid driving through the door's mouth and went round the whole
    #: car for 45 s, where its spot was a turn and a short reverse run away. 0: off.
    detour_ratio: float = 2.0
    detour_s: float = 10.0
    detour_wait_s: float = 20.0
    #: Tracking: share of top speed and yaw rate, gains, and when a segment is done. The
    #: speed and turn gains (1/s) stay below 1 / the monitor's horizon, so the monitor's
    #: rollout of a held command ends inside the segment, not past it at a wall. Full speed
    #: (with docking's ``max_speed_share`` 1) was 9 % faster on the training draws but left
    #: a skid of a plain 6-skid room park 0.35 m off its spot and one 32.6 s late against
    #: 16.3 s (``tests/data/ros2-open.yaml``), so half speed stays.
    speed_share: float = 0.5
    #: Each run and turn slows down as a skid braking at this share of its acceleration
    #: limit stops at its end (``sqrt(2 a d)``: the monitor's speed scales slow it where that
    #: rollout would overrun into something). The proportional law (``k_speed``, ``k_yaw``,
    #: 1/s) crept the last tenth of a metre or the last few degrees at ``min_speed_mps`` and
    #: ``min_yaw_rate_radps``: a 1.3 m manoeuvre took 10 s. 0: the proportional law.
    brake_share: float = 0.5
    k_speed: float = 0.9
    k_yaw: float = 0.9
    k_lateral: float = 3.0
    min_speed_mps: float = 0.05
    min_yaw_rate_radps: float = 0.1
    done_m: float = 0.03
    done_rad: float = float(np.deg2rad(2.0))

    def __post_init__(self) -> None:
        _check(self, {"stuck_s": ">0", "progress_m": ">0", "window_margin_m": ">0"})
        _check(self, {"near_goal_m": ">=0", "near_stuck_s": ">0"})
        _check(self, {"cramped_s": ">=0", "cramped_rad": ">0"})
        _check(self, {"roam_m": ">0", "escape_step_m": ">0", "escape_max_m": ">=0"})
        _check(self, {"max_window_m": ">0", "skid_margin_m": ">=0", "person_margin_m": ">=0"})
        _check(self, {"wide_margin_m": ">=0"})
        _check(self, {"max_cell_m": ">0", "goal_tol_m": ">=0"})
        _check(
            self,
            {"grow_m": ">=0", "roomy_grow_m": "tuple>=0", "reverse_cost": ">0", "budget": "int>0"},
        )
        _check(self, {"via_m": "tuple>0", "via_tangent_m": ">0"})
        _check(self, {"blocked_s": ">0", "retry_s": ">=0", "speed_share": "share"})
        _check(self, {"brake_share": "share"})
        _check(self, {"k_speed": ">0", "k_yaw": ">0", "k_lateral": ">0"})
        _check(self, {"min_speed_mps": ">0", "min_yaw_rate_radps": ">0", "done_m": ">0"})
        _check(self, {"done_rad": ">0", "timeout_factor": ">0", "timeout_s": ">=0"})
        _check(self, {"detour_ratio": ">=0", "detour_s": ">=0", "detour_wait_s": ">=0"})


@dataclass(frozen=True, kw_only=True)
class TrafficParams:
    """Queues at the bottlenecks (:mod:`.traffic`, :mod:`swarmpark.plan.bottlenecks`)."""

    #: Off: no zones, no queues.
    enabled: bool = True
    #: A lane is two of the widest skids side by side plus this; narrower passages are zones.
    lane_clearance_m: float = 1.2
    #: Zones reach half the longest skid plus this beyond the passage.
    pad_m: float = 0.3
    #: Bottlenecks are found on the map coarsened to this resolution.
    resolution_m: float = 0.1
    #: A skid asks for a zone its path enters within this distance.
    lookahead_m: float = 4.0
    #: Skids from the same side follow each other into a zone this long apart (0: a zone is
    #: a one-way lane; only skids coming the other way wait). Measured on the suite's
    #: elevator: 0 s 103 s, 2 s 72 s, 3 s 70 s, 4 s 86 s to park; on generated doors the
    #: results scatter (a 4-skid door parks at 2 and 4 s, not at 3 s): a jam at a door is
    #: sensitive to who arrives first.
    convoy_gap_s: float = 2.0
    #: A skid refused a zone held by skids coming the other way lets more of them follow
    #: into it (convoy_gap_s apart) for at most this long; then the way turns round. On the
    #: 14 training sites of sweeps/swap-train.yaml: 0 s (first come, first served) 1 run
    #: fully parked and 113 of 303 skids, 30 s 4 runs and 155 skids, 60 s 6 runs and 156.
    convoy_max_s: float = 60.0
    #: A skid without a grant stops this far short of the zone (its command checked this
    #: far ahead in time).
    gap_m: float = 0.3
    check_s: float = 0.5

    def __post_init__(self) -> None:
        _check(self, {"lane_clearance_m": ">=0", "pad_m": ">=0", "resolution_m": ">0"})
        _check(self, {"lookahead_m": ">0", "convoy_gap_s": ">=0", "gap_m": ">=0"})
        _check(self, {"convoy_max_s": ">=0"})
        _check(self, {"check_s": ">0"})
        if not isinstance(self.enabled, bool):
            raise ValueError(f"TrafficParams.enabled must be true or false (got {self.enabled!r})")


@dataclass(frozen=True, kw_only=True)
class FieldParams:
    """The action-point potential field (:mod:`.field`, 2015 paper Sect. 3.2)."""

    #: The goal force falls linearly inside this distance (2015 paper, extension 3) ...
    slow_radius_m: float = 1.2
    #: ... but not below this, so the skid still creeps into its spot.
    min_goal_speed_mps: float = 0.06
    #: Heading error counts toward the distance that sets the goal force at this lever.
    heading_lever_m: float = NAV_HEADING_LEVER_M
    #: Repulsion gains (force in m/s at 1 m is gain * (1 - 1/influence^3)); people twice a
    #: skid's, as they move unpredictably.
    k_static: float = 0.004
    k_robot: float = 0.004
    k_person: float = 0.008
    #: Reach of the repulsion beyond the skid's own reach.
    influence_m: float = 0.5
    #: Near its goal a skid ignores obstacles farther than this (parked neighbours sit there).
    influence_at_goal_m: float = 0.15
    #: Sampling of obstacle and skid outlines for the field (a tenth of the smallest gap).
    outline_step_m: float = 0.1
    #: Split each obstacle point's push between the front and rear action points as a lever
    #: (:func:`.apf.repulsion`); False: the paper's rule, all of it at the nearer end.
    lever_split: bool = True
    #: Slow down for a turn only as far as the skid does turn (the repulsion may hold it).
    throttle_turning: bool = False
    #: Other skids' outline points behind the pivot (as the skid drives) do not push it.
    ignore_followers: bool = True

    def __post_init__(self) -> None:
        _check(self, {"slow_radius_m": ">0", "min_goal_speed_mps": ">0", "heading_lever_m": ">=0"})
        _check(self, {"k_static": ">=0", "k_robot": ">=0", "k_person": ">=0"})
        _check(self, {"influence_m": ">0", "influence_at_goal_m": ">0", "outline_step_m": ">0"})


@dataclass(frozen=True, kw_only=True)
class DockingParams:
    """The goal-axis docking manoeuvre (:mod:`.docking`)."""

    #: Within this distance of the goal, align the heading and close the remaining
    #: distance straight along the goal heading (if the lateral error allows it).
    dock_radius_m: float = 0.3
    #: Largest lateral error that can still be closed by driving straight in.
    dock_lateral_m: float = 0.07
    #: Gain of the goal-axis tracking law (rad of aim per m of lateral error, via atan) ...
    k_lateral: float = 3.0
    #: ... farther out at most ``1 / (axis_ahead * distance left)``: the skid aims at the axis
    #: that share of the way to the goal ahead (a Stanley law with a lookahead, as pure
    #: pursuit's), so it closes the lateral error over the approach, not in the first metre.
    axis_ahead: float = 0.5
    #: Otherwise back out to this run-up distance along the goal heading and come in again;
    #: the planner also stages the path this far before the goal.
    runup_m: float = 0.9
    #: The manoeuvre takes over this close to the goal: room for a full run-up and back.
    manoeuvre_radius_m: float = 1.8
    #: A run-up ends once the lateral error is below this (half the docking tolerance) ...
    runup_done_lateral_m: float = 0.035
    #: ... or once it has backed this far while held still again.
    runup_min_back_m: float = 0.2
    #: Farther off the goal heading than this next to the goal, turn in place first (the
    #: axis law needs a rough alignment).
    align_first_rad: float = float(np.deg2rad(75.0))
    #: A docked skid holds still inside these errors and resumes beyond the outer ones.
    parked_pos_m: float = 0.03
    parked_yaw_rad: float = float(np.deg2rad(1.5))
    resume_pos_m: float = 0.09
    resume_yaw_rad: float = float(np.deg2rad(4.0))
    #: Speed per metre of longitudinal error (1/s) and yaw rate per radian of error (1/s).
    k_dock: float = 1.0
    k_dock_yaw: float = 1.5
    #: Docking speed bounds: at least the field's creep speed, at most this share of the
    #: skid's top speed (``k_dock`` slows it with the distance left: 0.3 m/s at 0.3 m).
    #: Full speed parked the training draws 3-9 % sooner but failed the suite's silent-robot
    #: and walled-in runs (see :class:`ManoeuvreParams`' ``speed_share``).
    min_speed_mps: float = 0.06
    max_speed_share: float = 0.5
    #: A skid already on the goal's axis and heading drives in at up to this share instead
    #: (a straight run on a line it holds is no precise manoeuvre): the cap rises from
    #: ``max_speed_share`` to this as the lateral error falls from ``aligned_lateral_m`` to 0
    #: and the heading error from ``aligned_yaw_rad`` to 0 (the product of the two shares).
    #: A run-up backs out at ``max_speed_share``.
    aligned_speed_share: float = 1.0
    aligned_lateral_m: float = 0.3
    aligned_yaw_rad: float = float(np.deg2rad(30.0))
    #: Closing in, the speed falls as a skid braking at this share of its acceleration limit
    #: stops on the goal (``sqrt(2 a d)``; 0: the proportional ``k_dock`` law, which took
    #: 2.3 s for the last 0.3 m at any speed).
    brake_share: float = 0.5

    def __post_init__(self) -> None:
        _check(self, {"dock_radius_m": ">0", "dock_lateral_m": ">0", "k_lateral": ">0"})
        _check(self, {"aligned_speed_share": "share", "aligned_lateral_m": ">0"})
        _check(self, {"aligned_yaw_rad": ">0", "brake_share": "share", "axis_ahead": ">=0"})
        _check(self, {"runup_m": ">0", "runup_done_lateral_m": ">0", "runup_min_back_m": ">=0"})
        _check(self, {"parked_pos_m": ">0", "parked_yaw_rad": ">0", "k_dock": ">0"})
        _check(self, {"k_dock_yaw": ">0", "min_speed_mps": ">0", "max_speed_share": "share"})
        _order(self, "parked_pos_m", "resume_pos_m")
        _order(self, "parked_yaw_rad", "resume_yaw_rad")
        _order(self, "runup_m", "manoeuvre_radius_m")
        if not (_is_number(self.align_first_rad) and 0 < self.align_first_rad < np.pi):
            raise ValueError(
                f"DockingParams.align_first_rad must be in (0, pi) (got {self.align_first_rad!r})"
            )


@dataclass(frozen=True, kw_only=True)
class MonitorParams:
    """The collision monitor (:mod:`.monitor`, as Navigation2's)."""

    #: Look this far ahead in time (a skid brakes from full speed in about that).
    horizon_s: float = 1.0
    #: Rollout samples over the horizon.
    samples: int = 5
    #: Over this first stretch of the horizon the rollout is also sampled at every control
    #: step. A corner swinging past a neighbour's comes and goes between samples 0.2 s apart:
    #: a skid backing and turning beside a standing one on a generated elevator was judged
    #: safe tick after tick, its contact 0.15 s, then 0.10 s, then 0.05 s ahead, until it
    #: touched.
    step_samples_s: float = 0.3
    #: Fractions of the commanded speed tried, fastest first; the last must be 0 (turn only).
    scales: tuple[float, ...] = (1.0, 0.6, 0.3, 0.0)
    #: Extra clearance the monitor keeps (the localization error is about 2 cm).
    margin_m: float = 0.03
    #: Skids whose pivots are farther apart than this cannot overlap now (twice the reach of
    #: a skid whose far corner is 1.5 m from its pivot; the default skid's is 0.72 m).
    neighbour_range_m: float = 3.0
    #: Check pairs of moving skids within reach of each other for contact under both their
    #: commands (:meth:`.monitor.CollisionMonitor.close_pairs`), not only pairs already
    #: within their margins.
    pairs_closing: bool = True

    def __post_init__(self) -> None:
        _check(self, {"horizon_s": ">0", "samples": "int>0", "margin_m": ">=0"})
        _check(self, {"step_samples_s": ">=0"})
        _check(self, {"neighbour_range_m": ">0"})
        s = self.scales
        numbers = isinstance(s, tuple) and all(_is_number(x) for x in s)
        if not (numbers and s and s[-1] == 0.0 and s[0] <= 1 and list(s) == sorted(s)[::-1]):
            raise ValueError(
                f"MonitorParams.scales must fall from at most 1 to 0 (got {self.scales!r})"
            )


@dataclass(frozen=True, kw_only=True)
class StallParams:
    """When a skid counts as held still (:class:`.recovery.StallWatch`)."""

    #: Held still this long (by the monitor or the field), a recovery starts.
    time_s: float = 2.0
    #: Below these commands a skid counts as still.
    speed_mps: float = 0.02
    yaw_rate_radps: float = 0.05

    def __post_init__(self) -> None:
        _check(self, {"time_s": ">0", "speed_mps": ">0", "yaw_rate_radps": ">0"})


@dataclass(frozen=True, kw_only=True)
class BackUpParams:
    """Backing up straight along the axis (Navigation2's back-up; RVO's back-out)."""

    #: Distance backed up (half a skid length: enough to free a corner).
    distance_m: float = 0.5
    #: Speed as a share of the skid's top speed (it drives blind over its rear).
    speed_share: float = 0.5

    def __post_init__(self) -> None:
        _check(self, {"distance_m": ">0", "speed_share": "share"})


@dataclass(frozen=True, kw_only=True)
class GiveWayParams:
    """Right of way at bottlenecks without RVO (:class:`.recovery.GiveWay`)."""

    #: Held up this long by a skid of higher rank, a skid backs away from it ...
    after_s: float = 1.0
    #: ... for at most this long ...
    duration_s: float = 3.0
    #: ... or until this far (centre to centre) from it,
    clear_m: float = 2.5
    #: at this share of its top speed.
    speed_share: float = 0.5
    #: Skids this close to their goal (two docking radii) are docking: they never give way.
    exempt_within_m: float = 0.6
    #: Held up this long by skids of lower rank, which have had ``after_s`` plus
    #: ``duration_s`` twice over to clear and have not, a skid gives way to them too.
    inherit_after_s: float = 8.0

    def __post_init__(self) -> None:
        _check(self, {"after_s": ">=0", "duration_s": ">0", "clear_m": ">0"})
        _check(self, {"speed_share": "share", "exempt_within_m": ">=0"})
        _check(self, {"inherit_after_s": ">0"})


@dataclass(frozen=True, kw_only=True)
class DeadlockParams:
    """The RVO deadlock recovery ladder (:class:`.recovery.DeadlockLadder`)."""

    #: Progress means coming this much closer (remaining distance, see core.progress) ...
    progress_m: float = 0.1
    #: ... within this long; otherwise the skid is stuck and its priority is bumped.
    stuck_s: float = 3.0
    #: The bump: this, plus up to as much again the nearer the goal (nearest goes first).
    bump: float = 2.0
    #: Each further ``stuck_s`` the skid side-steps for this long (0: never) ...
    sidestep_s: float = 2.0
    #: ... its preferred velocity turned this much to the right of its path.
    sidestep_rad: float = float(np.pi / 2)
    #: Heading lever of the remaining distance (core.progress.NAV_HEADING_LEVER_M).
    heading_lever_m: float = NAV_HEADING_LEVER_M

    def __post_init__(self) -> None:
        _check(self, {"progress_m": ">0", "stuck_s": ">0", "bump": ">=0"})
        _check(self, {"sidestep_s": ">=0", "sidestep_rad": ">=0", "heading_lever_m": ">=0"})


@dataclass(frozen=True, kw_only=True)
class MakeRoomParams:
    """Making room (:mod:`.make_room`): with RVO for every mover, in monitor mode for a skid of
    higher priority, a walled-in one or a walking person."""

    #: A parked skid in the corridor another skid will sweep (its path from its rear to this
    #: far ahead) or a walking person will cross (this far along their velocity) moves aside.
    lookahead_m: float = 4.0
    #: The corridor is the passing skid's half-width plus this to either side.
    clearance_m: float = 0.3
    #: Speed (m/s) per metre still to go while making room ...
    gain_per_s: float = 1.5
    #: ... and the ORCA priority meanwhile (above the parked priority, so it pushes
    #: still-parked neighbours on along their axes).
    priority: float = 0.5
    #: Candidate moves along the axis: steps of this up to this far either way.
    shift_step_m: float = 0.05
    shift_max_m: float = 2.0
    #: Aim this much past the first free shift (the speed does not vanish on arrival).
    overshoot_m: float = 0.05
    #: Monitor mode: a skid walled in by parked skids (its manoeuvre search found no way
    #: round the skids standing, but one with the settled skids left out) ranks above every
    #: other skid until it docks, so the parked neighbours in its way make room (priority
    #: inheritance).
    for_walled: bool = True
    #: Monitor mode: a skid waiting on purpose (held back by the fill order, queued at a
    #: bottleneck) in the way of a skid on the move drives along its axis out of it
    #: (:meth:`.make_room.MakeRoom.step_waiting`).
    for_waiting: bool = True

    def __post_init__(self) -> None:
        _check(self, {"lookahead_m": ">0", "clearance_m": ">=0", "gain_per_s": ">0"})
        _check(self, {"priority": ">=0", "shift_step_m": ">0", "overshoot_m": ">=0"})
        _order(self, "shift_step_m", "shift_max_m")


@dataclass(frozen=True, kw_only=True)
class AvoidanceParams:
    """The ORCA adapter (:mod:`.avoidance`)."""

    #: Priority of skids holding still on their goal or with no goal: they yield.
    parked_priority: float = 0.0
    #: Every skid keeps at least this share of the avoidance (a boxed-in skid cannot yield).
    min_share: float = 0.1
    #: A skid on its path aims its effective centre this far ahead on the path (long, so
    #: that a sidestep does not turn into a pull back onto the path).
    lookahead_m: float = 3.0
    #: Keep right: a skid on its path with another skid on the move coming the other way
    #: within ``keep_right_range_m`` turns its preferred velocity this much clockwise (times
    #: twice its ORCA share), so crossings resolve as a roundabout instead of stalling in
    #: symmetric jams (RVO2's examples break the symmetry with noise) ...
    keep_right_rad: float = 1.0
    keep_right_max_rad: float = float(np.pi / 2)
    keep_right_range_m: float = 4.0
    #: ... fully with static solids at least ``keep_right_open_m`` away, fading out to none
    #: at ``keep_right_tight_m`` (in a door both keeping right wedge on the jambs).
    keep_right_open_m: float = 2.5
    keep_right_tight_m: float = 1.0
    #: Extra margin around skids on the move (their turns lag the command).
    margin_m: float = 0.1
    #: Horizon of the velocity obstacles between skids: avoid this early.
    horizon_s: float = 5.0

    def __post_init__(self) -> None:
        _check(self, {"parked_priority": ">=0", "lookahead_m": ">0", "keep_right_rad": ">=0"})
        _check(self, {"keep_right_max_rad": ">=0", "keep_right_range_m": ">0"})
        _check(self, {"margin_m": ">=0", "horizon_s": ">0", "min_share": "half share"})
        _order(self, "keep_right_tight_m", "keep_right_open_m")


@dataclass(frozen=True, kw_only=True)
class KeepRightParams:
    """Keep right in the monitor mode (:class:`.keep_right.KeepRight`): a skid following its
    path with another skid on the move coming the other way within ``range_m`` ahead turns
    its lookahead point ``rad`` clockwise about itself (times twice its share, the lower
    priority the larger, at most ``max_rad``), fading out from static solids ``open_m`` away
    to none at ``tight_m``. Within ``near_goal_m`` of its goal a skid is parking, not
    travelling: it neither turns nor counts as oncoming traffic (in a block, neighbours backing
    and running up towards their spots would turn each other off their lines). The RVO mode
    turns its preferred velocity with :class:`AvoidanceParams`' ``keep_right_*``."""

    enabled: bool = True
    rad: float = 1.0
    max_rad: float = float(np.pi / 2)
    range_m: float = 4.0
    open_m: float = 2.5
    tight_m: float = 1.0
    min_share: float = 0.1
    near_goal_m: float = 2.0

    def __post_init__(self) -> None:
        _check(self, {"rad": ">=0", "max_rad": ">=0", "range_m": ">0", "near_goal_m": ">=0"})
        _check(self, {"min_share": "half share"})
        _order(self, "tight_m", "open_m")


@dataclass(frozen=True, kw_only=True)
class HoldParams:
    """Fill order: skids held back wait outside their parking boundary."""

    #: Held skids stop this far outside the boundary (room for the others to pass).
    gap_m: float = 1.0
    #: Their command is checked this far ahead in time.
    lookahead_s: float = 0.5
    #: A skid held outside that the monitor or the field has kept still this long on its way
    #: to its stop waits where it stands (it is queued behind the skids held before it);
    #: below the back-up's ``stall.time_s``, which would start first.
    stuck_s: float = 1.0

    def __post_init__(self) -> None:
        _check(self, {"gap_m": ">=0", "lookahead_s": ">0", "stuck_s": ">0"})


@dataclass(frozen=True, kw_only=True)
class PeopleParams:
    """Right of way for people (:mod:`.people`): skids keep out of a person's predicted walk,
    and in monitor mode parked skids in a walking person's way make room (:mod:`.make_room`)."""

    #: Off: people are left to the field and the monitor alone (the behaviour before), and
    #: parked skids make room for them only with RVO.
    enabled: bool = True
    #: A person's walk is predicted this far ahead at constant velocity (a skid needs about
    #: 2 s to back its own length out of the way; 3 s leaves room for the tracker's lag).
    horizon_s: float = 3.0
    #: Skids on the move keep this far from the predicted walk (the tracker's error plus a
    #: margin) ...
    clearance_m: float = 0.3
    #: ... but a skid standing (parked, or waiting) steps aside only when the person would
    #: pass closer than this: stepping aside means docking again.
    aside_clearance_m: float = 0.05
    #: People slower than this stand: they may set off any way, so skids keep an extra
    #: ``standing_berth_m`` from them (the tracker's velocity noise is about 0.1 m/s).
    walking_mps: float = 0.3
    standing_berth_m: float = 0.5
    #: A skid's command is simulated this far ahead and slowed or stopped before it takes
    #: the skid deeper into a person's way.
    rollout_s: float = 1.0
    rollout_samples: int = 5
    #: Predicted walks are sampled at this spacing (a fraction of a person's radius).
    sample_step_m: float = 0.1
    #: A skid standing in a walk moves along its axis to the nearest free place: steps of
    #: ``shift_step_m`` up to ``shift_max_m`` either way, at ``gain_per_s`` per metre to go,
    #: aiming ``overshoot_m`` past the first free shift.
    shift_step_m: float = 0.1
    shift_max_m: float = 3.0
    gain_per_s: float = 2.0
    overshoot_m: float = 0.1

    def __post_init__(self) -> None:
        if not isinstance(self.enabled, bool):
            raise ValueError(f"PeopleParams.enabled must be true or false (got {self.enabled!r})")
        _check(self, {"horizon_s": ">0", "clearance_m": ">=0", "walking_mps": ">0"})
        _check(self, {"standing_berth_m": ">=0", "rollout_s": ">0", "rollout_samples": "int>0"})
        _check(self, {"sample_step_m": ">0", "shift_step_m": ">0", "gain_per_s": ">0"})
        _check(self, {"overshoot_m": ">=0", "aside_clearance_m": ">=0"})
        _order(self, "shift_step_m", "shift_max_m")
        if not self.aside_clearance_m <= self.clearance_m:
            raise ValueError(
                "PeopleParams.aside_clearance_m must be at most clearance_m "
                f"(got {self.aside_clearance_m!r} > {self.clearance_m!r})"
            )


@dataclass(frozen=True, kw_only=True)
class NavParams:
    """Tuning of the whole navigation stack: the avoidance mode and one object per component."""

    #: Skid-skid avoidance, one of :data:`AVOIDANCE_MODES`.
    avoidance: str = "monitor"
    follower: FollowerParams = field(default_factory=FollowerParams)
    planner: PlannerParams = field(default_factory=PlannerParams)
    fleet_map: FleetMapParams = field(default_factory=FleetMapParams)
    manoeuvre: ManoeuvreParams = field(default_factory=ManoeuvreParams)
    traffic: TrafficParams = field(default_factory=TrafficParams)
    apf: FieldParams = field(default_factory=FieldParams)
    docking: DockingParams = field(default_factory=DockingParams)
    monitor: MonitorParams = field(default_factory=MonitorParams)
    stall: StallParams = field(default_factory=StallParams)
    backup: BackUpParams = field(default_factory=BackUpParams)
    give_way: GiveWayParams = field(default_factory=GiveWayParams)
    deadlock: DeadlockParams = field(default_factory=DeadlockParams)
    make_room: MakeRoomParams = field(default_factory=MakeRoomParams)
    rvo: AvoidanceParams = field(default_factory=AvoidanceParams)
    keep_right: KeepRightParams = field(default_factory=KeepRightParams)
    hold: HoldParams = field(default_factory=HoldParams)
    people: PeopleParams = field(default_factory=PeopleParams)

    def __post_init__(self) -> None:
        if self.avoidance not in AVOIDANCE_MODES:
            raise ValueError(
                f"NavParams.avoidance must be one of {list(AVOIDANCE_MODES)} "
                f"(got {self.avoidance!r})"
            )
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name != "avoidance" and type(value).__name__ != f.type:
                raise ValueError(f"NavParams.{f.name} must be a {f.type} (got {value!r})")
