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
def polygon_edges(sx, sy):
    """Per polygon ``(K, N)``, what the merges need, for ``B`` and for ``-A``: edges,
    pseudo-angles, rank in angle order and the first edge (computed once per robot, not
    once per pair). Returns ``(ex, ey, ang, rank, first)`` for ``B`` then for ``-A``."""
    k, n = sx.shape
    out = []
    for sign in (1.0, -1.0):
        ex, ey, ang = np.empty((k, n)), np.empty((k, n)), np.empty((k, n))
        rank, first = np.empty((k, n), np.int64), np.empty(n, np.int64)
        px, py = np.empty((k, 1)), np.empty((k, 1))
        e_x, e_y, e_a, e_r = np.empty(k), np.empty(k), np.empty(k), np.empty(k, np.int64)
        for i in range(n):
            for v in range(k):
                # -A: a point reflection keeps counter-clockwise order.
                px[v, 0] = sx[v, i] if sign > 0 else -sx[v, i]
                py[v, 0] = sy[v, i] if sign > 0 else -sy[v, i]
            fin = _edge_angles(px, py, 0, e_x, e_y, e_a)
            first[i] = _own_rank(e_a, fin, e_r)
            ex[:, i], ey[:, i], ang[:, i], rank[:, i] = e_x, e_y, e_a, e_r
        out.append((ex, ey, ang, rank, first))
    return out[0], out[1]


@njit(cache=True)
def _minkowski_one(sx, sy, b, a, off_x, off_y, out_x, out_y, col, edges_b, edges_a, ex, ey):
    """Column ``col`` of ``out``: ``off + shape[b] ⊕ -shape[a]`` (shapes ``(K, N)``, their
    :func:`polygon_edges`; ``ex, ey`` scratch of ``2K``).

    Each edge's place in the merged walk is its rank in its own polygon plus the number of
    the other polygon's edges before it (equal angles: the edge of B first).
    """
    ebx, eby, ang_b, rank_b, first_b = edges_b
    eax, eay, ang_a, rank_a, first_a = edges_a
    k = sx.shape[0]
    for kb in range(k):
        pos_b = rank_b[kb, b]
        for m in range(k):
            if ang_a[m, a] < ang_b[kb, b]:
                pos_b += 1
        ex[pos_b], ey[pos_b] = ebx[kb, b], eby[kb, b]
    for m in range(k):
        pos_a = rank_a[m, a]
        for kb in range(k):
            if not (ang_a[m, a] < ang_b[kb, b]):
                pos_a += 1
        ex[pos_a], ey[pos_a] = eax[m, a], eay[m, a]
    # The walk starts at the sum of the tails of both polygons' first edges.
    x0 = sx[first_b[b], b] + -sx[first_a[a], a]
    y0 = sy[first_b[b], b] + -sy[first_a[a], a]
    out_x[0, col] = x0 + off_x
    out_y[0, col] = y0 + off_y
    cx, cy = ex[0], ey[0]
    for v in range(1, 2 * k):
        out_x[v, col] = (x0 + cx) + off_x
        out_y[v, col] = (y0 + cy) + off_y
        cx += ex[v]
        cy += ey[v]


@njit(cache=True)
def minkowski_pairs(sx, sy, b_idx, a_idx, off_x, off_y):
    """Regions ``off + shape[b] ⊕ -shape[a]`` for pairs: ``(K + K, P)`` x and y.

    ``sx, sy`` are ``(K, N)`` vertex-major shapes, ``b_idx, a_idx`` ``(P,)`` robot indices
    and ``off_x, off_y`` ``(P,)`` offsets added to every vertex (the relative position).
    """
    k = sx.shape[0]
    n_pairs = b_idx.shape[0]
    out_x = np.empty((2 * k, n_pairs))
    out_y = np.empty((2 * k, n_pairs))
    edges_b, edges_a = polygon_edges(sx, sy)
    ex, ey = np.empty(2 * k), np.empty(2 * k)
    for p in range(n_pairs):
        _minkowski_one(
            sx,
            sy,
            b_idx[p],
            a_idx[p],
            off_x[p],
            off_y[p],
            out_x,
            out_y,
            p,
            edges_b,
            edges_a,
            ex,
            ey,
        )
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
    work = _vo_scratch(n_v)
    for p in range(n_p):
        ux_o[p], uy_o[p], nx_o[p], ny_o[p], inside_o[p] = _vo_one(
            rx, ry, p, wx[p], wy[p], inv_horizon[p], inv_dt, leg_preference, keep_right, work
        )
    return ux_o, uy_o, nx_o, ny_o, inside_o


@njit(cache=True)
def _vo_scratch(n_v):
    return (
        np.empty(n_v),
        np.empty(n_v),
        np.empty(n_v),
        np.empty(n_v),
        np.empty(n_v, np.bool_),
        np.empty(n_v, np.bool_),
    )


@njit(cache=True)
def _vo_one(rx, ry, p, wxp, wyp, inv_horizon, inv_dt, leg_preference, keep_right, work):
    """:func:`vo_projection` of column ``p``: ``(ux, uy, nx, ny, inside)``."""
    ex, ey, nx, ny, real, front = work
    n_v = rx.shape[0]
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
    inv = inv_dt if colliding else inv_horizon

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
    for v in range(n_v):
        if real[v] and (colliding or front[v]):
            s = nx[v] * (wxp - rx[v, p] * inv) + ny[v] * (wyp - ry[v, p] * inv)
        else:
            s = -np.inf
        if v == 0 or s > s_in:
            s_in, nix, niy = s, nx[v], ny[v]
    s_left = -np.inf if colliding else -luy * wxp + lux * wyp
    s_right = -np.inf if colliding else guy * wxp - gux * wyp
    # Near-ties go to the right leg: both robots keep right (the pair's obstacles are point
    # reflections of each other, which keeps handedness); without the margin a nearly
    # symmetric encounter flips sides with every small turn.
    speed = np.sqrt(wxp * wxp + wyp * wyp)
    if s_right + keep_right * speed >= s_left:
        s_leg, lnx, lny = s_right, guy, -gux
    else:
        s_leg, lnx, lny = s_left, -luy, lux
    inside = max(s_in, s_leg) <= 0.0
    # Inside, any facet line keeps the reciprocal guarantee; a flat cut-off face only
    # brakes two robots meeting head-on, so a leg within leg_preference * |w| is taken.
    if (not colliding) and (s_leg + leg_preference * speed >= s_in):
        s_in, nix, niy = s_leg, lnx, lny
    if inside:
        return -s_in * nix, -s_in * niy, nix, niy, True

    ux, uy, nox, noy = _vo_outside(
        rx, ry, p, wxp, wyp, inv, colliding, ex, ey, lux, luy, lx, ly, gux, guy, gx, gy
    )
    # On the boundary itself the facet normal found above is the outward normal.
    if nox != nox:
        return ux, uy, nix, niy, False
    return ux, uy, nox, noy, False


@njit(cache=True)
def _vo_outside(rx, ry, p, wxp, wyp, inv, colliding, ex, ey, lux, luy, lx, ly, gux, guy, gx, gy):
    """Relative velocity outside the obstacle: the move ``u`` to the nearest boundary point
    (edges of the cut-off polygon or, without collision, the legs) and the normal there
    (NaN when the velocity is on the boundary itself)."""
    # Edges facing away lie inside the obstacle and are never closer: try all.
    best = 0.0
    bx = by = 0.0
    for v in range(rx.shape[0]):
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
    awx, awy = wxp - bx, wyp - by
    dist = np.sqrt(awx * awx + awy * awy)
    if dist > 1e-12:
        inv_d = 1.0 / max(dist, 1e-12)
        return bx - wxp, by - wyp, awx * inv_d, awy * inv_d
    return bx - wxp, by - wyp, np.nan, np.nan


@njit(cache=True, inline="always")
def canonical(pos, i, j):
    """The pair ``(lo, hi)`` built from the side of the robot with the smaller ``(x, y)``
    (then the smaller index), so the floats do not depend on the robots' order."""
    lo, hi = min(i, j), max(i, j)
    if pos[hi, 0] < pos[lo, 0] or (pos[hi, 0] == pos[lo, 0] and pos[hi, 1] < pos[lo, 1]):
        return hi, lo
    return lo, hi


@njit(cache=True)
def robot_lines(pos, vel, prio, still, nbr, sx, sy, inv_h, inv_dt, leg, keep_right, min_share):
    """ORCA lines ``(N, M)`` of every robot against its nearest neighbours.

    ``nbr`` ``(N, M)``: each robot's neighbours, nearest first, ``-1`` after the last
    (:func:`.neighbours.grid_neighbours`).
    Each unordered pair's velocity obstacle is built once, from its canonical side (the
    obstacle of ``j`` seen from ``i`` is the point reflection of that of ``i`` seen from
    ``j``). Robot ``i`` takes the share ``p_j / (p_i + p_j)`` (clipped to
    ``[min_share, 1 - min_share]``) inside the obstacle and its complement outside (room
    to approach: the higher priority gets most of it); against an immobile robot, all.
    Returns ``px, py, dx, dy`` (float) and ``valid`` (bool), all ``(N, M)``.
    """
    n, m = nbr.shape
    k = sx.shape[0]
    ux, uy = np.zeros((n, m)), np.zeros((n, m))
    nx, ny = np.zeros((n, m)), np.zeros((n, m))
    inside = np.zeros((n, m), np.bool_)
    mirror = np.full((n, m), -1, np.int64)  # slot of the same pair in the other's list
    reg_x, reg_y = np.empty((2 * k, 1)), np.empty((2 * k, 1))
    edges_b, edges_a = polygon_edges(sx, sy)
    ex, ey = np.empty(2 * k), np.empty(2 * k)
    work = _vo_scratch(2 * k)
    for i in range(n):
        for s in range(m):
            j = nbr[i, s]
            if j < 0:
                break
            lo, hi = canonical(pos, i, j)
            if i == hi:
                for s2 in range(m):
                    if nbr[j, s2] == i:
                        mirror[i, s] = s2
                        break
                if mirror[i, s] >= 0:
                    continue  # built from j's side
            off_x, off_y = pos[hi, 0] - pos[lo, 0], pos[hi, 1] - pos[lo, 1]
            _minkowski_one(sx, sy, hi, lo, off_x, off_y, reg_x, reg_y, 0, edges_b, edges_a, ex, ey)
            wx, wy = vel[lo, 0] - vel[hi, 0], vel[lo, 1] - vel[hi, 1]
            ux[i, s], uy[i, s], nx[i, s], ny[i, s], inside[i, s] = _vo_one(
                reg_x, reg_y, 0, wx, wy, inv_h, inv_dt, leg, keep_right, work
            )
    px, py = np.zeros((n, m)), np.zeros((n, m))
    dx, dy = np.ones((n, m)), np.zeros((n, m))
    valid = np.zeros((n, m), np.bool_)
    for i in range(n):
        for s in range(m):
            j = nbr[i, s]
            if j < 0:
                break
            s2 = mirror[i, s]
            if s2 >= 0:
                u_x, u_y, n_x, n_y, ins = ux[j, s2], uy[j, s2], nx[j, s2], ny[j, s2], inside[j, s2]
            else:
                u_x, u_y, n_x, n_y, ins = ux[i, s], uy[i, s], nx[i, s], ny[i, s], inside[i, s]
            sign = 1.0 if canonical(pos, i, j)[0] == i else -1.0
            tot = prio[i] + prio[j]
            share = prio[j] / tot if tot > 0 else 0.5
            share = min(max(share, min_share), 1.0 - min_share)
            if not ins:
                share = 1.0 - share
            if still[j]:
                share = 1.0
            px[i, s] = vel[i, 0] + share * (sign * u_x)
            py[i, s] = vel[i, 1] + share * (sign * u_y)
            dx[i, s] = sign * n_y
            dy[i, s] = -(sign * n_x)
            valid[i, s] = True
    return px, py, dx, dy, valid


@njit(cache=True)
def canonical_pairs(pos, i, j):
    """:func:`canonical` for arrays of pairs: ``lo, hi`` ``(P,)``."""
    lo, hi = np.empty_like(i), np.empty_like(j)
    for p in range(i.shape[0]):
        lo[p], hi[p] = canonical(pos, i[p], j[p])
    return lo, hi


@njit(cache=True)
def first_not_convex_ccw(polys):
    """Index of the first polygon ``(N, K, 2)`` that is not convex with counter-clockwise
    vertices, or ``-1``. Padding by repeated vertices (zero edges) is allowed."""
    n, k = polys.shape[0], polys.shape[1]
    for i in range(n):
        area2 = 0.0
        for v in range(k):
            w = v + 1 if v + 1 < k else 0
            u = w + 1 if w + 1 < k else 0
            ex, ey = polys[i, w, 0] - polys[i, v, 0], polys[i, w, 1] - polys[i, v, 1]
            fx, fy = polys[i, u, 0] - polys[i, w, 0], polys[i, u, 1] - polys[i, w, 1]
            le, lf = np.sqrt(ex * ex + ey * ey), np.sqrt(fx * fx + fy * fy)
            # Turn between consecutive real edges (padding gives zero edges).
            cross = ex * fy - ey * fx
            if le > MIN_EDGE_M and lf > MIN_EDGE_M and cross < -1e-9 * max(le * lf, 1e-30):
                return i
            area2 += polys[i, v, 0] * polys[i, w, 1] - polys[i, v, 1] * polys[i, w, 0]
        if area2 < 0:
            return i
    return -1
