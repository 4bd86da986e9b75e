"""The operator audit trail of the server: every command request and every alarm, on disk.

:class:`AuditLog` appends JSON lines to a rotating file (stdlib
:class:`~logging.handlers.RotatingFileHandler`: a full file is renamed ``.1``, ``.2``, ...
and a new one begun), flushed line by line, so nothing lives only in memory.
:class:`AuditMiddleware` sees every ``POST /api/...`` (who sent it, whether it carried the
token, the server's answer) and hands the entry to the session's observers: the audit log
and the recording. :class:`AlarmTracker` turns the supervisor's state into alarms
(collisions, deadlocks, e-stop latched/released) for both.
"""

from __future__ import annotations

import datetime as _dt
import json
import logging
import logging.handlers
from pathlib import Path

__all__ = ["AuditLog", "AuditMiddleware", "AlarmTracker", "default_audit_path"]

#: Request bodies longer than this are cut in the audit entry (a boundary of many vertices).
MAX_BODY_CHARS = 4000
#: Rotation: bytes per file and files kept (10 x 10 MB: about 500 000 teleop commands).
MAX_BYTES = 10 * 1024 * 1024
BACKUPS = 10


def default_audit_path() -> Path:
    """``$XDG_STATE_HOME/swarmpark/audit.jsonl`` (``~/.local/state/swarmpark/audit.jsonl``)."""
    import os

    base = os.environ.get("XDG_STATE_HOME") or str(Path.home() / ".local" / "state")
    return Path(base) / "swarmpark" / "audit.jsonl"


def _now() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="milliseconds")


class AlarmTracker:
    """New alarms since the last call: collisions, deadlocks, e-stop changes."""

    def __init__(self) -> None:
        self.n_coll = 0
        self.n_dead = 0
        self.estop = False

    def new(self, sup) -> list[dict]:
        met = sup.metrics
        out = [{"kind": "collision", **c} for c in met.collisions[self.n_coll :]]
        self.n_coll = len(met.collisions)
        out += [{"kind": "deadlock", **d.as_dict()} for d in met.deadlocks[self.n_dead :]]
        self.n_dead = len(met.deadlocks)
        if bool(sup.estopped) != self.estop:
            self.estop = bool(sup.estopped)
            out.append({"kind": "estop", "latched": self.estop})
        return out


class AuditLog:
    """Observer of a served session that appends commands and alarms to a JSON-lines file.

    Parameters
    ----------
    path
        The file (its directory is created); rotated at ``max_bytes``.
    """

    def __init__(self, path: str | Path, *, max_bytes: int = MAX_BYTES, backups: int = BACKUPS):
        self.path = Path(path)
        self._rotate = (max_bytes, backups)
        self._handler: logging.handlers.RotatingFileHandler | None = None
        # A logger of our own (not propagated): the application's logging setup is untouched.
        self._log = logging.getLogger(f"swarmpark.audit.{id(self)}")
        self._log.propagate = False
        self._log.setLevel(logging.INFO)
        self._alarms = AlarmTracker()
        self.sup = None
        self.scenario = None

    def _open(self) -> logging.Handler:
        """The file is made at the first entry (a server that fails to start leaves none)."""
        if self._handler is None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            max_bytes, backups = self._rotate
            self._handler = logging.handlers.RotatingFileHandler(
                self.path, maxBytes=max_bytes, backupCount=backups, encoding="utf-8"
            )
            self._handler.setFormatter(logging.Formatter("%(message)s"))
            self._log.addHandler(self._handler)
        return self._handler

    def write(self, entry: dict) -> None:
        handler = self._open()
        self._log.info(json.dumps(entry, separators=(",", ":"), default=str))
        handler.flush()

    # ------------------------------------------------------------------ observer

    def on_start(self, sup) -> None:
        self.sup = sup
        self._alarms = AlarmTracker()
        self.scenario = sup.world.scenario.name
        self.write({"time": _now(), "event": "start", "scenario": self.scenario})

    def on_tick(self, sup) -> None:
        for a in self._alarms.new(sup):
            self.on_alarm(a)

    def on_command(self, entry: dict) -> None:
        self.write({"event": "command", **entry})

    def on_alarm(self, entry: dict) -> None:
        t = round(self.sup.t, 3) if self.sup is not None else None
        self.write({"time": _now(), "event": "alarm", "t_s": t, "scenario": self.scenario, **entry})

    def on_end(self, sup, result: dict | None = None) -> None:
        for a in self._alarms.new(sup):
            self.on_alarm(a)
        self.write(
            {"time": _now(), "event": "end", "scenario": self.scenario, "t_s": round(sup.t, 3)}
        )

    def close(self) -> None:
        if self._handler is not None:
            self._log.removeHandler(self._handler)
            self._handler.close()
            self._handler = None


class AuditMiddleware:
    """ASGI middleware: every ``POST /api/...`` becomes an audit entry for the session's
    observers (``on_command``): wall time, simulated time, client address, whether it held
    the token, the request body, the status and the server's answer (accepted, reason)."""

    def __init__(self, app) -> None:
        self.app = app

    async def __call__(self, scope, receive, send):
        if (
            scope["type"] != "http"
            or scope["method"] != "POST"
            or not scope["path"].startswith("/api/")
        ):
            await self.app(scope, receive, send)
            return
        body = bytearray()
        answer = {"status": None, "body": bytearray()}

        async def recv():
            msg = await receive()
            if msg["type"] == "http.request":
                body.extend(msg.get("body", b""))
            return msg

        async def snd(msg):
            if msg["type"] == "http.response.start":
                answer["status"] = msg["status"]
            elif msg["type"] == "http.response.body":
                answer["body"].extend(msg.get("body", b""))
            await send(msg)

        try:
            await self.app(scope, recv, snd)
        finally:
            self._record(scope, bytes(body), answer["status"], bytes(answer["body"]))

    @staticmethod
    def _record(scope, body: bytes, status: int | None, answer: bytes) -> None:
        from starlette.requests import Request

        from swarmpark.server.deps import has_control

        app = scope["app"]
        session = app.state.session
        request = Request(scope)
        client = scope.get("client")
        try:
            sent = json.loads(body) if body else None
        except ValueError:
            sent = body[:MAX_BODY_CHARS].decode("utf-8", "replace")
        if isinstance(sent, dict | list) and len(json.dumps(sent)) > MAX_BODY_CHARS:
            sent = json.dumps(sent)[:MAX_BODY_CHARS] + "..."
        try:
            reply = json.loads(answer) if answer else {}
        except ValueError:
            reply = {}
        reply = reply if isinstance(reply, dict) else {}
        ok = status is not None and status < 400
        accepted = reply.get("accepted", ok) if ok else False
        reason = reply.get("reason") or reply.get("message") or reply.get("detail") or ""
        entry = {
            "time": _now(),
            "t_s": round(session.sup.t, 3),
            "client": f"{client[0]}:{client[1]}" if client else None,
            "token_required": app.state.token is not None,
            "token_holder": has_control(request) if app.state.token is not None else None,
            "path": scope["path"],
            "request": sent,
            "status": status,
            "accepted": bool(accepted),
            "reason": reason if isinstance(reason, str) else json.dumps(reason, default=str),
        }
        for o in session.observers:
            fn = getattr(o, "on_command", None)
            if fn is not None:
                fn(entry)
