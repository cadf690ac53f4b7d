"""What the live app's routes share: its settings, its state, and the dependency that reaches it.

:func:`realpen.live.app.create_app` builds one :class:`LiveState` and keeps it on
``app.state.live``; a route asks for it with a parameter annotated :data:`State` (FastAPI's
dependency injection), never through a variable of the factory.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, Literal

from fastapi import Depends
from starlette.requests import HTTPConnection

from realpen.live.auth import LOOPBACK_HOSTS
from realpen.live.catalog import Catalog
from realpen.live.device import PenDevice
from realpen.live.messages import MAX_MESSAGE_BYTES
from realpen.live.pen_patterns import PenPatternCache
from realpen.live.session import Session
from realpen.live.store import SHUTDOWN_WAIT_S, StrokeStore
from realpen.study.db import STORE_ERRORS, error_line
from realpen.study.design import Design
from realpen.study.patterns import PatternCache
from realpen.study.sessions import DesignCache

__all__ = ["LiveSettings", "LiveState", "live_state", "State"]


@dataclass
class LiveSettings:
    """How a live app is set up.

    Attributes:
        store: the store: an SQLite file, or a database URL (``postgresql://…``; None:
            :func:`realpen.io.paths.default_store`).
        profiles: extra folders of profiles, after the bundled and user ones.
        tactile: ``"audio"`` plays the tactile pattern on the right audio channel by default
            (the page can toggle it); ``"none"`` leaves touch to the pen's own device.
        token: when set, every request must carry it (LAN mode sets a random one).
        allowed_hosts: host names the ``Host`` header may name (None: any). Loopback-only
            serving passes :data:`~realpen.live.auth.LOOPBACK_HOSTS`.
        device: what pen commands drive (None: a new :class:`~realpen.live.device.CommandLog`,
            no pen; see :func:`realpen.live.device.open_device`).
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


@dataclass
class LiveState:
    """Everything the routes share.

    Attributes:
        settings: how the app was set up.
        catalog: the pens offered.
        store: the stroke store (its writer also runs the study operations).
        device: what pen commands drive.
        designs: the study designs offered, by name (built-in and ``serve --design``).
        design_cache: the designs stored with the studies, read once per study.
        trial_patterns: the tactile patterns of study trials' conditions, built once.
        pen_patterns: the pens' patterns rendered for their own links, kept by rate.
        sessions: the open page connections, by id.
        pages: each page's live session, by the page's own id.
        final_counts: (strokes, samples) when the store closed.
        stopped: shut down (the store closed).
        count_problem: why ``final_counts`` is None after the shutdown.
        recorder: the "Record a pen" page's session (takes, build), made at its first use.
    """

    settings: LiveSettings
    catalog: Catalog
    store: StrokeStore
    device: PenDevice
    designs: dict[str, Design] = field(default_factory=dict)
    design_cache: DesignCache = field(default_factory=DesignCache)
    trial_patterns: PatternCache = field(default_factory=PatternCache)
    pen_patterns: PenPatternCache = field(default_factory=PenPatternCache)
    sessions: dict[str, Session] = field(default_factory=dict)
    pages: dict[str, Session] = field(default_factory=dict)  # page id → its live session
    final_counts: tuple[int, int] | None = None
    stopped: bool = False
    recorder: Any = None
    count_problem: str | None = None

    def open_session(self) -> Session:
        """A new page connection's :class:`~realpen.live.session.Session`."""
        session = Session(self.catalog, self.store, self.device, self.settings.max_message_bytes,
                          self.pages)
        self.sessions[session.id] = session
        return session

    async def close_session(self, session: Session) -> None:
        """End a page connection's session (its open stroke ends as ``disconnect``)."""
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
        if self.recorder is not None:
            # A take under way is stopped on the pen, and the takes' temporary files removed.
            self.recorder.close()
        try:
            self.final_counts = self.store.count(SHUTDOWN_WAIT_S)
        except (*STORE_ERRORS, TimeoutError) as error:
            self.count_problem = error_line(error) if str(error) else "no answer in time"
        self.store.close()
        self.device.close()


def live_state(connection: HTTPConnection) -> LiveState:
    """The app's :class:`LiveState` (a FastAPI dependency, for HTTP routes and WebSockets)."""
    return connection.app.state.live


State = Annotated[LiveState, Depends(live_state)]
"""A route parameter of this type receives the app's :class:`LiveState`."""
