"""Path planning for the navigator: least-cost paths on the inflated costmap (2018 paper,
Sect. 3.4) that end with a straight run along the goal's axis, a bounded number per tick."""

from __future__ import annotations

import numpy as np

from swarmpark.control.base import ControlView
from swarmpark.control.nav.fleetmap import (
    FleetState,
    blocking,
    fleet_layers,
    points_in_rects,
    run_extra,
)
from swarmpark.control.nav.follower import PathFollower, PathState, point_at
from swarmpark.control.nav.params import FleetMapParams, PeopleParams, PlannerParams
from swarmpark.core.geometry import Footprint
from swarmpark.plan.grid import Costmap, build_costmap, path_length, paths_from, shortcut

__all__ = ["Planner", "run_clear"]


class Planner:
    """Plans when a goal changes, again every ``replan_period_s`` after a failure, and (given
    the fleet) on the fleet layers, repaired when blocked or stuck (:mod:`.fleetmap`).

    Parameters
    ----------
    params
        :class:`~swarmpark.control.nav.params.PlannerParams`.
    fleet_params
        :class:`~swarmpark.control.nav.params.FleetMapParams` (fleet layers, repairs).
    staging_m
        The path is planned to a staging point this far before the goal on its axis (the
        docking run-up), and the goal appended.
    direct_within_m
        Closer to the goal than this, the path goes there directly (the docking manoeuvre
        takes over there).
    people
        :class:`~swarmpark.control.nav.params.PeopleParams` of the people yield: a stuck
        skid's repair keeps its stand-off from the people standing (None: people are left
        out of plans).
    zones
        A function of the view giving the map's bottleneck zones
        (:class:`~swarmpark.plan.bottlenecks.Bottlenecks`, kept while the map and the fleet
        are); in those that are doors the costmap's band is ``params.zone_band_m`` wider
        (None: nowhere).
    """

    def __init__(
        self,
        params: PlannerParams,
        *,
        staging_m: float,
        direct_within_m: float,
        fleet_params: FleetMapParams | None = None,
        people: PeopleParams | None = None,
        zones=None,
    ):
        self.params = params
        self._zones_of = zones
        self._zones = None
        #: The people yield's stand-off, for a stuck skid's repair round people standing
        #: (None: people are left out of plans).
        self.people = people
        self.fleet_params = FleetMapParams() if fleet_params is None else fleet_params
        self._parked: np.ndarray | None = None  # the parked skids of the last tick
        #: Skids whose plan is repaired next tick round the parked skids (:meth:`repair`).
        self._asked: set[int] = set()
        self.staging_m = staging_m
        self.direct_within_m = direct_within_m
        # Inflated costmaps per footprint, for the grid they were built on (held, so a new
        # map, e.g. with detected obstacles, is a different object).
        self._costmaps: dict[tuple[float, float], Costmap] = {}
        self._grid = None

    def costmap(self, view: ControlView, fp: Footprint) -> Costmap:
        """The costmap inflated for footprint ``fp`` on the view's grid (cached)."""
        key = (round(fp.width_m / 2, 4), round(fp.reach_m, 4))
        p = self.params
        z = self._zones_of(view) if self._zones_of is not None and p.zone_band_m > 0 else None
        if self._grid is not view.grid or self._zones is not z:
            self._costmaps, self._grid, self._zones = {}, view.grid, z
        if key not in self._costmaps:
            self._costmaps[key] = build_costmap(
                view.grid,
                key[0],
                key[1],
                resolution_m=p.plan_resolution_m,
                seen_within_m=p.seen_within_m,
                blind_weight=p.blind_weight,
                wide_at=None if z is None else _in_doors(z, view.footprints, p),
                wide_band_m=p.zone_band_m,
            )
        return self._costmaps[key]

    def update(
        self,
        view: ControlView,
        states: list[PathState],
        follower: PathFollower,
        fleet: FleetState | None = None,
    ) -> None:
        """Plan for the active robots whose goal changed, whose failed plan is due, or whose
        plan needs a repair (:mod:`.fleetmap`; only with ``fleet``)."""
        p = self.params
        active = np.flatnonzero(view.active)
        # Stale plans (for another goal) found for the whole fleet at once; failed plans are
        # few, so they are checked one by one.
        redo = follower.waiting(view, active, states) | view.goal_changed[active]
        wanted = [
            i
            for i, again in zip(active.tolist(), redo.tolist(), strict=True)
            if again or (states[i].failed and view.t - states[i].planned_t >= p.replan_period_s)
        ]
        # Repairs (only with the fleet known): on the fleet layers. A new goal's first plan and
        # the retries of a failed one are on the static map, as the skid will find the fleet
        # moved by the time it gets there.
        repair: set[int] = set()
        stuck: set[int] = set()
        asked, self._asked = self._asked, set()
        if fleet is not None:
            # Where the skids on their way stand on their paths: one projection for both.
            rows, left = self._remaining(
                view, np.flatnonzero(view.active & fleet.bound & ~fleet.parked), follower
            )
            stuck = self._stuck(view, states, fleet, rows, left)
            blocked = self._blocked(view, states, fleet, rows, left) | asked
            repair = (blocked | stuck) - set(wanted)
            wanted = sorted(set(wanted) | repair)
        # A bounded number of plans per tick (longest waiting first), and a bounded search
        # effort (cells expanded), so a park command for hundreds of skids does not stall the
        # loop; the others wait for their path.
        wanted.sort(key=lambda i: (states[i].planned_t, i))
        work: list[int] = []
        done: set[int] = set()
        for i in wanted[: p.max_plans_per_tick]:
            if sum(work) >= p.max_plan_cells_per_tick:
                break
            done.add(i)
            st = states[i]
            goal = view.goals[i]
            cm = self.costmap(view, view.footprints[i])
            path = None
            if i in repair:
                # A blocked plan goes round the skids parked on it; a stuck skid's also round
                # the skids standing still and, if it can, off the spots still to be filled.
                parked = fleet.parked | (fleet.still if i in stuck else False)
                bound = fleet.bound if i in stuck else np.zeros_like(fleet.bound)
                extra = run_extra(view, i, parked, bound, self.fleet_params)
                people = self._standing_people(view) if i in stuck else None
                with fleet_layers(cm, view, i, parked, bound, self.fleet_params, people) as fcm:
                    path = self.plan(
                        fcm, view.poses[i], goal, extra, work=work, footprint=view.footprints[i]
                    )
            if path is None:  # no way around the fleet: the static map's (avoidance copes)
                path = self.plan(cm, view.poses[i], goal, work=work, footprint=view.footprints[i])
            st.path, st.path_goal, st.planned_t = path, goal.copy(), view.t
            st.best_left_m, st.best_t = np.inf, view.t
            st.failed = path is None
            if path is not None:
                st.reverse = follower.choose_end(view, i, path)
        self._asked = (asked & repair) - done  # asked for, but over this tick's budget

    def _standing_people(self, view: ControlView):
        """The people standing (slower than the yield's ``walking_mps``) as discs to keep
        off: centres and their radii plus the yield's stand-off from a standing person
        (``clearance_m + standing_berth_m``), or None without the yield."""
        pp = self.people
        if pp is None or not len(view.people_xy):
            return None
        still = np.hypot(*view.people_vel.T) < pp.walking_mps
        berth = pp.clearance_m + pp.standing_berth_m
        return view.people_xy[still], view.people_radius[still] + berth

    def repair(self, i: int) -> None:
        """Plan skid ``i`` again at the next update, round the parked skids (as when a skid
        parks on its path), e.g. when it is cut off from its spot (:func:`.make_room.cut_off`)."""
        self._asked.add(int(i))

    def _remaining(
        self, view: ControlView, idx: np.ndarray, follower: PathFollower
    ) -> tuple[np.ndarray, np.ndarray]:
        """Robots of ``idx`` with a usable path, and the path length left to each goal."""
        pk = follower.packed
        rows = idx[pk.nseg[idx] > 0]
        if not len(rows):
            return rows, np.zeros(0)
        _, s_here = pk.project(rows, view.poses[rows, :2])
        return rows, pk.cum[rows, pk.nseg[rows]] - s_here

    def _blocked(self, view: ControlView, states: list[PathState], fleet, rows, left) -> set[int]:
        """Robots (of ``rows``, with ``left`` metres of path to go) whose path runs into a
        skid that parked since the last tick."""
        prev = self._parked
        self._parked = fleet.parked.copy()
        if prev is None or len(prev) != len(fleet.parked):
            return set()
        new = fleet.parked & ~prev
        if not new.any():
            return set()
        out: set[int] = set()
        step = self.params.staging_check_points
        for i, left_m in zip(rows.tolist(), left.tolist(), strict=True):
            st = states[i]
            if st.path is None or not st.is_for(view.goals[i]):
                continue
            block = blocking(view, i, new)
            if not block.any():
                continue
            geom = st.geometry()
            s = np.arange(geom.cum[-1] - left_m, geom.cum[-1], self.staging_m / step)
            pts = np.array([point_at(st.path, geom.cum, v)[0] for v in s]).reshape(-1, 2)
            r_in = view.footprints[i].width_m / 2
            js = np.flatnonzero(block)
            fps = [view.footprints[j] for j in js]
            if points_in_rects(pts, view.poses[js], fps, r_in - 1e-3).any():
                out.add(i)
        return out

    def _stuck(self, view: ControlView, states: list[PathState], fleet, rows, left) -> set[int]:
        """Robots (of ``rows``, with ``left`` metres of path to go) that have made no progress
        along their path for ``stuck_s`` (and are not yet where the docking manoeuvre takes
        over)."""
        fp = self.fleet_params
        out: set[int] = set()
        for i, left_m in zip(rows.tolist(), left.tolist(), strict=True):
            st = states[i]
            if fleet.waiting[i]:  # waiting on purpose: the clock stops
                st.best_left_m, st.best_t = left_m, view.t
            elif left_m < st.best_left_m - fp.stuck_progress_m:
                st.best_left_m, st.best_t = left_m, view.t
            elif (
                view.t - st.best_t >= fp.stuck_s
                and view.t - st.planned_t >= fp.stuck_s
                and left_m > self.direct_within_m
            ):
                out.add(i)
        return out

    def plan(
        self,
        cm: Costmap,
        pose: np.ndarray,
        goal: np.ndarray,
        run_extra=None,
        *,
        work=None,
        footprint: Footprint | None = None,
    ) -> np.ndarray | None:
        """A path that ends with a straight run along the goal's axis.

        The path is planned to a staging point ``staging_m`` before the goal on its axis
        (behind it, to drive in forwards, or in front of it, to back in: whichever is shorter,
        or on the fleet layers costs less, the run included) and the goal is appended, so the
        skid arrives aligned. Falls back to a direct path when neither staging point can be
        reached or the skid is already close. ``run_extra(points)``: the extra cost per metre the
        fleet layers add along a run (``inf``: blocked by a parked skid). ``work``: if given (a
        list), the number of grid cells the search expanded is appended to it. ``footprint``:
        the skid's, whose straight run from a staging point to the goal must be clear of the
        map's walls (:func:`run_clear`), not only the axis line.
        """
        axis = np.array([np.cos(goal[2]), np.sin(goal[2])])
        stages = [goal[:2] + side * self.staging_m * axis for side in (-1.0, 1.0)]
        # One search serves the direct path and both staging points.
        costs: list[float] = []
        direct, *heads = paths_from(
            cm, pose[:2], np.vstack([goal[:2], *stages]), costs=costs, expanded=work
        )
        # The direct path is shortcut only if it is the one returned.
        if direct is None:
            return None
        if np.linalg.norm(goal[:2] - pose[:2]) < self.direct_within_m:
            # Close by, straight in, unless the side it stands on has no clear run to the
            # spot (a pillar beside it): then round to the other side's staging point.
            side = -1 if np.dot(pose[:2] - goal[:2], axis) < 0 else 1
            near = stages[(side + 1) // 2]
            if footprint is None or run_clear(cm.grid, goal, near, footprint):
                return shortcut(direct, cm.cost, cm.grid, cm.blind)
        best, best_cost = None, np.inf
        for stage, head, c in zip(stages, heads, costs[1:], strict=True):
            run = self._run_cost(cm, goal, stage, run_extra)
            if footprint is not None and not run_clear(cm.grid, goal, stage, footprint):
                run = np.inf
            if head is None or not np.isfinite(run):
                continue
            cand = np.vstack([shortcut(head, cm.cost, cm.grid, cm.blind), goal[:2][None]])
            # On the static map the shorter path wins; on the fleet layers the cheaper one (a
            # path through the spots of skids still on their way costs more than its length).
            total = path_length(cand) if run_extra is None else c + run
            if total < best_cost:
                best, best_cost = cand, total
        return best if best is not None else shortcut(direct, cm.cost, cm.grid, cm.blind)

    def _run_cost(self, cm: Costmap, goal: np.ndarray, stage: np.ndarray, run_extra) -> float:
        """Cost of the straight run from the staging point to the goal: its length, times
        ``1 +`` what ``run_extra`` adds along it (the fleet layers; ``inf`` if blocked), or
        ``inf`` if a wall is in the way."""
        n = self.params.staging_check_points
        run = goal[:2][None] + np.linspace(0, 1, n)[:, None] * (stage - goal[:2])[None]
        rc = cm.grid.world_to_cell(run)
        if not cm.grid.in_bounds(rc).all() or cm.grid.occupied[rc[:, 0], rc[:, 1]].any():
            return np.inf
        extra = 0.0 if run_extra is None else run_extra(run[1:])
        return float(np.linalg.norm(stage - goal[:2]) * (1.0 + extra))


def run_clear(grid, goal: np.ndarray, stage: np.ndarray, footprint: Footprint) -> bool:
    """Whether a skid with ``footprint`` drives straight along the goal's axis from ``stage``
    to ``goal`` clear of ``grid``'s occupied cells: the rectangle it sweeps, shrunk by half a
    cell (a footprint touching a wall's cell is not blocked by it), sampled at half the
    resolution. The axis line alone passed a run past a pillar that overlapped the spot's
    side by 0.25 m: the skid came in beside the pillar and needed a manoeuvre (25 s) to get
    in, where backing in from the other side is clear."""
    axis = np.array([np.cos(goal[2]), np.sin(goal[2])])
    side = float(np.dot(stage[:2] - goal[:2], axis))
    res = grid.resolution_m
    shrink = 0.5 * res + 1e-6
    x0 = min(0.0, side) - footprint.pivot + shrink
    x1 = max(0.0, side) + footprint.length_m - footprint.pivot - shrink
    h = footprint.width_m / 2.0 - shrink
    if x1 <= x0 or h <= 0:
        return True
    xs = np.linspace(x0, x1, int(np.ceil((x1 - x0) / (0.5 * res))) + 1)
    ys = np.linspace(-h, h, int(np.ceil(2.0 * h / (0.5 * res))) + 1)
    bx, by = np.meshgrid(xs, ys)
    normal = np.array([-axis[1], axis[0]])
    pts = goal[:2] + bx.reshape(-1, 1) * axis + by.reshape(-1, 1) * normal
    rc = grid.world_to_cell(pts)
    inside = grid.in_bounds(rc)
    if not inside.all():
        return False
    return not grid.occupied[rc[:, 0], rc[:, 1]].any()


def _in_doors(z, footprints, p: PlannerParams):
    """A function of world points ``(K, 2)``: which lie in a door, a zone of ``z`` whose
    throat is at most ``p.door_throat_skids`` of the longest skid's lengths long (None: no
    zone is a door). Through a narrow corridor the band stays as elsewhere: a corridor's
    path has no jamb to turn round, and with the band there too the held-out corridors
    lost skids (docs/navigation.md, session 53, which says how this split was chosen)."""
    longest = max(f.length_m for f in footprints)
    doors = [k + 1 for k, t in enumerate(z.throats_m) if t <= p.door_throat_skids * longest]
    if not doors:
        return None
    return lambda xy: np.isin(z.zone_at(xy), doors)
