"""The participant screen's address as a QR code, for a tablet's camera.

``GET /api/sessions/{id}/participant-qr.svg``  the QR code (SVG) of the participant screen of
                                               session ID, with the LAN token when the server
                                               has one

The operator console shows it beside the address: a tablet scans it instead of having the long
token typed. The address is the one the console shows: this server as the request reached it
(its ``Host``), ``/study/participant?session=ID`` and, in LAN mode, ``&token=…``. Like every
route it needs the token itself, so it tells the token to no one who does not hold it; the
reply carries the app's security headers and ``Cache-Control: no-cache``.

The code is made by segno (https://segno.readthedocs.io: ISO/IEC 18004 QR codes, pure Python)
at error correction level M (15 % of the code may be unreadable: a screen's glare), as SVG
without a fixed size, so that the page scales it.
"""

from __future__ import annotations

import io
from urllib.parse import urlencode

import segno
from fastapi import APIRouter, Request
from fastapi.responses import Response

from realpen.live.routes.params import STORED_ID
from realpen.live.routes.studies import read_store
from realpen.live.state import State
from realpen.study.sessions import progress as session_progress

__all__ = ["router", "ERROR_LEVEL", "SVG_OPTIONS", "participant_url", "qr_svg"]

ERROR_LEVEL = "m"
SVG_OPTIONS = {"xmldecl": False, "omitsize": True, "border": 4, "dark": "#000",
               "light": "#fff"}
"""How :func:`qr_svg` writes the SVG (segno's ``save(kind="svg")`` options): no XML
declaration, no width or height (the page sizes it), the 4-module quiet zone the standard asks
for, black on white."""

router = APIRouter()


def participant_url(base: str, session_id: int, token: str | None) -> str:
    """The participant screen's address of a study session.

    Args:
        base: the server's address as the client reached it, ending in ``/``
            (``http://192.168.1.20:8765/``).
        session_id: the study session's id.
        token: the server's LAN token, or None when it needs none.

    Returns:
        ``{base}study/participant?session={session_id}`` and ``&token={token}`` when given.

    Examples:
        >>> participant_url("http://127.0.0.1:8765/", 7, None)
        'http://127.0.0.1:8765/study/participant?session=7'
        >>> participant_url("http://10.0.0.2:8765/", 7, "AbC_1-xyzxyzxyzxyzxyz")
        'http://10.0.0.2:8765/study/participant?session=7&token=AbC_1-xyzxyzxyzxyzxyz'
    """
    query = {"session": session_id} | ({"token": token} if token else {})
    return f"{base}study/participant?{urlencode(query)}"


def qr_svg(text: str, *, title: str = "") -> bytes:
    """``text`` as a QR code in SVG (UTF-8), sized by its viewBox only (one unit per module).

    Args:
        text: what the code holds (an address of up to a few hundred characters).
        title: the SVG's ``<title>`` (what a screen reader says), or "" for none.

    Returns:
        The SVG document (:data:`SVG_OPTIONS`, error correction :data:`ERROR_LEVEL`).

    Examples:
        >>> qr_svg("http://127.0.0.1:8765/study/participant?session=7").startswith(b"<svg")
        True
    """
    buffer = io.BytesIO()
    segno.make_qr(text, error=ERROR_LEVEL).save(buffer, kind="svg", title=title or None,
                                                **SVG_OPTIONS)
    return buffer.getvalue()


@router.get("/api/sessions/{session_id}/participant-qr.svg")
async def participant_qr(state: State, request: Request, session_id: STORED_ID) -> Response:
    await read_store(state, session_progress, session_id, state.design_cache)  # 404 if none
    url = participant_url(str(request.base_url), session_id, state.settings.token)
    svg = qr_svg(url, title=f"The participant screen of session {session_id}")
    # it may hold the LAN token: no cache keeps a copy
    return Response(svg, media_type="image/svg+xml", headers={"Cache-Control": "no-store"})
