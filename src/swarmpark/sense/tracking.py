"""People tracking: scan points clustered into detections, tracked with a velocity.

Detections are the connected components of the points the map does not explain (points
closer than ``cluster_gap_m`` join), kept when their extent fits a person. Each track is a
constant-velocity Kalman filter (state ``x, y, vx, vy``; white-noise acceleration, Bar-Shalom,
Li and Kirubarajan 2001, Sect. 6.3.2) and detections are associated to tracks by a gated
global nearest neighbour: the Hungarian assignment of squared Mahalanobis distances, with a
chi-square gate (as in ROS ``leg_detector`` / ``spencer_people_tracking``'s GNN tracker).
A track is confirmed after ``confirm_hits`` updates and dropped after ``max_coast_s`` without
one. Navigation reads the confirmed tracks' positions and velocities and predicts them
(:meth:`PeopleTracker.predict`).

>>> tracker = PeopleTracker()
>>> for k in range(20):  # a person walking east at 1 m/s, seen at 10 Hz
...     t = 0.1 * k
...     _ = tracker.update(t, np.array([[1.0 + t, 2.0], [1.1 + t, 2.05]]))
>>> [tr] = tracker.confirmed()
>>> np.round(tr.velocity, 1).tolist()
[1.0, 0.0]
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

__all__ = ["TrackerConfig", "Track", "PeopleTracker", "cluster_points"]

#: Chi-square value of 2 degrees of freedom at 99%: detections farther than this (squared
#: Mahalanobis distance) from a track's prediction cannot update it.
GATE_CHI2_2DOF_99 = 9.21


@dataclass(frozen=True, kw_only=True)
class TrackerConfig:
    """People-tracker settings (SI units).

    Parameters
    ----------
    cluster_gap_m
        Scan points closer than this belong to the same object (a person's outline seen by a
        5 cm-resolution scan at a few metres has gaps of a few centimetres; two people walking
        side by side are more than 0.3 m apart).
    max_extent_m
        A cluster wider than this is not a person (a crate, a parked skid, a wall the map
        lacks) and is not tracked.
    accel_noise_mps2
        Standard deviation of the white-noise acceleration: how sharply people change pace
        (1 m/s^2: from walking to standing in about a second).
    meas_noise_m
        Standard deviation of a detection's centroid (a scan sees only the near side of a
        person: the centroid is off by a fraction of the radius).
    confirm_hits
        Updates before a track is reported (one stray cluster is not a person).
    max_coast_s
        A track with no detection for this long is dropped (the person left the field of
        view or was a false detection).
    init_speed_std_mps
        Initial velocity uncertainty: people walk at up to about 2 m/s.
    """

    cluster_gap_m: float = 0.3
    max_extent_m: float = 1.0
    accel_noise_mps2: float = 1.0
    meas_noise_m: float = 0.08
    confirm_hits: int = 3
    max_coast_s: float = 1.0
    init_speed_std_mps: float = 1.5

    def __post_init__(self) -> None:
        for name in (
            "cluster_gap_m",
            "max_extent_m",
            "accel_noise_mps2",
            "meas_noise_m",
            "max_coast_s",
            "init_speed_std_mps",
        ):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"tracker.{name} must be a finite number > 0 (got {value!r})")
        if not (isinstance(self.confirm_hits, int) and self.confirm_hits >= 1):
            raise ValueError(
                f"tracker.confirm_hits must be an integer >= 1 (got {self.confirm_hits!r})"
            )


@dataclass
class Track:
    """One tracked person: the Kalman state ``[x, y, vx, vy]`` and its covariance."""

    id: int
    state: np.ndarray
    cov: np.ndarray
    t_s: float
    hits: int = 1
    last_seen_s: float = 0.0
    confirmed: bool = False
    history: list[tuple[float, float, float]] = field(default_factory=list)

    @property
    def position(self) -> np.ndarray:
        return self.state[:2].copy()

    @property
    def velocity(self) -> np.ndarray:
        return self.state[2:].copy()


def cluster_points(points: np.ndarray, gap_m: float, max_extent_m: float) -> np.ndarray:
    """Centroids ``(K, 2)`` of the clusters of ``points`` ``(M, 2)`` (non-finite rows
    ignored) whose points chain within ``gap_m``, keeping clusters no wider than
    ``max_extent_m``. Clusters are ordered by their lowest point index (deterministic)."""
    pts = np.asarray(points, float).reshape(-1, 2)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    if len(pts) == 0:
        return np.zeros((0, 2))
    pairs = cKDTree(pts).query_pairs(gap_m, output_type="ndarray")
    adj = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(pts), len(pts)))
    _, labels = connected_components(adj, directed=False)
    out = []
    for lab in np.unique(labels):  # ascending label = order of first point
        member = pts[labels == lab]
        extent = np.ptp(member, axis=0).max() if len(member) > 1 else 0.0
        if extent <= max_extent_m:
            out.append(member.mean(axis=0))
    return np.array(out).reshape(-1, 2)


class PeopleTracker:
    """Tracks people from unexplained scan points, one :meth:`update` per scan cycle."""

    def __init__(self, config: TrackerConfig | None = None) -> None:
        self.config = config or TrackerConfig()
        self.tracks: list[Track] = []
        self._next_id = 0
        self._t: float | None = None

    # ------------------------------------------------------------------ filter steps

    def _predict_all(self, t: float) -> None:
        cfg = self.config
        for tr in self.tracks:
            dt = t - tr.t_s
            if dt <= 0:
                continue
            f = np.eye(4)
            f[0, 2] = f[1, 3] = dt
            q1 = cfg.accel_noise_mps2**2 * np.array([[dt**4 / 4, dt**3 / 2], [dt**3 / 2, dt**2]])
            q = np.zeros((4, 4))
            q[np.ix_([0, 2], [0, 2])] = q1
            q[np.ix_([1, 3], [1, 3])] = q1
            tr.state = f @ tr.state
            tr.cov = f @ tr.cov @ f.T + q
            tr.t_s = t

    def _associate(self, detections: np.ndarray) -> tuple[list[tuple[int, int]], np.ndarray]:
        """Gated global nearest neighbour: (track, detection) pairs and the unused
        detections' indices."""
        if not self.tracks or not len(detections):
            return [], np.arange(len(detections))
        r = self.config.meas_noise_m**2 * np.eye(2)
        cost = np.empty((len(self.tracks), len(detections)))
        for i, tr in enumerate(self.tracks):
            s_inv = np.linalg.inv(tr.cov[:2, :2] + r)
            d = detections - tr.state[:2]
            cost[i] = np.einsum("ki,ij,kj->k", d, s_inv, d)
        big = GATE_CHI2_2DOF_99 * 1e3
        rows, cols = linear_sum_assignment(np.where(cost <= GATE_CHI2_2DOF_99, cost, big))
        pairs = [(i, j) for i, j in zip(rows, cols, strict=True) if cost[i, j] <= GATE_CHI2_2DOF_99]
        used = {j for _, j in pairs}
        return pairs, np.array([j for j in range(len(detections)) if j not in used], int)

    def _correct(self, tr: Track, z: np.ndarray, t: float) -> None:
        h = np.zeros((2, 4))
        h[0, 0] = h[1, 1] = 1.0
        s = h @ tr.cov @ h.T + self.config.meas_noise_m**2 * np.eye(2)
        gain = tr.cov @ h.T @ np.linalg.inv(s)
        tr.state = tr.state + gain @ (z - h @ tr.state)
        tr.cov = (np.eye(4) - gain @ h) @ tr.cov
        tr.hits += 1
        tr.last_seen_s = t
        tr.confirmed = tr.confirmed or tr.hits >= self.config.confirm_hits

    def _start(self, z: np.ndarray, t: float) -> None:
        cfg = self.config
        cov = np.diag([cfg.meas_noise_m**2] * 2 + [cfg.init_speed_std_mps**2] * 2)
        tr = Track(
            self._next_id,
            np.array([z[0], z[1], 0.0, 0.0]),
            cov,
            t,
            last_seen_s=t,
            confirmed=cfg.confirm_hits <= 1,
        )
        self._next_id += 1
        self.tracks.append(tr)

    # ------------------------------------------------------------------ public

    def update(self, t: float, points: np.ndarray) -> list[Track]:
        """Take the unexplained scan points ``(M, 2)`` (world frame) of one cycle at time
        ``t`` (s, not decreasing); returns the confirmed tracks."""
        if self._t is not None and t < self._t:
            raise ValueError(f"tracker: time went back from {self._t} to {t}")
        self._t = t
        cfg = self.config
        detections = cluster_points(points, cfg.cluster_gap_m, cfg.max_extent_m)
        self._predict_all(t)
        pairs, fresh = self._associate(detections)
        for i, j in pairs:
            self._correct(self.tracks[i], detections[j], t)
        for j in fresh:
            self._start(detections[j], t)
        self.tracks = [tr for tr in self.tracks if t - tr.last_seen_s <= cfg.max_coast_s]
        for tr in self.tracks:
            tr.history.append((t, float(tr.state[0]), float(tr.state[1])))
        return self.confirmed()

    def confirmed(self) -> list[Track]:
        return [tr for tr in self.tracks if tr.confirmed]

    def predict(self, horizon_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Positions ``(K, 2)`` of the confirmed tracks ``horizon_s`` ahead (constant
        velocity) and their velocities ``(K, 2)``."""
        tracks = self.confirmed()
        if not tracks:
            return np.zeros((0, 2)), np.zeros((0, 2))
        state = np.array([tr.state for tr in tracks])
        return state[:, :2] + horizon_s * state[:, 2:], state[:, 2:].copy()
