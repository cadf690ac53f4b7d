"""The study routes: the operator console, the participant screen and the study HTTP API.

Thin: each route validates its request, runs one operation of :mod:`realpen.study.sessions` on
the store's writer (so its reply is sent only after the commit) and turns a
:class:`~realpen.study.sessions.StudyError` into its status and a one-line ``detail``.
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
``POST /api/sessions/{id}/state``                pause, resume or finish
``GET  /api/sessions/{id}/trials/{n}/tactile.wav``  the trial's tactile pattern
"""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Annotated, Any, Literal

from fastapi import FastAPI, Query
from fastapi.exceptions import RequestValidationError
from fastapi.responses import HTMLResponse, JSONResponse, Response
from pydantic import BaseModel, ConfigDict, Field
from starlette.concurrency import run_in_threadpool

from realpen.errors import RealPenError
from realpen.study import sessions as study
from realpen.study.design import Design
from realpen.study.patterns import PatternCache
from realpen.study.tables import MAX_ID

__all__ = ["add_study_routes", "load_designs", "validation_line", "SessionBody", "AnswerBody",
           "StateBody", "MAX_ANSWER_CHARS"]

MAX_ANSWER_CHARS = 2000
REQUEST_WAIT_S = 30.0  # a request waits at most this long for the store, then gets 503
Id = Annotated[int, Field(ge=1, le=MAX_ID)]


class _Body(BaseModel):
    # strict: JSON types are taken as they are (true is not 1, "7" is not a number, 4.0 is not
    # a Likert point), so the answers' own checks see what the client sent.
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, strict=True)


class SessionBody(_Body):
    """``POST /api/sessions``: the design by name, the participant's ID, and optionally the
    site, demographics, consent, plan row and seed."""

    design: str = Field(min_length=1, max_length=100)
    participant: str = Field(min_length=1, max_length=study.MAX_CODE_CHARS)
    site: str = Field("", max_length=study.MAX_SITE_CHARS)
    demographics: dict[str, int | str | None] = Field(default_factory=dict, max_length=10)
    consent: bool = False
    index: int | None = Field(None, ge=0, lt=1_000_000)
    seed: int | None = Field(None, ge=0, lt=2**63)


class AnswerBody(_Body):
    """``POST /api/sessions/{id}/trials/{n}``: the answers by question id, and the response
    time in ms from the trial's start to the answer (``performance.now()`` on the page)."""

    answers: dict[str, Annotated[str, Field(max_length=MAX_ANSWER_CHARS)] | int | None] = \
        Field(max_length=100)
    rt_ms: float


class StateBody(_Body):
    """``POST /api/sessions/{id}/state``."""

    state: Literal["running", "paused", "finished"]


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


def validation_line(error: RequestValidationError) -> str:
    """A request's first validation problem as one line: ``body.answers.Q1: …``."""
    problems = error.errors()
    if not problems:
        return "invalid request"
    first = problems[0]
    where = ".".join(str(part) for part in first.get("loc", ()) if part != "__root__")
    more = f" (and {len(problems) - 1} more)" if len(problems) > 1 else ""
    return f"{where}: {first.get('msg', 'invalid')}{more}"


async def _outcome(future):
    """A store operation's result; the store's own failures become a :class:`StudyError`:
    409 for a write another server made first (a unique key), else 503 (try again)."""
    from sqlalchemy.exc import IntegrityError

    from realpen.live.store import STORE_ERRORS, error_line

    try:
        return await asyncio.wait_for(asyncio.wrap_future(future), REQUEST_WAIT_S)
    except TimeoutError:
        # A write may still be made (the store never cancels one): asking again gives 409.
        raise study.StudyError(503, f"the store did not answer within {REQUEST_WAIT_S:g} s; "
                                    f"try again") from None
    except IntegrityError as error:
        raise study.StudyError(409, f"another request changed this first; ask again "
                                    f"({error_line(error)})") from None
    except STORE_ERRORS as error:
        raise study.StudyError(503, f"the store could not do it now ({error_line(error)}); "
                                    f"try again") from None


def _reply(error: study.StudyError) -> JSONResponse:
    return JSONResponse({"detail": error.detail, **error.extra}, status_code=error.status)


def add_study_routes(app: FastAPI, state: Any, designs: dict[str, Design], static_dir) -> None:
    """Add the study pages and API to the live app.

    Args:
        app: the live app.
        state: its :class:`~realpen.live.app.LiveState` (the store and the catalog).
        designs: the designs offered, by name (built-in and given to ``serve --design``).
        static_dir: the live app's static folder (the pages are in ``study/``).
    """
    cache, patterns = study.DesignCache(), PatternCache()

    async def run(operation, *args):
        """A writing operation: its reply waits for the commit."""
        return await _outcome(state.store.submit(operation, *args))

    async def read(operation, *args):
        """A reading operation: beside the writer, never behind its commits."""
        return await _outcome(state.store.read(operation, *args))

    def page(name: str) -> HTMLResponse:
        return HTMLResponse((static_dir / "study" / name).read_text(encoding="utf-8"),
                            headers={"Cache-Control": "no-cache"})

    @app.get("/study", response_class=HTMLResponse)
    def operator_console() -> HTMLResponse:
        return page("operator.html")

    @app.get("/study/participant", response_class=HTMLResponse)
    def participant_screen() -> HTMLResponse:
        return page("participant.html")

    @app.get("/api/studies")
    def list_designs() -> dict:
        return {"designs": [study.design_summary(design) for design in designs.values()]}

    @app.get("/api/studies/{name}")
    def get_design(name: str) -> Response:
        design = designs.get(name)
        if design is None:
            return JSONResponse({"detail": f"no design '{name}' on this server"}, 404)
        return Response(design.to_json(), media_type="application/json")

    @app.post("/api/sessions")
    async def open_session(body: SessionBody) -> JSONResponse:
        design = designs.get(body.design)
        if design is None:
            return JSONResponse({"detail": f"design: no design '{body.design}' on this server "
                                           f"({', '.join(designs) or 'none'})"}, 422)
        missing = [pen.profile_ref for pen in design.pens
                   if state.catalog.get(pen.profile_ref) is None]
        if missing:
            return JSONResponse({"detail": f"design: '{design.name}' plays the pen profile "
                                           f"'{missing[0]}', which this server does not offer "
                                           f"(start the server with the folder that holds it)"}, 422)
        try:
            request = study.SessionRequest(body.participant, body.site, dict(body.demographics),
                                           body.consent, body.index, body.seed)
            result, created = await run(study.open_session, design, request, cache)
        except study.StudyError as error:
            return _reply(error)
        return JSONResponse(result, status_code=201 if created else 200)

    @app.get("/api/sessions")
    async def sessions_list(limit: int = Query(200, ge=1, le=1000)) -> Response:
        try:
            return JSONResponse({"sessions": await read(study.list_sessions, cache, limit)})
        except study.StudyError as error:
            return _reply(error)

    @app.get("/api/sessions/{session_id}")
    async def session_progress(session_id: Id) -> Response:
        try:
            return JSONResponse(await read(study.progress, session_id, cache))
        except study.StudyError as error:
            return _reply(error)

    @app.get("/api/sessions/{session_id}/next")
    async def next_trial(session_id: Id) -> Response:
        try:
            return JSONResponse(await read(study.next_trial, session_id, cache))
        except study.StudyError as error:
            return _reply(error)

    @app.post("/api/sessions/{session_id}/trials/{n}")
    async def answer(session_id: Id, n: Id, body: AnswerBody) -> Response:
        try:
            result = await run(study.answer_trial, session_id, n, dict(body.answers), body.rt_ms,
                               cache)
        except study.StudyError as error:
            return _reply(error)
        return JSONResponse(result, status_code=201)

    @app.post("/api/sessions/{session_id}/state")
    async def session_state(session_id: Id, body: StateBody) -> Response:
        try:
            return JSONResponse(await run(study.set_state, session_id, body.state, cache))
        except study.StudyError as error:
            return _reply(error)

    @app.get("/api/sessions/{session_id}/trials/{n}/tactile.wav")
    async def trial_tactile(session_id: Id, n: Id) -> Response:
        try:
            trial, design = await read(study.trial_plan, session_id, n, cache)
        except study.StudyError as error:
            return _reply(error)
        profile = study.pen_profile(design, trial.pen)
        entry = state.catalog.get(profile)
        if entry is None:
            return JSONResponse({"detail": f"trial {n}: the pen profile '{profile or 'none'}' "
                                           f"is not offered by this server"}, 404)
        if not trial.tactile:
            data = await run_in_threadpool(lambda: entry.tactile_wav)
        else:
            try:
                data = await run_in_threadpool(_condition_wav, entry, trial.tactile, patterns)
            except RealPenError as error:
                return JSONResponse({"detail": str(error)}, 409)
        return Response(data, media_type="audio/wav", headers={"Cache-Control": "no-cache"})


def _condition_wav(entry, tactile: dict, patterns: PatternCache) -> bytes:
    from realpen.live.catalog import playable_wav

    pattern = patterns.get(entry.profile, tactile)
    return playable_wav(pattern.samples, pattern.rate, entry.sound_rate,
                        f"{entry.profile.name} tactile pattern ({tactile})")
