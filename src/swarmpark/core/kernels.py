"""Compiled (numba) forms of the polygon tests of :mod:`swarmpark.core.geometry` that every
tick runs on thousands of pairs: the separating-axis overlap and the distance of convex
polygons.

Each does, pair by pair, the arithmetic of the numpy expression it replaces, in the same order
(no fused multiply-adds, no reassociation; maxima and minima are exact in any order), so the
results are the same numbers; ``tests/test_kernels.py`` compares them with the numpy forms.
They run in one pass per pair instead of numpy's temporaries of shape ``(M, axes, K)``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["convex_overlap_pairs", "convex_distance_pairs", "overlap_one", "box_pairs"]


@njit(cache=True)
def _unit_normals(p, out, off):  # pragma: no cover - compiled
    """Unit normals of the edges of polygon ``p`` ``(K, 2)`` into ``out[off:off + K]``, as
    ``geometry._edge_normals`` (a zero-length edge gives ``(1, 0)``)."""
    K = p.shape[0]
    for k in range(K):
        k1 = (k + 1) % K
        ex = p[k1, 0] - p[k, 0]
        ey = p[k1, 1] - p[k, 1]
        nx, ny = ey, -ex
        norm = math.sqrt(nx * nx + ny * ny)
        if norm > 1e-12:
            out[off + k, 0] = nx / norm
            out[off + k, 1] = ny / norm
        else:
            out[off + k, 0] = 1.0
            out[off + k, 1] = 0.0


@njit(cache=True)
def overlap_one(a, b, axes):  # pragma: no cover - compiled
    """Penetration depth of convex polygons ``a`` ``(K, 2)`` and ``b`` ``(L, 2)`` (``axes``:
    scratch ``(K + L, 2)``), as one row of ``geometry.convex_overlap``."""
    K, L = a.shape[0], b.shape[0]
    _unit_normals(a, axes, 0)
    _unit_normals(b, axes, K)
    best = np.inf
    for i in range(K + L):
        ax, ay = axes[i, 0], axes[i, 1]
        amin, amax = np.inf, -np.inf
        for k in range(K):
            v = ax * a[k, 0] + ay * a[k, 1]
            amin = min(amin, v)
            amax = max(amax, v)
        bmin, bmax = np.inf, -np.inf
        for k in range(L):
            v = ax * b[k, 0] + ay * b[k, 1]
            bmin = min(bmin, v)
            bmax = max(bmax, v)
        best = min(best, min(amax, bmax) - max(amin, bmin))
    return best


@njit(cache=True)
def convex_overlap_pairs(a, b):  # pragma: no cover - compiled
    """Penetration depth ``(M,)`` of convex polygon pairs ``a`` ``(M, K, 2)`` and ``b``
    ``(M, L, 2)`` by the separating-axis theorem (see ``geometry.convex_overlap``)."""
    M, K, L = a.shape[0], a.shape[1], b.shape[1]
    out = np.empty(M)
    axes = np.empty((K + L, 2))
    for m in range(M):
        out[m] = overlap_one(a[m], b[m], axes)
    return out


@njit(cache=True)
def _point_segment(px0, py0, sx0, sy0, sx1, sy1):  # pragma: no cover - compiled
    """``geometry.point_segment_distance`` of one point and one segment."""
    dx, dy = sx1 - sx0, sy1 - sy0
    px, py = px0 - sx0, py0 - sy0
    t = (px * dx + py * dy) / max(dx * dx + dy * dy, 1e-18)
    t = min(max(t, 0.0), 1.0)
    ex, ey = px - t * dx, py - t * dy
    return math.sqrt(ex * ex + ey * ey)


@njit(cache=True)
def convex_distance_pairs(a, b):  # pragma: no cover - compiled
    """Distance ``(M,)`` between convex polygon pairs known not to overlap, the least of every
    vertex of one to every edge of the other (see ``geometry.convex_distance``)."""
    M, K, L = a.shape[0], a.shape[1], b.shape[1]
    out = np.empty(M)
    for m in range(M):
        best = np.inf
        for k in range(K):
            for j in range(L):
                j1 = (j + 1) % L
                d = _point_segment(
                    a[m, k, 0], a[m, k, 1], b[m, j, 0], b[m, j, 1], b[m, j1, 0], b[m, j1, 1]
                )
                best = min(best, d)
        for k in range(L):
            for j in range(K):
                j1 = (j + 1) % K
                d = _point_segment(
                    b[m, k, 0], b[m, k, 1], a[m, j, 0], a[m, j, 1], a[m, j1, 0], a[m, j1, 1]
                )
                best = min(best, d)
        out[m] = best
    return out


@njit(cache=True)
def box_pairs(lo_q, hi_q, lo_s, hi_s):  # pragma: no cover - compiled
    """Every pair (query box ``q``, box ``s``) whose boxes meet, edges included (the test of
    a search tree's envelopes), by ``q`` then ``s``: their indices."""
    nq, ns = lo_q.shape[0], lo_s.shape[0]
    qi = np.empty(nq * ns, np.int64)
    si = np.empty(nq * ns, np.int64)
    n = 0
    for q in range(nq):
        for k in range(ns):
            if not (
                lo_s[k, 0] > hi_q[q, 0]
                or hi_s[k, 0] < lo_q[q, 0]
                or lo_s[k, 1] > hi_q[q, 1]
                or hi_s[k, 1] < lo_q[q, 1]
            ):
                qi[n] = q
                si[n] = k
                n += 1
    return qi[:n], si[:n]
