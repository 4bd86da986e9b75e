"""Path planning for the navigator: least-cost paths on the inflated costmap (2018 paper,
Sect. 3.4) that end with a straight run along the goal's axis, a bounded number per tick."""

from __future__ import annotations

import numpy as np

from swarmpark.control.base import ControlView
from swarmpark.control.nav.follower import PathFollower, PathState
from swarmpark.control.nav.params import PlannerParams
from swarmpark.core.geometry import Footprint
from swarmpark.plan.grid import Costmap, build_costmap, path_length, paths_from, shortcut

__all__ = ["Planner"]


class Planner:
    """Plans when a goal changes, and again every ``replan_period_s`` after a failure.

    Parameters
    ----------
    params
        :class:`~swarmpark.control.nav.params.PlannerParams`.
    staging_m
        The path is planned to a staging point this far before the goal on its axis (the
        docking run-up), and the goal appended.
    direct_within_m
        Closer to the goal than this, the path goes there directly (the docking manoeuvre
        takes over there).
    """

    def __init__(self, params: PlannerParams, *, staging_m: float, direct_within_m: float):
        self.params = params
        self.staging_m = staging_m
        self.direct_within_m = direct_within_m
        # Inflated costmaps per footprint, for the grid they were built on (held, so a new
        # map, e.g. with detected obstacles, is a different object).
        self._costmaps: dict[tuple[float, float], Costmap] = {}
        self._grid = None

    def costmap(self, view: ControlView, fp: Footprint) -> Costmap:
        """The costmap inflated for footprint ``fp`` on the view's grid (cached)."""
        key = (round(fp.width_m / 2, 4), round(fp.reach_m, 4))
        if self._grid is not view.grid:
            self._costmaps, self._grid = {}, view.grid
        if key not in self._costmaps:
            self._costmaps[key] = build_costmap(
                view.grid, key[0], key[1], resolution_m=self.params.plan_resolution_m
            )
        return self._costmaps[key]

    def update(self, view: ControlView, states: list[PathState], follower: PathFollower) -> None:
        """Plan for the active robots whose goal changed or whose failed plan is due."""
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
        # A bounded number of plans per tick (longest waiting first), so a park command for a
        # hundred skids does not stall the loop; the others wait for their path.
        wanted.sort(key=lambda i: (states[i].planned_t, i))
        for i in wanted[: p.max_plans_per_tick]:
            st = states[i]
            goal = view.goals[i]
            cm = self.costmap(view, view.footprints[i])
            path = self.plan(cm, view.poses[i], goal)
            st.path, st.path_goal, st.planned_t = path, goal.copy(), view.t
            st.failed = path is None
            if path is not None:
                st.reverse = follower.choose_end(view, i, path)

    def plan(self, cm: Costmap, pose: np.ndarray, goal: np.ndarray) -> np.ndarray | None:
        """A path that ends with a straight run along the goal's axis.

        The path is planned to a staging point ``staging_m`` before the goal on its axis
        (behind it, to drive in forwards, or in front of it, to back in: whichever plans
        shorter) and the goal is appended, so the skid arrives aligned. Falls back to a
        direct path when neither staging point can be reached or the skid is already close.
        """
        axis = np.array([np.cos(goal[2]), np.sin(goal[2])])
        stages = [goal[:2] + side * self.staging_m * axis for side in (-1.0, 1.0)]
        # One Dijkstra run serves the direct path and both staging points.
        direct, *heads = paths_from(cm, pose[:2], np.vstack([goal[:2], *stages]))
        if direct is not None:
            direct = shortcut(direct, cm.cost, cm.grid)
        if direct is None or np.linalg.norm(goal[:2] - pose[:2]) < self.direct_within_m:
            return direct
        best = None
        for stage, head in zip(stages, heads, strict=True):
            if head is None or not self._run_free(cm, goal, stage):
                continue
            cand = np.vstack([shortcut(head, cm.cost, cm.grid), goal[:2][None]])
            if best is None or path_length(cand) < path_length(best):
                best = cand
        return best if best is not None else direct

    def _run_free(self, cm: Costmap, goal: np.ndarray, stage: np.ndarray) -> bool:
        """Whether the straight run from the staging point to the goal is free."""
        n = self.params.staging_check_points
        run = goal[:2][None] + np.linspace(0, 1, n)[:, None] * (stage - goal[:2])[None]
        rc = cm.grid.world_to_cell(run)
        return bool(cm.grid.in_bounds(rc).all() and not cm.grid.occupied[rc[:, 0], rc[:, 1]].any())
