"""RealPen's errors as HTTP replies: the one place where a kind of problem becomes a status.

The library raises RealPen errors (:class:`~realpen.errors.RealPenError`), which know nothing
of HTTP; a route lets them through, and the handlers that :func:`add_error_handlers` adds reply
with the status of their kind (:data:`STUDY_STATUS`; any other RealPen error is data the server
cannot use: 422) and a one-line ``detail``, with a study error's ``extra`` fields beside it
(``{"detail": …, "next": 3}``). A request FastAPI cannot validate gets 422 and its first
problem on one line (:func:`realpen.validation.validation_line`).
"""

from __future__ import annotations

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse

from realpen.errors import RealPenError
from realpen.study.sessions import (
    StudyConflict,
    StudyError,
    StudyInvalid,
    StudyNotFound,
    StudyUnavailable,
)
from realpen.validation import validation_line

__all__ = ["STUDY_STATUS", "DATA_STATUS", "http_status", "error_reply", "request_error_reply",
           "add_error_handlers"]

STUDY_STATUS: dict[type[StudyError], int] = {
    StudyNotFound: 404,
    StudyConflict: 409,
    StudyInvalid: 422,
    StudyUnavailable: 503,
}
"""The HTTP status of each kind of :class:`~realpen.study.sessions.StudyError`."""
DATA_STATUS = 422
"""The status of any other :class:`~realpen.errors.RealPenError`: data the server cannot use."""


def http_status(error: RealPenError) -> int:
    """The HTTP status that answers ``error`` (:data:`STUDY_STATUS`, else :data:`DATA_STATUS`)."""
    for kind, status in STUDY_STATUS.items():
        if isinstance(error, kind):
            return status
    return DATA_STATUS


async def error_reply(request: Request, error: RealPenError) -> JSONResponse:
    """The reply to a :class:`~realpen.errors.RealPenError` a route raised: its status, its
    one-line ``detail`` and, for a study error, its ``extra`` fields."""
    if isinstance(error, StudyError):
        body = {"detail": error.detail, **error.extra}
    else:
        body = {"detail": str(error)}
    return JSONResponse(body, status_code=http_status(error))


async def request_error_reply(request: Request, error: RequestValidationError) -> JSONResponse:
    """The reply to a request FastAPI refused: 422 and its first problem on one line
    (``body.answers.Q1: …``)."""
    return JSONResponse({"detail": validation_line(error, count_others=True,
                                                   default="invalid request")},
                        status_code=422)


def add_error_handlers(app: FastAPI) -> None:
    """Make ``app`` answer RealPen errors and invalid requests as above."""
    app.add_exception_handler(RealPenError, error_reply)
    app.add_exception_handler(RequestValidationError, request_error_reply)
