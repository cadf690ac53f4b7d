"""The live RealPen app: write with a stylus in a browser, hear and feel the pen.

``realpen serve`` starts a FastAPI app (:func:`realpen.live.app.create_app`) that serves a
plain-ES-module page (``static/``), the pen profiles and their audio, and a WebSocket for pen
events. The pieces:

- :mod:`~realpen.live.messages` — the pydantic schema of every WebSocket message;
- :mod:`~realpen.live.session` — what one page's messages do (store, device, replies);
- :mod:`~realpen.live.store` — the stroke store (SQLite or PostgreSQL, on the tables of
  :mod:`realpen.study.tables`) and its CSV export;
- :mod:`~realpen.live.study_routes` — the study pages and HTTP API (:mod:`realpen.study`);
- :mod:`~realpen.live.bodies` — request bodies: small, and sent in time;
- :mod:`~realpen.live.device` — the seam for the pen's own hardware: the command log, :func:`open_device`;
- :mod:`~realpen.live.catalog` — the profiles the server offers;
- :mod:`~realpen.live.auth` — the LAN token, Host and Origin checks.

May import: any library layer below it (:mod:`realpen.io`, :mod:`realpen.profile`,
:mod:`realpen.exports`, :mod:`realpen.pens`, ...), never :mod:`realpen.cli`. Routes and
lifecycle only: what a message does to a pen or a sound is computed in the library.
:mod:`~realpen.live.messages` imports pydantic, :mod:`realpen.io.strokes` and
:mod:`realpen.profile.schema` only (neither scipy nor soundfile).
"""
