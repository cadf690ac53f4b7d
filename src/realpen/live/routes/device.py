"""The pen's own device, its command log, and the pens' patterns as the pen plays them.

``GET /api/device``                          the pen device: name, kind, connected, message, info
``GET /api/device/log?since=N&limit=M``      the device's command log, a page of at most
                                             :data:`DEVICE_LOG_PAGE` entries at a time
``GET /api/pens/{name}/pen-pattern?rate=R``  a pen's tactile pattern as the pen plays it: int16
                                             little-endian at R Hz (for the page's own links)
"""

from __future__ import annotations

from fastapi import APIRouter, HTTPException
from fastapi.responses import Response

from realpen.io.limits import MAX_JSON_INT
from realpen.live.device import device_status
from realpen.live.routes.pages import NO_CACHE
from realpen.live.routes.params import url_int
from realpen.live.routes.profiles import offered
from realpen.live.state import State

__all__ = ["router", "DEVICE_LOG_PAGE", "PEN_RATE_MIN", "PEN_RATE_MAX"]

DEVICE_LOG_PAGE = 1000  # entries per device-log response: one response never stalls the pens
PEN_RATE_MIN, PEN_RATE_MAX = 1000, 96000  # pen-pattern rates served, Hz

router = APIRouter()


@router.get("/api/device")
def device(state: State) -> dict:
    return device_status(state.device)


@router.get("/api/device/log")
def device_log(state: State, since: url_int(0, MAX_JSON_INT) = 0,
               limit: url_int(1, DEVICE_LOG_PAGE) = DEVICE_LOG_PAGE) -> dict:
    entries = getattr(state.device, "entries", None)
    if entries is None:
        raise HTTPException(404, f"the {state.device.name} device keeps no log")
    page = [entry.to_json() for entry in entries(since, limit)]
    # `next` is the `since` of the following page; `next == count`: this was the last.
    return {"device": state.device.name, "count": state.device.count, "entries": page,
            "next": page[-1]["index"] + 1 if page else since}


@router.get("/api/pens/{name}/pen-pattern")
def pen_pattern(state: State, name: str, rate: url_int(PEN_RATE_MIN, PEN_RATE_MAX)) -> Response:
    entry = offered(state, name)
    data = state.pen_patterns.get(entry.profile, rate)  # a rate it cannot take: 422
    return Response(data, media_type="application/octet-stream", headers={
        **NO_CACHE, "ETag": f'"{entry.profile.version}-pen-{rate}"',
        "X-Sample-Rate": str(rate)})
