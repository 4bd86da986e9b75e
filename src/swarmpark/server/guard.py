"""The server's front door: Host and Origin checks and the body-size cap, for HTTP and the
WebSocket alike (an ASGI middleware in front of every route).

* **Host** (DNS rebinding): a request whose ``Host`` is a *name* must name this server
  (``localhost``, the bound name, or ``--allow-host``); IP literals are accepted, since a
  rebinding attack needs a name the attacker controls.
* **Origin** (cross-site requests): a browser sends ``Origin`` with every POST and WebSocket
  handshake. It must be the server's own origin (same host and port as ``Host``) or one of
  ``--allow-origin``; anything else, ``null`` included, is refused (403; the WebSocket is
  closed before it is accepted). Requests without ``Origin`` (curl, scripts) pass: they are
  not a browser acting for another site.
* **Body size**: a body over :data:`~swarmpark.core.limits.MAX_BODY_BYTES` is refused with
  413 as soon as its ``Content-Length`` (or the bytes read so far) says so, before it is
  parsed. The park and park-preview requests may be larger, up to
  :data:`~swarmpark.core.limits.MAX_PARK_BODY_BYTES` (a boundary of up to
  :data:`~swarmpark.core.limits.MAX_BOUNDARY_VERTICES` vertices).
"""

from __future__ import annotations

import ipaddress
import json
from collections.abc import Iterable
from urllib.parse import urlsplit

from swarmpark.core.limits import MAX_BODY_BYTES, MAX_PARK_BODY_BYTES

__all__ = ["GuardMiddleware", "DEFAULT_HOSTS", "BODY_LIMITS", "host_allowed", "origin_allowed"]

#: Names always accepted in ``Host`` (``testserver``: Starlette's test client; a single-label
#: name no public DNS resolves, so no attacker can rebind it).
DEFAULT_HOSTS = ("localhost", "testserver")
#: Paths whose bodies may exceed the general cap, and their own cap.
BODY_LIMITS = {"/api/park": MAX_PARK_BODY_BYTES, "/api/park/preview": MAX_PARK_BODY_BYTES}


def _split_host(value: str) -> str:
    """The host part of a ``Host`` header (``name``, ``1.2.3.4``, ``[::1]``), lowercased."""
    value = value.strip().lower()
    if value.startswith("["):
        return value[1 : value.find("]")] if "]" in value else value
    return value.rsplit(":", 1)[0] if value.count(":") == 1 else value


def host_allowed(host_header: str, allowed: Iterable[str]) -> bool:
    host = _split_host(host_header)
    if not host:
        return False
    try:
        ipaddress.ip_address(host)
        return True
    except ValueError:
        pass
    return host in {h.lower() for h in allowed} or host.endswith(".localhost")


def origin_allowed(origin: str, host_header: str, allowed: Iterable[str]) -> bool:
    origin = origin.strip()
    if origin in set(allowed):
        return True
    parts = urlsplit(origin)
    if parts.scheme not in ("http", "https") or not parts.netloc:
        return False  # "null" (a sandboxed frame, a file) and anything odd
    return parts.netloc.lower() == host_header.strip().lower()


class GuardMiddleware:
    """ASGI middleware: Host, Origin and body size (see the module docstring)."""

    def __init__(
        self,
        app,
        *,
        allowed_hosts: Iterable[str] = (),
        allowed_origins: Iterable[str] = (),
        max_body: int = MAX_BODY_BYTES,
        body_limits: dict[str, int] | None = None,
    ) -> None:
        self.app = app
        self.hosts = tuple(DEFAULT_HOSTS) + tuple(allowed_hosts)
        self.origins = tuple(o.rstrip("/") for o in allowed_origins)
        self.max_body = int(max_body)
        self.body_limits = dict(BODY_LIMITS if body_limits is None else body_limits)

    async def __call__(self, scope, receive, send):
        kind = scope["type"]
        if kind not in ("http", "websocket"):
            return await self.app(scope, receive, send)
        headers = {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope["headers"]}
        host = headers.get("host", "")
        if not host_allowed(host, self.hosts):
            return await self._refuse(
                kind, send, 400, f"host: {host!r} is not this server (allowed: IP addresses, "
                f"{', '.join(self.hosts)}; add names with --allow-host)"
            )  # fmt: skip
        origin = headers.get("origin")
        if origin is not None and not origin_allowed(origin, host, self.origins):
            return await self._refuse(
                kind, send, 403, f"origin: {origin!r} is not this server's origin "
                "(cross-site requests are refused; add origins with --allow-origin)"
            )  # fmt: skip
        if kind == "websocket":
            return await self.app(scope, receive, send)
        max_body = self.body_limits.get(scope.get("path", ""), self.max_body)
        length = headers.get("content-length")
        if length is not None:
            try:
                too_big = int(length) > max_body
            except ValueError:
                return await self._refuse(kind, send, 400, f"content-length: {length!r}")
            if too_big:
                return await self._too_big(send, length, max_body)
        return await self.app(scope, self._capped(receive, send, max_body), send)

    def _capped(self, receive, send, max_body: int):
        """``receive`` that stops a chunked body once it passes the cap (413)."""
        seen = 0

        async def recv():
            nonlocal seen
            msg = await receive()
            if msg["type"] == "http.request":
                seen += len(msg.get("body", b""))
                if seen > max_body:
                    await self._too_big(send, f"more than {seen}", max_body)
                    return {"type": "http.disconnect"}
            return msg

        return recv

    async def _too_big(self, send, length, max_body: int) -> None:
        await self._refuse(
            "http", send, 413, f"body: {length} bytes is over the limit of {max_body} bytes"
        )

    @staticmethod
    async def _refuse(kind: str, send, status: int, message: str) -> None:
        if kind == "websocket":
            # Closing before accepting answers the handshake with HTTP 403.
            await send({"type": "websocket.close", "code": 1008, "reason": message[:120]})
            return
        body = json.dumps({"message": message, "detail": message}).encode()
        await send(
            {
                "type": "http.response.start",
                "status": status,
                "headers": [
                    (b"content-type", b"application/json"),
                    (b"content-length", str(len(body)).encode()),
                    (b"connection", b"close"),
                ],
            }
        )
        await send({"type": "http.response.body", "body": body})
