"""Compiled inner loops of the navigation tick (numba), where numpy would make one call per
time step over short arrays.

Each kernel does, element by element and in the same order, the arithmetic of the numpy code
it replaces (the same IEEE operations, no fused multiply-adds, the C library's ``sin`` and
``cos`` as numpy's), so the results are the same numbers; the tests compare them with the
numpy versions.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from swarmpark.core.kernels import overlap_one

__all__ = [
    "rollout_poses",
    "rollout_corners",
    "hits_against_skids",
    "pairs_touching",
    "outline_pairs",
]

#: Yaw rates below this are integrated as straight lines (as ``core.geometry``).
_STRAIGHT_EPS = 1e-9


@njit(cache=True)
def rollout_poses(poses, v, w, v_cmd, w_cmd, dv, dw, sub_dt, n_sub, record):  # pragma: no cover
    """Poses ``(M, T, 3)`` of ``M`` skids from ``poses`` ``(M, 3)`` and velocities ``v, w``
    driven towards ``v_cmd, w_cmd`` within steps ``dv, dw`` per sub-step, integrated for
    ``n_sub`` sub-steps of ``sub_dt`` as :func:`~swarmpark.core.geometry.integrate_unicycle`;
    time ``k`` is recorded after sub-step ``record[k]``."""
    m, T = poses.shape[0], record.shape[0]
    out = np.empty((m, T, 3))
    two_pi = 2 * math.pi
    for r in range(m):
        x, y, th = poses[r, 0], poses[r, 1], poses[r, 2]
        vr, wr = v[r], w[r]
        for step in range(1, n_sub + 1):
            # v + np.minimum(np.maximum(v_cmd - v, -dv), dv)
            d = v_cmd[r] - vr
            d = d if d >= -dv[r] else -dv[r]
            d = d if d <= dv[r] else dv[r]
            vr = vr + d
            d = w_cmd[r] - wr
            d = d if d >= -dw[r] else -dw[r]
            d = d if d <= dw[r] else dw[r]
            wr = wr + d
            dth = wr * sub_dt
            s0, c0 = math.sin(th), math.cos(th)
            th1 = th + dth
            if abs(wr) < _STRAIGHT_EPS:
                dx = vr * sub_dt * c0
                dy = vr * sub_dt * s0
            else:
                dx = vr / wr * (math.sin(th1) - s0)
                dy = -vr / wr * (math.cos(th1) - c0)
            x = x + dx
            y = y + dy
            th = (th1 + math.pi) % two_pi - math.pi
            for k in range(T):
                if record[k] == step:
                    out[r, k, 0] = x
                    out[r, k, 1] = y
                    out[r, k, 2] = th
    return out


@njit(cache=True)
def hits_against_skids(ra, rb, centres, other_c, corners, others, radius, group, tol, bad):
    # pragma: no cover - compiled
    """For candidate pairs (rollout ``ra[p]``, skid ``rb[p]``): each of the rollout's ``group``
    footprints (``corners[ra * group:]``, centres ``centres``) whose centre is within
    ``radius`` of the skid's (``other_c``) and that overlaps it (``others``) by more than
    ``tol`` is marked in ``bad``; returns the footprint and skid of every hit, in pair order
    (the monitor's ``_hits_skids`` test, footprint by footprint)."""
    hit_q = np.empty(len(ra) * group, np.int64)
    hit_b = np.empty(len(ra) * group, np.int64)
    axes = np.empty((corners.shape[1] + others.shape[1], 2))
    n = 0
    for p in range(len(ra)):
        b = rb[p]
        for q in range(ra[p] * group, (ra[p] + 1) * group):
            dx = centres[q, 0] - other_c[b, 0]
            dy = centres[q, 1] - other_c[b, 1]
            if math.sqrt(dx * dx + dy * dy) <= radius:
                if overlap_one(corners[q], others[b], axes) > tol:
                    bad[q] = True
                    hit_q[n] = q
                    hit_b[n] = b
                    n += 1
    return hit_q[:n], hit_b[:n]


@njit(cache=True)
def _disc(poly):  # pragma: no cover - compiled
    """A disc around polygon ``poly`` ``(K, 2)``: its vertices' mean and farthest distance."""
    K = poly.shape[0]
    cx, cy = 0.0, 0.0
    for k in range(K):
        cx += poly[k, 0]
        cy += poly[k, 1]
    cx /= K
    cy /= K
    r = 0.0
    for k in range(K):
        r = max(r, math.sqrt((poly[k, 0] - cx) ** 2 + (poly[k, 1] - cy) ** 2))
    return cx, cy, r


#: Discs farther apart than their radii and this cannot hold polygons that overlap by more
#: than the touch tolerance (1e-9 m), whatever the rounding: the exact test is skipped.
_DISC_SLACK_M = 1e-6


@njit(cache=True)
def pairs_touching(pairs, corners, tol):  # pragma: no cover - compiled
    """Whether each pair ``(a, b)`` of ``pairs`` ``(P, 2)`` overlaps by more than ``tol`` at
    any of the times of ``corners`` ``(n, T, 4, 2)`` (each skid's footprint per time), as the
    monitor's joint check tests them (stopping at a pair's first hit). Footprints whose
    covering discs are apart are not tested exactly (they cannot overlap)."""
    n, T = corners.shape[0], corners.shape[1]
    disc = np.empty((n, T, 3))
    for a in range(n):
        for t in range(T):
            disc[a, t, 0], disc[a, t, 1], disc[a, t, 2] = _disc(corners[a, t])
    out = np.zeros(len(pairs), np.bool_)
    axes = np.empty((corners.shape[2] * 2, 2))
    for p in range(len(pairs)):
        a, b = pairs[p, 0], pairs[p, 1]
        for t in range(T):
            dx = disc[a, t, 0] - disc[b, t, 0]
            dy = disc[a, t, 1] - disc[b, t, 1]
            reach = disc[a, t, 2] + disc[b, t, 2] + _DISC_SLACK_M
            if dx * dx + dy * dy > reach * reach:
                continue
            if overlap_one(corners[a, t], corners[b, t], axes) > tol:
                out[p] = True
                break
    return out


@njit(cache=True)
def outline_pairs(rb, sk, starts, counts, pts, here, r):  # pragma: no cover - compiled
    """For each pair (robot row ``rb[p]``, skid ``sk[p]``), the skid's outline points
    ``pts[starts[sk]:starts[sk] + counts[sk]]`` within ``r[rb]`` of ``here[rb]`` (squared
    distances compared, as the field's numpy filter): their rows and point indices, pair by
    pair and point by point."""
    total = 0
    for p in range(len(sk)):
        total += counts[sk[p]]
    rob = np.empty(total, np.int64)
    pt = np.empty(total, np.int64)
    n = 0
    for p in range(len(rb)):
        b, s = rb[p], sk[p]
        hx, hy = here[b, 0], here[b, 1]
        rr = r[b] * r[b]
        for q in range(starts[s], starts[s] + counts[s]):
            dx = pts[q, 0] - hx
            dy = pts[q, 1] - hy
            if dx * dx + dy * dy <= rr:
                rob[n] = b
                pt[n] = q
                n += 1
    return rob[:n], pt[:n]


@njit(cache=True)
def rollout_corners(poses, body, group):  # pragma: no cover - compiled
    """World corners ``(M, 4, 2)`` of footprints at ``poses`` ``(M, 3)``, pose ``m`` with the
    body corners ``body[m // group]``, as ``geometry.transform_points`` computes them
    (``x + c * bx - s * by``, ``y + s * bx + c * by``)."""
    M, K = poses.shape[0], body.shape[1]
    out = np.empty((M, K, 2))
    for m in range(M):
        c, s = math.cos(poses[m, 2]), math.sin(poses[m, 2])
        px, py = poses[m, 0], poses[m, 1]
        b = m // group
        for k in range(K):
            bx, by = body[b, k, 0], body[b, k, 1]
            out[m, k, 0] = px + c * bx - s * by
            out[m, k, 1] = py + s * bx + c * by
    return out
