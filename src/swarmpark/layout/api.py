"""Entry points: :func:`layout` (goals for given skids) and :func:`capacity` (how many fit).

Both build the layout-frame region, run one method, validate the result in the world frame
and compute the egress fill order. No wall-clock time is measured here; callers time the
call and add ``solve_time_s`` themselves.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import shapely

from swarmpark.core.geometry import Footprint, wrap_angle
from swarmpark.layout.egress import default_opening, egress_order
from swarmpark.layout.methods import LAYOUT_METHODS, capacity_stack, get_method
from swarmpark.layout.region import (
    LayoutError,
    Region,
    Skids,
    _as_boundary,
    _as_obstacles,
    centres_to_poses,
    make_region,
    make_skids,
    non_negative,
)
from swarmpark.layout.validate import check_layout

__all__ = ["METHODS", "LayoutResult", "layout", "capacity", "candidate_headings"]

#: Names of the registered layout methods (see :mod:`swarmpark.layout.methods`), at import.
METHODS = LAYOUT_METHODS.names()
#: At most this many headings are tried for ``heading="auto"`` (0, 90 deg and the
#: directions of the longest boundary edges and their normals).
MAX_AUTO_HEADINGS = 12
#: Headings closer than this (radians) are the same candidate.
_HEADING_DEDUP_RAD = 1e-6


@dataclass(frozen=True, eq=False)
class LayoutResult:
    """A validated parking layout.

    Attributes
    ----------
    poses
        ``(N, 3)`` world pivot poses ``(x, y, yaw)``, in the order of the footprints given.
    method
        The method that produced it.
    heading
        Yaw of every goal (radians), resolved if ``"auto"`` was asked for.
    fill_order
        Goal indices, deepest first: each goal is reachable from the opening with the goals
        before it occupied (see ``report["egress_ok"]``).
    report
        ``method``, ``heading_deg``, ``count``, ``margin_m``, ``min_spacing_m``,
        ``min_boundary_clearance_m``, ``egress_ok``, ``egress_layers``, ``opening``,
        ``notices`` (list of str), ``iterations`` and method-specific entries.
    """

    poses: np.ndarray
    method: str
    heading: float
    fill_order: tuple[int, ...]
    report: dict


def _parse_heading(heading) -> float | None:
    """Radians wrapped to ``[-pi, pi)``, or ``None`` for ``"auto"``."""
    if isinstance(heading, str):
        if heading == "auto":
            return None
        raise LayoutError(f"park.heading: a number in radians or 'auto' (got {heading!r})")
    try:
        h = float(heading)
    except (TypeError, ValueError) as exc:
        raise LayoutError(f"park.heading: a number in radians or 'auto' (got {heading!r})") from exc
    if not math.isfinite(h):
        raise LayoutError(f"park.heading: must be finite (got {heading!r})")
    return float(wrap_angle(h))


def candidate_headings(boundary) -> list[float]:
    """Headings tried by ``heading="auto"``: 0, 90 deg, then the longest edges' directions
    and normals, each in ``(-pi/2, pi/2]`` (a skid and its reverse cover the same ground).

    >>> [round(float(np.degrees(h))) for h in candidate_headings([[0, 0], [4, 0], [0, 3]])]
    [0, 90, -37, 53]
    """
    shell, _ = _as_boundary(boundary)
    pts = np.asarray(shell.exterior.coords)
    d = np.diff(pts, axis=0)
    lengths = np.hypot(d[:, 0], d[:, 1])
    cands = [0.0, np.pi / 2]
    for k in np.argsort(-lengths, kind="stable"):
        a = float(np.arctan2(d[k, 1], d[k, 0]))
        cands += [a, a + np.pi / 2]
    out: list[float] = []
    for a in cands:
        h = float(np.pi / 2 - (np.pi / 2 - a) % np.pi)
        if all(abs(wrap_angle(2 * (h - o))) > _HEADING_DEDUP_RAD for o in out):
            out.append(h)
        if len(out) >= MAX_AUTO_HEADINGS:
            break
    return out


def _room(region: Region, skids: Skids) -> int:
    """Stacking capacity of the largest footprint: the score ``heading="auto"`` maximizes."""
    big = max(skids.footprints, key=lambda fp: (fp.length_m * fp.width_m, fp.length_m))
    return capacity_stack(region, big).fits


def _solve(region: Region, skids: Skids, method: str) -> tuple[np.ndarray, dict]:
    """Layout-frame centres ``(N, 2)`` and method details; raises LayoutError if they don't fit."""
    return get_method(method).solve(region, skids)


def _apron(opening, apron_m):
    """``(opening, disc)``: the opening (world ``(x, y)``) and the disc of radius ``apron_m``
    around it kept free of spots; None without an opening or with no apron."""
    r = non_negative(apron_m, "park.apron_m")
    if opening is None or r == 0.0:
        return None
    x, y = _parse_opening(opening)
    return (x, y), shapely.Point(x, y).buffer(r)


def _solve_apron(region, skids, method, inputs, apron):
    """:func:`_solve`, leaving room by the opening (``apron``, from :func:`_apron`; None: the
    method's layout as it is). First with the apron's disc kept free; if the skids do not
    fit so, stacked from the corner away from the opening, so the room left over lies by it;
    if they do not fit so either, as the method lays them out. ``inputs``: the boundary,
    obstacles and margin ``region`` was made from. The centres are in ``region``'s frame."""
    if apron is None or len(skids) < 2:
        return _solve(region, skids, method)
    (ox, oy), disc = apron
    boundary, obstacles, margin_m = inputs
    extra = [disc] if obstacles is None else [_as_obstacles(obstacles), disc]
    tries = [("apron", lambda: make_region(boundary, extra, region.heading, margin_m))]
    lx, ly = region.to_layout(np.array([ox, oy]))[0]
    xmin, ymin, xmax, ymax = region.free.bounds
    flip = (bool(lx < 0.5 * (xmin + xmax)), bool(ly < 0.5 * (ymin + ymax)))
    tries.append(("far corner", lambda: replace(region, scan_flip=flip)))
    for name, make in tries:
        try:
            centres, info = _solve(make(), skids, method)
        except LayoutError as exc:
            if exc.fits is None:
                raise
            continue
        info["room_by_opening"] = name
        return centres, info
    centres, info = _solve(region, skids, method)
    info["room_by_opening"] = "none"
    return centres, info


def _finish_checked(boundary_world, region, skids, centres, method, info, opening):
    """:func:`_finish`, falling back to the method's ``fallback`` (convex: stacking) when its
    solution fails validation.

    The convex program keeps its constraints only within solver tolerance; should a solution
    still fail validation, an operator is better served by the stacking layout, with a
    notice, than by a refusal. (The known case, a skid within the margin of a wall across a
    cut between convex pieces, is fixed at its root in ``convex.columns.wall_cuts``.)
    """
    try:
        return _finish(boundary_world, region, skids, centres, method, info, opening)
    except LayoutError as exc:
        other = get_method(method).fallback
        if other is None or exc.fits is not None:
            raise
        centres, fallback = _solve(region, skids, other)
        fallback["notices"] = [f"{method}: {exc}; used the {other} layout instead"] + fallback.get(
            "notices", []
        )
        return _finish(boundary_world, region, skids, centres, other, fallback, opening)


def _finish(
    boundary_world,
    region: Region,
    skids: Skids,
    centres: np.ndarray,
    method: str,
    info: dict,
    opening,
) -> LayoutResult:
    """Validate, order for egress, and package the result."""
    poses = centres_to_poses(region, skids, centres)
    free_world = _world_free(region)
    chk = check_layout(poses, skids.footprints, free_world, region.margin)
    if not chk.ok:
        # Every method keeps its own constraints; reaching here is a bug, never a layout.
        raise LayoutError(
            f"park.method: {method!r} produced an invalid layout: " + "; ".join(chk.problems())
        )
    shell, _ = _as_boundary(boundary_world)
    if opening is None:
        opening_xy = default_opening(shell)
    else:
        opening_xy = _parse_opening(opening)
    eg = egress_order(region, skids, centres, opening_xy)
    notices = list(info.pop("notices", []))
    if not eg.ok:
        notices.append(
            f"egress: goals {list(eg.unreachable)} cannot be reached from the opening "
            f"({eg.opening[0]:.2f}, {eg.opening[1]:.2f}) in any fill order"
        )
    report = {
        "method": method,
        "heading_deg": math.degrees(region.heading),
        "count": len(skids),
        "margin_m": region.margin,
        "min_spacing_m": chk.min_spacing_m,
        "min_boundary_clearance_m": chk.min_boundary_clearance_m,
        "egress_ok": eg.ok,
        "egress_layers": eg.layers,
        "opening": list(eg.opening),
        "notices": notices,
        "iterations": int(info.pop("iterations", 0)),
    }
    report.update(info)
    return LayoutResult(poses, method, region.heading, eg.fill_order, report)


def _world_free(region: Region):
    from shapely import affinity

    return affinity.rotate(region.free, region.heading, origin=(0.0, 0.0), use_radians=True)


def _parse_opening(opening) -> np.ndarray:
    try:
        xy = np.asarray(opening, dtype=float).reshape(-1)
    except (TypeError, ValueError) as exc:
        raise LayoutError(f"park.opening: expected (x, y) (got {opening!r})") from exc
    if xy.shape != (2,) or not np.all(np.isfinite(xy)):
        raise LayoutError(f"park.opening: expected finite (x, y) (got {opening!r})")
    return xy


def layout(
    boundary,
    footprints: Sequence[Footprint],
    *,
    heading: float | str = 0.0,
    method: str = "stacking",
    margin_m: float = 0.3,
    obstacles=None,
    opening=None,
    apron_m: float = 0.0,
) -> LayoutResult:
    """Goal poses for ``footprints`` inside ``boundary``.

    Parameters
    ----------
    boundary
        Simple polygon: shapely ``Polygon`` (holes count as obstacles) or ``[[x, y], ...]``.
        May be non-convex.
    footprints
        One :class:`~swarmpark.core.geometry.Footprint` per skid (mixed sizes allowed).
    heading
        Yaw of every parked skid, radians, or ``"auto"``: the candidate heading (see
        :func:`candidate_headings`) with the most room, measured by how many of the largest
        footprint fit by stacking (ties: first candidate, so 0 wins over 90 deg).
    method
        A name registered in :data:`~swarmpark.layout.methods.LAYOUT_METHODS`:
        ``"stacking"``, ``"potential"`` or ``"convex"`` (or one registered later).
    margin_m
        Clearance between skids and from skids to the boundary, walls and obstacles.
    obstacles
        Shapely geometry (or a list of it) subtracted from the boundary, or ``None``.
    opening
        ``(x, y)`` of the entrance used for the egress fill order; projected onto the
        boundary. Default: midpoint of the boundary's longest edge.
    apron_m
        With an ``opening``: leave room by it, so that skids coming in can turn there and the
        first spots do not shut its mouth. The floor within this radius of the opening is
        kept free of spots if the skids still fit so; else the skids are stacked from the
        corner away from the opening (the room left over lies by it); else laid out as
        without. ``report["room_by_opening"]`` says which (``apron``, ``far corner``,
        ``none``). 0 (default): the method's layout as it is.

    Returns
    -------
    LayoutResult

    Raises
    ------
    GeometryError
        ``boundary`` is not a simple polygon.
    LayoutError
        Bad parameter, or the skids do not fit (``fits`` says how many do).

    Examples
    --------
    >>> fp = Footprint(1.0, 1.0)
    >>> res = layout([[0, 0], [4, 0], [4, 4], [0, 4]], [fp] * 9, margin_m=0.25)
    >>> sorted({round(float(x), 3) for x in res.poses[:, 0]})
    [0.75, 2.0, 3.25]
    >>> res.report["min_spacing_m"]
    0.25
    """
    get_method(method)  # an unknown name is refused before any work
    h = _parse_heading(heading)
    skids = make_skids(footprints)
    apron = _apron(opening, apron_m)
    if h is not None:
        region = make_region(boundary, obstacles, h, margin_m)
        centres, info = _solve_apron(region, skids, method, (boundary, obstacles, margin_m), apron)
        return _finish_checked(boundary, region, skids, centres, method, info, opening)

    cands = candidate_headings(boundary)
    scored = []
    for k, a in enumerate(cands):
        region = make_region(boundary, obstacles, a, margin_m)
        scored.append((-_room(region, skids), k, region))
    scored.sort(key=lambda t: (t[0], t[1]))
    last_error: LayoutError | None = None
    tried = []
    for _, _, region in scored:
        try:
            centres, info = _solve_apron(
                region, skids, method, (boundary, obstacles, margin_m), apron
            )
        except LayoutError as exc:
            if exc.fits is None:
                raise
            last_error = (
                exc
                if last_error is None or (exc.fits or 0) > (last_error.fits or 0)
                else last_error
            )
            tried.append(math.degrees(region.heading))
            continue
        info.setdefault("notices", [])
        info["auto_heading"] = {
            "candidates_deg": [math.degrees(a) for a in cands],
            "room": [-s for s, _, _ in sorted(scored, key=lambda t: t[1])],
        }
        if tried:
            info["notices"].append(
                f"heading auto: {len(skids)} skids did not fit at {tried} deg; "
                f"used {math.degrees(region.heading):g} deg"
            )
        return _finish_checked(boundary, region, skids, centres, method, info, opening)
    assert last_error is not None
    raise last_error


def _empty(method: str, region: Region, notices: list[str]) -> LayoutResult:
    """The layout of zero skids (for capacity 0)."""
    report = {
        "method": method,
        "heading_deg": math.degrees(region.heading),
        "count": 0,
        "capacity": 0,
        "margin_m": region.margin,
        "min_spacing_m": None,
        "min_boundary_clearance_m": None,
        "egress_ok": True,
        "egress_layers": 0,
        "opening": None,
        "notices": notices,
        "iterations": 0,
    }
    return LayoutResult(np.zeros((0, 3)), method, region.heading, (), report)


def capacity(
    boundary,
    footprint: Footprint,
    *,
    heading: float | str = 0.0,
    method: str = "stacking",
    margin_m: float = 0.3,
    obstacles=None,
    opening=None,
) -> LayoutResult:
    """The largest layout of one footprint size: ``len(result.poses)`` skids fit.

    Stacking is a greedy scan, so its count is a lower bound on what a human could fit;
    ``potential`` spreads the stacking layout; ``convex`` holds at least the stacking count
    (the stacking layout's constraint graph seeds its program) and tries a few more with
    its column plans.
    ``report["capacity"]`` holds the count. Parameters as in :func:`layout`.
    """
    fill = get_method(method).fill
    if not isinstance(footprint, Footprint):
        raise LayoutError(f"park.footprint: expected a Footprint (got {footprint!r})")
    h = _parse_heading(heading)
    heads = [h] if h is not None else candidate_headings(boundary)
    best = None
    for a in heads:
        region = make_region(boundary, obstacles, a, margin_m)
        st = capacity_stack(region, footprint)
        if best is None or st.fits > best[0]:
            best = (st.fits, region, st)
    assert best is not None
    k, region, st = best
    if k == 0:
        return _empty(method, region, ["not even one skid fits"])
    centres, info = fill(region, footprint, st)
    if len(centres) == 0:
        return _empty(method, region, [f"{method}: not even one skid fits"])
    skids = make_skids([footprint] * len(centres))
    result = _finish_checked(boundary, region, skids, centres, method, info, opening)
    result.report["capacity"] = len(result.poses)
    return result
