"""The "Record a pen" page and its API: takes of the pen's accelerometer and the page's
microphone, and the build of a profile from them (:mod:`realpen.live.recording`).

``GET /record``                                  the page
``GET /api/record``                              the pen, the takes, the last build, the limits
``GET /api/record/live``                         the running take's accelerometer level
``POST /api/record/takes``                       start a take (``accelerometer``, ``range_g``)
``POST /api/record/takes/{id}/stop``             stop it (its capture is written)
``PUT /api/record/takes/{id}/sound?offset=N``    a chunk of its microphone WAV (raw bytes)
``POST /api/record/takes/{id}/sound``            the WAV is complete: check and measure it
``PATCH /api/record/takes/{id}``                 keep it for Build, or not (``keep``)
``DELETE /api/record/takes/{id}``                drop it (its files are deleted)
``POST /api/record/build``                       build and install a profile (202: poll)
``GET /api/record/build``                        the build's progress, then its outcome
"""

from __future__ import annotations

import threading

from fastapi import APIRouter, HTTPException, Request
from fastapi.responses import HTMLResponse, JSONResponse
from pydantic import BaseModel, ConfigDict, Field
from starlette.concurrency import run_in_threadpool

from realpen.live.recording import DEFAULT_ACTUATOR, MAX_SOUND_BYTES, Recorder, RecorderBusy
from realpen.live.routes.pages import static_page
from realpen.live.routes.params import url_int
from realpen.live.state import LiveState, State

__all__ = ["router", "recorder", "StartBody", "KeepBody", "BuildBody"]

router = APIRouter()
_made = threading.Lock()
TakeId = url_int(1, 1_000_000)


class _Body(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, strict=True)


class StartBody(_Body):
    """``POST /api/record/takes``: capture the accelerometer (when the server drives a pen)
    at this full-scale range in g."""

    accelerometer: bool = True
    range_g: int = 2


class KeepBody(_Body):
    """``PATCH /api/record/takes/{id}``."""

    keep: bool


class BuildBody(_Body):
    """``POST /api/record/build``: the pen's name, tool type, description, actuator model."""

    name: str = Field(min_length=1, max_length=64)
    tool: str = Field("pen", min_length=1, max_length=40)
    description: str = Field("", max_length=400)
    actuator: str = Field(DEFAULT_ACTUATOR, min_length=1, max_length=80)


def recorder(state: LiveState) -> Recorder:
    """The server's recording session, made at its first use."""
    with _made:
        found = getattr(state, "recorder", None)
        if found is None:
            found = state.recorder = Recorder(state.device, state.catalog)
        return found


def _busy(action, *args, **kwargs):
    try:
        return action(*args, **kwargs)
    except RecorderBusy as error:
        raise HTTPException(409, str(error)) from None


@router.get("/record", response_class=HTMLResponse)
def page() -> HTMLResponse:
    return static_page("record.html")


@router.get("/api/record")
def status(state: State) -> dict:
    return recorder(state).status()


@router.get("/api/record/live")
def live(state: State) -> dict:
    return recorder(state).live()


@router.post("/api/record/takes", status_code=201)
def start(state: State, body: StartBody) -> dict:
    return _busy(recorder(state).start_take, accelerometer=body.accelerometer,
                 range_g=body.range_g).to_json()


@router.post("/api/record/takes/{take_id}/stop")
def stop(state: State, take_id: TakeId) -> dict:
    return recorder(state).stop_take(take_id).to_json()


@router.put("/api/record/takes/{take_id}/sound")
async def sound_chunk(state: State, take_id: TakeId, request: Request,
                      offset: url_int(0, MAX_SOUND_BYTES)) -> dict:
    data = await request.body()  # within the server's body limit (BodyLimit): one chunk
    take = await run_in_threadpool(_busy, recorder(state).add_sound, take_id, offset, data)
    return take.to_json()


@router.post("/api/record/takes/{take_id}/sound")
def sound_end(state: State, take_id: TakeId) -> dict:
    return recorder(state).end_sound(take_id).to_json()


@router.patch("/api/record/takes/{take_id}")
def keep(state: State, take_id: TakeId, body: KeepBody) -> dict:
    return recorder(state).set_keep(take_id, body.keep).to_json()


@router.delete("/api/record/takes/{take_id}", status_code=204)
def drop(state: State, take_id: TakeId) -> None:
    recorder(state).drop(take_id)


@router.post("/api/record/build", status_code=202)
def build(state: State, body: BuildBody) -> dict:
    return _busy(recorder(state).build, body.name, tool=body.tool,
                 description=body.description, actuator=body.actuator).to_json()


@router.get("/api/record/build")
def build_status(state: State) -> JSONResponse:
    job = recorder(state).job()
    if job is None:
        raise HTTPException(404, "no profile has been built in this session")
    return JSONResponse(job.to_json())
