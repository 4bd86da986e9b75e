"""Smooth paths through waypoints, parameterized by arc length (position, heading, curvature).

A :class:`SplinePath` is a cubic spline through 2-D waypoints (scipy's ``CubicSpline`` with
Matlab ``spline()``'s not-a-knot ends by default, as in Liu, Sun & Zhu 2010, Sect. III.A),
re-parameterized by arc length ``s`` so that ``f(s) = (x, y, theta)`` as in their eq. (8).
Curvature ``k(s)`` gives the angular rate of a unicycle driven along it, ``omega = k(s) v``
(their eq. 4). All evaluations are vectorized over arrays of ``s``.

The arc length of the spline has no closed form, so it is tabulated by Gauss-Legendre
quadrature (exact to round-off for these smooth pieces) and inverted with a cubic Hermite
estimate (using the exact derivative ``du/ds = 1 / |r'(u)|``) polished by Newton steps.

Examples
--------
>>> p = SplinePath.through([[0.0, 0.0], [3.0, 4.0]])
>>> round(p.length_m, 12)
5.0
>>> p.pose(2.5).round(6).tolist()
[1.5, 2.0, 0.927295]
>>> float(p.curvature(1.0))
0.0
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import CubicHermiteSpline, CubicSpline

__all__ = ["PathError", "SplinePath"]

#: Consecutive waypoints closer than this (metres) are duplicates: the chord-length
#: parameterization would divide by their distance.
MIN_WAYPOINT_SPACING_M = 1e-9
#: Gauss-Legendre sub-intervals per waypoint interval and nodes per sub-interval. The speed
#: |r'(u)| is the square root of a quartic in each interval, so 8 nodes integrate it to
#: round-off for any sensible spline. The sub-intervals are also the knots of the Hermite
#: estimate of the inverse: with 16, in tight turns that pass the cusp check (radius 1.4-15
#: cm) the two Newton steps started too far off and |dp/ds| was off by up to 7e-3; with 32 by
#: 4e-6 (tests/test_paths.py), and an evaluation is no slower.
_SUBINTERVALS = 32
_GL_NODES = 8
#: Newton steps that polish the inverse arc length s -> u (quadratic convergence from the
#: Hermite estimate: with 32 table intervals, two reach 4e-6 in |dp/ds| on the tight turns
#: of tests/test_paths.py and round-off elsewhere).
_NEWTON_STEPS = 2
#: A spline whose speed |r'(u)| drops below this fraction of its mean has a cusp or a hairpin
#: turn (turning radius about ratio^2 times the waypoint spacing): its heading flips there,
#: no skid can follow it, and the arc-length table loses accuracy. Waypoints that double back
#: on themselves do this.
_CUSP_RATIO = 0.1


class PathError(ValueError):
    """Waypoints or headings that do not define a usable path."""


def _check_waypoints(waypoints, field_name: str) -> np.ndarray:
    try:
        pts = np.asarray(waypoints, dtype=float)
    except (TypeError, ValueError) as exc:
        raise PathError(f"{field_name}: not a list of [x, y] points ({waypoints!r})") from exc
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise PathError(f"{field_name}: expected shape (K, 2), got {pts.shape} ({waypoints!r})")
    if pts.shape[0] < 2:
        raise PathError(f"{field_name}: a path needs at least 2 waypoints (got {pts.tolist()})")
    bad = np.flatnonzero(~np.isfinite(pts).all(axis=1))
    if bad.size:
        k = int(bad[0])
        raise PathError(f"{field_name}[{k}]: coordinates must be finite (got {pts[k].tolist()})")
    gaps = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    dup = np.flatnonzero(gaps < MIN_WAYPOINT_SPACING_M)
    if dup.size:
        k = int(dup[0])
        raise PathError(
            f"{field_name}[{k + 1}]: duplicate of the previous waypoint {pts[k].tolist()} "
            f"(consecutive waypoints must be at least {MIN_WAYPOINT_SPACING_M} m apart)"
        )
    return pts


def _check_heading(value, field_name: str) -> float | None:
    if value is None:
        return None
    try:
        h = float(value)
    except (TypeError, ValueError) as exc:
        raise PathError(f"{field_name}: must be a number in radians (got {value!r})") from exc
    if not np.isfinite(h):
        raise PathError(f"{field_name}: must be finite (got {value!r})")
    return h


def _min_speed(d1) -> float:
    """Exact minimum of ``|r'(u)|`` for a piecewise-quadratic derivative ``d1`` (a PPoly)."""
    c = d1.c  # (3, intervals, 2): highest power first, local variable t = u - x[k]
    widths = np.diff(d1.x)
    best = np.inf
    for k, h in enumerate(widths):
        # |r'|^2 is a quartic; its extremes are at the real roots of its derivative.
        quartic = np.polyadd(np.polymul(c[:, k, 0], c[:, k, 0]), np.polymul(c[:, k, 1], c[:, k, 1]))
        deriv = np.polyder(quartic)
        # Leading coefficients that are round-off (denormal, say) would overflow the roots.
        deriv[np.abs(deriv) <= 1e-12 * np.abs(deriv).max(initial=0.0)] = 0.0
        deriv = np.trim_zeros(deriv, "f")
        crit = np.roots(deriv) if len(deriv) > 1 else np.array([])
        crit = crit[np.abs(crit.imag) < 1e-12].real
        t = np.concatenate([[0.0, h], crit[(crit > 0) & (crit < h)]])
        best = min(best, float(np.sqrt(max(np.polyval(quartic, t).min(), 0.0))))
    return best


@dataclass(frozen=True, eq=False)
class SplinePath:
    """A planar cubic-spline path parameterized by arc length ``s`` in ``[0, length_m]``.

    Build it with :meth:`through`. Evaluation methods take ``s`` as a scalar or an array of
    any shape and return arrays of the same shape (with a trailing axis for vectors). ``s``
    outside ``[0, length_m]`` is clamped to the ends: a robot that has arrived holds its goal.

    Attributes
    ----------
    waypoints : ndarray, shape (K, 2)
        The waypoints the path passes through, in order.
    length_m : float
        Total arc length.
    knot_s : ndarray, shape (K,)
        Arc length at each waypoint (``knot_s[0] == 0``, ``knot_s[-1] == length_m``).
    """

    waypoints: np.ndarray
    start_heading: float | None = None
    end_heading: float | None = None
    length_m: float = field(init=False)
    knot_s: np.ndarray = field(init=False, repr=False)
    _spline: CubicSpline = field(init=False, repr=False)
    _u_of_s: CubicHermiteSpline = field(init=False, repr=False)
    _ub: np.ndarray = field(init=False, repr=False)
    _sb: np.ndarray = field(init=False, repr=False)
    _gl: tuple = field(init=False, repr=False)

    @classmethod
    def through(
        cls,
        waypoints,
        *,
        start_heading: float | None = None,
        end_heading: float | None = None,
        field_name: str = "waypoints",
    ) -> SplinePath:
        """Spline through ``waypoints`` ``(K, 2)`` (metres).

        Parameters
        ----------
        waypoints
            At least two finite points; consecutive points must differ.
        start_heading, end_heading
            Optional headings (radians, CCW from +x) the path must have at its ends; without
            them the ends are not-a-knot (Matlab ``spline()``), a straight line for K = 2.
        field_name
            Name used in error messages (e.g. ``"robots[3].waypoints"``).

        Raises
        ------
        PathError
            Fewer than two waypoints, a non-finite coordinate, a repeated waypoint, a heading
            that is not a finite number, or a spline with a cusp.
        """
        return cls(waypoints, start_heading, end_heading, _field_name=field_name)

    def __init__(
        self,
        waypoints,
        start_heading: float | None = None,
        end_heading: float | None = None,
        *,
        _field_name: str = "waypoints",
    ) -> None:
        pts = _check_waypoints(waypoints, _field_name)
        pts.setflags(write=False)
        set_ = object.__setattr__
        set_(self, "waypoints", pts)
        set_(self, "start_heading", _check_heading(start_heading, f"{_field_name}.start_heading"))
        set_(self, "end_heading", _check_heading(end_heading, f"{_field_name}.end_heading"))

        # Chord-length parameter u: close to arc length, so |r'(u)| stays near 1.
        u = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
        # A clamped end's derivative is the unit tangent: |r'(u)| is about 1 for chord length.
        bc_type = tuple(
            "not-a-knot" if h is None else (1, np.array([np.cos(h), np.sin(h)]))
            for h in (self.start_heading, self.end_heading)
        )
        spline = CubicSpline(u, pts, bc_type=bc_type)
        d1 = spline.derivative(1)

        # Arc length at sub-interval breakpoints by Gauss-Legendre quadrature.
        nodes, weights = np.polynomial.legendre.leggauss(_GL_NODES)
        frac = np.linspace(0.0, 1.0, _SUBINTERVALS + 1)
        ub = (u[:-1, None] + np.diff(u)[:, None] * frac[None, :-1]).ravel()
        ub = np.append(ub, u[-1])
        half = 0.5 * np.diff(ub)
        mid = 0.5 * (ub[:-1] + ub[1:])
        uq = mid[:, None] + half[:, None] * nodes[None, :]
        speed_q = np.linalg.norm(d1(uq), axis=-1)
        seg = (half[:, None] * weights[None, :] * speed_q).sum(axis=1)
        sb = np.concatenate([[0.0], np.cumsum(seg)])
        speed_b = np.linalg.norm(d1(ub), axis=-1)
        mean_speed = sb[-1] / u[-1]
        ratio = _min_speed(d1) / mean_speed
        if ratio < _CUSP_RATIO:
            raise PathError(
                f"{_field_name}: the spline through these waypoints doubles back (a cusp or "
                f"hairpin: its speed drops to {ratio:.2%} of the mean); add or move waypoints "
                f"({pts.tolist()})"
            )
        set_(self, "_spline", spline)
        set_(self, "_u_of_s", CubicHermiteSpline(sb, ub, 1.0 / speed_b))
        set_(self, "_ub", ub)
        set_(self, "_sb", sb)
        set_(self, "_gl", (nodes, weights))
        set_(self, "length_m", float(sb[-1]))
        knot_s = sb[::_SUBINTERVALS].copy()
        knot_s.setflags(write=False)
        set_(self, "knot_s", knot_s)

    # ----------------------------------------------------------------- evaluation
    def _r(self, u: np.ndarray, order: int) -> list[np.ndarray]:
        """``r(u)`` and its derivatives up to ``order``."""
        return [self._spline(u, nu) for nu in range(order + 1)]

    def _u(self, s) -> np.ndarray:
        s = np.asarray(s, dtype=float)
        if not np.all(np.isfinite(s)):
            raise PathError(f"s: arc lengths must be finite (got {s!r})")
        s = np.clip(s, 0.0, self.length_m)
        ub, sb = self._ub, self._sb
        k = np.clip(np.searchsorted(sb, s, side="right") - 1, 0, sb.size - 2)
        lo, hi = ub[k], ub[k + 1]
        u = self._u_of_s(s)
        # Polish with Newton steps on the exact arc length (quadrature from the tabulated
        # breakpoint below), kept inside the bracket: the Hermite estimate alone loses
        # accuracy where the speed |r'(u)| varies fast (tight turns).
        nodes, weights = self._gl
        for _ in range(_NEWTON_STEPS):
            u = np.clip(u, lo, hi)
            half = 0.5 * (u - lo)
            uq = np.concatenate(
                [(lo + half)[..., None] + half[..., None] * nodes, u[..., None]], -1
            )
            speed = np.linalg.norm(self._spline(uq, 1), axis=-1)
            arc = sb[k] + half * np.sum(weights * speed[..., :-1], axis=-1)
            u = u - (arc - s) / speed[..., -1]
        return np.clip(u, lo, hi)

    def position(self, s) -> np.ndarray:
        """Points ``(..., 2)`` at arc lengths ``s``."""
        return self._r(self._u(s), 0)[0]

    def tangent(self, s) -> np.ndarray:
        """Unit tangents ``(..., 2)`` (``(cos theta, sin theta)``) at arc lengths ``s``."""
        d = self._r(self._u(s), 1)[1]
        return d / np.linalg.norm(d, axis=-1, keepdims=True)

    def heading(self, s) -> np.ndarray:
        """Headings ``theta`` (radians, CCW from +x, in ``(-pi, pi]``) at arc lengths ``s``."""
        d = self._r(self._u(s), 1)[1]
        return np.arctan2(d[..., 1], d[..., 0])

    def curvature(self, s) -> np.ndarray:
        """Signed curvature ``k`` (1/m, positive turning left) at arc lengths ``s``."""
        return self.frame(s)[1]

    def pose(self, s) -> np.ndarray:
        """Poses ``(..., 3)`` = ``(x, y, theta)``, the path function ``f(s)`` of eq. (8)."""
        p, d = self._r(self._u(s), 1)
        return np.concatenate([p, np.arctan2(d[..., 1], d[..., 0])[..., None]], axis=-1)

    def frame(self, s) -> tuple[np.ndarray, np.ndarray]:
        """Poses ``(..., 3)`` and curvatures ``(...)`` at arc lengths ``s`` in one pass."""
        p, d1, d2 = self._r(self._u(s), 2)
        cross = d1[..., 0] * d2[..., 1] - d1[..., 1] * d2[..., 0]
        kappa = cross / np.linalg.norm(d1, axis=-1) ** 3
        pose = np.concatenate([p, np.arctan2(d1[..., 1], d1[..., 0])[..., None]], axis=-1)
        return pose, kappa

    def table(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """Samples at ``n`` evenly spaced arc lengths: ``s`` ``(n,)`` and ``(n, 4)`` columns
        ``x, y, cos theta, sin theta`` (used to build smooth interpolants in solvers)."""
        if n < 2:
            raise PathError(f"n: need at least 2 samples (got {n})")
        s = np.linspace(0.0, self.length_m, n)
        u = self._u(s)
        p, d = self._r(u, 1)
        return s, np.concatenate([p, d / np.linalg.norm(d, axis=-1, keepdims=True)], axis=-1)
