"""Administering a study: withdraw a participant, abandon sessions, find a session by its
participant, and run such an operation on a store from the command line.

A participant who withdraws consent leaves a record and no data: :func:`withdraw` deletes, in
the caller's one transaction, the session's answers, its planned trials (their answer times
and response times), the strokes drawn in it with their samples, and the participant's
demographics; the participant's ID is replaced by ``withdrawn-<session>``, consent is cleared,
and the session row stays with state ``withdrawn`` and the time of the withdrawal. Its plan
row is freed (:data:`realpen.study.tables.HOLDS_PLAN_ROW`), so that the next participant takes
it and the counterbalancing stays complete.

An abandoned session (state ``abandoned``, :func:`realpen.study.sessions.set_state`) keeps its
answers: it is a participant who did not finish, and the export says so. :func:`abandon_stale`
ends every session still running or paused that has had no answer for a while.

Each function that takes ``conn`` is a store operation, like those of
:mod:`realpen.study.sessions`: run it in one transaction (the live app's writer, or
:func:`on_store` from the command line).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from datetime import UTC, datetime, timedelta
from typing import Any, TypeVar

from sqlalchemy import Connection, delete, func, select, update

from realpen.study.sessions import (
    DesignCache,
    StudyConflict,
    StudyInvalid,
    StudyNotFound,
    now,
    progress,
    set_state,
)
from realpen.study.tables import (
    answers,
    participants,
    samples,
    sessions,
    strokes,
    studies,
    trials,
)

__all__ = ["withdraw", "withdrawn_code", "abandon_stale", "find_session", "on_store"]

T = TypeVar("T")


def withdrawn_code(session_id: int) -> str:
    """What a withdrawn participant's ID becomes: ``withdrawn-<session>`` (their own ID is
    deleted with their data)."""
    return f"withdrawn-{session_id}"


def withdraw(conn: Connection, session_id: int, confirm: str, cache: DesignCache) -> dict:
    """Withdraw the participant of a session: delete their data, keep a record.

    Deleted: the session's answers and planned trials, the strokes drawn in it (and their
    samples), the participant's demographics and ID (replaced by :func:`withdrawn_code`);
    consent is cleared. Kept: the session row, with state ``withdrawn``, ``withdrawn_at`` (now),
    its site, start, plan row and seed; the row is free for a new participant.

    Args:
        session_id: the session.
        confirm: the participant's ID, typed again: a withdrawal cannot be undone.
        cache: the store's designs (for the reply).

    Returns:
        The session's :func:`~realpen.study.sessions.progress` after the withdrawal (no trials).

    Raises:
        StudyNotFound: no such session.
        StudyInvalid: ``confirm`` is not the session's participant ID.
        StudyConflict: the session is withdrawn already.
    """
    # The session row locked first (PostgreSQL; SQLite has one writer): a stroke that another
    # server is storing for it either commits before this or sees the session withdrawn.
    if conn.execute(select(sessions.c.id).where(sessions.c.id == session_id)
                    .with_for_update()).first() is None:
        raise StudyNotFound(f"no session {session_id}")
    row = conn.execute(
        select(sessions.c.state, sessions.c.participant_id, participants.c.code)
        .join(participants, sessions.c.participant_id == participants.c.id)
        .where(sessions.c.id == session_id)).first()
    if row is None:
        raise StudyNotFound(f"no session {session_id}")
    if row.state == "withdrawn":
        raise StudyConflict(f"session {session_id} is withdrawn already")
    if not isinstance(confirm, str) or confirm.strip() != row.code:
        raise StudyInvalid(f"confirm: type the participant's ID of session {session_id} exactly "
                           f"to withdraw them (their data is deleted; this cannot be undone)")
    drawn = select(strokes.c.id).where(strokes.c.study_session == session_id)
    # Samples first: a store upgraded from the first stroke store has no cascade from strokes.
    conn.execute(delete(samples).where(samples.c.stroke_id.in_(drawn)))
    conn.execute(delete(strokes).where(strokes.c.study_session == session_id))
    conn.execute(delete(answers).where(answers.c.session_id == session_id))
    conn.execute(delete(trials).where(trials.c.session_id == session_id))
    conn.execute(update(participants).where(participants.c.id == row.participant_id).values(
        code=withdrawn_code(session_id), age=None, gender=None, handedness=None, consent=False))
    conn.execute(update(sessions).where(sessions.c.id == session_id).values(
        state="withdrawn", withdrawn_at=now()))
    return progress(conn, session_id, cache)


def abandon_stale(conn: Connection, hours: float, cache: DesignCache,
                  design: str | None = None, at: datetime | None = None) -> list[dict]:
    """End as abandoned every session still running or paused whose last answer (or start,
    when it has none) is more than ``hours`` old.

    Args:
        hours: how long without an answer, in hours (> 0).
        design: only this design's sessions (its name); None: every design.
        at: the time to measure from (default: now, UTC).

    Returns:
        The :func:`~realpen.study.sessions.progress` of each session ended, oldest id first.

    Raises:
        StudyInvalid: ``hours`` is not a positive number.
    """
    if isinstance(hours, bool) or not isinstance(hours, int | float) or not 0 < hours < 1e6:
        raise StudyInvalid("hours: must be a positive number of hours")
    cutoff = (at or datetime.now(UTC)) - timedelta(hours=hours)
    last = (select(trials.c.session_id, func.max(trials.c.answered_at).label("last"))
            .group_by(trials.c.session_id).subquery())
    query = (select(sessions.c.id, sessions.c.started_at, last.c.last)
             .join(studies, sessions.c.study_id == studies.c.id)
             .outerjoin(last, last.c.session_id == sessions.c.id)
             .where(sessions.c.state.in_(("running", "paused"))).order_by(sessions.c.id))
    if design is not None:
        query = query.where(studies.c.name == design)
    stale = [row.id for row in conn.execute(query) if _time(row.last or row.started_at) < cutoff]
    ended = []
    for session_id in stale:
        # Looked at again under the session's lock: another server may have answered or ended
        # it since, and such a session is skipped, not abandoned (nor a reason to stop).
        again = conn.execute(query.where(sessions.c.id == session_id).with_for_update(
            of=sessions)).first()
        if again is not None and _time(again.last or again.started_at) < cutoff:
            ended.append(set_state(conn, session_id, "abandoned", cache))
    return ended


def _time(text: str) -> datetime:
    """A stored time (ISO 8601, UTC) as an aware datetime."""
    moment = datetime.fromisoformat(text)
    return moment if moment.tzinfo else moment.replace(tzinfo=UTC)


def find_session(conn: Connection, session: str, design: str | None = None) -> int:
    """The session an operator names: a participant's ID within ``design``, or a session id.

    Args:
        session: a participant's ID (e.g. ``P07``; needs ``design``) or a session's id (digits).
            A participant ID made of digits wins over a session id.
        design: the design's name (e.g. ``study1``).

    Raises:
        StudyNotFound: neither names a session (of ``design``, when given).
    """
    text = session.strip()
    if design is not None:
        found = conn.execute(
            select(sessions.c.id).join(participants, sessions.c.participant_id == participants.c.id)
            .join(studies, sessions.c.study_id == studies.c.id)
            .where(studies.c.name == design, participants.c.code == text)).scalar()
        if found is not None:
            return found
    if text.isdecimal() and text.isascii() and len(text) <= 10:
        query = select(sessions.c.id).where(sessions.c.id == int(text))
        if design is not None:
            query = query.join(studies, sessions.c.study_id == studies.c.id) \
                .where(studies.c.name == design)
        found = conn.execute(query).scalar()
        if found is not None:
            return found
    where = f" of the design '{design}'" if design is not None else \
        " (a participant's ID names a session only with its design)"
    raise StudyNotFound(f"no session '{text}'{where}")


def on_store(target: str | os.PathLike, operation: Callable[..., T], *args: Any,
             create: bool = False) -> T:
    """Run one store operation on a store, in one transaction, as its writer (the command
    line's way; a running server does the same through its writer).

    The store must exist (``create``: it is made when missing, as ``realpen serve`` makes it);
    one of an older schema is brought to the newest first. An SQLite
    store that a server has open is refused in one line (stop the server, or use its console or
    API); a PostgreSQL store may be shared with running servers.

    Raises:
        RealPenError: the store cannot be opened or written (one line naming it).
        StudyError: what the operation raises (nothing is changed then).
    """
    from realpen.study.db import STORE_ERRORS, head_revision, open_database, store_error

    database = open_database(target, create=create)
    if database.revision != head_revision():
        database.close()
        database = open_database(target, create=True)
    try:
        with database.engine.begin() as conn:
            return operation(conn, *args)
    except STORE_ERRORS as error:
        raise store_error(target, error) from None
    finally:
        database.close()
