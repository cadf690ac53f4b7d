"""The writing page: ``GET /`` and its static files, and what the page needs to know.

``GET /``              the writing page
``GET /static/…``      its ES modules and style sheet (mounted by :func:`mount_static`)
``GET /api/config``    what the page needs to know about the server
"""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path

from fastapi import APIRouter, FastAPI
from fastapi.responses import HTMLResponse, Response
from fastapi.staticfiles import StaticFiles

from realpen._version import __version__
from realpen.live.messages import MAX_SAMPLES, MODALITIES, PROTOCOL
from realpen.live.state import State

__all__ = ["router", "STATIC_DIR", "NO_CACHE", "NoCacheStatic", "mount_static", "static_page"]

STATIC_DIR = Path(str(files("realpen.live") / "static"))
NO_CACHE = {"Cache-Control": "no-cache"}

router = APIRouter()


class NoCacheStatic(StaticFiles):
    """Static files the browser revalidates every time (no stale modules after an upgrade)."""

    def file_response(self, *args, **kwargs) -> Response:
        response = super().file_response(*args, **kwargs)
        response.headers.update(NO_CACHE)
        return response


def mount_static(app: FastAPI) -> None:
    """Serve :data:`STATIC_DIR` under ``/static`` (a mount belongs to the app, not a router)."""
    app.mount("/static", NoCacheStatic(directory=STATIC_DIR), name="static")


def static_page(*parts: str) -> HTMLResponse:
    """An HTML page of the static folder (``static_page("study", "operator.html")``),
    revalidated every time."""
    return HTMLResponse(STATIC_DIR.joinpath(*parts).read_text(encoding="utf-8"), headers=NO_CACHE)


@router.get("/", response_class=HTMLResponse)
def page() -> HTMLResponse:
    return static_page("index.html")


@router.get("/api/config")
def config(state: State) -> dict:
    settings = state.settings
    return {"realpen": __version__, "protocol": PROTOCOL, "tactile": settings.tactile,
            "token_required": settings.token is not None, "device": state.device.name,
            "modalities": list(MODALITIES), "max_message_bytes": settings.max_message_bytes,
            "max_samples": MAX_SAMPLES}
