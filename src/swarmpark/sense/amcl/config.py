"""Settings of the particle filter (:class:`FilterConfig`, :data:`RECOVERY`) and the pose
estimate it reports (:class:`PoseEstimate`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["FilterConfig", "RECOVERY", "PoseEstimate"]


@dataclass(frozen=True, kw_only=True)
class FilterConfig:
    """Particle-filter settings (names after ROS amcl where one exists).

    Parameters
    ----------
    min_particles, max_particles
        Bounds of the particle count; without KLD (``adaptive=False``) ``max_particles`` is used.
        Where no structure is in range the cloud is wide in the unseen direction, and every
        resampling moves its mean by about its spread over the square root of the count: a
        skid crossing 12 m of open deck ended 7.6 cm off sideways on average with 200
        particles (as KLD-sampling keeps while tracking) and 4.8 cm with 1000 (40 seeded
        runs, docs/sensing.md); the default is 1000.
    adaptive
        KLD-sampling: after each resampling keep only as many particles as needed so that the
        histogram of the belief is within ``kld_err`` (with probability ``kld_quantile``).
    kld_bin_m, kld_bin_rad
        Histogram bins of KLD-sampling (and of clustering for :meth:`ParticleFilter.estimate`).
    alpha1, alpha2, alpha3, alpha4
        Odometry noise of Thrun's model: rotation from rotation, rotation from translation,
        translation from translation, translation from rotation. The default (0.02, i.e. a
        standard deviation of 14 % of each motion) covers :class:`OdometryDrift`'s default
        errors; amcl's 0.2 spreads the particles so fast that in a hall with few features in
        range the estimate wanders more than the odometry does (hangar-park replay: mean
        error 2.2 cm at 0.02, 3.5 cm at 0.1).
    max_beams
        Beams scored per update (evenly spread over the valid returns).
    likelihood_power
        Exponent applied to the product of beam likelihoods (1 = the textbook product). Beams
        are not independent (a wall shifts all of its returns together), so the default counts
        the scored beams as about a third as many independent ones.
    resample_neff_ratio
        Resample when the effective sample size falls below this share of the particles.
    min_neff_ratio
        Adaptive tempering: a scan whose full likelihood would leave fewer effective particles
        than this share is applied with an exponent below 1 (0 turns tempering off).
    global_candidates
        Uniform poses scored by the first scan of a global localization (see
        :meth:`ParticleFilter.init_global`).
    injection_candidates
        Injected particles are drawn from this many uniform candidates, weighted by the current
        scan (0 = plain uniform injection as in amcl).
    alpha_slow, alpha_fast
        Smoothing rates of the long- and short-term average likelihood (augmented MCL, the
        recovery from a kidnapping). ``alpha_fast = 0`` (the default, as in amcl) turns
        recovery off; :data:`RECOVERY` (``alpha_fast = 0.2``) turns it on. Off by default
        because a fleet in a hangar with few features in range gets false alarms: when a
        skid's scan fits poorly for another reason (obstacles the map lacks, a neighbour whose
        estimate is off, drift where nothing is in range) recovery moves its estimate to some
        other place the scan happens to fit, and a wrong neighbour estimate then spoils the
        others' scans too (replaying hangar-park at 20 Hz: mean error 0.03 m without
        recovery, jumps of 10-20 m with it). ``alpha_slow`` (0.02) reacts faster than amcl's
        0.001, whose long-term average takes minutes to settle.
    recovery_ratio
        Particles are injected with probability ``max(0, 1 - (w_fast / w_slow) /
        recovery_ratio)``; Thrun's rule is ``recovery_ratio = 1``. Below 1 the filter ignores
        dips of the fit that occlusion causes (a skid or a person in front of the scanner
        lowers it by 10-15 %), while a kidnapping (a drop of a third and more) still triggers
        recovery. Replaying the hangar-park scenario, 0.8 was as accurate as 1 and 2.5 times
        cheaper (fewer needless injections, each of which scores a candidate pool).
    """

    min_particles: int = 1000
    max_particles: int = 3000
    adaptive: bool = True
    kld_err: float = 0.05
    kld_quantile: float = 0.99
    kld_bin_m: float = 0.25
    kld_bin_rad: float = np.radians(10.0)
    alpha1: float = 0.02
    alpha2: float = 0.02
    alpha3: float = 0.02
    alpha4: float = 0.02
    max_beams: int = 60
    likelihood_power: float = 0.3
    resample_neff_ratio: float = 0.5
    min_neff_ratio: float = 0.1
    global_candidates: int = 50_000
    injection_candidates: int = 5000
    alpha_slow: float = 0.02
    alpha_fast: float = 0.0
    recovery_ratio: float = 0.8

    def __post_init__(self) -> None:
        if not (1 <= self.min_particles <= self.max_particles):
            raise ValueError(
                "filter.min_particles and max_particles must satisfy 1 <= min <= max "
                f"(got {self.min_particles}, {self.max_particles})"
            )
        for name in ("alpha1", "alpha2", "alpha3", "alpha4"):
            if getattr(self, name) < 0:
                raise ValueError(f"filter.{name} must be >= 0 (got {getattr(self, name)})")
        if self.max_beams < 1:
            raise ValueError(f"filter.max_beams must be >= 1 (got {self.max_beams})")
        if not 0 < self.kld_err < 1 or not 0.5 < self.kld_quantile < 1:
            raise ValueError(
                "filter.kld_err must be in (0, 1) and kld_quantile in (0.5, 1) "
                f"(got {self.kld_err}, {self.kld_quantile})"
            )
        if not 0 <= self.alpha_slow < 1 or not 0 <= self.alpha_fast <= 1:
            raise ValueError(
                "filter.alpha_slow must be in [0, 1) and alpha_fast in [0, 1] "
                f"(got {self.alpha_slow}, {self.alpha_fast})"
            )
        if not 0 < self.resample_neff_ratio <= 1:
            raise ValueError(
                f"filter.resample_neff_ratio must be in (0, 1] (got {self.resample_neff_ratio})"
            )
        if not 0 <= self.min_neff_ratio < 1:
            raise ValueError(f"filter.min_neff_ratio must be in [0, 1) (got {self.min_neff_ratio})")
        if not 0 < self.recovery_ratio <= 1:
            raise ValueError(f"filter.recovery_ratio must be in (0, 1] (got {self.recovery_ratio})")
        if not self.likelihood_power > 0:
            raise ValueError(f"filter.likelihood_power must be > 0 (got {self.likelihood_power})")


#: Filter settings with kidnapping recovery (augmented MCL with sensor resetting) turned on.
RECOVERY = FilterConfig(alpha_fast=0.2)


@dataclass(frozen=True)
class PoseEstimate:
    """A pose estimate: ``pose`` ``(3,)``, ``cov`` ``(3, 3)`` (x, y, yaw) and the share of the
    belief's weight in the cluster it was computed from."""

    pose: np.ndarray
    cov: np.ndarray
    weight: float
