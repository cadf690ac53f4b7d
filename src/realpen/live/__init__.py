"""The live RealPen app: write with a stylus in a browser, hear and feel the pen.

``realpen serve`` starts a FastAPI app (:func:`realpen.live.app.create_app`) that serves a
plain-ES-module page (``static/``), the pen profiles and their audio, and a WebSocket for pen
events. The pieces:

- :mod:`~realpen.live.app` — the factory: state, middleware, error handlers, routers;
- :mod:`~realpen.live.routes` — the routes, one ``APIRouter`` per concern (the page, the
  profiles, the strokes and WebSocket, the studies, the device);
- :mod:`~realpen.live.state` — the settings and the state the routes share, and the
  dependency that hands it to them;
- :mod:`~realpen.live.errors` — RealPen errors as HTTP replies, in one place;
- :mod:`~realpen.live.messages` — the pydantic schema of every WebSocket message;
- :mod:`~realpen.live.session` — what one page's messages do (store, device, replies);
- :mod:`~realpen.live.store` — the stroke store (SQLite or PostgreSQL, on the tables of
  :mod:`realpen.study.tables`) and its CSV export;
- :mod:`~realpen.live.writer` — a store's batching writer thread, which the stroke store and
  the study routes share;
- :mod:`~realpen.live.pen_patterns` — the pens' patterns rendered for their own links, kept;
- :mod:`~realpen.live.bodies` — request bodies: small, and sent in time;
- :mod:`~realpen.live.device` — the seam for the pen's own hardware: the command log, :func:`open_device`;
- :mod:`~realpen.live.catalog` — the profiles the server offers;
- :mod:`~realpen.live.auth` — the LAN token, Host and Origin checks;
- :mod:`~realpen.live.server` — running the app under uvicorn.

May import: any library layer below it — :mod:`realpen.errors`, :mod:`realpen.validation`,
:mod:`realpen._version`, :mod:`realpen.io`, :mod:`realpen.profile`, :mod:`realpen.exports`,
:mod:`realpen.pens`, :mod:`realpen.study` (its store, designs, sessions, trial patterns) and,
inside functions, :mod:`realpen.device` — never :mod:`realpen.cli`. Routes and lifecycle only:
what a message does to a pen or a sound is computed in the library.
:mod:`~realpen.live.messages` imports pydantic, :mod:`realpen.errors`,
:mod:`realpen.validation`, :mod:`realpen.io.strokes` and :mod:`realpen.profile.schema` only
(neither scipy nor soundfile).
"""
