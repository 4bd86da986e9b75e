"""``swarmpark serve``: run the operator interface with uvicorn.

Binds 127.0.0.1 by default; ``--host 0.0.0.0`` exposes it on the ship's network, where
``--token`` should guard the controls. Exit codes: 0 after a clean shutdown, 2 bad input
(one line on stderr).
"""

from __future__ import annotations

import argparse
import ipaddress
import math
import secrets
import sys

__all__ = ["serve_command", "build_parser"]

EXIT_OK, EXIT_BAD_INPUT = 0, 2


class _BadInput(Exception):
    pass


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # type: ignore[override]
        raise _BadInput(f"{self.prog}: error: {message}")


def build_parser() -> argparse.ArgumentParser:
    from swarmpark.server.schemas import MAX_SPEED_FACTOR, MIN_SPEED_FACTOR

    p = _Parser(
        prog="swarmpark serve",
        description="Serve the operator interface (map view, park, goals, e-stop, teleop).",
    )
    p.add_argument(
        "scenario",
        nargs="?",
        help="scenario YAML (default: hangar-park.yaml in the scenarios directory)",
    )
    p.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1)")
    p.add_argument("--port", type=int, default=8000, help="TCP port (default 8000)")
    p.add_argument("--token", help="control commands need this token; others are read-only")
    p.add_argument(
        "--allow-host", action="append", default=[], metavar="NAME",
        help="also answer requests whose Host is NAME (IP addresses and localhost always are)",
    )  # fmt: skip
    p.add_argument(
        "--allow-origin", action="append", default=[], metavar="ORIGIN",
        help="also accept requests from pages of ORIGIN (e.g. https://console.example)",
    )  # fmt: skip
    p.add_argument(
        "--speed",
        type=float,
        default=1.0,
        help=f"simulated seconds per wall second ({MIN_SPEED_FACTOR}..{MAX_SPEED_FACTOR})",
    )
    p.add_argument("--scenarios-dir", help="directory the scenario picker lists")
    p.add_argument("--paused", action="store_true", help="start with the simulation paused")
    p.add_argument(
        "--no-script", action="store_true", help="ignore the scenario's own timed commands"
    )
    p.add_argument(
        "--record", metavar="DIR", help="record every run as MCAP (ROS 2 types) into DIR"
    )
    p.add_argument(
        "--foxglove", nargs="?", type=int, const=8765, metavar="PORT",
        help="stream the recorded channels to Foxglove (WebSocket, default port 8765)",
    )  # fmt: skip
    p.add_argument(
        "--foxglove-host", default="127.0.0.1",
        help="address the Foxglove server binds (default 127.0.0.1)",
    )  # fmt: skip
    p.add_argument(
        "--audit", metavar="FILE",
        help="operator audit log, JSON lines, rotated (default: DIR/audit.jsonl with --record, "
        "else ~/.local/state/swarmpark/audit.jsonl)",
    )  # fmt: skip
    p.add_argument(
        "--record-rate",
        type=float,
        default=10.0,
        metavar="HZ",
        help="pose samples per simulated second in the recording (0: every tick)",
    )
    p.add_argument(
        "--scan-rate",
        type=float,
        default=5.0,
        metavar="HZ",
        help="LIDAR scans per simulated second in the recording (0: with every pose sample)",
    )
    from swarmpark.links.ros2 import add_link_args

    add_link_args(p)
    return p


def _check(args) -> None:
    from swarmpark.server.schemas import MAX_SPEED_FACTOR, MIN_SPEED_FACTOR

    if not 0 < args.port < 65536:
        raise _BadInput(f"swarmpark serve: error: --port must be 1..65535 (got {args.port})")
    if not (math.isfinite(args.speed) and MIN_SPEED_FACTOR <= args.speed <= MAX_SPEED_FACTOR):
        raise _BadInput(
            f"swarmpark serve: error: --speed must be {MIN_SPEED_FACTOR}..{MAX_SPEED_FACTOR} "
            f"(got {args.speed})"
        )
    if args.token is not None and not args.token.strip():
        raise _BadInput("swarmpark serve: error: --token must not be empty")
    if args.foxglove is not None and not 0 <= args.foxglove < 65536:
        raise _BadInput(
            f"swarmpark serve: error: --foxglove must be 0..65535 (got {args.foxglove})"
        )
    for name in ("record_rate", "scan_rate"):
        v = getattr(args, name)
        if not (math.isfinite(v) and v >= 0):
            flag = "--" + name.replace("_", "-")
            raise _BadInput(f"swarmpark serve: error: {flag} must be >= 0 Hz (got {v})")


def _observers(args) -> tuple[list, list[str]]:
    """The audit log (always: nothing is kept only in memory), the recorder, Foxglove; and
    the lines that tell the operator where they are (printed once the server starts)."""
    from pathlib import Path

    from swarmpark.record.audit import AuditLog, default_audit_path
    from swarmpark.record.live import LiveRecording
    from swarmpark.record.recorder import RecordConfig

    if args.audit:
        audit_path = Path(args.audit)
    elif args.record:
        audit_path = Path(args.record) / "audit.jsonl"
    else:
        audit_path = default_audit_path()
    observers: list = [AuditLog(audit_path)]
    notes = [f"audit log {audit_path}"]
    if args.record or args.foxglove is not None:
        live = LiveRecording(
            directory=args.record,
            foxglove_port=args.foxglove,
            foxglove_host=args.foxglove_host,
            # 0 Hz: every tick (as for `swarmpark run`).
            config=RecordConfig(
                rate_hz=args.record_rate or None, scan_rate_hz=args.scan_rate or None
            ),
        )
        observers.append(live)
        if args.record:
            notes.append(f"recording into {args.record}/")
        if live.foxglove_port is not None:
            notes.append(f"Foxglove on ws://{args.foxglove_host}:{live.foxglove_port}")
    return observers, notes


def _is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def serve_command(argv: list[str]) -> int:
    """Parse ``argv`` (the words after ``serve``), build the app and run it until Ctrl-C."""
    from swarmpark.server.app import create_app
    from swarmpark.world.scenario import ScenarioError

    try:
        try:
            args = build_parser().parse_args(argv)
        except SystemExit as exc:  # -h / --help printed the usage
            return int(exc.code or 0)
        _check(args)
        factory = None
        if args.link == "ros2":
            if args.speed != 1.0:
                raise _BadInput("swarmpark serve: error: --link ros2 runs in real time (--speed 1)")
            from swarmpark.links.ros2 import link_from_args

            def factory(world):
                return link_from_args(world, args, paced=False)  # the session paces

        secret = secrets.token_urlsafe(18)
        try:
            observers, notes = _observers(args)
        except (OSError, RuntimeError) as exc:  # the Foxglove port in use (FoxgloveError)
            raise _BadInput(f"swarmpark serve: error: --record/--audit/--foxglove: {exc}") from None
        try:
            app = create_app(
                args.scenario,
                link_factory=factory,
                token=args.token,
                scenarios_dir=args.scenarios_dir,
                speed=args.speed,
                autostart=not args.paused,
                scripted=not args.no_script,
                observers=observers,
                # Without a token the controls still need a per-server secret (sent by the
                # page, from the URL printed below), so no other site can drive the swarm.
                secret=None if args.token else secret,
                allowed_hosts=[*args.allow_host, args.host],
                allowed_origins=args.allow_origin,
            )
        except BaseException:
            for o in observers:
                o.close()
            raise
    except _BadInput as exc:
        sys.stderr.write(f"{exc}\n")
        return EXIT_BAD_INPUT
    except (ScenarioError, OSError, ValueError) as exc:  # OSError: the record dir, the audit file
        sys.stderr.write(f"swarmpark serve: error: {exc}\n")
        return EXIT_BAD_INPUT
    import uvicorn

    if not _is_loopback(args.host) and args.token is None:
        sys.stderr.write(
            f"swarmpark serve: warning: listening on {args.host} without --token: "
            "anyone on the network can command the swarm\n"
        )
    for note in notes:
        sys.stderr.write(f"swarmpark serve: {note}\n")
    shown = f"[{args.host}]" if ":" in args.host else args.host
    query = "" if args.token else f"?secret={secret}"
    sys.stderr.write(f"swarmpark serve: operator interface on http://{shown}:{args.port}/{query}\n")
    try:
        uvicorn.run(
            app,
            host=args.host,
            port=args.port,
            log_level="warning",
            # Every viewer gets the same frame: compressing it once per connection (the
            # per-message deflate browsers ask for) costs more CPU than the frames save on
            # a console's LAN, and 200 viewers would slow the simulation.
            ws_per_message_deflate=False,
        )
    except OSError as exc:  # address not available
        sys.stderr.write(f"swarmpark serve: error: {exc}\n")
        return EXIT_BAD_INPUT
    except SystemExit as exc:  # uvicorn exits 1 when it cannot bind (it logged why)
        return EXIT_BAD_INPUT if exc.code else EXIT_OK
    return EXIT_OK
