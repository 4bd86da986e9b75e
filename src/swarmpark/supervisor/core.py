"""The supervisor: operator commands, per-robot state, and the tick that holds the loop together.

Each :meth:`Supervisor.tick` runs the scenario's due commands, re-runs the parking groups'
assignment (with hysteresis), asks the controller for velocities from one snapshot of the
swarm, steps the robot link (the simulator by default) and feeds the metrics.

Commands are validated before anything changes: a refused command returns an
:class:`Outcome` with the reason and the swarm keeps its previous orders.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import shapely
from shapely.geometry import Point, Polygon
from shapely.ops import nearest_points, unary_union

from swarmpark import assign as assign_mod
from swarmpark.control.base import Controller, ControlView
from swarmpark.core.geometry import GeometryError, as_simple_polygon
from swarmpark.metrics import (
    HEADING_TOL_RAD,
    POSITION_TOL_M,
    MetricsRecorder,
    goal_errors,
)
from swarmpark.sim.simulator import Simulator
from swarmpark.world.scenario import CommandSpec, GotoCmd, ParkCmd, World

__all__ = ["Supervisor", "Outcome", "ROBOT_STATES"]

ROBOT_STATES = ("idle", "moving", "parked", "stopped", "estopped", "teleop", "stuck")
#: Beams of each scan scored by the particle filter (a subsample, as AMCL's max_beams).
AMCL_BEAMS = 240
#: An estimate that jumps this far in one tick (a relocalized skid) makes the skid replan.
ESTIMATE_JUMP_M = 0.5
#: A kidnapped skid counts as found again once its error is below this (and stays).
RECOVERED_ERROR_M = 0.1
#: With onboard sensing, the planner's map (the static map plus the detected obstacles) is
#: refreshed this often (a costmap's update rate; planning itself is event-driven).
DETECTION_PLAN_PERIOD_S = 1.0
#: Detected obstacle cells go to the reactive layer (potential field, collision monitor, ORCA)
#: as static solids: one square of this size for each square holding detected cells.
DETECTION_SQUARE_M = 0.1
#: Fill-order blocking is judged on a grid this coarse, cropped this far around the boundary.
BLOCKING_RESOLUTION_M = 0.1
BLOCKING_MAX_GOALS = 40
BLOCKING_CROP_M = 3.0
#: A formation group keeps tracking its plan this long after the plan ends, then the
#: navigation stack docks each skid exactly.
FORMATION_GRACE_S = 3.0
#: Teleop commands older than this are dropped (the operator let go or the link died).
TELEOP_TIMEOUT_S = 0.5


@dataclass(frozen=True)
class Outcome:
    accepted: bool
    command: str
    reason: str = ""
    t_s: float = 0.0
    detail: dict = field(default_factory=dict)

    def as_dict(self) -> dict:
        return {
            "accepted": self.accepted,
            "command": self.command,
            "reason": self.reason,
            "t_s": round(self.t_s, 3),
            **({"detail": self.detail} if self.detail else {}),
        }


@dataclass
class ParkGroup:
    """Robots parked together: their goals, the cost, and the current assignment."""

    robots: np.ndarray  # robot indices
    goals: np.ndarray  # (G, 3)
    cost: str
    goal_of: np.ndarray  # goal index per robot in `robots`
    fill_order: tuple[int, ...]
    boundary: Polygon
    method: str
    report: dict
    #: (length, width) of the footprint each goal was laid out for.
    goal_dims: tuple[tuple[float, float], ...] = ()
    #: blocks[k]: goals j that become unreachable once goal k is occupied (fill order).
    blocks: tuple[tuple[int, ...], ...] = ()
    switches: int = 0


class Supervisor:
    """Runs a :class:`World` with a controller on a robot link (the simulator by default)."""

    def __init__(
        self, world: World, controller: Controller | None = None, link: Simulator | None = None
    ) -> None:
        from swarmpark.control.nav.navigator import (  # the default navigation stack
            Navigator,
            NavParams,
        )

        self.world = world
        self.sim = link if link is not None else Simulator(world)
        self.controller = (
            controller
            if controller is not None
            else Navigator(NavParams(avoidance=world.scenario.navigation.avoidance))
        )
        n = self.sim.n
        self.ids = list(world.ids)
        self.index = {rid: i for i, rid in enumerate(self.ids)}
        self.goals = np.zeros((n, 3))
        self.has_goal = np.zeros(n, dtype=bool)
        self.priority = np.array([r.priority for r in world.robots], float)
        self.stopped = np.zeros(n, dtype=bool)
        self.estopped = False
        self.teleop = np.zeros(n, dtype=bool)
        self._teleop_cmd = np.zeros((n, 2))
        self._teleop_t = np.full(n, -np.inf)
        self.goal_changed = np.zeros(n, dtype=bool)
        self.groups: list[ParkGroup] = []
        self.formations: list = []
        self.outcomes: list[Outcome] = []
        self.metrics = MetricsRecorder(self.ids, self.sim.poses.copy())
        # What the skids know of the world for planning: the map plus the static obstacles
        # (ground truth until onboard sensing feeds detections into the costmap).
        base = world.believed_grid if world.believed_grid is not None else world.grid
        self.known_grid = base.with_polygons(list(world.static_obstacles))
        self._base_grid = base
        self.localizer = None
        self.costmap = None  # onboard obstacle detection (with sensing)
        self.estimates = self.sim.poses.copy()
        self.loc_errors: list[np.ndarray] = []
        self.loc_times: list[float] = []
        self.kidnapped: list[tuple[int, float]] = []  # (robot, time) of each kidnapping done
        self._kidnaps = sorted(world.scenario.sensing.kidnap, key=lambda k: k.at_s)
        if world.scenario.sensing.localization == "amcl":
            self._start_localization()
        self._pending = sorted(
            enumerate(world.scenario.commands), key=lambda kv: (kv[1].at_s, kv[0])
        )

    # ------------------------------------------------------------------ state

    @property
    def t(self) -> float:
        return self.sim.t

    @property
    def poses_known(self) -> np.ndarray:
        """The poses the controller decides from: the skids' estimates when they localize
        onboard (``sensing.localization: amcl``), else the true poses. Metrics and the
        parked/settled checks always use the true poses."""
        return self.estimates if self.localizer is not None else self.sim.poses

    def modes(self) -> list[str]:
        """Per-robot state: idle, moving, parked, stopped, estopped, teleop or stuck."""
        pos_err, head_err = goal_errors(self.sim.poses, self.goals)
        at_goal = self.has_goal & (pos_err <= POSITION_TOL_M) & (head_err <= HEADING_TOL_RAD)
        stuck = self.metrics.stuck()
        out = []
        for i in range(self.sim.n):
            if self.estopped:
                out.append("estopped")
            elif self.teleop[i]:
                out.append("teleop")
            elif self.stopped[i]:
                out.append("stopped")
            elif at_goal[i]:
                out.append("parked")
            elif stuck[i]:
                out.append("stuck")
            elif self.has_goal[i]:
                out.append("moving")
            else:
                out.append("idle")
        return out

    def pending_done(self) -> bool:
        return not self._pending

    # ------------------------------------------------------------------ commands

    def _refuse(self, command: str, reason: str) -> Outcome:
        out = Outcome(False, command, reason, self.t)
        self.outcomes.append(out)
        return out

    def _accept(self, command: str, **detail) -> Outcome:
        out = Outcome(True, command, "", self.t, detail)
        self.outcomes.append(out)
        return out

    def _robot_indices(self, names, command: str) -> np.ndarray | str:
        if names == "all":
            return np.arange(self.sim.n)
        bad = [r for r in names if r not in self.index]
        if bad:
            return f"{command}: unknown robot {bad[0]!r}"
        return np.array([self.index[r] for r in names], dtype=int)

    def execute(self, cmd: CommandSpec) -> Outcome:
        """Carry out one scenario/operator command (the union form of the scenario schema)."""
        kind = cmd.kind
        if kind == "park":
            return self.park(cmd.park)  # type: ignore[arg-type]
        if kind == "goto":
            return self.goto(cmd.goto)  # type: ignore[arg-type]
        if kind == "formation":
            return self.formation(cmd.formation)  # type: ignore[arg-type]
        if kind == "stop":
            return self.stop(cmd.stop)  # type: ignore[arg-type]
        if kind == "estop":
            return self.estop()
        return self.resume(cmd.resume)  # type: ignore[arg-type]

    def plan_layout(self, cmd: ParkCmd):
        """The layout a park command would produce (for previews); raises ValueError."""
        from swarmpark.layout import layout

        idx = self._robot_indices(cmd.robots, "park.robots")
        if isinstance(idx, str):
            raise ValueError(idx)
        if len(set(cmd.robots)) != len(cmd.robots):
            raise ValueError(f"park.robots: robot listed twice in {list(cmd.robots)}")
        boundary = as_simple_polygon(cmd.boundary, "park.boundary")
        heading = cmd.heading_deg if cmd.heading_deg == "auto" else np.deg2rad(cmd.heading_deg)
        fps = [self.world.robots[i].footprint for i in idx]
        # The skids enter from their side: the opening is the boundary point nearest to them.
        centroid = Point(self.poses_known[idx, :2].mean(axis=0))
        opening = nearest_points(boundary.exterior, centroid)[0]
        lay = layout(
            boundary,
            fps,
            heading=heading,
            method=cmd.method,
            margin_m=cmd.margin_m,
            obstacles=self._known_solids(boundary),
            opening=(opening.x, opening.y),
        )
        return idx, boundary, lay

    def _known_solids(self, region: Polygon):
        """Walls and static obstacles the operator knows of, within ``region``."""
        parts = [p for p in self.world.wall_polygons if p.intersects(region)]
        if not self.world.wall_polygons:
            geom = self.world.grid.occupied_geometry(region)
            if not geom.is_empty:
                parts.append(geom)
        parts += [p for p in self.world.static_obstacles if p.intersects(region)]
        return unary_union(parts) if parts else None

    def park(self, cmd: ParkCmd) -> Outcome:
        """Lay out goals in the boundary and assign them to the robots (all or nothing)."""
        try:
            idx, boundary, lay = self.plan_layout(cmd)
        except (ValueError, GeometryError) as exc:
            return self._refuse("park", str(exc))
        busy = [self.ids[i] for i in idx if self.teleop[i]]
        if busy:
            return self._refuse("park", f"park.robots: robot {busy[0]!r} is under teleop")
        goals = np.asarray(lay.poses, float)
        fps = [self.world.robots[i].footprint for i in idx]
        fits = assign_mod.footprint_fits(
            [(f.length_m, f.width_m) for f in fps], [(f.length_m, f.width_m) for f in fps]
        )
        cost = self._cost_matrix(idx, goals, cmd.assignment, fits)
        try:
            goal_of = assign_mod.assign(cost)
        except assign_mod.AssignmentError as exc:
            return self._refuse("park", str(exc))
        # The command is good: drop these robots from other groups and from goto orders.
        self._leave_groups(idx)
        group = ParkGroup(
            idx,
            goals,
            cmd.assignment,
            goal_of,
            tuple(lay.fill_order),
            boundary,
            lay.method,
            dict(lay.report),
            goal_dims=tuple((f.length_m, f.width_m) for f in fps),
            blocks=self._blockers(goals, fps, boundary, tuple(lay.fill_order)),
        )
        self.groups.append(group)
        self._set_goals(idx, goals[goal_of])
        self.metrics.defer_lower_bound(
            self.world.grid,
            self.sim.poses[idx],
            goals,
            min(f.width_m for f in fps) / 2,
            self.sim.max_speed[idx],
        )
        return self._accept(
            "park",
            robots=[self.ids[i] for i in idx],
            method=lay.method,
            goals=np.round(goals[goal_of], 4).tolist(),
        )

    def _blockers(
        self, goals: np.ndarray, fps, boundary: Polygon, fill_order
    ) -> tuple[tuple[int, ...], ...]:
        """For each goal k, the goals j filled before k (in the layout's fill order) that can
        be reached from outside the boundary with the goals before j occupied, but not once
        k is occupied as well: k must stay free until those are filled.

        Reachability is connectivity of the free space for a disc one skid wide, on a coarse
        grid cropped around the boundary (scipy.ndimage.label), seeded outside the boundary.
        """
        from scipy import ndimage

        from swarmpark.core.geometry import footprint_polygon

        n = len(goals)
        if n < 2 or n > BLOCKING_MAX_GOALS:
            # The pairwise test is quadratic: big groups go without fill-order holds.
            return tuple(() for _ in goals)
        half = max(f.width_m for f in fps) / 2
        grid = self.known_grid
        res = max(grid.resolution_m, BLOCKING_RESOLUTION_M)
        xmin, ymin, xmax, ymax = boundary.buffer(BLOCKING_CROP_M).bounds
        gx0, gy0, gx1, gy1 = grid.bounds
        xmin, ymin, xmax, ymax = max(xmin, gx0), max(ymin, gy0), min(xmax, gx1), min(ymax, gy1)
        xs = np.arange(xmin + res / 2, xmax, res)
        ys = np.arange(ymin + res / 2, ymax, res)
        X, Y = np.meshgrid(xs, ys)
        pts = np.column_stack([X.ravel(), Y.ravel()])
        occ = grid.is_occupied(pts).reshape(X.shape)
        free = ndimage.distance_transform_edt(~occ) * res > half
        polys = [footprint_polygon(g, f) for g, f in zip(goals, fps, strict=True)]
        masks = [shapely.contains_xy(poly.buffer(half - 1e-6), X, Y) for poly in polys]
        seeds = ~shapely.contains_xy(boundary.buffer(res), X, Y) & free
        centers = np.array([list(p.centroid.coords)[0] for p in polys])
        cj = np.clip(((centers[:, 1] - ymin) / res).astype(int), 0, len(ys) - 1)
        ci = np.clip(((centers[:, 0] - xmin) / res).astype(int), 0, len(xs) - 1)
        rank = {g: r for r, g in enumerate(fill_order)}
        order = sorted(range(n), key=lambda g: rank.get(g, n))

        def reachable(space: np.ndarray, j: int) -> bool:
            labels, _ = ndimage.label(space, structure=np.ones((3, 3)))
            lab = labels[cj[j], ci[j]]
            return bool(lab) and bool(np.any(labels[seeds & space] == lab))

        blocks: list[set[int]] = [set() for _ in range(n)]
        occupied = np.zeros(X.shape, dtype=bool)
        for pos, j in enumerate(order):
            base = free & ~occupied
            if reachable(base, j):
                for k in order[pos + 1 :]:
                    if not reachable(base & ~masks[k], j):
                        blocks[k].add(j)
            occupied |= masks[j]
        return tuple(tuple(sorted(b)) for b in blocks)

    def held(self) -> np.ndarray:
        """Robots that must wait outside their boundary: their goal would block a deeper goal
        that is not filled yet and whose skid is not ahead of them (deepest goals first, 2018
        Fig. 6). A skid may follow the one bound deeper; it must not overtake it."""
        hold = np.zeros(self.sim.n, dtype=bool)
        for g in self.groups:
            if not g.blocks or not any(g.blocks):
                continue
            pos_err, head_err = goal_errors(self.poses_known[g.robots], g.goals[g.goal_of])
            parked = (pos_err <= POSITION_TOL_M) & (head_err <= HEADING_TOL_RAD)
            filled = np.zeros(len(g.goals), dtype=bool)
            filled[g.goal_of[parked]] = True
            to_go = np.full(len(g.goals), np.inf)  # distance of each goal's skid to it
            to_go[g.goal_of] = pos_err
            for r, k, d in zip(g.robots, g.goal_of, pos_err, strict=True):
                hold[r] = any(not filled[j] and to_go[j] >= d for j in g.blocks[k])
        return hold

    def hold_zones(self) -> list:
        zones: list = [None] * self.sim.n
        for g in self.groups:
            for r in g.robots:
                zones[r] = g.boundary
        return zones

    def _cost_matrix(self, idx: np.ndarray, goals: np.ndarray, cost: str, fits) -> np.ndarray:
        lengths = None
        if cost == "path":
            lengths = self.controller_path_lengths(idx, goals)
        return assign_mod.cost_matrix(
            self.poses_known[idx, :2], goals[:, :2], cost, path_lengths=lengths, fits=fits
        )

    def controller_path_lengths(self, idx: np.ndarray, goals: np.ndarray) -> np.ndarray:
        """Free-space path lengths robot -> goal ``(R, G)`` (one Dijkstra per goal)."""
        from swarmpark.plan.grid import build_costmap, path_length_matrix

        widths = [self.world.robots[i].footprint.width_m for i in idx]
        cm = build_costmap(self.world.grid, min(widths) / 2, min(widths) / 2)
        return path_length_matrix(cm, self.poses_known[idx, :2], goals[:, :2])

    def goto(self, cmd: GotoCmd) -> Outcome:
        if cmd.robot not in self.index:
            return self._refuse("goto", f"goto.robot: unknown robot {cmd.robot!r}")
        i = self.index[cmd.robot]
        if self.teleop[i]:
            return self._refuse("goto", f"goto.robot: robot {cmd.robot!r} is under teleop")
        goal = np.array([cmd.pose[0], cmd.pose[1], np.deg2rad(cmd.pose[2])])
        reason = self._goal_reachability(i, goal)
        if reason:
            return self._refuse("goto", reason)
        self._leave_groups(np.array([i]))
        if cmd.priority is not None:
            self.priority[i] = cmd.priority
        self._set_goals(np.array([i]), goal[None])
        return self._accept("goto", robot=cmd.robot, pose=np.round(goal, 4).tolist())

    def _goal_reachability(self, i: int, goal: np.ndarray) -> str:
        """Reason a goal pose cannot be taken (footprint in a wall or off the map), or ''."""
        from swarmpark.core.geometry import convex_gap, footprint_corners

        corners = footprint_corners(goal[None], self.sim.corners_body[i : i + 1])
        pieces = self.sim.static_pieces
        gap = convex_gap(np.repeat(corners, len(pieces), axis=0), pieces)
        if np.any(gap < 0):
            owner = self.sim.static_owner[int(np.argmin(gap))]
            return (
                f"goto.pose: robot {self.ids[i]!r} would overlap {owner.replace(':', ' ')} at "
                f"{[round(float(goal[0]), 3), round(float(goal[1]), 3), round(float(np.rad2deg(goal[2])), 1)]}"
            )
        return ""

    def formation(self, cmd) -> Outcome:
        """Move a group along paths holding a formation (Liu, Sun, Zhu 2010); the group is
        handed back to the navigation stack for the final docking when the plan ends."""
        from swarmpark.control.formation.run import FormationError, FormationRun

        idx = self._robot_indices(cmd.robots, "formation.robots")
        if isinstance(idx, str):
            return self._refuse("formation", idx)
        busy = [self.ids[i] for i in idx if self.teleop[i]]
        if busy:
            return self._refuse("formation", f"formation.robots: robot {busy[0]!r} is under teleop")
        try:
            run = FormationRun.start(
                idx,
                self.poses_known[idx],
                [self.world.robots[i].footprint for i in idx],
                self.sim.max_speed[idx],
                self.sim.max_accel[idx],
                cmd,
                self.t,
            )
        except (ValueError, FormationError) as exc:
            return self._refuse("formation", str(exc))
        self._leave_groups(idx)
        self.formations.append(run)
        self._set_goals(idx, run.goals)
        return self._accept(
            "formation",
            robots=[self.ids[i] for i in idx],
            plan_duration_s=round(float(run.adjuster.plan.duration_s), 3),
        )

    def _formation_mask(self) -> np.ndarray:
        """Robots currently driven by a formation plan (until it ends, plus a grace time)."""
        mask = np.zeros(self.sim.n, dtype=bool)
        for f in self.formations:
            if self.t - f.t0 <= f.adjuster.plan.duration_s + FORMATION_GRACE_S:
                mask[f.idx] = True
        return mask

    def stop(self, names) -> Outcome:
        idx = self._robot_indices(names, "stop")
        if isinstance(idx, str):
            return self._refuse("stop", idx)
        self.stopped[idx] = True
        return self._accept("stop", robots=[self.ids[i] for i in idx])

    def estop(self) -> Outcome:
        self.estopped = True
        return self._accept("estop")

    def resume(self, names) -> Outcome:
        idx = self._robot_indices(names, "resume")
        if isinstance(idx, str):
            return self._refuse("resume", idx)
        if names != "all" and self.estopped:
            return self._refuse(
                "resume", "resume: the e-stop is latched; resume 'all' to release it"
            )
        if names == "all":
            self.estopped = False
        self.stopped[idx] = False
        return self._accept("resume", robots=[self.ids[i] for i in idx])

    def set_teleop(self, robot: str, v: float, omega: float) -> Outcome:
        """Take over one robot with a velocity command (hand it back with :meth:`release`)."""
        if robot not in self.index:
            return self._refuse("teleop", f"teleop.robot: unknown robot {robot!r}")
        if not (np.isfinite(v) and np.isfinite(omega)):
            return self._refuse("teleop", f"teleop: v and omega must be finite (got {v}, {omega})")
        i = self.index[robot]
        taking_over = not self.teleop[i]
        self.teleop[i] = True
        self._teleop_cmd[i] = (v, omega)
        self._teleop_t[i] = self.t
        if taking_over:  # log the take-over, not every joystick update
            return self._accept("teleop", robot=robot)
        return Outcome(True, "teleop", "", self.t)

    def release(self, robot: str) -> Outcome:
        if robot not in self.index:
            return self._refuse("release", f"release.robot: unknown robot {robot!r}")
        i = self.index[robot]
        self.teleop[i] = False
        self._teleop_cmd[i] = 0.0
        self.goal_changed[i] = True  # autonomy takes over from wherever the operator left it
        return self._accept("release", robot=robot)

    def _leave_groups(self, idx: np.ndarray) -> None:
        self.formations = [f for f in self.formations if not np.isin(f.idx, idx).any()]
        keep = []
        for g in self.groups:
            mask = ~np.isin(g.robots, idx)
            if mask.all():
                keep.append(g)
            elif mask.any():
                g.robots, g.goal_of = g.robots[mask], g.goal_of[mask]
                keep.append(g)
        self.groups = keep

    def _set_goals(self, idx: np.ndarray, goals: np.ndarray) -> None:
        changed = ~self.has_goal[idx] | np.any(np.abs(self.goals[idx] - goals) > 1e-9, axis=1)
        self.goals[idx] = goals
        self.has_goal[idx] = True
        self.goal_changed[idx[changed]] = True
        if changed.any():
            self.metrics.on_goal(self.t, idx[changed], goals[changed])

    # ------------------------------------------------------------------ the tick

    def _start_localization(self) -> None:
        """Per-skid AMCL on simulated scans and drifting odometry (2018 paper Sect. 3.5)."""
        from swarmpark.core.geometry import pad_polygons, triangulate
        from swarmpark.sense.amcl import RECOVERY, FilterConfig, FleetLocalizer, LikelihoodField
        from swarmpark.sense.lidar import LidarSpec, prepare_grid

        cfg = self.world.scenario.sensing
        self.lidar_spec = LidarSpec(
            num_beams=cfg.lidar_beams,
            max_range_m=cfg.lidar_range_m,
            range_noise_std_m=cfg.range_noise_std_m,
            dropout_prob=cfg.dropout_prob,
        )
        self._scan_field = prepare_grid(self.world.grid)
        tris = [t for poly in self.world.static_obstacles for t in triangulate(poly)]
        self._obstacle_tris = pad_polygons(tris, 4) if tris else np.zeros((0, 4, 2))
        seed = np.random.SeedSequence(self.world.scenario.seed)
        scan_seed, loc_seed = seed.spawn(2)
        self._scan_rng = np.random.default_rng(scan_seed)
        self.localizer = FleetLocalizer(
            LikelihoodField(
                self.world.believed_grid or self.world.grid, max_range_m=cfg.lidar_range_m
            ),
            self.lidar_spec,
            self.sim.poses.copy(),
            rng=np.random.default_rng(loc_seed),
            footprint=self.sim.footprints[0],
            config=FilterConfig(
                max_beams=AMCL_BEAMS, alpha_fast=RECOVERY.alpha_fast if cfg.recovery else 0.0
            ),
        )
        self.estimates = self.localizer.estimates.copy()
        # Obstacle detection (Hing 2018, Sect. 3.5.1): what the scans show and the map does not
        # goes into the skids' costmap, and planning and avoidance use it instead of the
        # scenario's obstacles and people (the simulator keeps those as the truth).
        from swarmpark.sense.costmap import LocalCostmap

        self.costmap = LocalCostmap(self._base_grid, self.sim.n, self.lidar_spec)
        self.known_grid = self._base_grid.copy()
        self._detected_mask = np.zeros(self._base_grid.shape, dtype=bool)
        self._plan_grid_t = -np.inf
        pieces, owners = self.world.static_convex_pieces()
        self._wall_pieces = pieces[np.array([o == "wall" for o in owners])]
        self._detected_squares = np.zeros((0, 2), dtype=np.int64)
        self._static_view = self._wall_pieces  # walls and detected squares, for the view

    def _detect(self, ranges: np.ndarray) -> None:
        """Feed the scans (less the returns from other skids, whose places the fleet knows) to
        the costmap at the estimated poses; refresh the solids the reactive layer avoids and,
        at :data:`DETECTION_PLAN_PERIOD_S`, the planner's map. Detections are shared by the
        fleet (the union of every skid's costmap): the central controller plans for all."""
        t = self.sim.t
        others = self.localizer.other_skid_beams(ranges)
        seen = ranges if others is None else np.where(others, np.nan, ranges)
        self.costmap.update(t, self.estimates, seen)
        cells = np.concatenate([self.costmap.obstacles(i, t).cells for i in range(self.sim.n)])
        grid = self._base_grid
        pts = grid.cell_to_world(cells) if len(cells) else np.zeros((0, 2))
        squares = np.unique(np.floor(pts / DETECTION_SQUARE_M).astype(np.int64), axis=0)
        if not np.array_equal(squares, self._detected_squares):
            # Each square grown by half a cell covers the cells whose centres lie in it.
            half = 0.5 * grid.resolution_m
            lo = squares * DETECTION_SQUARE_M - half
            hi = lo + DETECTION_SQUARE_M + 2 * half
            boxes = np.stack(
                [
                    np.column_stack([lo[:, 0], lo[:, 1]]),
                    np.column_stack([hi[:, 0], lo[:, 1]]),
                    np.column_stack([hi[:, 0], hi[:, 1]]),
                    np.column_stack([lo[:, 0], hi[:, 1]]),
                ],
                axis=1,
            )
            self._detected_squares = squares
            self._static_view = np.concatenate([self._wall_pieces, boxes])
        if t - self._plan_grid_t >= DETECTION_PLAN_PERIOD_S - 1e-9:
            self._plan_grid_t = t
            mask = np.zeros(grid.shape, dtype=bool)
            if len(cells):
                mask[cells[:, 0], cells[:, 1]] = True
            if not np.array_equal(mask, self._detected_mask):
                appeared = mask & ~self._detected_mask
                self._detected_mask = mask
                known = grid.copy()
                known.occupied |= mask
                known.unknown &= ~known.occupied
                self.known_grid = known  # a new object: the navigator rebuilds its costmap
                if appeared.any():
                    self._replan_blocked(grid.cell_to_world(np.argwhere(appeared)))

    def _replan_blocked(self, new_xy: np.ndarray) -> None:
        """Make skids whose planned path (the part still ahead) runs within a skid's half width
        (plus :data:`DETECTION_SQUARE_M`) of newly detected obstacle points plan again."""
        from scipy.spatial import cKDTree

        paths = getattr(self.controller, "paths", None)
        if paths is None:
            return
        tree = cKDTree(new_xy)
        for i, path in enumerate(paths()):
            if path is None or len(path) < 2 or not self.has_goal[i]:
                continue
            path = np.asarray(path, float)[:, :2]
            seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
            n = np.maximum(np.ceil(seg / DETECTION_SQUARE_M).astype(int), 1)
            dense = np.vstack(
                [
                    a + np.linspace(0, 1, k, endpoint=False)[:, None] * (b - a)
                    for a, b, k in zip(path[:-1], path[1:], n, strict=True)
                ]
                + [path[-1:]]
            )
            ahead = dense[int(np.argmin(np.hypot(*(dense - self.estimates[i, :2]).T))) :]
            reach = self.sim.footprints[i].width_m / 2 + DETECTION_SQUARE_M
            if np.isfinite(tree.query(ahead, distance_upper_bound=reach)[0]).any():
                self.goal_changed[i] = True

    def _sense(self) -> None:
        """Scan from the true poses (the world as it is) and update every skid's estimate."""
        from swarmpark.sense.lidar import scan

        sim = self.sim
        skids = sim.corners()
        polys = np.concatenate([skids, self._obstacle_tris])
        owner = np.concatenate([np.arange(sim.n), np.full(len(self._obstacle_tris), -1)])
        ranges = scan(
            self.lidar_spec,
            sim.poses,
            self._scan_field,
            polygons=polys,
            polygon_owner=owner,
            discs=sim.person_positions(),
            disc_radii=sim.person_radius,
            rng=self._scan_rng,
        )
        # Static obstacles are known but not in the map: their beams are not scored.
        known = self._obstacle_tris if len(self._obstacle_tris) else None
        before = self.estimates
        self.estimates = self.localizer.step(sim.poses, ranges, known_polygons=known).copy()
        # A skid whose estimate jumped (found again after a kidnapping) plans from where it is.
        jumped = np.hypot(*(self.estimates[:, :2] - before[:, :2]).T) > ESTIMATE_JUMP_M
        self.goal_changed |= jumped & self.has_goal
        self.loc_errors.append(self.localizer.errors(sim.poses)[0])
        self.loc_times.append(sim.t)
        self._detect(ranges)

    def _run_due_kidnaps(self) -> None:
        """Carry skids to their kidnap poses (the simulator's truth; odometry does not see it)."""
        eps = 1e-9
        while self._kidnaps and self._kidnaps[0].at_s <= self.t + eps:
            kid = self._kidnaps.pop(0)
            i = self.index[kid.robot]
            pose = np.array([kid.pose[0], kid.pose[1], np.deg2rad(kid.pose[2])], float)
            self.sim.poses[i] = pose
            self.sim.vel[i] = 0.0
            self.localizer.kidnap(i, pose[None])
            self.metrics.moved_by_hand(i, pose)
            self.kidnapped.append((i, self.t))

    def localization_summary(self) -> dict:
        """Localization error over the run (position, m) and, per kidnapping, how long the
        skid took to be found again (error below :data:`RECOVERED_ERROR_M` for good)."""
        if not self.loc_errors:
            return {}
        err = np.stack(self.loc_errors)
        t = np.asarray(self.loc_times)
        out = {
            "method": "amcl",
            "recovery": bool(self.world.scenario.sensing.recovery),
            "mean_error_m": round(float(err.mean()), 4),
            "max_error_m": round(float(err.max()), 4),
            "final_max_error_m": round(float(err[-1].max()), 4),
            "per_robot_mean_error_m": {
                rid: round(float(e), 4) for rid, e in zip(self.ids, err.mean(axis=0), strict=True)
            },
        }
        if self.world.believed_grid is not None:
            out["map_agreement"] = self._map_agreement()
        if self.kidnapped:
            events = []
            for k, (i, t0) in enumerate(self.kidnapped):
                later = [t1 for j, t1 in self.kidnapped[k + 1 :] if j == i]
                window = (t > t0) & (t < (later[0] if later else np.inf))
                e, tw = err[window, i], t[window]
                bad = np.flatnonzero(e >= RECOVERED_ERROR_M)
                if len(e) == 0 or (len(bad) and bad[-1] == len(e) - 1):
                    found = None  # still lost at the end of the window
                else:
                    found = float(tw[bad[-1] + 1] - t0) if len(bad) else float(tw[0] - t0)
                events.append(
                    {
                        "robot": self.ids[i],
                        "at_s": round(t0, 3),
                        "error_after_m": round(float(e[0]), 4) if len(e) else None,
                        "recovered_after_s": None if found is None else round(found, 3),
                    }
                )
            out["kidnaps"] = events
        return out

    def _map_agreement(self) -> dict | None:
        """Agreement of the map the skids localize in (``sensing.map``) with the true map,
        when the two share a grid (a map built by ``swarmpark map`` in the same world does)."""
        from swarmpark.sense.mapping import map_agreement

        try:
            agree = map_agreement(self.world.believed_grid, self.world.grid, tolerance_cells=1)
        except ValueError:
            return None  # a map of another extent or resolution: no cell-by-cell comparison
        return {k: round(float(v), 4) for k, v in agree.items()}

    def _run_due_commands(self) -> None:
        eps = 1e-9
        while self._pending and self._pending[0][1].at_s <= self.t + eps:
            _, cmd = self._pending.pop(0)
            self.execute(cmd)

    def _reassign(self) -> None:
        """Re-run each parking group's assignment (2018 Algorithm 2), with hysteresis."""
        for g in self.groups:
            if g.cost == "sequential" or len(g.robots) < 2:
                continue
            fps = [self.world.robots[i].footprint for i in g.robots]
            fits = assign_mod.footprint_fits([(f.length_m, f.width_m) for f in fps], g.goal_dims)
            if g.cost == "path":
                continue  # path costs are recomputed on replans only (Dijkstra per goal)
            cost = self._cost_matrix(g.robots, g.goals, g.cost, fits)
            pos_err, head_err = goal_errors(self.poses_known[g.robots], g.goals[g.goal_of])
            locked = (pos_err <= POSITION_TOL_M) & (head_err <= HEADING_TOL_RAD)
            try:
                new, changed = assign_mod.reassign(cost, g.goal_of, locked)
            except assign_mod.AssignmentError:
                continue
            if changed:
                g.switches += int(np.sum(new != g.goal_of))
                g.goal_of = new
                self._set_goals(g.robots, g.goals[new])

    def view(self) -> ControlView:
        sim = self.sim
        if self.costmap is not None:
            # Onboard sensing: avoid the walls and what the scans detected (people included,
            # as still obstacles refreshed every scan), not the scenario's obstacles and people.
            ppos, prad = np.zeros((0, 2)), np.zeros(0)
            pvel = np.zeros_like(ppos)
            static_pieces = self._static_view
        else:
            ppos, prad = sim.person_positions(), sim.person_radius
            pvel = np.zeros_like(ppos)
            static_pieces = sim.static_pieces
        if len(ppos) and self.costmap is None:
            ahead = sim.person_positions(sim.person_s + 1e-3)
            moving = self._people_walking()
            speed = np.array([p.speed_mps for p in sim.people])
            dirn = ahead - ppos
            norm = np.linalg.norm(dirn, axis=1, keepdims=True)
            pvel = np.where(
                (norm > 0) & moving[:, None], dirn / np.maximum(norm, 1e-12) * speed[:, None], 0.0
            )
        return ControlView(
            t=sim.t,
            dt=sim.dt,
            poses=(self.estimates if self.localizer is not None else sim.poses).copy(),
            vel=sim.vel.copy(),
            goals=self.goals.copy(),
            active=self.has_goal
            & ~self.stopped
            & ~self.teleop
            & (not self.estopped)
            & ~self._formation_mask(),
            priority=self.priority.copy(),
            footprints=tuple(sim.footprints),
            max_speed=sim.max_speed,
            max_yaw_rate=sim.max_yaw_rate,
            max_accel=sim.max_accel,
            max_yaw_accel=sim.max_yaw_accel,
            grid=self.known_grid,
            people_xy=ppos,
            people_vel=pvel,
            people_radius=prad,
            static_pieces=static_pieces,
            goal_changed=self.goal_changed.copy(),
            hold=self.held(),
            stopped=self.stopped | self.teleop | self.estopped,
            hold_zones=tuple(self.hold_zones()),
        )

    def _people_walking(self) -> np.ndarray:
        sim = self.sim
        return np.array(
            [
                sim.t >= p.start_s and (p.loop or s < p.route_length_m - 1e-9)
                for p, s in zip(sim.people, sim.person_s, strict=True)
            ],
            dtype=bool,
        )

    def tick(self):
        """One decision phase for every robot from one snapshot, then one move phase."""
        self._run_due_commands()
        if self._kidnaps:
            self._run_due_kidnaps()
        self._reassign()
        view = self.view()
        cmd = np.asarray(self.controller.compute(view), float).reshape(self.sim.n, 2)
        cmd[~view.active] = 0.0
        for f in self.formations:
            if self.t - f.t0 <= f.adjuster.plan.duration_s + FORMATION_GRACE_S:
                go = ~self.stopped[f.idx] & ~self.teleop[f.idx] & (not self.estopped)
                fc = f.command(
                    self.t,
                    self.poses_known[f.idx],
                    view.people_xy,
                    self.sim.max_speed[f.idx],
                    self.sim.max_yaw_rate[f.idx],
                )
                cmd[f.idx] = np.where(go[:, None], fc, 0.0)
        fresh = self.teleop & (self.t - self._teleop_t <= TELEOP_TIMEOUT_S)
        cmd[fresh] = self._teleop_cmd[fresh]
        self.goal_changed[:] = False
        hold = np.full(self.sim.n, self.estopped)
        step = self.sim.step(cmd, hold=hold)
        if self.localizer is not None:
            self._sense()
        # Waiting on purpose (stopped, held back by the fill order) is not a deadlock.
        paused = self.stopped | self.teleop | self.estopped | view.hold
        aside = getattr(self.controller, "making_room", None)  # standing aside (RVO)
        if aside is not None and len(aside) == self.sim.n:
            paused = paused | aside
        self.metrics.on_step(
            self.sim.t,
            self.sim.poses,
            self.goals,
            self.has_goal,
            paused,
            step,
        )
        return step

    def settled(self) -> bool:
        """Every commanded robot is at its goal and at rest, and nothing else is pending."""
        if self._pending or not self.has_goal.any():
            return False
        pos_err, head_err = goal_errors(self.sim.poses, self.goals)
        at = (pos_err <= POSITION_TOL_M) & (head_err <= HEADING_TOL_RAD)
        at_rest = np.abs(self.sim.vel).max(initial=0.0) < 1e-3
        return bool(np.all(at[self.has_goal]) and at_rest and self.sim.people_done())

    def snapshot(self) -> dict:
        """The state streamed to the operator interface (JSON-ready, SI units, radians)."""
        sim = self.sim
        return {
            "t_s": round(sim.t, 3),
            "estop": self.estopped,
            "robots": [
                {
                    "id": rid,
                    "pose": [round(float(v), 4) for v in sim.poses[i]],
                    "vel": [round(float(v), 4) for v in sim.vel[i]],
                    "state": m,
                    "goal": [round(float(v), 4) for v in self.goals[i]]
                    if self.has_goal[i]
                    else None,
                    "priority": float(self.priority[i]),
                    "footprint": {
                        "length_m": sim.footprints[i].length_m,
                        "width_m": sim.footprints[i].width_m,
                        "pivot_from_rear_m": sim.footprints[i].pivot,
                    },
                }
                for i, (rid, m) in enumerate(zip(self.ids, self.modes(), strict=True))
            ],
            "people": [
                {"id": p.id, "xy": [round(float(v), 4) for v in xy], "radius_m": p.radius_m}
                for p, xy in zip(sim.people, sim.person_positions(), strict=False)
            ],
        }
