"""Mapping as a pose graph: keyframes, scan-matching odometry edges, loop closures and a map
re-rendered from the optimized poses (graph SLAM: Grisetti, Kümmerle, Stachniss and Burgard
2010, "A tutorial on graph-based SLAM").

:class:`PoseGraphMapper` wraps a :class:`~swarmpark.sense.mapping.GridMapper` (the front end:
scan-to-map ICP of every scan, a keyframe every 0.5 m / 15 deg). Each keyframe becomes a node
of a :class:`~swarmpark.sense.posegraph.PoseGraph` and keeps its scan. Consecutive keyframes
are joined by the front end's relative pose, unless the scan-to-scan ICP of the two disagrees
with it: then the front end snapped back onto an old part of the map, its relative pose
carries the correction (hiding the drift behind it from the graph), and the scan-to-scan
match is the edge. A new keyframe is matched against older keyframes (not the last
``min_separation_keyframes``) whose estimated pose is within ``search_radius_m``: place
recognition by proximity, then scan-to-scan ICP (:func:`~swarmpark.sense.scanmatch.
icp_point_to_line`, the front end's matcher) against the old keyframe and its neighbours. A
match becomes a loop-closure edge only if it passes five gates: enough inliers at the final
correspondence gate, a small RMS residual, points seen from the same side of their surfaces
in both scans (the two faces of a rack upright are 0.6 m apart and parallel), a translation
the scan constrains in both directions (a featureless corridor is refused), and uniqueness --
ICP started half a metre off in each direction must not settle elsewhere with an equally
good fit (rack uprights 3 m apart are refused when the guess is ambiguous). If a loop closure
shows drift (it moves the keyframe by a few centimetres or more, or the front end snapped
onto the old map), the graph is optimized and, if a pose moved, the occupancy grid is
re-rendered from the keyframe scans at their optimized poses.

The optimizer is swarmpark's scipy one (:mod:`swarmpark.sense.posegraph`, sparse analytic
Jacobian, Levenberg-Marquardt with a sparse direct solve). Checked instead (``pip download
--no-deps``): ``gtsam`` 4.3.0 has a cp311 wheel (34 MB, 113 MB unpacked, and it declares
``pytest`` as a runtime dependency); its Pose2 factors and iSAM2 would do the same job and
incrementally, but a 500-keyframe graph with 600 loop edges already optimizes in about 0.4 s
here (``swarmpark bench --only sense.posegraph``), which is small against a mapping run.
``small_gicp`` 1.0.1 (a 0.4 MB wheel) registers 3-D clouds: a 2-D scan lifted to z = 0 leaves
z, roll and pitch to be pinned by hand, it runs OpenMP threads (the core keeps out threads for
determinism), and it has no pose-graph back end; the 2-D point-to-line ICP here is enough for
scan-to-scan matching. Neither is worth a binary dependency.

Deterministic: no randomness, no wall-clock time; the same scans give the same map.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from swarmpark.core.gridmap import OccupancyGrid
from swarmpark.sense.mapping import GridMapper, MatchResult, compose, relative_pose
from swarmpark.sense.posegraph import PoseGraph
from swarmpark.sense.scanmatch import IcpFit, icp_point_to_line, surface_reference

__all__ = ["LoopClosureConfig", "PoseGraphMapper", "LoopClosure"]


def _transform(pose: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Points ``(K, 2)`` given in ``pose``'s frame, in the frame ``pose`` is expressed in."""
    c, s = np.cos(pose[2]), np.sin(pose[2])
    return np.column_stack(
        [pose[0] + c * pts[:, 0] - s * pts[:, 1], pose[1] + s * pts[:, 0] + c * pts[:, 1]]
    )


@dataclass(frozen=True, kw_only=True)
class LoopClosureConfig:
    """Loop-closure settings of :class:`PoseGraphMapper`.

    Parameters
    ----------
    enabled
        Look for loop closures (``False``: the graph only has odometry edges and is never
        optimized; the map is the front end's).
    search_radius_m
        Older keyframes whose estimated pose is this close are candidates.
    min_separation_keyframes
        The last this many keyframes are not candidates (they are the odometry chain).
    max_candidates
        At most this many candidates (the nearest) are matched per keyframe.
    submap_keyframes
        The candidate's reference is its scan plus this many neighbours on each side.
    match_points
        Scan points of the new keyframe used by the matcher.
    iterations, max_dist_m, min_dist_m
        ICP iteration cap and correspondence gate (wide first to absorb drift).
    min_inliers
        Share of scan points with a correspondence within ``min_dist_m`` at the end.
    max_rms_m
        RMS point-to-line residual at the end.
    min_facing
        Share of the matched points that must have been seen from the same side of their
        surface in both scans (else two faces of a thin thing were laid onto each other).
    min_constraint
        Smallest over largest eigenvalue of the translational block of ``J^T J``: below it
        the scan does not fix the position along some direction (a corridor).
    max_correction_m, max_correction_rad
        The match may move the new keyframe this far from where the graph has it.
    min_correction_m, min_correction_rad
        The graph is optimized only when a new loop closure moves its keyframe at least this
        far (or turns it this much) from where the graph has it, or when an odometry edge
        since the last optimization came from the scan-to-scan match (the front end snapped
        onto the old map, so the chain behind it holds drift). Smaller corrections are
        added as edges but do not trigger an optimization: the front end already closed that
        loop by matching against the old part of the map, and optimizing would only spread
        the matches' own errors (on the hangar route, 0.002 rad per loop edge twisted a
        25 m loop by 10 cm).
    ambiguity_offset_m, ambiguity_tolerance_m
        ICP is also started this far off along the body's x and y axes; if one of those
        settles more than ``ambiguity_tolerance_m`` from the first solution and passes the
        inlier and RMS gates, the place is ambiguous and the match is refused.
    sigma_m, independent_points
        Noise of a matched point and how many points count as independent: they turn the
        ICP's ``J^T J`` into an edge's information.
    odometry_sigma_m, odometry_sigma_rad
        Information floor of every edge, so that a direction the scans do not constrain is
        held by the front end's estimate.
    rerender_min_shift_m
        After an optimization, the grid is re-rendered only if a keyframe moved this much.
    snap_m, snap_rad
        The odometry edge between consecutive keyframes is the front end's relative pose
        unless the scan-to-scan match of the two differs from it by more than this (the
        front end snapped onto an old part of the map); then it is the scan-to-scan match.
    """

    enabled: bool = True
    search_radius_m: float = 4.0
    min_separation_keyframes: int = 20
    max_candidates: int = 2
    submap_keyframes: int = 2
    match_points: int = 300
    iterations: int = 30
    max_dist_m: float = 1.0
    min_dist_m: float = 0.1
    min_inliers: float = 0.6
    max_rms_m: float = 0.04
    min_constraint: float = 0.05
    min_facing: float = 0.9
    max_correction_m: float = 1.5
    min_correction_m: float = 0.03
    min_correction_rad: float = 0.01
    max_correction_rad: float = np.radians(20.0)
    ambiguity_offset_m: float = 0.5
    ambiguity_tolerance_m: float = 0.15
    sigma_m: float = 0.02
    independent_points: int = 25
    odometry_sigma_m: float = 0.1
    odometry_sigma_rad: float = 0.05
    rerender_min_shift_m: float = 0.01
    snap_m: float = 0.02
    snap_rad: float = 0.01

    def __post_init__(self) -> None:
        for name in ("search_radius_m", "max_dist_m", "min_dist_m", "sigma_m"):
            if not getattr(self, name) > 0:
                raise ValueError(f"loop_closure.{name} must be > 0 (got {getattr(self, name)})")
        if self.min_dist_m > self.max_dist_m:
            raise ValueError(
                "loop_closure.min_dist_m must be <= max_dist_m "
                f"(got {self.min_dist_m}, {self.max_dist_m})"
            )
        if self.independent_points < 1:
            raise ValueError(
                f"loop_closure.independent_points must be >= 1 (got {self.independent_points})"
            )
        if self.min_separation_keyframes < 1 or self.max_candidates < 1:
            raise ValueError(
                "loop_closure.min_separation_keyframes and max_candidates must be >= 1 (got "
                f"{self.min_separation_keyframes}, {self.max_candidates})"
            )
        if not 0 < self.min_inliers <= 1:
            raise ValueError(f"loop_closure.min_inliers must be in (0, 1] (got {self.min_inliers})")


@dataclass(frozen=True)
class LoopClosure:
    """An accepted loop-closure edge: keyframe ``j`` (new) seen from keyframe ``i`` (old)."""

    i: int
    j: int
    z: np.ndarray
    inlier_share: float
    rms_m: float
    drift: bool = False  # the match moved the keyframe by min_correction or more


@dataclass
class _Stats:
    tried: int = 0
    rejected: dict = field(default_factory=dict)
    log: list = field(default_factory=list)  # (old, new, inlier share, rms, verdict)
    optimizations: int = 0
    snaps: int = 0
    rerenders: int = 0


class PoseGraphMapper:
    """A :class:`GridMapper` whose keyframes form a pose graph with loop closures.

    Parameters
    ----------
    mapper
        The front end; its map is re-rendered when a loop closes.
    config
        Loop-closure settings.

    Call :meth:`update` as :meth:`GridMapper.update`. :attr:`keyframe_poses` are the graph's
    (optimized) poses, :attr:`loops` the accepted loop closures.
    """

    def __init__(self, mapper: GridMapper, config: LoopClosureConfig | None = None) -> None:
        self.mapper = mapper
        self.config = config if config is not None else LoopClosureConfig()
        self.graph = PoseGraph()
        self.ranges: list[np.ndarray] = []  # each keyframe's scan, to re-render the map
        self._body: list[np.ndarray] = []
        self._refs: dict[tuple, tuple] = {}
        self._eyes: dict[tuple, np.ndarray] = {}
        self._front: list[np.ndarray] = []  # the front end's pose of each keyframe
        self._unresolved = False
        self.loops: list[LoopClosure] = []
        self.stats = _Stats()
        cfg = self.config
        # ICP settings of the scan-to-scan matches: the front end's, with wider gates.
        self._icp = replace(
            mapper.config,
            match_iterations=cfg.iterations,
            match_max_dist_m=cfg.max_dist_m,
            match_min_dist_m=cfg.min_dist_m,
        )

    @property
    def pose(self) -> np.ndarray | None:
        """The front end's current map-frame pose."""
        return self.mapper.pose

    @property
    def keyframe_poses(self) -> np.ndarray:
        return self.graph.poses if len(self.graph) else np.zeros((0, 3))

    def update(
        self, odom: np.ndarray, ranges: np.ndarray, *, initial_pose: np.ndarray | None = None
    ) -> MatchResult:
        """:meth:`GridMapper.update`, plus a graph node when the scan became a keyframe."""
        before = self.mapper.scans
        result = self.mapper.update(odom, ranges, initial_pose=initial_pose)
        if self.mapper.scans > before:
            self._add_keyframe(self.mapper.pose.copy(), np.asarray(ranges, float).copy())
        return result

    def to_occupancy_grid(self, **kwargs) -> OccupancyGrid:
        return self.mapper.to_occupancy_grid(**kwargs)

    # -- graph --------------------------------------------------------------------------
    def _sample(self, body: np.ndarray) -> np.ndarray:
        n = self.config.match_points
        if len(body) <= n:
            return body
        return body[np.linspace(0, len(body) - 1, n).round().astype(int)]

    def _information(self, fit: IcpFit | None) -> np.ndarray:
        cfg = self.config
        floor = np.diag([cfg.odometry_sigma_m**-2] * 2 + [cfg.odometry_sigma_rad**-2])
        if fit is None:
            return floor
        n = max(fit.inlier_share * cfg.match_points, 1.0)
        # J^T J over the point noise is the information of n independent points; the points'
        # errors are correlated (the same walls, the same normals), so count at most
        # ``independent_points`` of them. J's rotation column is in metres (the lever arm), so
        # this weighs rotation against translation as the scan geometry does.
        info = fit.hessian * (min(n, cfg.independent_points) / n) / cfg.sigma_m**2
        return 0.5 * (info + info.T) + floor

    def _reference(self, k: int, span: int) -> tuple | None:
        """Points of keyframes ``k - span .. k + span`` (those that exist and are older than
        the newest) in keyframe ``k``'s frame, as a matcher reference."""
        key = (k, span)
        if key in self._refs:
            return self._refs[key]
        poses = self.graph.poses
        last = len(self._body) - 1
        parts, eyes = [], []
        for m in range(max(k - span, 0), min(k + span, last - 1) + 1):
            rel = relative_pose(poses[k], poses[m])
            parts.append(_transform(rel, self._body[m]))
            eyes.append(np.broadcast_to(rel[:2], parts[-1].shape))
        pts = np.concatenate(parts) if parts else np.zeros((0, 2))
        ref = surface_reference(pts) if len(pts) >= 10 else None
        # Where each point was seen from: the side of the surface it lies on.
        self._eyes[key] = np.concatenate(eyes) if eyes else np.zeros((0, 2))
        self._refs[key] = ref
        return ref

    def _facing_share(self, key: tuple, ref: tuple, body: np.ndarray, pose: np.ndarray) -> float:
        """Share of the matched points seen from the same side of their surface in both
        scans: a thin wall or a rack upright seen from its two sides gives two parallel faces
        (0.6 m apart for the racks) that ICP happily lays onto each other."""
        tree, ref_pts, normals = ref
        pts = _transform(pose, body)
        dist, j = tree.query(pts, distance_upper_bound=self.config.min_dist_m)
        ok = dist < np.inf
        if not ok.any():
            return 0.0
        jo = j[ok]
        # The side of the surface (its normal) each eye is on; the view directions themselves
        # may differ a lot (one wall seen from either end).
        side_ref = np.einsum("ij,ij->i", normals[jo], self._eyes[key][jo] - ref_pts[jo])
        side_new = np.einsum("ij,ij->i", normals[jo], pose[:2] - pts[ok])
        return float(np.mean(side_ref * side_new > 0.0))

    def _add_keyframe(self, pose: np.ndarray, ranges: np.ndarray) -> None:
        k = self.graph.add_node(pose)
        self.ranges.append(ranges)
        self._body.append(self.mapper.body_points(ranges))
        self._front.append(pose.copy())
        if k == 0:
            return
        # The front end's relative pose is the better odometry edge (matched against the map,
        # not one scan) -- except where it snapped back onto an old part of the map: then it
        # carries the correction a loop closure should spread, and the scan-to-scan match of
        # the two keyframes, which knows nothing of the old map, disagrees with it.
        front = relative_pose(self._front[k - 1], self._front[k])
        ref = self._reference(k - 1, 0)
        body = self._sample(self._body[k])
        fit = None
        if ref is not None and len(body) >= 3:
            fit = icp_point_to_line(body, front, ref, self.mapper.config)
            if fit.inlier_share < self.mapper.config.match_min_inliers:
                fit = None
        z = front
        if fit is not None:
            jump = relative_pose(front, fit.pose)
            if np.hypot(jump[0], jump[1]) > self.config.snap_m or abs(jump[2]) > (
                self.config.snap_rad
            ):
                z = fit.pose
                self.stats.snaps += 1
                self._unresolved = True  # the graph now disagrees with the front end's poses
        self.graph.add_edge(k - 1, k, z, self._information(fit))
        if self.config.enabled:
            self._close_loops(k)

    # -- loop closure -------------------------------------------------------------------
    def _candidates(self, k: int) -> list[int]:
        cfg = self.config
        old = k - cfg.min_separation_keyframes
        if old <= 0:
            return []
        poses = self.graph.poses
        d = np.hypot(*(poses[:old, :2] - poses[k, :2]).T)
        near = np.flatnonzero(d <= cfg.search_radius_m)
        if len(near) == 0:
            return []
        near = near[np.argsort(d[near], kind="stable")]
        # Spread the candidates over different passes: skip neighbours of one already taken.
        chosen: list[int] = []
        for m in near:
            if all(abs(int(m) - c) > 2 * cfg.submap_keyframes for c in chosen):
                chosen.append(int(m))
            if len(chosen) == cfg.max_candidates:
                break
        return chosen

    def _reject(self, why: str) -> None:
        self.stats.rejected[why] = self.stats.rejected.get(why, 0) + 1

    def _good(self, fit: IcpFit) -> bool:
        return fit.inlier_share >= self.config.min_inliers and fit.rms_m <= self.config.max_rms_m

    def match_keyframes(self, i: int, k: int) -> tuple[LoopClosure, IcpFit] | None:
        """Scan-to-scan ICP of keyframe ``k`` against keyframe ``i`` (and its neighbours) from
        the graph's current relative pose; the loop closure and its fit if it passes every
        gate, else ``None`` (the gate is counted in :meth:`summary`)."""
        cfg = self.config
        ref = self._reference(i, cfg.submap_keyframes)
        body = self._sample(self._body[k])
        if ref is None or len(body) < 10:
            self._reject("no points")
            return None
        poses = self.graph.poses
        guess = relative_pose(poses[i], poses[k])
        fit = icp_point_to_line(body, guess, ref, self._icp)
        self.stats.log.append((i, k, round(fit.inlier_share, 3), round(fit.rms_m, 4)))
        if not self._good(fit):
            self._reject("fit")
            return None
        corr = relative_pose(guess, fit.pose)
        if np.hypot(corr[0], corr[1]) > cfg.max_correction_m or abs(corr[2]) > (
            cfg.max_correction_rad
        ):
            self._reject("correction")
            return None
        if self._facing_share((i, cfg.submap_keyframes), ref, body, fit.pose) < cfg.min_facing:
            self._reject("opposite faces")
            return None
        ev = np.linalg.eigvalsh(fit.hessian[:2, :2])
        if ev[0] < cfg.min_constraint * max(ev[1], 1e-12):
            self._reject("degenerate")
            return None
        for off in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            start = compose(fit.pose, np.array([*off, 0.0]) * cfg.ambiguity_offset_m)
            other = icp_point_to_line(body, start, ref, self._icp)
            if self._good(other) and np.hypot(*(other.pose[:2] - fit.pose[:2])) > (
                cfg.ambiguity_tolerance_m
            ):
                self._reject("ambiguous")
                return None
        drift = np.hypot(corr[0], corr[1]) >= cfg.min_correction_m or abs(corr[2]) >= (
            cfg.min_correction_rad
        )
        return LoopClosure(i, k, fit.pose, fit.inlier_share, fit.rms_m, bool(drift)), fit

    def _close_loops(self, k: int) -> None:
        found = []
        for i in self._candidates(k):
            self.stats.tried += 1
            out = self.match_keyframes(i, k)
            if out is not None:
                loop, fit = out
                self.graph.add_edge(i, k, loop.z, self._information(fit), loop=True)
                self.loops.append(loop)
                found.append(loop)
        # Optimize only on evidence of drift: where the front end already matched the old map,
        # the optimum of the graph would differ from it by the matches' own errors only.
        if found and (self._unresolved or any(lc.drift for lc in found)):
            self.optimize()

    def optimize(self) -> dict:
        """Optimize the graph; re-render the map and move the front end's pose if a keyframe
        moved more than ``rerender_min_shift_m``. Returns the optimizer's report."""
        before = self.graph.poses
        report = self.graph.optimize()
        self.stats.optimizations += 1
        self._unresolved = False
        after = self.graph.poses
        shift = float(np.max(np.hypot(*(after[:, :2] - before[:, :2]).T)))
        report["max_shift_m"] = shift
        if shift >= self.config.rerender_min_shift_m:
            self._refs.clear()
            self.rerender()
            # The front end tracks on from the newest keyframe's optimized pose.
            delta = relative_pose(before[-1], self.mapper.pose)
            self.mapper.relocate(compose(after[-1], delta), keyframe=after[-1])
            self._front[-1] = after[-1].copy()
        return report

    def rerender(self) -> None:
        """Rebuild the occupancy grid from every keyframe's scan at its graph pose."""
        m = self.mapper
        scans = m.scans
        m.clear()
        for pose, ranges in zip(self.graph.poses, self.ranges, strict=True):
            m.insert(pose, ranges)
        m.scans = scans
        self.stats.rerenders += 1

    def summary(self) -> dict:
        """Counts: keyframes, loop closures, candidates tried and rejected (by gate),
        optimizations and re-renders."""
        return {
            "keyframes": len(self.graph),
            "loop_closures": len(self.loops),
            "loop_candidates_tried": self.stats.tried,
            "loop_candidates_rejected": dict(sorted(self.stats.rejected.items())),
            "odometry_edges_from_scan_to_scan": self.stats.snaps,
            "optimizations": self.stats.optimizations,
            "rerenders": self.stats.rerenders,
        }
