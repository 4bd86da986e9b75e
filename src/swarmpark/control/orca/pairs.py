"""Compiled per-pair geometry of the ORCA kernel: Minkowski regions and velocity obstacles.

The collision region ``B ⊕ -A`` of a pair of convex footprints (edges merged by angle) and the
shortest move from the relative velocity to the boundary of its truncated-cone velocity
obstacle, one pair at a time in a compiled loop (``numba``). These were numpy kernels over
``(V, P)`` arrays that made a dozen temporaries per pair; the loop keeps a pair's few
vertices in registers. Every floating-point operation is the one the numpy kernels did, in
the same order, so the results are bit-for-bit those of the previous release.

Layout: regions are vertex-major ``(V, P)`` (``x`` and ``y`` apart), as the safety filter
reads them.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["minkowski_pairs", "vo_projection", "MIN_EDGE_M"]

#: Edges shorter than this (metres) are padding or round-off, not edges.
MIN_EDGE_M = 1e-12


@njit(cache=True, inline="always")
def _pseudo_angle(x, y):
    """A strictly increasing function of ``atan2(y, x)`` on ``[0, 2 pi)``, values in ``[0, 4)``."""
    s = abs(x) + abs(y)
    r = x / (s if s > 0 else 1.0)
    return 1.0 - r if y >= 0 else 3.0 + r


@njit(cache=True)
def _edge_angles(px, py, p, ex, ey, ang):
    """Edges (``next - vertex``) of column ``p`` of ``(K, P)`` and their pseudo-angles
    (``inf`` for zero edges, which sort last); returns whether all are real edges."""
    k = px.shape[0]
    finite = True
    for v in range(k):
        w = v + 1 if v + 1 < k else 0
        ex[v] = px[w, p] - px[v, p]
        ey[v] = py[w, p] - py[v, p]
        if abs(ex[v]) + abs(ey[v]) > MIN_EDGE_M:
            ang[v] = _pseudo_angle(ex[v], ey[v])
        else:
            ang[v] = np.inf
            finite = False
    return finite


@njit(cache=True)
def _own_rank(ang, finite, rank):
    """Rank of each edge in angle order within its polygon; returns the first (smallest)."""
    k = ang.shape[0]
    first = 0
    for v in range(1, k):
        if ang[v] < ang[first]:
            first = v
    for v in range(k):
        if finite:
            # Edges of a convex polygon are already in cyclic angle order.
            rank[v] = (v - first) % k
        else:
            r = 0
            for m in range(k):
                if m != v and ((ang[m] < ang[v]) or (ang[m] == ang[v] and m < v)):
                    r += 1
            rank[v] = r
    return first


@njit(cache=True)
def minkowski_pairs(sx, sy, b_idx, a_idx, off_x, off_y):
    """Regions ``off + shape[b] ⊕ -shape[a]`` for pairs: ``(K + K, P)`` x and y.

    ``sx, sy`` are ``(K, N)`` vertex-major shapes, ``b_idx, a_idx`` ``(P,)`` robot indices
    and ``off_x, off_y`` ``(P,)`` offsets added to every vertex (the relative position).
    Each edge's place in the merged walk is its rank in its own polygon plus the number of
    the other polygon's edges before it (equal angles: the edge of B first).
    """
    k = sx.shape[0]
    n_pairs = b_idx.shape[0]
    out_x = np.empty((2 * k, n_pairs))
    out_y = np.empty((2 * k, n_pairs))
    ebx, eby, ang_b = np.empty(k), np.empty(k), np.empty(k)
    eax, eay, ang_a = np.empty(k), np.empty(k), np.empty(k)
    rank_b, rank_a = np.empty(k, np.int64), np.empty(k, np.int64)
    ex, ey = np.empty(2 * k), np.empty(2 * k)
    nax, nay = np.empty((k, 1)), np.empty((k, 1))
    for p in range(n_pairs):
        b, a = b_idx[p], a_idx[p]
        for v in range(k):
            nax[v, 0] = -sx[v, a]  # a point reflection keeps counter-clockwise order
            nay[v, 0] = -sy[v, a]
        fin_b = _edge_angles(sx[:, b : b + 1], sy[:, b : b + 1], 0, ebx, eby, ang_b)
        fin_a = _edge_angles(nax, nay, 0, eax, eay, ang_a)
        first_b = _own_rank(ang_b, fin_b, rank_b)
        first_a = _own_rank(ang_a, fin_a, rank_a)
        for kb in range(k):
            pos_b = rank_b[kb]
            for m in range(k):
                if ang_a[m] < ang_b[kb]:
                    pos_b += 1
            ex[pos_b], ey[pos_b] = ebx[kb], eby[kb]
        for m in range(k):
            pos_a = rank_a[m]
            for kb in range(k):
                if not (ang_a[m] < ang_b[kb]):
                    pos_a += 1
            ex[pos_a], ey[pos_a] = eax[m], eay[m]
        # The walk starts at the sum of the tails of both polygons' first edges.
        x0 = sx[first_b, b] + nax[first_a, 0]
        y0 = sy[first_b, b] + nay[first_a, 0]
        out_x[0, p] = x0 + off_x[p]
        out_y[0, p] = y0 + off_y[p]
        cx, cy = ex[0], ey[0]
        for v in range(1, 2 * k):
            out_x[v, p] = (x0 + cx) + off_x[p]
            out_y[v, p] = (y0 + cy) + off_y[p]
            cx += ex[v]
            cy += ey[v]
    return out_x, out_y


@njit(cache=True)
def vo_projection(rx, ry, wx, wy, inv_horizon, inv_dt, leg_preference, keep_right):
    """Shortest move ``u`` from the relative velocity to the boundary of the velocity
    obstacle, and the obstacle's outward normal ``n`` there (see ``pair_halfplanes``).

    ``rx, ry`` ``(V, P)`` region vertices (counter-clockwise, repeats allowed), ``wx, wy``
    and ``inv_horizon`` ``(P,)``. Returns ``ux, uy, nx, ny`` ``(P,)`` and ``inside`` (bool).
    """
    n_v, n_p = rx.shape
    ux_o, uy_o = np.empty(n_p), np.empty(n_p)
    nx_o, ny_o = np.empty(n_p), np.empty(n_p)
    inside_o = np.empty(n_p, np.bool_)
    ex, ey = np.empty(n_v), np.empty(n_v)
    nx, ny = np.empty(n_v), np.empty(n_v)
    real, front = np.empty(n_v, np.bool_), np.empty(n_v, np.bool_)
    for p in range(n_p):
        wxp, wyp = wx[p], wy[p]
        colliding = True
        for v in range(n_v):
            w = v + 1 if v + 1 < n_v else 0
            ex[v] = rx[w, p] - rx[v, p]
            ey[v] = ry[w, p] - ry[v, p]
            elen = np.sqrt(ex[v] * ex[v] + ey[v] * ey[v])
            real[v] = elen > MIN_EDGE_M
            inv_len = 1.0 / max(elen, MIN_EDGE_M)
            # Outward normal of a counter-clockwise polygon: right-hand perpendicular.
            nx[v], ny[v] = ey[v] * inv_len, -ex[v] * inv_len
            # The origin lies outside this edge's line.
            front[v] = real[v] and (nx[v] * rx[v, p] + ny[v] * ry[v, p] < 0.0)
            if front[v]:
                colliding = False
        inv = inv_dt if colliding else inv_horizon[p]

        # Legs of the cone: rays through the extreme vertices seen from the origin.
        cx, cy = rx[0, p], ry[0, p]
        for v in range(1, n_v):
            cx += rx[v, p]
            cy += ry[v, p]
        kl = kr = 0
        kmax = kmin = 0.0
        for v in range(n_v):
            key = _pseudo_angle(cx * rx[v, p] + cy * ry[v, p], cx * ry[v, p] - cy * rx[v, p])
            # Angles relative to the centroid lie in (-pi, pi): shift to a monotone order.
            key = key - 4.0 if key >= 2.0 else key
            if v == 0 or key > kmax:
                kmax, kl = key, v
            if v == 0 or key < kmin:
                kmin, kr = key, v
        lx, ly, gx, gy = rx[kl, p], ry[kl, p], rx[kr, p], ry[kr, p]
        ll = 1.0 / max(np.sqrt(lx * lx + ly * ly), MIN_EDGE_M)
        gl = 1.0 / max(np.sqrt(gx * gx + gy * gy), MIN_EDGE_M)
        lux, luy, gux, guy = lx * ll, ly * ll, gx * gl, gy * gl

        # Facets: edges facing the origin and both legs (no collision) or all edges.
        s_in = -np.inf
        nix = niy = 0.0
        first = True
        for v in range(n_v):
            if real[v] and (colliding or front[v]):
                s = nx[v] * (wxp - rx[v, p] * inv) + ny[v] * (wyp - ry[v, p] * inv)
            else:
                s = -np.inf
            if first or s > s_in:
                s_in, nix, niy = s, nx[v], ny[v]
                first = False
        s_left = -np.inf if colliding else -luy * wxp + lux * wyp
        s_right = -np.inf if colliding else guy * wxp - gux * wyp
        # Near-ties go to the right leg: both robots keep right.
        speed = np.sqrt(wxp * wxp + wyp * wyp)
        right = s_right + keep_right * speed >= s_left
        if right:
            s_leg, lnx, lny = s_right, guy, -gux
        else:
            s_leg, lnx, lny = s_left, -luy, lux
        inside = max(s_in, s_leg) <= 0.0
        # A leg within leg_preference * |w| of the nearest face is taken instead.
        if (not colliding) and (s_leg + leg_preference * speed >= s_in):
            s_in, nix, niy = s_leg, lnx, lny

        # Outside: project on the boundary pieces (edges facing away are never closer).
        best = 0.0
        bx = by = 0.0
        for v in range(n_v):
            qx, qy = rx[v, p] * inv, ry[v, p] * inv
            esx, esy = ex[v] * inv, ey[v] * inv
            t = ((wxp - qx) * esx + (wyp - qy) * esy) / max(esx * esx + esy * esy, 1e-300)
            t = min(max(t, 0.0), 1.0)
            px, py = qx + t * esx, qy + t * esy
            d2 = (wxp - px) * (wxp - px) + (wyp - py) * (wyp - py)
            if v == 0 or d2 < best:
                best, bx, by = d2, px, py
        if not colliding:
            for leg in range(2):
                if leg == 0:
                    ux_, uy_, ox, oy = lux, luy, lx * inv, ly * inv
                else:
                    ux_, uy_, ox, oy = gux, guy, gx * inv, gy * inv
                tr = max((wxp - ox) * ux_ + (wyp - oy) * uy_, 0.0)
                cxr, cyr = ox + tr * ux_, oy + tr * uy_
                dr = (wxp - cxr) * (wxp - cxr) + (wyp - cyr) * (wyp - cyr)
                if dr < best:
                    best, bx, by = dr, cxr, cyr
        inside_o[p] = inside
        if inside:
            ux_o[p], uy_o[p] = -s_in * nix, -s_in * niy
            nx_o[p], ny_o[p] = nix, niy
        else:
            awx, awy = wxp - bx, wyp - by
            dist = np.sqrt(awx * awx + awy * awy)
            ux_o[p], uy_o[p] = bx - wxp, by - wyp
            # On the boundary itself the facet normal found above is the outward normal.
            if dist > 1e-12:
                inv_d = 1.0 / max(dist, 1e-12)
                nx_o[p], ny_o[p] = awx * inv_d, awy * inv_d
            else:
                nx_o[p], ny_o[p] = nix, niy
    return ux_o, uy_o, nx_o, ny_o, inside_o
