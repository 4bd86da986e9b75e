"""The ``swarmpark`` command: run, generate and sweep scenarios, lay out parking, serve the UI, bench.

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


def _lost(lost: dict | None) -> str:
    """The run's time lost against top speed, largest first (``-`` if not recorded)."""
    if not lost:
        return "-"
    top = sorted(((v, k) for k, v in lost.items() if v > 0), reverse=True)
    return ", ".join(f"{k} {v:.1f}" for v, k in top) or "0"


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
        f"time_lost_s     {_lost(r.get('time_lost_s'))}",
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
    for d in r["deadlocks"]:
        end = "the end" if d["end_s"] is None else f"{d['end_s']:.2f} s"
        where = ""
        if d.get("pose") is not None:
            x, y, _ = d["pose"]
            where = f" at ({x:.2f}, {y:.2f}), {d['goal_distance_m']:.2f} m from its goal"
        lines.append(
            f"deadlock {d['robot']} {d['start_s']:.2f} s to {end}{where}: {d.get('cause') or '-'}"
        )
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
        scn = load_scenario(args.scenario)
        # Overrides are applied to the validated scenario, so they are checked like the file.
        if args.seed is not None:
            scn = scn.model_copy(update={"seed": args.seed})
        if args.duration is not None:
            scn = scn.model_copy(update={"duration_s": args.duration})
        world = build_world(scn)
    except ScenarioError as exc:
        return _fail(f"{args.scenario}: {exc}")
    from swarmpark.links.ros2 import link_from_args

    observers = []
    if args.record:
        from swarmpark.record import RecordConfig, Recorder
        from swarmpark.record.sinks import McapSink

        try:
            config = RecordConfig(rate_hz=args.record_rate, scan_rate_hz=args.scan_rate)
            sink = McapSink(args.record)
        except (ValueError, OSError) as exc:
            return _fail(f"run --record: {exc}")
        observers.append(Recorder([sink], config, meta={"file": Path(args.scenario).name}))
    show = sys.stderr.isatty() and not args.quiet
    link = None
    try:
        link = link_from_args(world, args)  # None: the simulator
        out = run_world(
            world,
            progress=terminal_progress if show else None,
            observers=observers,
            link=link,
        )
    except (ValueError, TimeoutError) as exc:
        return _fail(f"run --link {args.link}: {exc}")
    finally:
        for o in observers:
            if o.sup is not None:
                o.on_end(o.sup)  # closes the file if the run failed (a no-op after a clean end)
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


def _rate(text: str) -> float | None:
    """A rate in Hz; 0 means "every sample" (``None``)."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not (v >= 0 and v < float("inf")):
        raise argparse.ArgumentTypeError(f"must be >= 0 Hz (got {text!r})")
    return v or None


def cmd_replay(args) -> int:
    from swarmpark.record.replay import replay_command

    return replay_command(args)


def _seed(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--seed: an integer >= 0 (got {text!r})") from None
    if v < 0:
        raise argparse.ArgumentTypeError(f"--seed: an integer >= 0 (got {text!r})")
    return v


def _positive(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        v = float("nan")
    if not v > 0 or v == float("inf"):
        raise argparse.ArgumentTypeError(f"a number > 0 (got {text!r})")
    return v


#: The generator's kinds (``swarmpark.apps.generate.KINDS``, which a test keeps equal), named
#: here so that building the parser does not import the generator and the layout code.
GENERATOR_KINDS = (
    "hangar", "elevator", "door", "corridor", "l-bay", "pass-through", "people", "open-deck",
    "unload", "swap",
)  # fmt: skip


# ----------------------------------------------------------------------------- generate


def cmd_generate(args) -> int:
    from swarmpark.apps.generate import GenerateError, generate, write_scenario

    try:
        data = generate(args.kind, args.seed, robots=args.robots)
    except GenerateError as exc:
        return _fail(f"generate: {exc}")
    header = f"Generated by: swarmpark generate {args.kind} --seed {args.seed}" + (
        f" --robots {args.robots}" if args.robots is not None else ""
    )
    path = write_scenario(data, args.out, header=header)
    print(
        f"wrote {path}: {data['name']}, {len(data['robots'])} robots, "
        f"{data['map']['size_m'][0]:g} x {data['map']['size_m'][1]:g} m, "
        f"duration {data['duration_s']:g} s"
    )
    return EXIT_OK


# ----------------------------------------------------------------------------- sweep


def cmd_sweep(args) -> int:
    from swarmpark.apps.sweep import SpecError, run_sweep_cli

    try:
        return run_sweep_cli(args)
    except SpecError as exc:
        return _fail(str(exc))


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
    fleet = report["benchmarks"].get("nav.fleet")
    if fleet is not None and "nav.fleet" in selected and not args.quick:
        from swarmpark.apps.bench.plots import scaling_png

        rvo = report["benchmarks"].get("nav.fleet_rvo")
        rvo_rows = rvo["rows"] if rvo is not None else None
        print(f"wrote {scaling_png(fleet['rows'], Path(args.plot), rvo_rows)}")
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
    summary = build_map(
        world,
        args.robot,
        args.out,
        loop_closure=not args.no_loop_closure,
        progress=terminal_progress if show else None,
    )
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


# ----------------------------------------------------------------------------- figures


def cmd_figures(args) -> int:
    """Regenerate the docs' figures and tables and fidelity.md (see apps/figures.py)."""
    from swarmpark.apps.figures import run_figures

    def say(msg: str) -> None:
        sys.stderr.write(msg + "\n")

    out = run_figures(Path(args.out), quick=args.quick, compare=not args.no_compare, progress=say)
    for f in out["files"]:
        print(f)
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
    r.add_argument("--record", metavar="FILE.mcap", help="record the run as MCAP (ROS 2 types)")
    r.add_argument(
        "--record-rate", type=_rate, default=10.0, metavar="HZ",
        help="poses and states per simulated second in the recording (0: every tick)",
    )  # fmt: skip
    r.add_argument(
        "--scan-rate", type=_rate, default=5.0, metavar="HZ",
        help="LIDAR scans per simulated second in the recording (0: with every pose sample)",
    )  # fmt: skip

    r.add_argument("--seed", type=_seed, help="override the scenario's seed")
    r.add_argument("--duration", type=_positive, metavar="S", help="override duration_s")
    _add_link_args(r)
    r.set_defaults(func=cmd_run)

    rp = sub.add_parser("replay", help="replay a recorded run (MCAP) in the browser UI")
    rp.add_argument("file", help="recording (.mcap) written by run --record or serve --record")
    rp.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1)")
    rp.add_argument("--port", type=int, default=8001, help="TCP port (default 8001)")
    rp.add_argument("--no-browser", action="store_true", help="do not open a browser")
    rp.add_argument("--check", action="store_true", help="only read the file and print a summary")
    rp.set_defaults(func=cmd_replay)

    g = sub.add_parser("generate", help="write a random feasible scenario of a site kind")
    g.add_argument("kind", help=f"site kind: {', '.join(GENERATOR_KINDS)}")
    g.add_argument("--seed", type=_seed, required=True, help="random seed (same seed, same file)")
    g.add_argument("--robots", type=int, help="fleet size (default: drawn from the seed, 4-30)")
    g.add_argument("--out", required=True, metavar="FILE", help="scenario YAML to write")
    g.set_defaults(func=cmd_generate)

    s = sub.add_parser("sweep", help="run a sweep of scenarios x seeds x parameters on Dask")
    s.add_argument("spec", help="sweep spec YAML (see docs/sweeps.md)")
    s.add_argument("--out", metavar="DIR", help="output directory (default: sweeps/out/<spec>)")
    s.add_argument("--scheduler", metavar="ADDR", help="existing Dask scheduler, tcp://HOST:PORT")
    s.add_argument("--workers", type=int, help="LocalCluster workers (default: cores)")
    s.add_argument("--retries", type=int, default=0, help="re-run a failed job this many times")
    s.add_argument("--timeout", type=_positive, help="seconds per job (default: spec, 1800)")
    s.add_argument(
        "--no-run", action="store_true", help="only rebuild table and summary from the records"
    )
    s.set_defaults(func=cmd_sweep)

    b = sub.add_parser("bench", help="run the timing and quality benchmarks")
    b.add_argument("--only", nargs="*", metavar="PREFIX", help="benchmarks whose name starts so")
    b.add_argument("--quick", action="store_true", help="small sizes (smoke run)")
    b.add_argument("--list", action="store_true", help="list the benchmarks and exit")
    b.add_argument("--out", default="benchmarks/results.json", help="JSON output path")
    b.add_argument(
        "--plot",
        default="docs/img/performance-scaling.png",
        help="where nav.fleet's scaling plot goes (a full run of nav.fleet only)",
    )
    b.set_defaults(func=cmd_bench)

    f = sub.add_parser("formation", help="formation velocity planning (Liu, Sun, Zhu 2010)")
    f.add_argument("--paper", action="store_true", help="reproduce the paper's figures and table")
    f.add_argument("--out", default="docs/img", metavar="DIR", help="where to write them")
    f.set_defaults(func=cmd_formation)

    m = sub.add_parser("map", help="build a map with one skid's LIDAR while a scenario runs")
    m.add_argument("scenario", help="scenario YAML file (the route is its commands)")
    m.add_argument("--robot", required=True, help="the skid that maps")
    m.add_argument("--out", required=True, metavar="FILE", help="map_server YAML to write")
    m.add_argument(
        "--no-loop-closure",
        action="store_true",
        help="keyframe scan matching only (no pose graph optimization)",
    )
    m.set_defaults(func=cmd_map)

    c = sub.add_parser("compare", help="compare assignment costs on the scenario suite")
    c.add_argument("scenarios", nargs="*", help="scenario files (default: scenarios/*.yaml)")
    c.add_argument("--out", metavar="FILE", help="also write the table as markdown")
    c.add_argument("--workers", type=int, default=2, help="parallel runs (processes)")
    c.set_defaults(func=cmd_compare)

    g = sub.add_parser("figures", help="regenerate the docs' figures, tables and fidelity.md")
    g.add_argument(
        "--out", default="docs", metavar="DIR", help="docs directory (figures in DIR/img)"
    )
    g.add_argument("--quick", action="store_true", help="short runs (smoke test, not the docs)")
    g.add_argument(
        "--no-compare",
        action="store_true",
        help="keep assignment-comparison.md (compare costs on the Fig. 6/7 scenarios only)",
    )
    g.set_defaults(func=cmd_figures)

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
