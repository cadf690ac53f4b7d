"""The live app's FastAPI factory: thin routes over the catalog, the session, store and device.

Routes (all behind :class:`~realpen.live.auth.AccessGuard`, which refuses other sites' requests,
and :class:`~realpen.live.auth.SecurityHeaders`, which adds the security headers):

``GET /``                                    the writing page
``GET /static/…``                            its ES modules and style sheet
``GET /api/config``                          what the page needs to know about the server
``GET /api/profiles``                        the pens offered (name, version, coupling, …)
``GET /api/profiles/{name}/sound.wav``       a pen's sound unit (32-bit float WAV)
``GET /api/profiles/{name}/tactile.wav``     a pen's tactile pattern (32-bit float WAV)
``GET /api/profiles/{name}/grid/{i}.wav``    the loop of point i of a pen's vibration grid
``GET /api/device``                          the pen device: name, kind, connected, message, info
``GET /api/device/log?since=N&limit=M``      the device's command log, a page of at most
                                             :data:`DEVICE_LOG_PAGE` entries at a time
``GET /api/pens/{name}/pen-pattern?rate=R``  a pen's tactile pattern as the pen plays it: int16
                                             little-endian at R Hz (for the page's own links)
``GET /api/status``                          pages connected, strokes and samples stored
``/study``, ``/api/studies``, ``/api/sessions…``  the studies (:mod:`realpen.live.study_routes`)
``WS  /ws``                                  pen events (:mod:`realpen.live.messages`)
"""

from __future__ import annotations

import contextlib
import threading
from dataclasses import dataclass, field
from importlib.resources import files
from pathlib import Path
from typing import Literal

from fastapi import FastAPI, HTTPException, Query, Request, WebSocket, WebSocketDisconnect
from fastapi import Path as PathParam
from fastapi.exceptions import RequestValidationError
from fastapi.responses import HTMLResponse, JSONResponse, Response
from fastapi.staticfiles import StaticFiles

from realpen import __version__
from realpen.errors import RealPenError
from realpen.io.paths import default_store
from realpen.live.auth import LOOPBACK_HOSTS, AccessGuard, SecurityHeaders
from realpen.live.bodies import BodyLimit
from realpen.live.catalog import Catalog
from realpen.live.device import CommandLog, PenDevice, device_status
from realpen.live.messages import MAX_MESSAGE_BYTES, MAX_SAMPLES, MODALITIES, PROTOCOL
from realpen.live.session import Session
from realpen.live.store import SHUTDOWN_WAIT_S, STORE_ERRORS, StrokeStore, error_line
from realpen.live.study_routes import add_study_routes, load_designs, validation_line

STATIC_DIR = Path(str(files(__package__) / "static"))
NO_CACHE = {"Cache-Control": "no-cache"}
DEVICE_LOG_PAGE = 1000  # entries per device-log response: one response never stalls the pens
PEN_RATE_MIN, PEN_RATE_MAX = 1000, 96000  # pen-pattern rates served, Hz
PEN_PATTERNS_KEPT = 16  # rendered pen patterns kept (by pen, version and rate)


@dataclass
class LiveSettings:
    """How a live app is set up.

    Attributes:
        store: the store: an SQLite file, or a database URL (``postgresql://…``; None:
            :func:`realpen.paths.default_store`).
        profiles: extra folders of profiles, after the bundled and user ones.
        tactile: ``"audio"`` plays the tactile pattern on the right audio channel by default
            (the page can toggle it); ``"none"`` leaves touch to the pen's own device.
        token: when set, every request must carry it (LAN mode sets a random one).
        allowed_hosts: host names the ``Host`` header may name (None: any). Loopback-only
            serving passes :data:`~realpen.live.auth.LOOPBACK_HOSTS`.
        device: what pen commands drive (None: a new :class:`CommandLog`, no pen; see
            :func:`realpen.live.device.open_device`).
        max_message_bytes: the size limit of one WebSocket message.
        designs: study design files offered beside the built-in ``study1`` and ``study2``.
    """

    store: Path | str | None = None
    profiles: list[Path] = field(default_factory=list)
    tactile: Literal["audio", "none"] = "none"
    token: str | None = None
    allowed_hosts: tuple[str, ...] | None = None
    device: PenDevice | None = None
    max_message_bytes: int = MAX_MESSAGE_BYTES
    designs: list[Path] = field(default_factory=list)

    @classmethod
    def loopback(cls, **kwargs) -> LiveSettings:
        """Settings for a server that only listens on 127.0.0.1 (Host must be loopback)."""
        return cls(allowed_hosts=LOOPBACK_HOSTS, **kwargs)


class NoCacheStatic(StaticFiles):
    """Static files the browser revalidates every time (no stale modules after an upgrade)."""

    def file_response(self, *args, **kwargs) -> Response:
        response = super().file_response(*args, **kwargs)
        response.headers.update(NO_CACHE)
        return response


@dataclass
class LiveState:
    """Everything the routes share."""

    settings: LiveSettings
    catalog: Catalog
    store: StrokeStore
    device: PenDevice
    sessions: dict[str, Session] = field(default_factory=dict)
    pages: dict[str, Session] = field(default_factory=dict)  # page id → its live session
    final_counts: tuple[int, int] | None = None  # (strokes, samples) when the store closed
    designs: dict = field(default_factory=dict)  # the study designs offered, by name
    stopped: bool = False  # shut down (the store closed)
    count_problem: str | None = None  # why final_counts is None after the shutdown

    def open_session(self) -> Session:
        session = Session(self.catalog, self.store, self.device, self.settings.max_message_bytes,
                          self.pages)
        self.sessions[session.id] = session
        return session

    async def close_session(self, session: Session) -> None:
        self.sessions.pop(session.id, None)
        await session.close()

    def shutdown(self) -> None:
        """Close the pages' sessions, the store and the device (once; later calls do nothing).

        ``final_counts`` is then what the store holds, or None when the database could not say
        (``count_problem`` says why, in one line); the store is closed either way.
        """
        if self.stopped:
            return
        self.stopped = True
        for session in list(self.sessions.values()):
            session.close_now()
        self.sessions.clear()
        try:
            self.final_counts = self.store.count(SHUTDOWN_WAIT_S)
        except (*STORE_ERRORS, TimeoutError) as error:
            self.count_problem = error_line(error) if str(error) else "no answer in time"
        self.store.close()
        self.device.close()


def create_app(settings: LiveSettings | None = None) -> FastAPI:
    """Build the live app. Profiles are loaded and the store opened here (the store last), so
    problems with them surface as :class:`~realpen.errors.RealPenError` before serving; the store
    is closed (every stroke committed) when the app shuts down. A caller that then fails to
    serve should call ``app.state.live.store.discard()``: it closes the store and removes the
    file if this app created it and nothing was stored.
    """
    settings = settings or LiveSettings()
    catalog = Catalog(settings.profiles)
    designs = load_designs(settings.designs)
    store = StrokeStore(settings.store or default_store())
    state = LiveState(settings, catalog, store, settings.device or CommandLog())

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
    app.mount("/static", NoCacheStatic(directory=STATIC_DIR), name="static")

    @app.exception_handler(RequestValidationError)
    async def one_line_422(request: Request, error: RequestValidationError) -> JSONResponse:
        return JSONResponse({"detail": validation_line(error)}, status_code=422)

    state.designs = designs
    add_study_routes(app, state, designs, STATIC_DIR)

    @app.get("/", response_class=HTMLResponse)
    def page() -> HTMLResponse:
        return HTMLResponse((STATIC_DIR / "index.html").read_text(encoding="utf-8"),
                            headers=NO_CACHE)

    @app.get("/api/config")
    def config() -> dict:
        return {"realpen": __version__, "protocol": PROTOCOL, "tactile": settings.tactile,
                "token_required": settings.token is not None, "device": state.device.name,
                "modalities": list(MODALITIES), "max_message_bytes": settings.max_message_bytes,
                "max_samples": MAX_SAMPLES}

    @app.get("/api/profiles")
    def profiles() -> dict:
        return {"profiles": catalog.to_json()}

    @app.get("/api/profiles/{name}/{part}.wav")
    def profile_audio(name: str, part: Literal["sound", "tactile"]) -> Response:
        entry = catalog.get(name)
        if entry is None:
            raise HTTPException(404, f"no profile '{name}'")
        data = entry.sound_wav if part == "sound" else entry.tactile_wav
        return Response(data, media_type="audio/wav",
                        headers={**NO_CACHE, "ETag": f'"{entry.profile.version}-{part}"'})

    @app.get("/api/profiles/{name}/grid/{index}.wav")
    def grid_audio(name: str, index: int = PathParam(ge=0)) -> Response:
        entry = catalog.get(name)
        if entry is None:
            raise HTTPException(404, f"no profile '{name}'")
        try:
            data = entry.point_wav(index)
        except IndexError:
            raise HTTPException(404, f"the profile '{name}' has no grid point {index}") from None
        return Response(data, media_type="audio/wav",
                        headers={**NO_CACHE, "ETag": f'"{entry.profile.version}-grid-{index}"'})

    @app.get("/api/device")
    def device() -> dict:
        return device_status(state.device)

    pen_patterns: dict[tuple[str, str, int], bytes] = {}  # rendered once per pen and rate
    pen_patterns_lock = threading.Lock()  # the route runs on the thread pool

    @app.get("/api/pens/{name}/pen-pattern")
    def pen_pattern(name: str,
                    rate: int = Query(..., ge=PEN_RATE_MIN, le=PEN_RATE_MAX)) -> Response:
        from realpen.device.pattern import pattern_bytes
        from realpen.device.pattern import pen_pattern as render

        entry = catalog.get(name)
        if entry is None:
            raise HTTPException(404, f"no profile '{name}'")
        key = (name, entry.profile.version, rate)
        with pen_patterns_lock:
            data = pen_patterns.get(key)
        if data is None:
            try:
                data = pattern_bytes(render(entry.profile, rate))
            except RealPenError as error:  # a rate the pattern cannot take
                raise HTTPException(422, str(error)) from None
            with pen_patterns_lock:
                if len(pen_patterns) >= PEN_PATTERNS_KEPT:
                    pen_patterns.pop(next(iter(pen_patterns)))
                pen_patterns[key] = data
        return Response(data, media_type="application/octet-stream", headers={
            **NO_CACHE, "ETag": f'"{entry.profile.version}-pen-{rate}"',
            "X-Sample-Rate": str(rate)})

    @app.get("/api/device/log")
    def device_log(since: int = Query(0, ge=0, le=2**53),
                   limit: int = Query(DEVICE_LOG_PAGE, ge=1, le=DEVICE_LOG_PAGE)) -> dict:
        entries = getattr(state.device, "entries", None)
        if entries is None:
            raise HTTPException(404, f"the {state.device.name} device keeps no log")
        page = [entry.to_json() for entry in entries(since, limit)]
        # `next` is the `since` of the following page; `next == count`: this was the last.
        return {"device": state.device.name, "count": state.device.count, "entries": page,
                "next": page[-1]["index"] + 1 if page else since}

    @app.get("/api/status")
    def status() -> dict:
        strokes, samples = store.count()
        return {"pages": len(state.sessions), "strokes": strokes, "samples": samples,
                "store": store.display}

    @app.websocket("/ws")
    async def pen_events(websocket: WebSocket) -> None:
        await websocket.accept()
        session = state.open_session()
        try:
            while True:
                frame = await websocket.receive()
                if frame["type"] == "websocket.disconnect":
                    break
                raw = frame["text"] if frame.get("text") is not None else frame.get("bytes", b"")
                # One message at a time: the next frame is read once this one is stored and
                # acknowledged. That is the backpressure: a page that sends faster than the
                # store writes waits in its own TCP window, and no one else does.
                reply = await session.handle(raw)
                await websocket.send_text(reply.model_dump_json(exclude_none=True))
                if getattr(reply, "code", None) == "store":
                    # The store could not record it: closing makes the page send again, in
                    # order, everything not acknowledged (later messages depend on this one).
                    await websocket.close(1011, "the stroke store could not record a message")
                    break
        except (WebSocketDisconnect, OSError, RuntimeError):
            pass
        finally:
            await state.close_session(session)

    return app
