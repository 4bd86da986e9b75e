"""Sensing orchestration: localization, obstacle detection and replanning on what the link reports.

With ``sensing.localization: amcl`` every skid localizes as its onboard stack would: its own
AMCL filter fed with the odometry and the scans its link reports (2018 paper, Sect. 3.5).
What the scans show and the map does not goes into the fleet's costmap (Sect. 3.5.1):
planning and avoidance then use the walls and those detections instead of the scenario's
obstacles and people, and a skid whose path ahead runs into a new detection plans again.

Nothing here sees the simulator's truth: only :class:`~swarmpark.links.base.Inbox` state.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from swarmpark.core.geometry import pad_polygons, triangulate
from swarmpark.links.base import FleetInfo, Inbox, TrackedPeople
from swarmpark.world.scenario import World

__all__ = [
    "OnboardSensing",
    "AMCL_BEAMS",
    "ESTIMATE_JUMP_M",
    "DETECTION_PLAN_PERIOD_S",
    "DETECTION_SQUARE_M",
    "PERSON_RADIUS_M",
    "PERSON_MOVED_M",
    "PERSON_MAX_SPEED_MPS",
    "PERSON_LEFT_M",
]

#: Beams of each scan scored by the particle filter (a subsample, as AMCL's max_beams).
AMCL_BEAMS = 240
#: An estimate that jumps this far in one tick (a relocalized skid) makes the skid replan.
ESTIMATE_JUMP_M = 0.5
#: With onboard sensing, the planner's map (the static map plus the detected obstacles) is
#: refreshed this often (a costmap's update rate; planning itself is event-driven).
DETECTION_PLAN_PERIOD_S = 1.0
#: Detected obstacle cells go to the reactive layer (potential field, collision monitor, ORCA)
#: as static solids: one square of this size for each square holding detected cells.
DETECTION_SQUARE_M = 0.1
#: Tracked people are given to navigation with this radius (the tracker sees centroids).
PERSON_RADIUS_M = 0.25
#: A track is a person once it has moved this far from where it was first seen: crates and
#: parts of the map the scans see differently never move, so they stay detections only.
PERSON_MOVED_M = 0.5
#: ... and never faster than this (people walk at up to about 2 m/s): the centroid of the
#: visible part of a crate's edge slides along it as a skid drives by, at 2-3 m/s.
PERSON_MAX_SPEED_MPS = 2.0
#: ... and where it was first seen is free of detections by then (within this distance).
PERSON_LEFT_M = 0.2


class OnboardSensing:
    """Per-skid AMCL and the fleet's shared obstacle detection.

    Parameters
    ----------
    world
        The scenario's world: the map the skids believe in (``sensing.map``, else the map),
        the static obstacles the operator placed (known, so their beams are not scored) and
        the scanner's settings.
    info
        The fleet's static facts from the link (start poses seed the filters).
    inbox
        The link's state at connect (the odometry the filters start from).
    base_grid
        The planner's map before detections.
    """

    def __init__(self, world: World, info: FleetInfo, inbox: Inbox, base_grid) -> None:
        from swarmpark.sense.amcl import RECOVERY, FilterConfig, FleetLocalizer, LikelihoodField
        from swarmpark.sense.amcl.coop import CoopConfig
        from swarmpark.sense.costmap import FleetLayer, LocalCostmap
        from swarmpark.sense.lidar import LidarSpec

        cfg = world.scenario.sensing
        self.n = info.n
        self.lidar_spec = LidarSpec(
            num_beams=cfg.lidar_beams,
            max_range_m=cfg.lidar_range_m,
            range_noise_std_m=cfg.range_noise_std_m,
            dropout_prob=cfg.dropout_prob,
        )
        tris = [t for poly in world.static_obstacles for t in triangulate(poly)]
        self._obstacle_tris = pad_polygons(tris, 4) if tris else np.zeros((0, 4, 2))
        _, loc_seed = np.random.SeedSequence(world.scenario.seed).spawn(2)
        self.localizer = FleetLocalizer(
            LikelihoodField(world.believed_grid or world.grid, max_range_m=cfg.lidar_range_m),
            self.lidar_spec,
            info.start_poses.copy(),
            rng=np.random.default_rng(loc_seed),
            footprint=info.footprints[0],
            config=FilterConfig(
                max_beams=AMCL_BEAMS, alpha_fast=RECOVERY.alpha_fast if cfg.recovery else 0.0
            ),
            odom_start=inbox.odom.copy(),
            coop=CoopConfig() if cfg.cooperative else None,
            footprints=info.footprints,
        )
        self.estimates = self.localizer.estimates.copy()
        self._base_grid = base_grid
        self.costmap = LocalCostmap(base_grid, self.n, self.lidar_spec)
        self.fleet_layer = FleetLayer(self.costmap)
        self.known_grid = base_grid.copy()
        self._detected_mask = np.zeros(base_grid.shape, dtype=bool)
        self._plan_grid_t = -np.inf
        pieces, owners = world.static_convex_pieces()
        self._wall_pieces = pieces[np.array([o == "wall" for o in owners])]
        self._detected_squares = np.zeros((0, 2), dtype=np.int64)
        #: ``(M, 2)`` (row, col) cells of ``base_grid`` in the fleet's obstacle layer after the
        #: last scans (what the park layout adds to the prior map, supervisor/known_map.py).
        self.detected_cells = np.zeros((0, 2), dtype=np.int64)
        #: ``(M, 2)`` the same cells' centres (world frame).
        self.detected_points = np.zeros((0, 2))
        #: Each skid's last scan (returns off other skids masked, ``nan``) and the pose it
        #: believed it took it at: what lies behind the detections (sense/shadow.py).
        self.last_scans = np.full((self.n, self.lidar_spec.num_beams), np.nan)
        self.last_scan_poses = self.estimates.copy()
        self.static_view = self._wall_pieces  # walls and detected squares, for the view
        from swarmpark.sense.tracking import PeopleTracker

        self.tracker = PeopleTracker()
        self._movers: set[int] = set()
        self._phantoms: set[int] = set()  # tracks too fast for a person, ever
        z = np.zeros((0, 2))
        #: The people the tracker follows (tracks that moved), as the link's message.
        self.people = TrackedPeople(0.0, z, z.copy(), np.zeros(0))

    @property
    def detected_squares(self) -> np.ndarray:
        """``(K, 2)`` integer indices of the :data:`DETECTION_SQUARE_M` squares holding
        detected obstacle cells (square ``(i, j)`` spans ``[i, i + 1) * DETECTION_SQUARE_M``
        in x, likewise in y), sorted."""
        return self._detected_squares

    def update(
        self, t: float, inbox: Inbox, has_goal: np.ndarray, paths, half_widths: np.ndarray
    ) -> np.ndarray:
        """Take the scans that arrived: localize the skids that sent one, feed the costmap, and
        return which skids must plan again (``(N,)`` bool): a jumped estimate (found again
        after a kidnapping) or a path ahead blocked by a new detection."""
        fresh = inbox.take_scans()
        replan = np.zeros(self.n, dtype=bool)
        if not len(fresh):
            return replan
        ranges = np.full((self.n, self.lidar_spec.num_beams), np.nan)
        for i in fresh:
            ranges[i] = inbox.scans[i]
        # Static obstacles are known but not in the map: their beams are not scored.
        known = self._obstacle_tris if len(self._obstacle_tris) else None
        before = self.estimates
        self.estimates = self.localizer.step(
            inbox.odom, ranges, known_polygons=known, robots=fresh
        ).copy()
        jumped = np.hypot(*(self.estimates[:, :2] - before[:, :2]).T) > ESTIMATE_JUMP_M
        replan |= jumped & has_goal
        replan |= self._detect(t, ranges, has_goal, paths, half_widths)
        return replan

    def _detect(self, t: float, ranges: np.ndarray, has_goal, paths, half_widths) -> np.ndarray:
        """Feed the scans (less the returns from other skids, whose places the fleet knows) to
        the costmap at the estimated poses; refresh the solids the reactive layer avoids and,
        at :data:`DETECTION_PLAN_PERIOD_S`, the planner's map. Detections are shared by the
        fleet (every skid's costmap merged, :class:`~swarmpark.sense.costmap.FleetLayer`: what
        only a skid whose scans do not fit the map sees fades out): the central controller
        plans for all."""
        others = self.localizer.other_skid_beams(ranges)
        seen = ranges if others is None else np.where(others, np.nan, ranges)
        self.costmap.update(t, self.estimates, seen)
        rows = np.flatnonzero(~np.all(np.isnan(ranges), axis=1))
        # New arrays, not in place: a server lays a park out off the sim thread.
        scans, poses = self.last_scans.copy(), self.last_scan_poses.copy()
        scans[rows], poses[rows] = seen[rows], self.estimates[rows]
        self.last_scans, self.last_scan_poses = scans, poses
        cells = self.fleet_layer.merge(t)
        grid = self._base_grid
        pts = grid.cell_to_world(cells) if len(cells) else np.zeros((0, 2))
        self.detected_cells, self.detected_points = cells, pts
        self._track_people(t, self.costmap.unexplained_points(self.estimates, seen), pts)
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
            self.static_view = np.concatenate([self._wall_pieces, boxes])
        replan = np.zeros(self.n, dtype=bool)
        if t - self._plan_grid_t >= DETECTION_PLAN_PERIOD_S - 1e-9:
            self._plan_grid_t = t
            mask = self.detected_mask()
            if not np.array_equal(mask, self._detected_mask):
                appeared = mask & ~self._detected_mask
                self._detected_mask = mask
                # A new object: the navigator rebuilds its costmap.
                self.known_grid = self.with_detections(mask)
                if appeared.any() and paths is not None:
                    replan = self._blocked_paths(
                        grid.cell_to_world(np.argwhere(appeared)), has_goal, paths(), half_widths
                    )
        return replan

    def detected_mask(self) -> np.ndarray:
        """``(H, W)`` bool: the cells of the planner's base map in the fleet's obstacle layer
        after the last scans (:attr:`detected_cells`)."""
        mask = np.zeros(self._base_grid.shape, dtype=bool)
        cells = self.detected_cells
        if len(cells):
            mask[cells[:, 0], cells[:, 1]] = True
        return mask

    def with_detections(self, mask: np.ndarray):
        """The base map with the cells ``mask`` occupied (a new grid)."""
        out = self._base_grid.copy()
        out.occupied |= mask
        out.unknown &= ~out.occupied
        return out

    def shadowed_mask(self) -> np.ndarray:
        """``(H, W)`` bool cells of the planner's base map behind what the skids' last scans
        detected that none of them saw free (:func:`swarmpark.sense.shadow.shadowed_cells`)."""
        from swarmpark.sense.shadow import shadowed_cells

        return shadowed_cells(
            self._base_grid,
            self.lidar_spec,
            self.last_scan_poses,
            self.last_scans,
            map_tolerance_m=self.costmap.config.map_tolerance_m,
        )

    def _track_people(self, t: float, points: np.ndarray, detected: np.ndarray) -> None:
        """Feed the fleet's people tracker (:mod:`swarmpark.sense.tracking`) with the points
        the map does not explain and publish the tracks that have moved as people (with
        their velocities: navigation predicts them). ``detected`` ``(M, 2)``: the fleet's
        detected obstacle cells (world)."""
        tracks = self.tracker.update(t, points)
        tree = cKDTree(detected) if len(detected) else None
        for tr in tracks:
            if tr.id in self._movers or tr.id in self._phantoms:
                continue
            if np.hypot(*tr.state[2:]) > PERSON_MAX_SPEED_MPS:
                self._phantoms.add(tr.id)
            elif np.hypot(*(tr.state[:2] - tr.history[0][1:])) >= PERSON_MOVED_M:
                # Someone who walked off has left the place free; the visible piece of a
                # crate's edge "moves" along the edge, which is still there.
                start = np.array(tr.history[0][1:])
                left = tree is None or not tree.query_ball_point(start, PERSON_LEFT_M)
                (self._movers if left else self._phantoms).add(tr.id)
        people = [tr for tr in tracks if tr.id in self._movers and tr.id not in self._phantoms]
        live = {tr.id for tr in self.tracker.tracks}
        self._movers &= live
        self._phantoms &= live
        xy = np.array([tr.state[:2] for tr in people]).reshape(-1, 2)
        vel = np.array([tr.state[2:] for tr in people]).reshape(-1, 2)
        self.people = TrackedPeople(t, xy, vel, np.full(len(people), PERSON_RADIUS_M))

    def _blocked_paths(self, new_xy: np.ndarray, has_goal, paths, half_widths) -> np.ndarray:
        """Skids whose planned path (the part still ahead) runs within a skid's half width
        (plus :data:`DETECTION_SQUARE_M`) of newly detected obstacle points."""
        out = np.zeros(self.n, dtype=bool)
        tree = cKDTree(new_xy)
        for i, path in enumerate(paths):
            if path is None or len(path) < 2 or not has_goal[i]:
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
            reach = half_widths[i] + DETECTION_SQUARE_M
            if np.isfinite(tree.query(ahead, distance_upper_bound=reach)[0]).any():
                out[i] = True
        return out
