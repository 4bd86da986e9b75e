"""Operator commands: park, goto, formation, stop, e-stop, resume, teleop and release.

The handlers of the command registry (:mod:`swarmpark.supervisor.registry`), as a mixin of
:class:`~swarmpark.supervisor.core.Supervisor`. Commands are validated before anything
changes: a refused command returns an :class:`Outcome` with the reason and the swarm keeps
its previous orders. Also here: the parking groups' assignment, re-run every tick with
hysteresis (2018 Algorithm 2).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial
from typing import Any

import numpy as np
from pydantic import ValidationError
from shapely.geometry import Point, Polygon
from shapely.ops import nearest_points, unary_union

from swarmpark import assign as assign_mod
from swarmpark.core.geometry import (
    Footprint,
    GeometryError,
    as_simple_polygon,
    footprint_polygon,
)
from swarmpark.core.limits import MAX_BOUNDARY_VERTICES
from swarmpark.metrics import HEADING_TOL_RAD, POSITION_TOL_M, goal_errors
from swarmpark.plan.grid import build_costmap, entry_points
from swarmpark.plan.spot_reach import as_report, spot_reach
from swarmpark.supervisor import fill_order
from swarmpark.supervisor.fill_order import Reach
from swarmpark.supervisor.known_map import KnownMap, OperatorMap, SensedMap
from swarmpark.supervisor.registry import COMMANDS
from swarmpark.world.scenario import CommandSpec, GotoCmd, ParkCmd

__all__ = ["CommandsMixin", "Outcome", "ParkGroup", "ParkPlan", "FORMATION_GRACE_S"]

#: A formation group keeps tracking its plan this long after the plan ends, then the
#: navigation stack docks each skid exactly.
FORMATION_GRACE_S = 3.0
#: Parks of up to this many spots get the manoeuvre check of their spots (plan/spot_reach).
MAX_REACH_CHECKED = 60
#: A re-assignment that would move the goal of a skid this near it (two docking radii:
#: parked or docking) is not taken. The solve itself only prices the parked ones' other
#: goals higher, so a formation cost's saving could free them: a skid just parked was
#: handed the deeper spot of its row past a skid parked in between (a generated people site:
#: it never got there, 9 of 10 parked).
DOCKING_LOCK_M = 0.6


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


#: Grid (m) the way in to a park's boundary is looked for on first (``_opening``).
OPENING_RESOLUTION_M = 0.2


@dataclass(frozen=True)
class ParkPlan:
    """A park command worked out but not committed (:meth:`CommandsMixin.prepare_park`)."""

    group: ParkGroup
    #: The inputs of the run's lower bound on the time to park (computed lazily by the
    #: metrics, outside the control tick: :meth:`MetricsRecorder.defer_lower_bound`).
    bound_inputs: tuple
    #: Whether the manoeuvre check of the spots ran (else the metrics run it after the run).
    reach_checked: bool = True
    #: The spots no manoeuvre reaches, when the fill order's search already knows them
    #: (empty: it found an order that reaches every spot); None: check them as usual.
    flags: list | None = None


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
    #: The footprint each goal was laid out for (its pivot is the goal's pose).
    goal_fps: tuple[Footprint, ...] = ()
    #: blocks[k]: goals j that become unreachable once goal k is occupied (fill order).
    blocks: tuple[tuple[int, ...], ...] = ()
    #: Reachability of the goals from outside with some of them taken (holds as they fill).
    reach: Reach | None = None
    switches: int = 0
    #: The park command that made it (to lay it out again, :mod:`.spot_watch`).
    command: ParkCmd | None = None
    #: Times it was laid out again because a spot was found blocked, and the consecutive
    #: checks that found one blocked (:mod:`.spot_watch`).
    relayouts: int = 0
    blocked_checks: int = 0

    @property
    def goal_dims(self) -> tuple[tuple[float, float], ...]:
        """(length, width) of the footprint each goal was laid out for."""
        return tuple((f.length_m, f.width_m) for f in self.goal_fps)


def uniform_spots(fps) -> list | None:
    """One spot size for a park of skids of several sizes: the longest length and the widest
    width, pivot in the middle, or None (one size already, or a pivot off the middle: a
    smaller skid's goal would not be the spot's). Spots of one size are interchangeable:
    any skid may take any goal, so the fill order's hand-over (:func:`.fill_order.hand_over`)
    and the re-assignment are never refused by size. With spots laid out one per skid's
    size, a small skid waiting at a car's door for a large one bound deeper could never hand
    over: only a large skid fits a large spot, and every large spot has its large skid."""
    sizes = {(f.length_m, f.width_m) for f in fps}
    if len(sizes) < 2 or any(abs(f.pivot_from_rear_m - f.length_m / 2) > 1e-9 for f in fps):
        return None
    length = max(f.length_m for f in fps)
    width = max(f.width_m for f in fps)
    return [Footprint(length, width, length / 2)] * len(fps)


class CommandsMixin:
    """Command handlers of the supervisor (state lives in :class:`Supervisor`)."""

    def _refuse(self, command: str, reason: str) -> Outcome:
        out = Outcome(False, command, reason, self.t)
        self.outcomes.append(out)
        return out

    def _accept(self, command: str, **detail) -> Outcome:
        # Between two ticks a command counts from now. The e-stop and stops also come from
        # another thread during a tick (the server's event loop): that tick decided, or
        # stepped, without them, so they count from its end.
        start = self._tick_start
        t = self.t if start is None else max(self.t, start + self.info.dt_s)
        out = Outcome(True, command, "", t, detail)
        self.outcomes.append(out)
        return out

    def _robot_indices(self, names, command: str) -> np.ndarray | str:
        if names == "all":
            return np.arange(self.n)
        bad = [r for r in names if r not in self.index]
        if bad:
            return f"{command}: unknown robot {bad[0]!r}"
        return np.array([self.index[r] for r in names], dtype=int)

    def command(self, name: str, payload: Any = None) -> Outcome:
        """Carry out the operator command ``name`` (see :data:`~swarmpark.supervisor.registry.COMMANDS`)
        with its payload; a name nobody registered is refused with the known ones."""
        if name not in COMMANDS:
            return self._refuse(str(name), str(COMMANDS.error(name)))
        spec = COMMANDS.get(name)
        if isinstance(payload, dict) and spec.request is not None:
            # A plain mapping (a message from a topic, a script) is checked against the
            # command's schema first, as the API checks its bodies.
            try:
                payload = spec.request.model_validate(payload)
            except ValidationError as exc:
                err = exc.errors()[0]
                where = ".".join(str(x) for x in err["loc"])
                return self._refuse(name, f"{name}.{where}: {err['msg']}")
        return spec.handler(self, payload)

    def execute(self, cmd: CommandSpec) -> Outcome:
        """Carry out one scenario command (the union form of the scenario schema)."""
        kind = cmd.kind
        return self.command(kind, getattr(cmd, kind))

    def plan_layout(self, cmd: ParkCmd):
        """The layout a park command would produce (for previews): ``(robot indices, boundary,
        layout, spot footprints)``, the last the footprints the spots were laid out for (one
        size for all, :func:`uniform_spots`, or each skid's own). Raises ValueError."""
        from swarmpark.layout import LayoutError, layout

        idx = self._robot_indices(cmd.robots, "park.robots")
        if isinstance(idx, str):
            raise ValueError(idx)
        if len(set(cmd.robots)) != len(cmd.robots):
            raise ValueError(f"park.robots: robot listed twice in {list(cmd.robots)}")
        # The order the operator listed the skids in must not matter: lay out and assign in
        # the fleet's order (robots sorted by id, world.build.robot_order_key).
        idx = np.sort(idx)
        boundary = as_simple_polygon(
            cmd.boundary, "park.boundary", max_vertices=MAX_BOUNDARY_VERTICES
        )
        heading = cmd.heading_deg if cmd.heading_deg == "auto" else np.deg2rad(cmd.heading_deg)
        fps = [self.info.footprints[i] for i in idx]
        opening = self._opening(idx, boundary, fps)
        names, places = self._standing_others(idx, boundary)
        solids = self._known_solids(boundary)
        if places:
            solids = unary_union(places if solids is None else [solids, *places])

        def lay_out(spots):
            return layout(
                boundary,
                spots,
                heading=heading,
                method=cmd.method,
                margin_m=cmd.margin_m,
                obstacles=solids,
                opening=opening,
                # Room for a skid coming in to turn on the spot by the opening.
                apron_m=2.0 * max(f.reach_m for f in spots),
            )

        uniform = uniform_spots(fps)
        if uniform is not None:
            try:
                return idx, boundary, lay_out(uniform), uniform
            except LayoutError:
                pass  # no room for every spot at the largest size: one spot per skid's size
        try:
            lay = lay_out(fps)
        except LayoutError as exc:
            if not names or exc.fits is None:
                raise
            shown = ", ".join(repr(n) for n in names[:5]) + (", ..." if len(names) > 5 else "")
            raise LayoutError(
                f"{exc}, clear of the {len(names)} other skid(s) that stand or park in it "
                f"({shown})",
                fits=exc.fits,
            ) from None
        return idx, boundary, lay, fps

    def _standing_others(self, idx: np.ndarray, boundary: Polygon) -> tuple[list[str], list]:
        """The skids outside a park command that will stand in its boundary, as their ids and
        footprints there: a skid with a goal (parked, or bound for a spot of another group
        or a goto) at its goal, a skid without one where it stands. The layout keeps clear
        of them as of a wall: laid over an idle skid, a spot could never be taken (a new
        user's site: one skid of six held before it for the whole run), and two groups sent
        into one boundary were given overlapping spots. Skids driven by hand or in a running
        formation are on the move and do not count."""
        moving = self._formation_mask() | self.teleop
        others = np.ones(self.n, dtype=bool)
        others[idx] = False
        names, places = [], []
        for i in np.flatnonzero(others & ~moving):
            pose = self.goals[i] if self.has_goal[i] else self.poses_known[i]
            poly = footprint_polygon(pose, self.info.footprints[i])
            if poly.intersects(boundary):
                names.append(self.ids[i])
                places.append(poly)
        return names, places

    def _opening(self, idx: np.ndarray, boundary: Polygon, fps) -> tuple[float, float]:
        """Where skids ``idx`` come into ``boundary``: the mean of the points at which their
        shortest free-space paths on the known map reach its edge, brought back onto the
        edge. Through a door they all come in at the door, not at the side of the boundary
        straight ahead of them behind a wall. Without any path: the edge point nearest to
        the skids' centroid."""
        half = min(f.width_m for f in fps) / 2.0
        grid = self.known_grid
        # On a coarse grid first (it only has to find the way in; on the map's grid a 100-skid
        # park spent 180 ms here). Coarsening closes gaps (conservatively): if it closes
        # them all, on the map's grid.
        coarse = max(OPENING_RESOLUTION_M, grid.resolution_m)
        for res in dict.fromkeys((coarse, grid.resolution_m)):
            ring = boundary.exterior.segmentize(res)
            edge = np.asarray(ring.coords)[:-1]
            costmap = build_costmap(grid, half, half, resolution_m=res)
            entries = entry_points(costmap, self.poses_known[idx, :2], edge)
            found = np.isfinite(entries[:, 0])
            if found.any():
                break
        aim = entries[found].mean(axis=0) if found.any() else self.poses_known[idx, :2].mean(0)
        p = nearest_points(boundary.exterior, Point(aim))[0]
        return p.x, p.y

    @property
    def park_map(self) -> KnownMap:
        """What a park command is laid out, assigned and checked on
        (:mod:`swarmpark.supervisor.known_map`): with onboard sensing the prior map and the
        fleet's detections, else the scenario's map and obstacles."""
        if self.sensing is not None:
            return SensedMap(self.world, self.sensing)
        return OperatorMap(self.world)

    def _known_solids(self, region: Polygon):
        """Walls and obstacles the operator knows of, within ``region`` (:attr:`park_map`)."""
        return self.park_map.solids(region)

    def park(self, cmd: ParkCmd) -> Outcome:
        """Lay out goals in the boundary and assign them to the robots (all or nothing).
        This runs inside the control tick, so the manoeuvre check of the spots is left to
        the run's metrics (``unreachable_spots`` in the result)."""
        return self.apply_park(self.prepare_park(cmd, check_reach=False))

    def prepare_park(self, cmd: ParkCmd, *, check_reach: bool = True) -> ParkPlan | str:
        """The heavy half of :meth:`park` (layout, costs, fill-order blockers, the lower
        bound, with ``check_reach`` the spots no manoeuvre reaches): reads the supervisor,
        changes nothing, so a server can run it off its sim thread. Returns the plan or the
        reason it cannot be made."""
        try:
            idx, boundary, lay, fps = self.plan_layout(cmd)
        except (ValueError, GeometryError) as exc:
            return str(exc)
        goals = np.asarray(lay.poses, float)
        report = dict(lay.report)
        order, blocks, reach, flags = self._fill_holds(goals, fps, boundary, tuple(lay.fill_order))
        if check_reach or flags is not None:
            self._flag_unreachable(report, goals, fps, order, flags)
        own = [self.info.footprints[i] for i in idx]
        fits = assign_mod.footprint_fits(
            [(f.length_m, f.width_m) for f in own], [(f.length_m, f.width_m) for f in fps]
        )
        cost = self._cost_matrix(idx, goals, cmd.assignment, fits)
        try:
            goal_of = assign_mod.assign(cost)
        except assign_mod.AssignmentError as exc:
            return str(exc)
        group = ParkGroup(
            idx,
            goals,
            cmd.assignment,
            goal_of,
            order,
            boundary,
            lay.method,
            report,
            goal_fps=tuple(fps),
            blocks=blocks,
            reach=reach,
            command=cmd,
        )
        bound_inputs = (
            self.world.grid,
            self.truth_poses()[idx],
            goals,
            min(f.width_m for f in own) / 2,
            self.info.max_speed_mps[idx],
        )
        return ParkPlan(group, bound_inputs, check_reach, flags)

    def _flag_unreachable(
        self, report: dict, goals: np.ndarray, fps, order, flagged: list | None = None
    ) -> None:
        """Flag, in the layout report, the spots no manoeuvre gets a skid into in fill order
        (:mod:`swarmpark.plan.spot_reach`; ``flagged`` if already found): the operator sees
        them before confirming; the skids still try. Parks of more than
        ``MAX_REACH_CHECKED`` spots are not checked (the check costs a few ms per spot), and
        the report says so."""
        if flagged is None and len(goals) > MAX_REACH_CHECKED:
            report["notices"] = list(report.get("notices", [])) + [
                f"manoeuvre check skipped: {len(goals)} spots (checked up to {MAX_REACH_CHECKED})"
            ]
            return
        if flagged is None:
            flagged = self._spot_check(goals, fps, order)()
        if not flagged:
            return
        report["unreachable_spots"] = as_report(flagged)
        report["notices"] = list(report.get("notices", [])) + [
            f"spot {f.spot} at ({f.pose[0]:.2f}, {f.pose[1]:.2f}): {f.reason}" for f in flagged
        ]

    def _spot_check(self, goals: np.ndarray, fps, order):
        """The manoeuvre check of a layout's spots on the map as it is now, to run now or
        later (:func:`swarmpark.plan.spot_reach.spot_reach`)."""
        grid = self.park_map.grid()
        return partial(
            spot_reach,
            grid.occupied,
            grid.origin,
            grid.resolution_m,
            goals,
            list(fps),
            order,
            finer=self._spot_window(),
        )

    def apply_park(self, plan: ParkPlan | str) -> Outcome:
        """Commit a plan of :meth:`prepare_park` (cheap; refused if it went stale)."""
        if isinstance(plan, str):
            return self._refuse("park", plan)
        group = plan.group
        idx = group.robots
        busy = [self.ids[i] for i in idx if self.teleop[i]]
        if busy:
            return self._refuse("park", f"park.robots: robot {busy[0]!r} is under teleop")
        # The command is good: drop these robots from other groups and from goto orders.
        self._leave_groups(idx)
        self.groups.append(group)
        goals = group.goals
        self._set_goals(idx, goals[group.goal_of])
        self.metrics.defer_lower_bound(*plan.bound_inputs)
        if not plan.reach_checked and len(goals) <= MAX_REACH_CHECKED:
            fps = group.goal_fps
            if plan.flags is not None:
                check = partial(list, plan.flags)
            else:
                check = self._spot_check(np.array(goals), fps, tuple(group.fill_order))
            self.metrics.defer_spot_check(self.t, check)
        extra = {}
        if group.report.get("unreachable_spots"):
            extra["unreachable_spots"] = group.report["unreachable_spots"]
        return self._accept(
            "park",
            robots=[self.ids[i] for i in idx],
            method=group.method,
            goals=np.round(goals[group.goal_of], 4).tolist(),
            **extra,
        )

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

        widths = [self.info.footprints[i].width_m for i in idx]
        cm = build_costmap(self.park_map.grid(), min(widths) / 2, min(widths) / 2)
        return path_length_matrix(cm, self.poses_known[idx, :2], goals[:, :2])

    def goto(self, cmd: GotoCmd) -> Outcome:
        if cmd.robot not in self.index:
            return self._refuse("goto", f"goto.robot: unknown robot {cmd.robot!r}")
        i = self.index[cmd.robot]
        if self.teleop[i]:
            return self._refuse("goto", f"goto.robot: robot {cmd.robot!r} is under teleop")
        goal = np.array([cmd.pose[0], cmd.pose[1], np.deg2rad(cmd.pose[2])])
        reason = self._goal_reachability(i, goal) or self._goal_connected(i, goal)
        if reason:
            return self._refuse("goto", reason)
        self._leave_groups(np.array([i]))
        if cmd.priority is not None:
            self.priority[i] = cmd.priority
        self._set_goals(np.array([i]), goal[None])
        return self._accept("goto", robot=cmd.robot, pose=np.round(goal, 4).tolist())

    def _goal_reachability(self, i: int, goal: np.ndarray) -> str:
        """Reason a goal pose cannot be taken (footprint in a wall or off the map), or ''.
        With onboard sensing it is judged on what the operator knows (:attr:`park_map`: the
        prior map and the detections), as the park's layout is, never the scenario's
        obstacles."""
        from swarmpark.core.geometry import convex_gap, footprint_corners

        corners = footprint_corners(goal[None], self._corners_body[i : i + 1])
        where = [round(float(goal[0]), 3), round(float(goal[1]), 3)]
        where.append(round(float(np.rad2deg(goal[2])), 1))
        if self.sensing is not None:
            return self._goal_on_known_map(i, where, corners[0])
        pieces = self._static_pieces
        gap = convex_gap(np.repeat(corners, len(pieces), axis=0), pieces)
        if np.any(gap < 0):
            owner = self._static_owner[int(np.argmin(gap))]
            return (
                f"goto.pose: robot {self.ids[i]!r} would overlap {owner.replace(':', ' ')} at "
                f"{where}"
            )
        if self.world.off_map_or_in_cells(corners)[0]:
            return (
                f"goto.pose: robot {self.ids[i]!r} would be in an occupied cell of the map or "
                f"outside it at {where}"
            )
        return ""

    def _goal_connected(self, i: int, goal: np.ndarray) -> str:
        """Reason the skid cannot get to ``goal`` at all on the known map (every way there
        narrower than the skid is wide: a closed room, a pocket behind obstacles), or ''.
        Judged on the map's own grid, more leniently than the navigation plans (on a
        coarser grid), so that a goal refused here is out of reach for certain."""
        from swarmpark.plan.grid import build_costmap, plan_path

        grid, half = self.known_grid, self.info.footprints[i].width_m / 2
        cached = self._goto_costmap
        if cached is None or cached[0] is not grid or cached[1] != half:
            cached = self._goto_costmap = (grid, half, build_costmap(grid, half, half))
        if plan_path(cached[2], self.poses_known[i, :2], goal[:2]) is not None:
            return ""
        where = [round(float(goal[0]), 3), round(float(goal[1]), 3)]
        where.append(round(float(np.rad2deg(goal[2])), 1))
        return (
            f"goto.pose: robot {self.ids[i]!r} has no way to {where} on the known map (every "
            f"way there is narrower than its width, {2 * half:.2f} m)"
        )

    def _goal_on_known_map(self, i: int, where: list, corners: np.ndarray) -> str:
        """:meth:`_goal_reachability` on the sensed map (footprint ``corners`` at the goal
        ``where``, rounded, in degrees)."""
        known = self.park_map
        xmin, ymin, xmax, ymax = known.prior.bounds
        if np.any(corners < (xmin, ymin)) or np.any(corners > (xmax, ymax)):
            return f"goto.pose: robot {self.ids[i]!r} would reach outside the map at {where}"
        body = Polygon(corners)
        solids = known.solids(body)
        if solids is not None and solids.intersection(body).area > 1e-6:
            return (
                f"goto.pose: robot {self.ids[i]!r} would overlap a wall or a detected obstacle "
                f"of the known map at {where}"
            )
        return ""

    def formation(self, cmd) -> Outcome:
        """Move a group along paths holding a formation (Liu, Sun, Zhu 2010); the group is
        handed back to the navigation stack for the final docking when the plan ends."""
        from swarmpark.control.formation.run import (
            FormationError,
            FormationRun,
            first_map_conflict,
        )

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
                [self.info.footprints[i] for i in idx],
                self.info.max_speed_mps[idx],
                self.info.max_accel_mps2[idx],
                cmd,
                self.t,
            )
        except (ValueError, FormationError) as exc:
            return self._refuse("formation", str(exc))
        conflict = first_map_conflict(
            run.problem.paths, [self.info.footprints[i] for i in idx], self.known_grid
        )
        if conflict is not None:
            k, s, pose, off = conflict
            how = (
                "its path is the leader's carried at its offset: draw the leader's path "
                "farther from it, or give one path per robot"
                if k > 0 and len(cmd.paths) == 1
                else "draw the path clear of it"
            )
            return self._refuse(
                "formation",
                f"formation.paths: robot {self.ids[idx[k]]!r} would "
                f"{'leave the map' if off else 'hit a wall or obstacle'} {s:.1f} m along its "
                f"path, at ({pose[0]:.2f}, {pose[1]:.2f}) m ({how})",
            )
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
        mask = np.zeros(self.n, dtype=bool)
        for f in self._running_formations():
            mask[f.idx] = True
        return mask

    def _running_formations(self) -> list:
        """The formation plans still driving their skids (until each ends, plus a grace time)."""
        return [
            f
            for f in self.formations
            if self.t - f.t0 <= f.adjuster.plan.duration_s + FORMATION_GRACE_S
        ]

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
        self.health.release(idx)
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

    def _reassign(self) -> None:
        """Re-run each parking group's assignment (2018 Algorithm 2), with hysteresis."""
        for g in self.groups:
            new = self._reassigned(g, g.goal_of)
            if new is not None:
                g.switches += int(np.sum(new != g.goal_of))
                g.goal_of = new
                self._set_goals(g.robots, g.goals[new])

    def _reassigned(self, g, goal_of: np.ndarray) -> np.ndarray | None:
        """What the re-assignment makes of group ``g``'s goals ``goal_of``: the new goal per
        robot, or None where it keeps them (within its hysteresis, or because it would take a
        spot from under a skid parked or docking on it)."""
        if g.cost == "sequential" or len(g.robots) < 2:
            return None
        if g.cost == "path":
            return None  # path costs are recomputed on replans only (Dijkstra per goal)
        fps = [self.info.footprints[i] for i in g.robots]
        dims = [(f.length_m, f.width_m) for f in fps]
        pos_err, head_err = goal_errors(self.poses_known[g.robots], g.goals[goal_of])
        locked = (pos_err <= POSITION_TOL_M) & (head_err <= HEADING_TOL_RAD)
        docking = pos_err <= DOCKING_LOCK_M  # parked or docking
        try:
            if len(g.robots) > assign_mod.LOCAL_REASSIGN_ABOVE:
                new, changed = self._reassign_local(g, goal_of, dims, locked)
            else:
                fits = assign_mod.footprint_fits(dims, g.goal_dims)
                cost = self._cost_matrix(g.robots, g.goals, g.cost, fits)
                new, changed = assign_mod.reassign(cost, goal_of, locked)
        except assign_mod.AssignmentError:
            return None
        if not changed or np.any(new[docking] != goal_of[docking]):
            return None
        return new

    def _hand_over(self) -> None:
        """Swap the goals of a skid waiting outside for a deeper one and the skid it waits
        for, when it stands nearer that deeper goal (:func:`.fill_order.hand_over`), unless
        the re-assignment, run on the swapped goals, would change them (:meth:`_reassigned`;
        it has just run on the goals before the swap, so a change is the swap undone)."""
        for g in self.groups:
            if g.cost == "sequential" or (g.reach is None and not any(g.blocks)):
                continue
            dims = [(f.length_m, f.width_m) for f in (self.info.footprints[i] for i in g.robots)]
            fit = assign_mod.footprint_fits(dims, g.goal_dims)
            pair = fill_order.hand_over(
                g, self.poses_known, (lambda a, j, fit=fit: bool(fit[a, j])) if fit.size else None
            )
            if pair is None:
                continue
            a, b = pair
            new = g.goal_of.copy()
            new[a], new[b] = g.goal_of[b], g.goal_of[a]
            if self._reassigned(g, new) is not None:
                continue
            g.switches += 2
            g.goal_of = new
            self._set_goals(g.robots, g.goals[new])

    def _reassign_local(self, g, goal_of, dims, locked) -> tuple[np.ndarray, bool]:
        """A large group's re-assignment of goals ``goal_of`` by swaps between neighbours
        (O(n k), not O(n^3))."""
        rd, gd = np.asarray(dims, float), np.asarray(g.goal_dims, float).reshape(-1, 2)

        def fits(rows, cols):
            tol = 1e-9
            return (rd[rows, 0] <= gd[cols, 0] + tol) & (rd[rows, 1] <= gd[cols, 1] + tol)

        return assign_mod.reassign_local(
            self.poses_known[g.robots, :2],
            g.goals[:, :2],
            goal_of,
            g.cost,
            fits=fits if len(gd) else None,
            locked=locked,
        )

    def hold_zones(self, short: np.ndarray | None = None) -> list:
        """Where each robot held back by the fill order waits outside of: its parking
        boundary, or for the robots in ``short`` (following a skid bound deeper) its own
        spot grown by the room the skid needs to turn on the spot (its reach)."""
        zones: list = [None] * self.n
        for g in self.groups:
            for row, r in enumerate(g.robots):
                if short is not None and short[r]:
                    fp = self.info.footprints[r]
                    spot = footprint_polygon(g.goals[g.goal_of[row]], fp)
                    zones[r] = spot.buffer(fp.reach_m)
                else:
                    zones[r] = g.boundary
        return zones
