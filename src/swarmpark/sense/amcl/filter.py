"""Monte Carlo localization of one skid in a known map (:class:`ParticleFilter`): prediction
by the odometry motion model, weighting by the likelihood field on a subsample of beams,
resampling with KLD-sampling, augmented MCL with sensor resetting, clustered estimates."""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from swarmpark.core.geometry import wrap_angle
from swarmpark.sense.amcl.config import FilterConfig, PoseEstimate
from swarmpark.sense.amcl.coop import LandmarkBeams, rectangle_log_likelihood
from swarmpark.sense.amcl.likelihood import LikelihoodField
from swarmpark.sense.amcl.motion import _sample_odometry, relative_motion
from swarmpark.sense.amcl.resample import (
    _temper,
    kld_sample_count,
    logsumexp,
    low_variance_resample,
)
from swarmpark.sense.lidar import LidarSpec, beam_angles

__all__ = ["ParticleFilter", "SCORE_BLOCK"]

#: Particles scored per block (bounds the size of temporaries).
SCORE_BLOCK = 4096


class ParticleFilter:
    """Monte Carlo localization of one skid in a known map.

    Parameters
    ----------
    field
        The map's :class:`LikelihoodField` (share one between all skids on a map).
    spec
        The skid's scanner (beam directions, mount, range).
    config
        Filter settings.
    rng
        The filter's random generator.
    initial_pose, initial_std
        A Gaussian start around a known pose (``initial_std`` = (x, y, yaw) standard
        deviations); without ``initial_pose`` particles start uniform over free space
        (global localization) with ``max_particles`` of them.
    """

    def __init__(
        self,
        field: LikelihoodField,
        spec: LidarSpec,
        *,
        config: FilterConfig | None = None,
        rng: np.random.Generator,
        initial_pose: np.ndarray | None = None,
        initial_std: tuple[float, float, float] = (0.1, 0.1, np.radians(5.0)),
    ) -> None:
        self.field = field
        self.spec = spec
        self.config = config if config is not None else FilterConfig()
        self.rng = rng
        self._beam_dirs = beam_angles(spec) + spec.mount_yaw_rad
        self.w_slow = 0.0
        self.w_fast = 0.0
        self.updates = 0
        if initial_pose is None:
            self.init_global()
        else:
            self.init_pose(initial_pose, initial_std)

    # -- initialization -------------------------------------------------------------------
    def init_global(self) -> None:
        """Spread ``max_particles`` uniformly over free space.

        The first scan after this is scored on ``global_candidates`` fresh uniform poses instead
        (and ``max_particles`` are drawn from them): a few thousand particles rarely land close
        enough to the true pose for a sharp sensor model to single it out.
        """
        m = self.config.max_particles
        self.particles = self.field.sample_free(m, self.rng)
        self.log_w = np.full(m, -np.log(m))
        self._global_pending = True

    def init_pose(
        self,
        pose: np.ndarray,
        std: tuple[float, float, float] = (0.1, 0.1, np.radians(5.0)),
    ) -> None:
        """Gaussian cloud around ``pose`` with ``max_particles`` (or ``min_particles`` when
        adaptive: a known start needs few)."""
        pose = np.asarray(pose, dtype=float).reshape(3)
        if not np.all(np.isfinite(pose)):
            raise ValueError(f"filter.initial_pose must be finite (got {pose.tolist()})")
        m = self.config.min_particles if self.config.adaptive else self.config.max_particles
        p = pose + self.rng.standard_normal((m, 3)) * np.asarray(std, dtype=float)
        p[:, 2] = wrap_angle(p[:, 2])
        self.particles = p
        self.log_w = np.full(m, -np.log(m))
        self._global_pending = False

    # -- state ---------------------------------------------------------------------------
    @property
    def weights(self) -> np.ndarray:
        """Normalized weights ``(M,)``."""
        w = np.exp(self.log_w - logsumexp(self.log_w))
        return w / w.sum()

    @property
    def n_eff(self) -> float:
        w = self.weights
        return float(1.0 / np.sum(w * w))

    # -- steps ---------------------------------------------------------------------------
    def predict(self, odom_prev: np.ndarray, odom_now: np.ndarray) -> None:
        """Move every particle by the odometry increment from ``odom_prev`` to ``odom_now``
        (poses in the odometry frame), with sampled noise."""
        rot1, trans, rot2 = relative_motion(odom_prev, odom_now)
        c = self.config
        self.particles = _sample_odometry(
            self.particles, rot1, trans, rot2, (c.alpha1, c.alpha2, c.alpha3, c.alpha4), self.rng
        )

    def _beam_subset(self, ranges: np.ndarray) -> np.ndarray:
        r = np.asarray(ranges, dtype=float).reshape(self.spec.num_beams)
        valid = np.flatnonzero(np.isfinite(r) & (r < self.spec.max_range_m))
        k = self.config.max_beams
        if len(valid) > k:
            valid = valid[np.linspace(0, len(valid) - 1, k).round().astype(np.int64)]
        return valid

    def scan_log_likelihood(self, particles: np.ndarray, ranges: np.ndarray) -> np.ndarray:
        """Log-likelihood ``(M,)`` of a scan at each of ``particles`` ``(M, 3)``, per beam
        (the mean over the scored beams, so it does not grow with their number)."""
        return self._score(particles, ranges)[0]

    def _score(self, particles: np.ndarray, ranges: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per particle: the mean log-likelihood of the scored beams (for the weights) and
        their mean likelihood (for augmented MCL, see :meth:`update`)."""
        beams = self._beam_subset(ranges)
        m = len(particles)
        if len(beams) == 0:
            return np.zeros(m), np.ones(m)
        r = np.asarray(ranges, dtype=float).reshape(-1)[beams]
        a = self._beam_dirs[beams]
        # End points in the body frame (mount offset included), then to world per particle,
        # in blocks so that the temporaries stay small when scoring many candidates.
        bx = self.spec.mount_x_m + r * np.cos(a)
        by = self.spec.mount_y_m + r * np.sin(a)
        mean_log, mean_p = np.empty(m), np.empty(m)
        for lo in range(0, m, SCORE_BLOCK):
            p = particles[lo : lo + SCORE_BLOCK]
            c, s = np.cos(p[:, 2:3]), np.sin(p[:, 2:3])
            wx = p[:, 0:1] + c * bx - s * by
            wy = p[:, 1:2] + s * bx + c * by
            ll = self.field.log_likelihood_xy(wx, wy)
            mean_log[lo : lo + SCORE_BLOCK] = ll.mean(axis=1)
            mean_p[lo : lo + SCORE_BLOCK] = np.exp(ll).mean(axis=1)
        return mean_log, mean_p

    def _landmark_score(
        self, particles: np.ndarray, ranges: np.ndarray, lm: LandmarkBeams
    ) -> np.ndarray:
        """Per particle: the weighted sum of the log-likelihoods of the returns off
        neighbouring skids, against their outlines (:mod:`.coop`)."""
        r = np.asarray(ranges, dtype=float).reshape(-1)[lm.beams]
        a = self._beam_dirs[lm.beams]
        bx = self.spec.mount_x_m + r * np.cos(a)
        by = self.spec.mount_y_m + r * np.sin(a)
        f = self.field
        out = np.empty(len(particles))
        for lo in range(0, len(particles), SCORE_BLOCK):
            p = particles[lo : lo + SCORE_BLOCK]
            c, s = np.cos(p[:, 2:3]), np.sin(p[:, 2:3])
            wx = p[:, 0:1] + c * bx - s * by
            wy = p[:, 1:2] + s * bx + c * by
            out[lo : lo + SCORE_BLOCK] = rectangle_log_likelihood(
                wx, wy, lm, f.z_hit, f.z_rand / f.max_range_m
            )
        return out

    def update(
        self,
        ranges: np.ndarray,
        ignore: np.ndarray | None = None,
        landmarks: LandmarkBeams | None = None,
    ) -> dict:
        """Weigh particles by a scan ``(B,)`` (ranges as from :func:`~.lidar.scan`), then
        resample if the effective sample size is low or random particles are due.

        ``ignore`` ``(B,)`` bool marks beams not to score against the map (returns from other
        skids, whose positions the fleet knows and the map does not). ``landmarks`` are
        returns off neighbouring skids scored against their outlines instead (cooperative
        localization, :mod:`.coop`).

        Returns a dict of diagnostics: ``n_particles``, ``n_eff``, ``p_inject``,
        ``resampled``, ``beams``, ``tempering``.
        """
        cfg = self.config
        lm_ll = None
        if landmarks is not None and len(landmarks.beams):
            lm_ll = cfg.likelihood_power * self._landmark_score(self.particles, ranges, landmarks)
        if ignore is not None:
            ranges = np.where(np.asarray(ignore, dtype=bool), np.nan, ranges)
        beams = self._beam_subset(ranges)
        k = len(beams)
        diag = {"beams": k, "p_inject": 0.0, "resampled": False, "tempering": 1.0}
        if k == 0 and lm_ll is not None:
            return self._weigh(lm_ll, diag)
        if k > 0 and self._global_pending and cfg.global_candidates > len(self.particles):
            self.particles = self.field.sample_free(cfg.global_candidates, self.rng)
            self.log_w = np.full(cfg.global_candidates, -np.log(cfg.global_candidates))
        if k > 0:
            self._global_pending = False
        per_beam, mean_p = self._score(self.particles, ranges)
        if k == 0:
            diag.update(n_particles=len(self.particles), n_eff=self.n_eff)
            return diag
        w_prev = self.weights
        # Augmented MCL watches the mean *per-beam* likelihood (arithmetic, not the product):
        # it does not grow with the number of beams, and a neighbour hiding a third of the
        # walls lowers it by about a third, not by orders of magnitude as the product would --
        # so occlusion does not look like a kidnapping, while a real kidnapping (almost no
        # beam fits) still does.
        w_avg = float(np.sum(w_prev * mean_p))
        if self.updates == 0 or self.w_slow == 0.0:
            self.w_slow = self.w_fast = w_avg
        else:
            self.w_slow += cfg.alpha_slow * (w_avg - self.w_slow)
            self.w_fast += cfg.alpha_fast * (w_avg - self.w_fast)
        self.updates += 1
        ll = cfg.likelihood_power * k * per_beam
        if lm_ll is not None:
            ll = ll + lm_ll
        beta = _temper(self.log_w, ll, cfg.min_neff_ratio)
        diag["tempering"] = beta
        if lm_ll is None:  # the map alone, in the order of operations it always had
            self.log_w = self.log_w + beta * cfg.likelihood_power * k * per_beam
        else:
            self.log_w = self.log_w + beta * ll
        self.log_w -= logsumexp(self.log_w)
        ratio = self.w_fast / self.w_slow
        p_inject = max(0.0, 1.0 - ratio / cfg.recovery_ratio) if cfg.alpha_fast > 0 else 0.0
        pool = None
        if p_inject > 0 and cfg.injection_candidates > 0:
            pool = self._recovery_pool(ranges)
        diag["p_inject"] = p_inject
        neff = self.n_eff
        if neff < cfg.resample_neff_ratio * len(self.particles) or p_inject > 0:
            self._resample(p_inject, pool)
            diag["resampled"] = True
        diag.update(n_particles=len(self.particles), n_eff=self.n_eff)
        return diag

    def _weigh(self, ll: np.ndarray, diag: dict) -> dict:
        """Weigh by the log-likelihoods ``ll`` of the neighbours' returns alone (no map beam
        in range: augmented MCL has nothing to watch) and resample if due."""
        beta = _temper(self.log_w, ll, self.config.min_neff_ratio)
        diag["tempering"] = beta
        self.log_w = self.log_w + beta * ll
        self.log_w -= logsumexp(self.log_w)
        if self.n_eff < self.config.resample_neff_ratio * len(self.particles):
            self._resample(0.0, None)
            diag["resampled"] = True
        diag.update(n_particles=len(self.particles), n_eff=self.n_eff)
        return diag

    def _bins(self, particles: np.ndarray) -> np.ndarray:
        cfg = self.config
        n_yaw = max(int(np.ceil(2 * np.pi / cfg.kld_bin_rad)), 1)
        ix = np.floor(particles[:, 0] / cfg.kld_bin_m).astype(np.int64)
        iy = np.floor(particles[:, 1] / cfg.kld_bin_m).astype(np.int64)
        it = np.floor((particles[:, 2] + np.pi) / (2 * np.pi) * n_yaw).astype(np.int64) % n_yaw
        return np.column_stack([ix, iy, it])

    def _resample(self, p_inject: float, pool: tuple | None) -> None:
        cfg = self.config
        w = self.weights
        m_max = cfg.max_particles if cfg.adaptive else min(len(self.particles), cfg.max_particles)
        idx = low_variance_resample(w, m_max, self.rng)
        new = self.particles[idx]
        # A random order, so that any prefix is itself a fair sample (KLD stops at a prefix).
        new = new[self.rng.permutation(m_max)]
        if p_inject > 0:
            swap = self.rng.random(m_max) < p_inject
            new[swap] = self._injection(int(swap.sum()), pool)
        if cfg.adaptive:
            bins = self._bins(new)
            key = (bins[:, 0] * 1_000_003 + bins[:, 1]) * 1_009 + bins[:, 2]
            _, first = np.unique(key, return_index=True)
            is_new = np.zeros(m_max, dtype=bool)
            is_new[first] = True
            k = np.cumsum(is_new)
            need = np.maximum(kld_sample_count(k, cfg.kld_err, cfg.kld_quantile), cfg.min_particles)
            enough = np.flatnonzero(np.arange(1, m_max + 1) >= need)
            m = int(enough[0]) + 1 if len(enough) else m_max
            new = new[:m]
        self.particles = new
        self.log_w = np.full(len(new), -np.log(len(new)))

    def _recovery_pool(self, ranges: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``injection_candidates`` uniform poses and their (power-scaled) log-likelihood
        under the current scan."""
        cand = self.field.sample_free(self.config.injection_candidates, self.rng)
        k = len(self._beam_subset(ranges))
        return cand, self.config.likelihood_power * k * self.scan_log_likelihood(cand, ranges)

    def _injection(self, n: int, pool: tuple | None) -> np.ndarray:
        """``n`` random poses for augmented MCL: drawn from the candidate pool in proportion to
        the current scan's (tempered) likelihood -- sensor-resetting localization (Lenser and
        Veloso 2000), so that a kidnapped skid is found in a large map, not only by luck -- or
        uniform without a pool (``injection_candidates = 0``, as amcl)."""
        if n == 0 or pool is None:
            return self.field.sample_free(n, self.rng)
        cand, ll = pool
        flat = np.full(len(cand), -np.log(len(cand)))
        beta = _temper(flat, ll, self.config.min_neff_ratio)
        lw = beta * ll
        out = cand[low_variance_resample(np.exp(lw - lw.max()), n, self.rng)]
        # Each candidate stands for the cell of pose space around it (the pool is coarse: one
        # candidate per ~0.2 m in a 150 m^2 room), and copies of one candidate would stay
        # identical while the skid stands still (no motion noise): spread them over half the
        # pool's spacing so the next scans can pick the best (a regularized particle filter).
        area_m2 = len(self.field.free_cells) * self.field.resolution_m**2
        h_xy = 0.5 * np.sqrt(area_m2 / len(cand))
        h_yaw = 0.5 * 2 * np.pi / np.cbrt(len(cand))
        out = out + self.rng.standard_normal((n, 3)) * np.array([h_xy, h_xy, h_yaw])
        out[:, 2] = wrap_angle(out[:, 2])
        return out

    def kidnap_reset(self) -> None:
        """Restart global localization (what an operator does for a robot moved by hand)."""
        self.init_global()
        self.w_slow = self.w_fast = 0.0

    # -- output --------------------------------------------------------------------------
    def estimate(self, *, cluster: bool = True) -> PoseEstimate:
        """Mean pose (circular mean of yaw) and covariance of the belief.

        With ``cluster`` (as amcl) the particles are grouped into connected histogram bins
        (:attr:`FilterConfig.kld_bin_m`, ``kld_bin_rad``) and the heaviest group is used, so a
        belief with two hypotheses does not report the point between them.
        """
        w = self.weights
        p = self.particles
        total = 1.0
        if cluster and len(p) > 1:
            labels = self._cluster_labels(p)
            sums = np.bincount(labels, weights=w)
            best = int(np.argmax(sums))
            keep = labels == best
            total = float(sums[best])
            p, w = p[keep], w[keep] / sums[best]
        yaw = float(np.arctan2(np.sum(w * np.sin(p[:, 2])), np.sum(w * np.cos(p[:, 2]))))
        mean = np.array([np.sum(w * p[:, 0]), np.sum(w * p[:, 1]), yaw])
        dev = np.column_stack([p[:, 0] - mean[0], p[:, 1] - mean[1], wrap_angle(p[:, 2] - yaw)])
        cov = (dev * w[:, None]).T @ dev
        return PoseEstimate(mean, cov, total)

    def _cluster_labels(self, particles: np.ndarray) -> np.ndarray:
        bins = self._bins(particles)
        uniq, inverse = np.unique(bins, axis=0, return_inverse=True)
        inverse = inverse.reshape(-1)
        n = len(uniq)
        n_yaw = max(int(np.ceil(2 * np.pi / self.config.kld_bin_rad)), 1)
        tree = cKDTree(uniq.astype(float))
        # Bins touching in x, y and yaw (Chebyshev distance 1), with yaw wrapping around.
        pairs = [tree.query_pairs(1.0, p=np.inf, output_type="ndarray")]
        for shift in (n_yaw, -n_yaw):
            other = cKDTree(uniq.astype(float) + [0.0, 0.0, shift])
            sdm = tree.sparse_distance_matrix(other, 1.0, p=np.inf, output_type="ndarray")
            pairs.append(np.column_stack([sdm["i"], sdm["j"]]))
        edges = np.concatenate(pairs).reshape(-1, 2)
        graph = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
        _, labels = connected_components(graph, directed=False)
        return labels[inverse]
