"""Operator interface in the browser: FastAPI app (REST + WebSocket) and the static UI.

``create_app(...)`` builds the app; ``swarmpark serve`` (:func:`serve_command`) runs it with
uvicorn. See docs/ui.md.
"""

from swarmpark.server.app import create_app

__all__ = ["create_app"]
