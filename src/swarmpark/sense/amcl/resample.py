"""Weights of a particle set: log-sum-exp, adaptive tempering, low-variance resampling
(Thrun Table 4.4) and the particle count of KLD-sampling (Fox 2003)."""

from __future__ import annotations

import numpy as np
from scipy.special import ndtri

__all__ = ["logsumexp", "low_variance_resample", "kld_sample_count", "TEMPER_BISECTIONS"]

#: Bisection steps when choosing the tempering exponent (resolution 2**-12).
TEMPER_BISECTIONS = 12


def logsumexp(a: np.ndarray) -> float:
    """``log(sum(exp(a)))`` without overflow (1-D)."""
    m = float(np.max(a))
    if not np.isfinite(m):
        return m
    return m + float(np.log(np.sum(np.exp(a - m))))


def _ess_ratio(log_w: np.ndarray) -> float:
    w = np.exp(log_w - logsumexp(log_w))
    return float(1.0 / np.sum(w * w) / len(w))


def _temper(log_w: np.ndarray, log_lik: np.ndarray, min_ratio: float) -> float:
    """Largest exponent ``beta`` in (0, 1] such that weighting by ``beta * log_lik`` keeps the
    effective sample size at least ``min_ratio`` of the particles (found by bisection).

    One scan of a sharp sensor model can otherwise put all weight on the few particles that
    happen to lie nearest some pose -- often a wrong one while localizing globally -- and
    resampling then loses the true pose. Tempering gives up part of one scan's information
    only when the update would degenerate; a filter that is tracking keeps ``beta = 1``.
    """
    if min_ratio <= 0 or _ess_ratio(log_w + log_lik) >= min_ratio:
        return 1.0
    lo, hi = 0.0, 1.0
    for _ in range(TEMPER_BISECTIONS):
        mid = 0.5 * (lo + hi)
        if _ess_ratio(log_w + mid * log_lik) >= min_ratio:
            lo = mid
        else:
            hi = mid
    return max(lo, 1.0 / 2**TEMPER_BISECTIONS)


def low_variance_resample(weights: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """Indices ``(n,)`` drawn by low-variance (systematic) resampling (Thrun Table 4.4).

    Examples
    --------
    >>> low_variance_resample(np.array([0.5, 0.25, 0.25]), 4, np.random.default_rng(0)).tolist()
    [0, 0, 1, 2]
    """
    w = np.asarray(weights, dtype=float)
    c = np.cumsum(w / w.sum())
    c[-1] = 1.0  # round-off must not leave the last pointer past the end
    u = (rng.random() + np.arange(n)) / n
    return np.searchsorted(c, u, side="right").clip(0, len(w) - 1)


def kld_sample_count(k: np.ndarray, err: float, quantile: float) -> np.ndarray:
    """Particles needed for ``k`` non-empty histogram bins (Fox 2003, Wilson-Hilferty form)."""
    k = np.asarray(k, dtype=float)
    z = ndtri(quantile)
    km1 = np.maximum(k - 1.0, 1.0)
    a = 2.0 / (9.0 * km1)
    return np.where(k <= 1, 1.0, km1 / (2.0 * err) * (1.0 - a + np.sqrt(a) * z) ** 3)
