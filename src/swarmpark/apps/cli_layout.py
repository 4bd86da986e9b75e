"""The ``swarmpark layout`` subcommand: parking goals for a boundary, as JSON, a table or a PNG.

Examples::

    swarmpark layout --boundary '[[0,0],[12,0],[12,4],[4,4],[4,10],[0,10]]' \\
        --count 20 --footprint 1.2 0.8 --method convex --json
    swarmpark layout --boundary '[[0,0],[7,0],[7,4],[0,4]]' --footprint 1.2 0.8 --capacity
    swarmpark layout --boundary '...' --count 20 --footprint 1.2 0.8 --png layout.png

Degrees at this edge (``--heading-deg``, ``yaw_deg`` in the output), radians inside. Bad
input prints one message naming the option and value on stderr and returns 2.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from swarmpark.core.limits import MAX_ROBOTS_PER_COMMAND

__all__ = ["layout_command", "build_parser"]

EXIT_OK, EXIT_BAD_INPUT = 0, 2
#: Library field names and the option that sets them, for error messages.
_FIELD_OPTIONS = {
    "park.boundary": "--boundary",
    "park.margin_m": "--margin-m",
    "park.heading": "--heading-deg",
    "park.method": "--method",
    "park.opening": "--opening",
    "park.footprints": "--footprint",
    "park.footprint": "--footprint",
    "park.obstacles": "--map",
    "footprint": "--footprint",
    "map.yaml": "--map",
}


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # type: ignore[override]
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message}\n")


class _BadInput(Exception):
    """A CLI input problem; the message names the option."""


def build_parser() -> argparse.ArgumentParser:
    from swarmpark.layout import LAYOUT_METHODS

    p = _Parser(
        prog="swarmpark layout",
        description="Parking goals for skids inside a boundary ("
        + ", ".join(LAYOUT_METHODS.names())
        + ").",
    )
    p.add_argument("--boundary", required=True, metavar="JSON", help="'[[x, y], ...]' metres")
    p.add_argument("--count", type=int, metavar="N", help="number of skids (with --footprint)")
    p.add_argument(
        "--footprint", nargs=2, type=float, metavar=("L", "W"), help="skid length and width, m"
    )
    p.add_argument(
        "--pivot-from-rear-m",
        type=float,
        metavar="P",
        help="pivot distance from the rear edge (default: middle)",
    )
    p.add_argument(
        "--footprints",
        metavar="JSON",
        help="mixed sizes instead of --count/--footprint: '[[L, W], [L, W, pivot], ...]'",
    )
    p.add_argument(
        "--method",
        choices=LAYOUT_METHODS.names(),
        help="layout method (default stacking): "
        + "; ".join(f"{e.name}: {e.description}" for e in LAYOUT_METHODS.entries()),
    )
    p.add_argument("--heading-deg", default="0", metavar="D|auto", help="skid heading (deg)")
    p.add_argument("--margin-m", type=float, default=0.3, metavar="M", help="safety margin")
    p.add_argument("--map", metavar="FILE", help="map_server YAML; occupied cells are obstacles")
    p.add_argument("--opening", nargs=2, type=float, metavar=("X", "Y"), help="entrance point")
    p.add_argument("--capacity", action="store_true", help="how many of the footprint fit")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.add_argument(
        "--png", metavar="FILE", help="draw the layout (every method if --method is not set)"
    )
    return p


def _check_png_path(path: str) -> None:
    """Refuse a drawing path whose folder does not exist or whose extension matplotlib
    cannot write, before any work is done."""
    from matplotlib.backend_bases import FigureCanvasBase

    target = Path(path)
    if not target.parent.is_dir():
        raise _BadInput(f"--png: folder {str(target.parent)!r} does not exist")
    ext = target.suffix.lower().lstrip(".")
    formats = FigureCanvasBase.get_supported_filetypes()
    if ext not in formats:
        raise _BadInput(
            f"--png: cannot write {ext or 'a file without extension'!r} "
            f"(use one of {', '.join(sorted(formats))}): {path!r}"
        )


def _json_arg(text: str, option: str):
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise _BadInput(f"{option}: not valid JSON ({exc.msg}): {text!r}") from exc


def _footprints(args):
    from swarmpark.core.geometry import Footprint, GeometryError

    if args.footprints is not None:
        if args.footprint is not None or args.count is not None:
            raise _BadInput("--footprints: use either --footprints or --count with --footprint")
        spec = _json_arg(args.footprints, "--footprints")
        if not isinstance(spec, list) or not spec:
            raise _BadInput(f"--footprints: expected a non-empty list of [L, W] (got {spec!r})")
        out = []
        for i, item in enumerate(spec):
            ok = isinstance(item, list) and len(item) in (2, 3)
            ok = ok and all(isinstance(v, int | float) and not isinstance(v, bool) for v in item)
            if not ok:
                raise _BadInput(f"--footprints[{i}]: expected [L, W] or [L, W, pivot] ({item!r})")
            try:
                out.append(Footprint(*map(float, item)))
            except GeometryError as exc:
                raise _BadInput(f"--footprints[{i}]: {exc}") from exc
        return out
    if args.footprint is None:
        raise _BadInput("--footprint: required (L W in metres), or give --footprints")
    length, width = args.footprint
    try:
        fp = Footprint(length, width, args.pivot_from_rear_m)
    except GeometryError as exc:
        raise _BadInput(f"--footprint: {exc}") from exc
    if args.capacity:
        return [fp]
    if args.count is None:
        raise _BadInput("--count: required with --footprint (or use --capacity)")
    if args.count < 1:
        raise _BadInput(f"--count: must be >= 1 (got {args.count})")
    if args.count > MAX_ROBOTS_PER_COMMAND:
        raise _BadInput(f"--count: at most {MAX_ROBOTS_PER_COMMAND} skids (got {args.count})")
    return [fp] * args.count


def _heading(text: str):
    if text == "auto":
        return "auto"
    try:
        deg = float(text)
    except ValueError as exc:
        raise _BadInput(f"--heading-deg: a number of degrees or 'auto' (got {text!r})") from exc
    if not math.isfinite(deg):
        raise _BadInput(f"--heading-deg: must be finite (got {text!r})")
    return math.radians(deg)


def _obstacles(args, boundary):
    if args.map is None:
        return None
    from swarmpark.core.geometry import as_simple_polygon
    from swarmpark.core.gridmap import load_map_yaml

    grid = load_map_yaml(args.map)
    geom = grid.occupied_geometry(as_simple_polygon(boundary, "park.boundary"))
    return None if geom.is_empty else geom


def _option_message(exc: Exception) -> str:
    """The library's message with its field name replaced by the CLI option."""
    msg = str(exc)
    for field_name, option in sorted(_FIELD_OPTIONS.items(), key=lambda kv: -len(kv[0])):
        if msg.startswith(field_name):
            return option + msg[len(field_name) :]
    return msg


def _run(args, footprints, method: str, boundary, obstacles):
    """One layout (or capacity) call, timed here at the edge; returns (result, seconds)."""
    from swarmpark.layout import capacity, layout

    kw = dict(
        heading=_heading(args.heading_deg),
        method=method,
        margin_m=args.margin_m,
        obstacles=obstacles,
    )
    t0 = time.perf_counter()
    if args.capacity:
        res = capacity(boundary, footprints[0], opening=args.opening, **kw)
    else:
        res = layout(boundary, footprints, opening=args.opening, **kw)
    return res, time.perf_counter() - t0


def _as_dict(res, seconds: float) -> dict:
    goals = [
        {"x_m": float(p[0]), "y_m": float(p[1]), "yaw_deg": math.degrees(float(p[2]))}
        for p in res.poses
    ]
    report = dict(res.report)
    report["solve_time_s"] = seconds
    return {
        "method": res.method,
        "heading_deg": math.degrees(res.heading),
        "count": len(res.poses),
        "goals": goals,
        "fill_order": list(res.fill_order),
        "report": report,
    }


def _fmt(v, spec: str = ".3f") -> str:
    return "-" if v is None else format(v, spec)


def _print_table(d: dict, capacity: bool) -> None:
    r = d["report"]
    head = f"{d['count']} skids fit" if capacity else f"{d['count']} goals"
    print(
        f"method {d['method']}, heading {d['heading_deg']:.1f} deg, {head}, "
        f"margin {r['margin_m']:g} m"
    )
    print(
        f"min spacing {_fmt(r['min_spacing_m'])} m, min boundary clearance "
        f"{_fmt(r['min_boundary_clearance_m'])} m, egress "
        f"{'ok' if r['egress_ok'] else 'NOT ok'} ({r['egress_layers']} layers), "
        f"solve {r['solve_time_s']:.3f} s"
    )
    if d["goals"]:
        rank = {g: k for k, g in enumerate(d["fill_order"])}
        print(f"{'#':>4}{'x_m':>10}{'y_m':>10}{'yaw_deg':>10}{'fill':>6}")
        for i, g in enumerate(d["goals"]):
            print(f"{i:>4}{g['x_m']:>10.3f}{g['y_m']:>10.3f}{g['yaw_deg']:>10.1f}{rank[i]:>6}")
    for n in r["notices"]:
        print(f"notice: {n}")


def _draw(path: str, panels, boundary, obstacles, footprints) -> Path:
    """Panels side by side: (title, result or None, error text)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection
    from shapely.geometry import Polygon

    from swarmpark.core.geometry import footprint_corners

    shell = Polygon(boundary)
    fig, axes = plt.subplots(1, len(panels), figsize=(4.6 * len(panels), 4.6), squeeze=False)
    for ax, (title, res, err) in zip(axes[0], panels, strict=True):
        x, y = shell.exterior.xy
        ax.plot(x, y, color="black", lw=1.5)
        if obstacles is not None:
            from shapely import get_parts

            for g in get_parts(obstacles):
                if g.geom_type == "Polygon":
                    gx, gy = g.exterior.xy
                    ax.fill(gx, gy, color="0.45", lw=0)
        if res is not None and len(res.poses):
            fps = (
                footprints if len(footprints) == len(res.poses) else footprints[:1] * len(res.poses)
            )
            corners = footprint_corners(res.poses, np.stack([f.corners_body() for f in fps]))
            ax.add_collection(
                PolyCollection(corners, facecolors="tab:blue", edgecolors="navy", alpha=0.55)
            )
            ax.plot(res.poses[:, 0], res.poses[:, 1], "k.", ms=3)
            rank = {g: k for k, g in enumerate(res.fill_order)}
            centre = corners.mean(axis=1)
            for i, c in enumerate(centre):
                ax.text(c[0], c[1], str(rank[i] + 1), fontsize=6, ha="center", va="center")
            if res.report.get("opening"):
                ox, oy = res.report["opening"]
                ax.plot([ox], [oy], marker="v", color="tab:red", ms=8)
            r = res.report
            title += (
                f"\nspacing {r['min_spacing_m'] or 0:.2f} m, clearance "
                f"{r['min_boundary_clearance_m']:.2f} m, {r['solve_time_s']:.2f} s"
            )
        elif err:
            ax.text(
                0.5,
                0.5,
                err,
                transform=ax.transAxes,
                ha="center",
                va="center",
                fontsize=7,
                wrap=True,
            )
        ax.set_title(title, fontsize=9)
        ax.set_aspect("equal")
        ax.autoscale_view()
        ax.tick_params(labelsize=7)
    fig.tight_layout()
    out = Path(path)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def layout_command(argv: list[str]) -> int:
    """Run ``swarmpark layout`` with ``argv`` (without the word ``layout``); exit code."""
    from swarmpark.core.geometry import GeometryError
    from swarmpark.core.gridmap import MapError
    from swarmpark.layout import LAYOUT_METHODS, LayoutError

    args = build_parser().parse_args(argv)
    try:
        if not math.isfinite(args.margin_m):
            raise _BadInput(f"--margin-m: must be finite (got {args.margin_m})")
        if args.png:
            _check_png_path(args.png)
        boundary = _json_arg(args.boundary, "--boundary")
        footprints = _footprints(args)
        obstacles = _obstacles(args, boundary)
        method = args.method or "stacking"
        res, seconds = _run(args, footprints, method, boundary, obstacles)
        panels = []
        if args.png:
            for m in [args.method] if args.method else list(LAYOUT_METHODS.names()):
                if m == method:
                    r, s, err = res, seconds, None
                else:
                    try:
                        r, s = _run(args, footprints, m, boundary, obstacles)
                        err = None
                    except LayoutError as exc:
                        r, s, err = None, 0.0, _option_message(exc)
                if r is not None:
                    r.report["solve_time_s"] = s
                panels.append((m, r, err))
    except _BadInput as exc:
        sys.stderr.write(f"swarmpark layout: error: {exc}\n")
        return EXIT_BAD_INPUT
    except (LayoutError, GeometryError, MapError) as exc:
        sys.stderr.write(f"swarmpark layout: error: {_option_message(exc)}\n")
        return EXIT_BAD_INPUT
    out = _as_dict(res, seconds)
    if args.json:
        print(json.dumps(out, indent=2))
    else:
        _print_table(out, args.capacity)
    if args.png:
        path = _draw(args.png, panels, boundary, obstacles, footprints)
        if not args.json:
            print(f"wrote {path}")
    return EXIT_OK
