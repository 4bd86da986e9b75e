"""Compiled one-step safety filter of ORCA: exact overlap checks of straight moves.

A pair collides during a step iff the relative displacement ``t * d`` (``0 <= t <= 1``)
enters the interior of its collision region ``B ⊕ -A`` (translated by the relative
position). Regions are vertex-major ``(V, P)``; each pair's edge lines are computed once,
then the filter halves the velocities of robots in a hitting pair (finally stops them)
until none hits. Same operations, in the same order, as the numpy version it replaces.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["SAFETY_HALVINGS", "edge_planes", "sweep", "inside_now", "safety_filter"]

#: Edges shorter than this (metres) are padding or round-off, not edges.
MIN_EDGE_M = 1e-12
#: Times the safety filter halves a velocity before it stops the robot.
SAFETY_HALVINGS = 4
#: ``|n . d|`` below this: the move runs parallel to that edge.
FLAT = 1e-15


@njit(cache=True)
def edge_planes(rx, ry):
    """Edge lines of convex regions ``(V, P)``: unit outward normals ``nx, ny``, offsets
    ``c`` (interior: ``n · x < c`` for every real edge) and the mask of real edges."""
    n_v, n_p = rx.shape
    nx, ny, c = np.empty((n_v, n_p)), np.empty((n_v, n_p)), np.empty((n_v, n_p))
    real = np.empty((n_v, n_p), np.bool_)
    for v in range(n_v):
        w = v + 1 if v + 1 < n_v else 0
        for p in range(n_p):
            ex = rx[w, p] - rx[v, p]
            ey = ry[w, p] - ry[v, p]
            elen = np.sqrt(ex * ex + ey * ey)
            real[v, p] = elen > MIN_EDGE_M
            inv_len = 1.0 / max(elen, MIN_EDGE_M)
            nx[v, p], ny[v, p] = ey * inv_len, -ex * inv_len
            c[v, p] = nx[v, p] * rx[v, p] + ny[v, p] * ry[v, p]
    return nx, ny, c, real


@njit(cache=True, inline="always")
def _sweep_one(nx, ny, c, real, p, dx, dy, tol):
    """Whether ``t * (dx, dy)``, ``0 <= t <= 1``, enters the interior of region ``p`` by more
    than ``tol``."""
    t_hi, t_lo = 1.0, 0.0
    for v in range(nx.shape[0]):
        if not real[v, p]:
            continue
        # Inside edge e at time t: t * (n_e . d) < c_e - tol (touching is not a hit).
        a = nx[v, p] * dx + ny[v, p] * dy
        b = c[v, p] - tol
        if abs(a) <= FLAT:
            if b <= 0.0:
                return False
        elif a > 0:
            t_hi = min(t_hi, b / a)
        else:
            t_lo = max(t_lo, b / a)
    return t_lo < t_hi


@njit(cache=True)
def sweep(nx, ny, c, real, dx, dy, tol):
    """:func:`_sweep_one` for every region ``p`` with displacement ``(dx[p], dy[p])``."""
    n_p = nx.shape[1]
    out = np.empty(n_p, np.bool_)
    for p in range(n_p):
        out[p] = _sweep_one(nx, ny, c, real, p, dx[p], dy[p], tol)
    return out


@njit(cache=True)
def inside_now(c, real, tol):
    """Whether the origin lies in the interior of each region (the shapes overlap now)."""
    n_v, n_p = c.shape
    out = np.ones(n_p, np.bool_)
    for p in range(n_p):
        for v in range(n_v):
            if real[v, p] and c[v, p] - tol <= 0.0:
                out[p] = False
                break
    return out


@njit(cache=True)
def safety_filter(vel, dt, i, j, rx, ry, io, ox, oy, tol):
    """Slow robots whose straight one-step motions overlap (``OrcaParams.safety_filter``).

    ``(i, j, rx, ry)``: every robot pair that can meet within one step (regions
    vertex-major); ``(io, ox, oy)`` the same for robot and static obstacle. Scales only go
    down and a stopped pair that does not overlap now is safe, so the loop ends; pairs that
    overlap already are left to ORCA's separating constraints. ``tol``: touching closer than
    this is not a hit (``TOUCH_TOLERANCE_M``; an argument, not a global, so the on-disk
    compiled code never keeps a stale value). Returns the new velocities and which robots
    were slowed.
    """
    n = vel.shape[0]
    nx, ny, c, real = edge_planes(rx, ry)
    onx, ony, oc, oreal = edge_planes(ox, oy)
    free = ~inside_now(c, real, tol)
    o_free = ~inside_now(oc, oreal, tol)
    scale = np.ones(n)
    bad = np.zeros(n, np.bool_)
    halvings = 0
    while True:
        bad[:] = False
        for p in range(i.shape[0]):
            a, b = i[p], j[p]
            if not free[p] or (scale[a] <= 0 and scale[b] <= 0):
                continue
            dx = (vel[a, 0] * scale[a] - vel[b, 0] * scale[b]) * dt
            dy = (vel[a, 1] * scale[a] - vel[b, 1] * scale[b]) * dt
            if _sweep_one(nx, ny, c, real, p, dx, dy, tol):
                bad[a] = True
                bad[b] = True
        for p in range(io.shape[0]):
            a = io[p]
            if not o_free[p] or scale[a] <= 0:
                continue
            if _sweep_one(
                onx, ony, oc, oreal, p, vel[a, 0] * scale[a] * dt, vel[a, 1] * scale[a] * dt, tol
            ):
                bad[a] = True
        any_bad = False
        for r in range(n):
            if bad[r] and scale[r] > 0:
                any_bad = True
        if not any_bad:
            break
        halvings += 1
        for r in range(n):
            if bad[r] and scale[r] > 0:
                scale[r] = 0.5 * scale[r] if halvings <= SAFETY_HALVINGS else 0.0
    out = np.empty_like(vel)
    for r in range(n):
        out[r, 0], out[r, 1] = vel[r, 0] * scale[r], vel[r, 1] * scale[r]
    return out, scale < 1.0
