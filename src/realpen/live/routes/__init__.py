"""The live app's HTTP and WebSocket routes: one :class:`fastapi.APIRouter` per concern.

- :mod:`~realpen.live.routes.pages` — the writing page, its static files, ``/api/config``;
- :mod:`~realpen.live.routes.profiles` — the pens offered and their audio;
- :mod:`~realpen.live.routes.strokes` — the pen-event WebSocket and ``/api/status``;
- :mod:`~realpen.live.routes.studies` — the study pages and HTTP API;
- :mod:`~realpen.live.routes.qr` — the participant screen's address as a QR code;
- :mod:`~realpen.live.routes.device` — the pen device, its command log, the pen patterns;
- :mod:`~realpen.live.routes.record` — the "Record a pen" page: takes and the profile build;
- :mod:`~realpen.live.routes.params` — no router: the integer URL parameters (digits only, in a
  range) that the routers share.

A new route goes into the router of its concern (or a new module here, added to
:data:`ROUTERS`). Routes are thin: they reach the app's state through the :data:`State`
dependency (:mod:`realpen.live.state`), run the library, and let RealPen errors through to the
one handler that turns them into HTTP replies (:mod:`realpen.live.errors`).
"""

from __future__ import annotations

from realpen.live.routes import device, pages, profiles, qr, record, strokes, studies

__all__ = ["ROUTERS"]

ROUTERS = (studies.router, qr.router, pages.router, profiles.router, device.router,
           record.router, strokes.router)
"""Every router, in the order the app includes them."""
