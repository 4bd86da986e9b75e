"""Compiled small linear programs of ORCA (RVO2's ``linearProgram1/2/3``), one robot at a time.

Each robot's program is a handful of half-planes and a speed circle: the compiled loop over
robots solves each as RVO2 does, with the same floating-point operations in the same order
as the numpy version that ran across robots one constraint slot at a time (results are
bit-for-bit the same).

Constraints are in RVO2's line form: a velocity ``v`` is allowed by line ``(p, d)`` iff
``det(d, v - p) >= 0`` (left of the line).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["LP_EPSILON", "solve_lp2", "solve_lp3"]

#: Determinants below this are "parallel lines" (RVO2's RVO_EPSILON).
LP_EPSILON = 1e-9


@njit(cache=True)
def _lp1(px, py, dx, dy, valid, i, radius, opt_x, opt_y, direction_opt, out):
    """Best point on line ``i`` within the speed circle and lines ``< i``; False if none."""
    pix, piy, dix, diy = px[i], py[i], dx[i], dy[i]
    dotp = pix * dix + piy * diy
    disc = dotp * dotp + radius * radius - (pix * pix + piy * piy)
    ok = disc >= 0.0
    sq = np.sqrt(max(disc, 0.0))
    t_left, t_right = -dotp - sq, -dotp + sq
    if i > 0:
        lo, hi = -np.inf, np.inf
        for j in range(i):
            if not valid[j]:
                continue
            denom = dix * dy[j] - diy * dx[j]
            numer = dx[j] * (piy - py[j]) - dy[j] * (pix - px[j])
            if abs(denom) <= LP_EPSILON:
                # A parallel line that excludes all of line i makes it infeasible.
                if numer < 0.0:
                    ok = False
                continue
            t = numer / denom
            if denom > 0:
                hi = min(hi, t)
            else:
                lo = max(lo, t)
        t_right = min(t_right, hi)
        t_left = max(t_left, lo)
        ok = ok and t_left <= t_right
    if direction_opt:
        t = t_right if opt_x * dix + opt_y * diy > 0.0 else t_left
    else:
        t = dix * (opt_x - pix) + diy * (opt_y - piy)
        t = min(max(t, t_left), t_right)
    out[0] = pix + t * dix
    out[1] = piy + t * diy
    return ok


@njit(cache=True)
def _lp2_one(px, py, dx, dy, valid, radius, opt_x, opt_y, direction_opt, out):
    """Velocity closest to ``opt`` (or farthest along it) in all lines and the circle.

    Writes it to ``out``; returns the first line that could not be met (``M``: none).
    """
    m = valid.shape[0]
    if direction_opt:
        out[0], out[1] = opt_x * radius, opt_y * radius
    else:
        speed = np.sqrt(opt_x * opt_x + opt_y * opt_y)
        scale = radius / max(speed, 1e-300) if speed > radius else 1.0
        out[0], out[1] = opt_x * scale, opt_y * scale
    tmp = np.empty(2)
    for i in range(m):
        if not valid[i]:
            continue
        if dx[i] * (py[i] - out[1]) - dy[i] * (px[i] - out[0]) > 0.0:
            if not _lp1(px, py, dx, dy, valid, i, radius, opt_x, opt_y, direction_opt, tmp):
                return i
            out[0], out[1] = tmp[0], tmp[1]
    return m


@njit(cache=True)
def solve_lp2(px, py, dx, dy, valid, radius, opt_x, opt_y, out):
    """:func:`_lp2_one` for every robot: ``(N, M)`` lines, ``(N,)`` radius and preferred
    velocity; writes ``out`` ``(N, 2)`` and returns the failing line per robot."""
    n, m = valid.shape
    fail = np.empty(n, np.int64)
    for r in range(n):
        fail[r] = _lp2_one(
            px[r], py[r], dx[r], dy[r], valid[r], radius[r], opt_x[r], opt_y[r], False, out[r]
        )
    return fail


@njit(cache=True)
def solve_lp3(px, py, dx, dy, valid, n_hard, fail, radius, result):
    """Where the lines are infeasible, minimise the largest violation of the soft ones (the
    3-D program of RVO2), keeping the hard ones. Updates ``result`` in place."""
    n, m = valid.shape
    qx, qy = np.empty(m), np.empty(m)
    ex, ey = np.empty(m), np.empty(m)
    qv = np.empty(m, np.bool_)
    new = np.empty(2)
    for r in range(n):
        if fail[r] >= m:
            continue
        rx, ry = result[r, 0], result[r, 1]
        distance = 0.0
        for i in range(fail[r], m):
            pix, piy, dix, diy = px[r, i], py[r, i], dx[r, i], dy[r, i]
            if not (valid[r, i] and dix * (piy - ry) - diy * (pix - rx) > distance):
                continue
            # The hard lines always hold, as in RVO2.
            for j in range(n_hard):
                qx[j], qy[j], ex[j], ey[j], qv[j] = (
                    px[r, j],
                    py[r, j],
                    dx[r, j],
                    dy[r, j],
                    valid[r, j],
                )
            for j in range(n_hard, i):
                pjx, pjy, djx, djy = px[r, j], py[r, j], dx[r, j], dy[r, j]
                d_ij = dix * djy - diy * djx
                parallel = abs(d_ij) <= LP_EPSILON
                same_way = parallel and (dix * djx + diy * djy > 0.0)
                # Lines equidistant to line i and line j: violating both is balanced.
                if parallel:
                    qx[j], qy[j] = 0.5 * (pix + pjx), 0.5 * (piy + pjy)
                else:
                    s = (djx * (piy - pjy) - djy * (pix - pjx)) / d_ij
                    qx[j], qy[j] = pix + s * dix, piy + s * diy
                ux, uy = djx - dix, djy - diy
                norm = max(np.sqrt(ux * ux + uy * uy), 1e-300)
                ex[j], ey[j] = ux / norm, uy / norm
                qv[j] = valid[r, j] and not same_way
            size = n_hard + max(i - n_hard, 0)
            k = _lp2_one(
                qx[:size],
                qy[:size],
                ex[:size],
                ey[:size],
                qv[:size],
                radius[r],
                -diy,
                dix,
                True,
                new,
            )
            # Failure here is float round-off only (the old result is feasible): keep it.
            if k >= size:
                rx, ry = new[0], new[1]
            distance = dix * (piy - ry) - diy * (pix - rx)
        result[r, 0], result[r, 1] = rx, ry
