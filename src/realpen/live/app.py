"""The live app's FastAPI factory: build the state, add the middleware, include the routers.

Every request passes :class:`~realpen.live.auth.AccessGuard`, which refuses other sites'
requests, and :class:`~realpen.live.auth.SecurityHeaders`, which adds the security headers.
The routes are in :mod:`realpen.live.routes`, one router per concern (the page, the profiles,
the strokes and WebSocket, the studies, the device); RealPen errors become HTTP replies in one
place, :mod:`realpen.live.errors`.
"""

from __future__ import annotations

import contextlib

from fastapi import FastAPI

from realpen._version import __version__
from realpen.io.paths import default_store
from realpen.live.auth import AccessGuard, SecurityHeaders
from realpen.live.bodies import BodyLimit
from realpen.live.catalog import Catalog
from realpen.live.device import CommandLog
from realpen.live.errors import add_error_handlers
from realpen.live.routes import ROUTERS
from realpen.live.routes.pages import mount_static
from realpen.live.routes.studies import load_designs
from realpen.live.state import LiveSettings, LiveState
from realpen.live.store import StrokeStore

__all__ = ["create_app", "LiveSettings", "LiveState"]


def create_app(settings: LiveSettings | None = None) -> FastAPI:
    """Build the live app. Profiles are loaded and the store opened here (the store last), so
    problems with them surface as :class:`~realpen.errors.RealPenError` before serving; the store
    is closed (every stroke committed) when the app shuts down. A caller that then fails to
    serve should call ``app.state.live.store.discard()``: it closes the store and removes the
    file if this app created it and nothing was stored.

    Args:
        settings: how the app is set up (None: :class:`~realpen.live.state.LiveSettings`'
            defaults).

    Returns:
        The app; its :class:`~realpen.live.state.LiveState` is ``app.state.live``.
    """
    settings = settings or LiveSettings()
    # Routes resample and smooth with scipy.signal in worker threads, and scipy's lazy loading
    # of its submodules is not thread-safe (two first requests at once can fail with
    # "Module 'scipy' has no attribute '_lib'"): load it once, here, before any request.
    import scipy.signal  # noqa: F401

    catalog = Catalog(settings.profiles)
    designs = load_designs(settings.designs)
    store = StrokeStore(settings.store or default_store())
    state = LiveState(settings, catalog, store, settings.device or CommandLog(), designs)

    @contextlib.asynccontextmanager
    async def lifespan(app: FastAPI):
        try:
            yield
        finally:
            state.shutdown()

    app = FastAPI(title="RealPen live", version=__version__, lifespan=lifespan,
                  docs_url=None, redoc_url=None, openapi_url=None)
    app.state.live = state
    app.add_middleware(BodyLimit)  # innermost: a refused request's body is never read
    app.add_middleware(AccessGuard, token=settings.token, allowed_hosts=settings.allowed_hosts)
    app.add_middleware(SecurityHeaders)  # outermost: refusals carry the headers too
    add_error_handlers(app)
    mount_static(app)
    for router in ROUTERS:
        app.include_router(router)
    return app
