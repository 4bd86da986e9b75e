"""The ``swarmpark`` command: run scenarios, lay out parking spots, serve the operator UI, bench.

Exit codes: 0 success (for ``run``: the scenario's ``expect`` was met), 1 the run did not meet
``expect``, 2 bad input (one clear message on stderr, no traceback).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

__all__ = ["main"]

EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT = 0, 1, 2


class _Parser(argparse.ArgumentParser):
    """argparse exits 2 on bad options already; keep its message to one line."""

    def error(self, message: str):  # type: ignore[override]
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message}\n")


def _fail(msg: str) -> int:
    sys.stderr.write(f"swarmpark: error: {msg}\n")
    return EXIT_BAD_INPUT


# ----------------------------------------------------------------------------- run


def _fmt(v) -> str:
    return "-" if v is None else (f"{v:.3f}" if isinstance(v, float) else str(v))


def _print_table(result: dict) -> None:
    r = result
    lines = [
        f"scenario        {r['scenario']} (seed {r['seed']})",
        f"success         {r['success']}",
        f"time_to_park_s  {_fmt(r['time_to_park_s'])}   (lower bound {_fmt(r['lower_bound_s'])})",
        f"collisions      {len(r['collisions'])}",
        f"min_clearance_m {_fmt(r['min_clearance_m'])}   (robot {_fmt(r['min_clearance_robot_m'])},"
        f" wall {_fmt(r['min_clearance_wall_m'])})",
        f"deadlocks       {len(r['deadlocks'])}",
        f"tick_ms         mean {r['tick_ms']['mean']:.3f}, p99 {r['tick_ms']['p99']:.3f}",
        f"sim_time_s      {r['sim_time_s']}",
        "",
        f"{'robot':<10}{'parked':>8}{'at_s':>9}{'path_m':>9}{'pos_err_m':>11}{'head_err_deg':>14}",
    ]
    for rid, s in r["robots"].items():
        if not s["commanded"]:
            continue
        lines.append(
            f"{rid:<10}{str(s['parked']):>8}{_fmt(s['parked_at_s']):>9}{s['path_length_m']:>9.2f}"
            f"{_fmt(s['final_position_error_m']):>11}{_fmt(s['final_heading_error_deg']):>14}"
        )
    for c in r["collisions"]:
        lines.append(f"collision at {c['t_s']:.2f} s: {c['a']} - {c['b']} ({c['kind']})")
    for c in r["commands"]:
        if not c["accepted"]:
            lines.append(f"refused {c['command']} at {c['t_s']:.2f} s: {c['reason']}")
    if not r["expect_met"]:
        lines.append("expect NOT met: " + "; ".join(r["expect_failures"]))
    print("\n".join(lines))


def cmd_run(args) -> int:
    from swarmpark.apps.run import run_world, terminal_progress, write_outputs
    from swarmpark.world.scenario import ScenarioError, build_world, load_scenario

    try:
        world = build_world(load_scenario(args.scenario))
    except ScenarioError as exc:
        return _fail(f"{args.scenario}: {exc}")
    from swarmpark.links.ros2 import link_from_args

    show = sys.stderr.isatty() and not args.quiet
    link = None
    try:
        link = link_from_args(world, args)  # None: the simulator
        out = run_world(world, progress=terminal_progress if show else None, link=link)
    except (ValueError, TimeoutError) as exc:
        return _fail(f"run --link {args.link}: {exc}")
    finally:
        if link is not None:
            link.close()  # the robots stop
    if show:
        sys.stderr.write("\n")
    if args.out:
        paths = write_outputs(out, args.out)
        if not args.json:
            print(f"wrote {', '.join(str(p) for p in paths.values())}")
    if args.json:
        print(json.dumps(out.result, indent=2))
    else:
        _print_table(out.result)
    return EXIT_OK if out.result["expect_met"] else EXIT_FAILED


# ----------------------------------------------------------------------------- bench


def cmd_bench(args) -> int:
    import platform

    from swarmpark.apps.bench import discover

    reg = discover()
    names = sorted(reg)
    if args.list:
        for n in names:
            b = reg[n]
            print(f"{n:<24}{b.description}" + (f"  [target: {b.target}]" if b.target else ""))
        return EXIT_OK
    selected = [n for n in names if not args.only or any(n.startswith(p) for p in args.only)]
    if not selected:
        return _fail(f"bench --only: no benchmark matches {args.only} (have {', '.join(names)})")
    report = {
        "machine": {"python": platform.python_version(), "platform": platform.platform()},
        "quick": args.quick,
        "benchmarks": {},
    }
    for n in selected:
        b = reg[n]
        print(
            f"\n== {n}: {b.description}" + (f"  [target: {b.target}]" if b.target else ""),
            flush=True,
        )
        rows = b.fn(args.quick)
        report["benchmarks"][n] = {"description": b.description, "target": b.target, "rows": rows}
        _print_rows(rows)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    if args.only and out.exists():
        # A partial run updates its benchmarks in the file and keeps the others.
        try:
            kept = json.loads(out.read_text()).get("benchmarks", {})
        except (json.JSONDecodeError, AttributeError):
            kept = {}
        report["benchmarks"] = {**kept, **report["benchmarks"]}
    out.write_text(json.dumps(report, indent=2) + "\n")
    print(f"\nwrote {out}")
    return EXIT_OK


def _print_rows(rows: list[dict]) -> None:
    if not rows:
        print("(no rows)")
        return
    cols = list(dict.fromkeys(k for r in rows for k in r))
    cells = [[_cell(r.get(c)) for c in cols] for r in rows]
    widths = [max(len(c), *(len(row[i]) for row in cells)) for i, c in enumerate(cols)]
    print("  ".join(c.ljust(w) for c, w in zip(cols, widths, strict=True)))
    for row in cells:
        print("  ".join(v.ljust(w) for v, w in zip(row, widths, strict=True)))


def _cell(v) -> str:
    if isinstance(v, float):
        return f"{v:.4g}" if abs(v) < 1e5 else f"{v:.3e}"
    return "-" if v is None else str(v)


# ----------------------------------------------------------------------------- formation


def cmd_formation(args) -> int:
    """Reproduce Liu, Sun and Zhu (2010): formation errors of three methods, the obstacle run."""
    if not args.paper:
        return _fail("formation: only --paper is available (the paper's experiments)")
    from swarmpark.control.formation.paper_report import run_paper

    out = run_paper(Path(args.out))
    print(json.dumps(out, indent=2, default=str))
    return EXIT_OK


# ----------------------------------------------------------------------------- map


def cmd_map(args) -> int:
    """Run a scenario while one skid builds a map with its LIDAR; save it for map_server."""
    from swarmpark.apps.mapping_run import build_map
    from swarmpark.apps.run import terminal_progress
    from swarmpark.world.scenario import ScenarioError, build_world, load_scenario

    try:
        world = build_world(load_scenario(args.scenario))
    except ScenarioError as exc:
        return _fail(f"{args.scenario}: {exc}")
    if args.robot not in world.ids:
        return _fail(f"map --robot: unknown robot {args.robot!r} (have {', '.join(world.ids)})")
    show = sys.stderr.isatty()
    summary = build_map(world, args.robot, args.out, progress=terminal_progress if show else None)
    if show:
        sys.stderr.write("\n")
    print(json.dumps(summary, indent=2))
    return EXIT_OK


# ----------------------------------------------------------------------------- compare


def cmd_compare(args) -> int:
    """Assignment costs on the scenario suite, as a markdown table."""
    from swarmpark.apps.compare import compare_costs, markdown_table

    paths = [Path(p) for p in args.scenarios] or sorted(Path("scenarios").glob("*.yaml"))
    missing = [str(p) for p in paths if not p.is_file()]
    if missing:
        return _fail(f"compare: scenario file not found: {missing[0]!r}")
    rows = compare_costs(paths, workers=args.workers)
    table = markdown_table(rows)
    if args.out:
        out = Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(
            "# Assignment costs on the scenario suite\n\n"
            "Generated by `swarmpark compare --out " + str(args.out) + "`: every park scenario, "
            "once per assignment cost, everything else unchanged. *ratio* is time to park over "
            "the lower bound (bottleneck assignment of shortest free-space paths at full "
            "speed).\n\n" + table
        )
    print(table, end="")
    return EXIT_OK


# ----------------------------------------------------------------------------- main


def _add_link_args(p) -> None:
    from swarmpark.links.ros2 import add_link_args

    add_link_args(p)


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="swarmpark", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    r = sub.add_parser("run", help="run a scenario headless and print the result")
    r.add_argument("scenario", help="scenario YAML file")
    r.add_argument("--json", action="store_true", help="print the result as JSON")
    r.add_argument("--out", metavar="DIR", help="write result.json, trajectories.npz, run.png")
    r.add_argument("--quiet", action="store_true", help="no progress bar")
    _add_link_args(r)
    r.set_defaults(func=cmd_run)

    b = sub.add_parser("bench", help="run the timing and quality benchmarks")
    b.add_argument("--only", nargs="*", metavar="PREFIX", help="benchmarks whose name starts so")
    b.add_argument("--quick", action="store_true", help="small sizes (smoke run)")
    b.add_argument("--list", action="store_true", help="list the benchmarks and exit")
    b.add_argument("--out", default="benchmarks/results.json", help="JSON output path")
    b.set_defaults(func=cmd_bench)

    f = sub.add_parser("formation", help="formation velocity planning (Liu, Sun, Zhu 2010)")
    f.add_argument("--paper", action="store_true", help="reproduce the paper's figures and table")
    f.add_argument("--out", default="docs/img", metavar="DIR", help="where to write them")
    f.set_defaults(func=cmd_formation)

    m = sub.add_parser("map", help="build a map with one skid's LIDAR while a scenario runs")
    m.add_argument("scenario", help="scenario YAML file (the route is its commands)")
    m.add_argument("--robot", required=True, help="the skid that maps")
    m.add_argument("--out", required=True, metavar="FILE", help="map_server YAML to write")
    m.set_defaults(func=cmd_map)

    c = sub.add_parser("compare", help="compare assignment costs on the scenario suite")
    c.add_argument("scenarios", nargs="*", help="scenario files (default: scenarios/*.yaml)")
    c.add_argument("--out", metavar="FILE", help="also write the table as markdown")
    c.add_argument("--workers", type=int, default=2, help="parallel runs (processes)")
    c.set_defaults(func=cmd_compare)

    sub.add_parser(
        "serve",
        help="serve the operator interface in the browser (see 'swarmpark serve -h')",
        add_help=False,
    )
    sub.add_parser(
        "layout",
        help="lay out parking goals in a boundary (see 'swarmpark layout -h')",
        add_help=False,
    )
    return p


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] == "layout":
        from swarmpark.apps.cli_layout import layout_command

        return layout_command(argv[1:])
    if argv and argv[0] == "serve":
        from swarmpark.server.cli import serve_command

        return serve_command(argv[1:])
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except BrokenPipeError:  # e.g. `swarmpark run ... | head`: the reader went away
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
