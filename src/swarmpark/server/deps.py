"""Shared request dependencies: the served session and the control-token check."""

from __future__ import annotations

import secrets
from typing import Annotated

from fastapi import Depends, HTTPException, Request

from swarmpark.server.engine import Session

__all__ = ["get_session", "require_control", "has_control", "AUTH_HEADER", "SessionDep"]

AUTH_HEADER = "Authorization"


def get_session(request: Request) -> Session:
    return request.app.state.session


#: The served session, as a handler parameter: ``session: SessionDep``.
SessionDep = Annotated[Session, Depends(get_session)]


def has_control(request: Request) -> bool:
    """True if the server has no token, or the request carries it as ``Bearer <token>``."""
    token: str | None = request.app.state.token
    if token is None:
        return True
    given = request.headers.get(AUTH_HEADER, "")
    scheme, _, value = given.partition(" ")
    return scheme.lower() == "bearer" and secrets.compare_digest(value.strip(), token)


def require_control(request: Request) -> None:
    """Dependency of every control endpoint: without the token the viewer is read-only."""
    if not has_control(request):
        raise HTTPException(
            status_code=401,
            detail="control commands need the server's token "
            "(header 'Authorization: Bearer <token>'); without it this viewer is read-only",
            headers={"WWW-Authenticate": "Bearer"},
        )
