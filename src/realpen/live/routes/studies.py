"""The study routes: the operator console, the participant screen and the study HTTP API.

Thin: each route validates its request (ids in the URL: digits only, 1 to 2,147,483,647,
:mod:`realpen.live.routes.params`), runs one operation of :mod:`realpen.study.sessions` on
the store's writer (so its reply is sent only after the commit) and lets a
:class:`~realpen.study.sessions.StudyError` through to the app's one error handler
(:mod:`realpen.live.errors`), which replies with its kind's status and a one-line ``detail``.
``docs/studies.md`` documents the API for other apps (PsychoPy, jsPsych, …).

``GET  /study``                                  the operator console
``GET  /study/participant?session=ID``           the participant screen
``GET  /api/studies``                            the designs this server runs
``GET  /api/studies/{name}``                     one design (the design file as JSON)
``POST /api/sessions``                           start a session, or find the participant's
``GET  /api/sessions``                           the newest sessions' progress
``GET  /api/sessions/{id}``                      one session's progress
``GET  /api/sessions/{id}/next``                 the first unanswered trial, or done
``POST /api/sessions/{id}/trials/{n}``           answer trial n
``POST /api/sessions/{id}/state``                pause, resume, finish or abandon
``POST /api/sessions/{id}/withdraw``             withdraw the participant (their data deleted)
``GET  /api/sessions/{id}/trials/{n}/tactile.wav``  the trial's tactile pattern
"""

from __future__ import annotations

import asyncio
from concurrent.futures import Future
from pathlib import Path
from typing import Annotated, Literal

from fastapi import APIRouter
from fastapi.responses import HTMLResponse, JSONResponse, Response
from pydantic import BaseModel, ConfigDict, Field
from sqlalchemy.exc import IntegrityError
from starlette.concurrency import run_in_threadpool

from realpen.errors import RealPenError
from realpen.live.catalog import CatalogEntry, playable_wav
from realpen.live.routes.pages import static_page
from realpen.live.routes.params import STORED_ID, url_int
from realpen.live.state import State
from realpen.study import admin
from realpen.study import sessions as study
from realpen.study.db import STORE_ERRORS, error_line
from realpen.study.design import MAX_ANSWER_CHARS, Design
from realpen.study.patterns import PatternCache

__all__ = ["router", "load_designs", "read_store", "SessionBody", "AnswerBody", "StateBody", "WithdrawBody",
           "REQUEST_WAIT_S"]

REQUEST_WAIT_S = 30.0  # a request waits at most this long for the store, then gets 503
Id = STORED_ID

router = APIRouter()


class _Body(BaseModel):
    # strict: JSON types are taken as they are (true is not 1, "7" is not a number, 4.0 is not
    # a Likert point), so the answers' own checks see what the client sent.
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, strict=True)


class SessionBody(_Body):
    """``POST /api/sessions``: the design by name, the participant's ID, and optionally the
    site, demographics, consent, plan row, seed and whether it is a pilot session."""

    design: str = Field(min_length=1, max_length=100)
    participant: str = Field(min_length=1, max_length=study.MAX_CODE_CHARS)
    site: str = Field("", max_length=study.MAX_SITE_CHARS)
    demographics: dict[str, int | str | None] = Field(default_factory=dict, max_length=10)
    consent: bool = False
    index: int | None = Field(None, ge=0, lt=1_000_000)
    seed: int | None = Field(None, ge=0, lt=2**63)
    pilot: bool = False


class AnswerBody(_Body):
    """``POST /api/sessions/{id}/trials/{n}``: the answers by question id, and the response
    time in ms from the trial's start to the answer (``performance.now()`` on the page)."""

    answers: dict[str, Annotated[str, Field(max_length=MAX_ANSWER_CHARS)] | int | None] = \
        Field(max_length=100)
    rt_ms: float


class StateBody(_Body):
    """``POST /api/sessions/{id}/state``."""

    state: Literal["running", "paused", "finished", "abandoned"]


class WithdrawBody(_Body):
    """``POST /api/sessions/{id}/withdraw``: the participant's ID, typed again to confirm."""

    confirm: str = Field(max_length=study.MAX_CODE_CHARS)


def load_designs(paths: list[Path]) -> dict[str, Design]:
    """The built-in designs, then the given design files, by name (a file may replace a
    built-in of the same name).

    Raises:
        RealPenError: a bad design file (one line naming the file and the field).
    """
    from realpen.study.design import builtin_designs, load_design

    designs = {name: load_design(name) for name in builtin_designs()}
    for path in paths:
        design = load_design(path)
        designs[design.name] = design
    return designs


async def _committed(future: Future):
    """A store operation's result; the store's own failures become a study error: a conflict
    for a write another server made first (a unique key), else unavailable (try again)."""
    try:
        return await asyncio.wait_for(asyncio.wrap_future(future), REQUEST_WAIT_S)
    except TimeoutError:
        # A write may still be made (the store never cancels one): asking again gives 409.
        raise study.StudyUnavailable(f"the store did not answer within {REQUEST_WAIT_S:g} s; "
                                     f"try again") from None
    except IntegrityError as error:
        raise study.StudyConflict(f"another request changed this first; ask again "
                                  f"({error_line(error)})") from None
    except STORE_ERRORS as error:
        raise study.StudyUnavailable(f"the store could not do it now ({error_line(error)}); "
                                     f"try again") from None


async def _write(state: State, operation, *args):
    """A writing operation: its reply waits for the commit."""
    return await _committed(state.store.submit(operation, *args))


async def read_store(state: State, operation, *args):
    """A reading operation: beside the writer, never behind its commits."""
    return await _committed(state.store.read(operation, *args))


@router.get("/study", response_class=HTMLResponse)
def operator_console() -> HTMLResponse:
    return static_page("study", "operator.html")


@router.get("/study/participant", response_class=HTMLResponse)
def participant_screen() -> HTMLResponse:
    return static_page("study", "participant.html")


@router.get("/api/studies")
def list_designs(state: State) -> dict:
    return {"designs": [study.design_summary(design) for design in state.designs.values()]}


@router.get("/api/studies/{name}")
def get_design(state: State, name: str) -> Response:
    design = state.designs.get(name)
    if design is None:
        raise study.StudyNotFound(f"no design '{name}' on this server")
    return Response(design.to_json(), media_type="application/json")


@router.post("/api/sessions")
async def open_session(state: State, body: SessionBody) -> JSONResponse:
    designs = state.designs
    design = designs.get(body.design)
    if design is None:
        raise study.StudyInvalid(f"design: no design '{body.design}' on this server "
                                 f"({', '.join(designs) or 'none'})")
    missing = [pen.profile_ref for pen in design.pens
               if state.catalog.get(pen.profile_ref) is None]
    if missing:
        raise study.StudyInvalid(f"design: '{design.name}' plays the pen profile "
                                 f"'{missing[0]}', which this server does not offer "
                                 f"(start the server with the folder that holds it)")
    request = study.SessionRequest(body.participant, body.site, dict(body.demographics),
                                   body.consent, body.index, body.seed, body.pilot)
    result, created = await _write(state, study.open_session, design, request,
                                   state.design_cache)
    return JSONResponse(result, status_code=201 if created else 200)


@router.get("/api/sessions")
async def sessions_list(state: State, limit: url_int(1, 1000) = 200) -> Response:
    return JSONResponse({"sessions": await read_store(state, study.list_sessions, state.design_cache,
                                                 limit)})


@router.get("/api/sessions/{session_id}")
async def session_progress(state: State, session_id: Id) -> Response:
    return JSONResponse(await read_store(state, study.progress, session_id, state.design_cache))


@router.get("/api/sessions/{session_id}/next")
async def next_trial(state: State, session_id: Id) -> Response:
    return JSONResponse(await read_store(state, study.next_trial, session_id, state.design_cache))


@router.post("/api/sessions/{session_id}/trials/{n}")
async def answer(state: State, session_id: Id, n: Id, body: AnswerBody) -> Response:
    result = await _write(state, study.answer_trial, session_id, n, dict(body.answers),
                          body.rt_ms, state.design_cache)
    return JSONResponse(result, status_code=201)


@router.post("/api/sessions/{session_id}/state")
async def session_state(state: State, session_id: Id, body: StateBody) -> Response:
    return JSONResponse(await _write(state, study.set_state, session_id, body.state,
                                     state.design_cache))


@router.post("/api/sessions/{session_id}/withdraw")
async def withdraw(state: State, session_id: Id, body: WithdrawBody) -> Response:
    return JSONResponse(await _write(state, admin.withdraw, session_id, body.confirm,
                                     state.design_cache))


@router.get("/api/sessions/{session_id}/trials/{n}/tactile.wav")
async def trial_tactile(state: State, session_id: Id, n: Id) -> Response:
    trial, design = await read_store(state, study.trial_plan, session_id, n, state.design_cache)
    profile = study.pen_profile(design, trial.pen)
    entry = state.catalog.get(profile)
    if entry is None:
        raise study.StudyNotFound(f"trial {n}: the pen profile '{profile or 'none'}' is not "
                                  f"offered by this server")
    if not trial.tactile:
        data = await run_in_threadpool(lambda: entry.tactile_wav)
    else:
        try:
            data = await run_in_threadpool(_condition_wav, entry, trial.tactile,
                                           state.trial_patterns)
        except RealPenError as error:  # the condition cannot be built from this pen's source
            raise study.StudyConflict(str(error)) from None
    return Response(data, media_type="audio/wav", headers={"Cache-Control": "no-cache"})


def _condition_wav(entry: CatalogEntry, tactile: dict, patterns: PatternCache) -> bytes:
    pattern = patterns.get(entry.profile, tactile)
    return playable_wav(pattern.samples, pattern.rate, entry.sound_rate,
                        f"{entry.profile.name} tactile pattern ({tactile})")
