"""The stroke store: written as strokes are drawn, one SQLite file or a PostgreSQL database.

The tables are :data:`realpen.study.tables.strokes` and :data:`~realpen.study.tables.samples`
(SQLAlchemy Core; opened and migrated by :func:`realpen.study.db.open_database`). ``strokes``:
one row per stroke — the page connection (``session``), the page that drew it (``page``: the
page's own id, the same across its reconnects), the page's stroke number, the pen (profile name
and content version), modality, ink, pointer type, the page's calibration, start and end times
(UTC, server clock), why it ended (``pen_up``, ``disconnect``, ``replaced`` by a new pen-down,
``shutdown``, or ``crash``: found open when the store was opened again after the server was
killed) and, in a study, its study session and trial. ``samples``: one row per pen sample,
numbered within its stroke (``seq``) — the fields of the one stroke-sample definition
(:class:`realpen.io.strokes.StrokeSample`, :data:`SAMPLE_FIELDS` in that order): ``t`` in s
since pen down, ``x``, ``y`` in mm, ``pressure`` 0–1, ``tilt_x``, ``tilt_y`` in degrees,
``speed`` in mm/s.

Nothing is stored twice: a stroke is known by its page and stroke number, a sample by its stroke
and number, so a page that resends what it is not sure arrived (after a reconnect) changes
nothing that is already stored.

Numbers are held to one range on both databases: a stroke or sample number, a study session or
trial is at most :data:`~realpen.io.limits.MAX_STORED_INT` (PostgreSQL's INTEGER; SQLite would
take more). The WebSocket schema refuses larger ones before they get here; the store refuses
them too (a :class:`~realpen.errors.ParameterError`, nothing written), so no caller meets a
database's own overflow error, which would read as a failure to retry.

All writes run on the store's one writer thread (:class:`realpen.live.writer.BatchWriter`), in
batches, each operation in its own SAVEPOINT; each write returns a
:class:`concurrent.futures.Future` that resolves once its batch is committed.
:meth:`StrokeStore.submit` runs any other operation that way, e.g. the study sessions' answers.

On SQLite, one server at a time may write a store (an exclusive ``flock`` on the file; a second
is refused in one line). On PostgreSQL several servers may write one database; strokes found
open there are ended as ``crash`` only by a store that is alone on it.
"""

from __future__ import annotations

import contextlib
import csv
import logging
import os
import sqlite3
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import Future
from datetime import UTC, datetime, timedelta
from pathlib import Path

from sqlalchemy import Connection, bindparam, case, func, inspect, select, text, update
from sqlalchemy.dialects import postgresql as pg_dialect
from sqlalchemy.dialects import sqlite as sqlite_dialect
from sqlalchemy.exc import DBAPIError, SQLAlchemyError

from realpen.defaults import OLD_MODALITY_NAMES
from realpen.errors import ParameterError, fail
from realpen.io.files import atomic_path
from realpen.io.limits import MAX_STORED_INT
from realpen.io.strokes import SAMPLE_FIELDS, StrokeSample
from realpen.live.writer import CHECKPOINT_S, WAL_CHECKPOINT_BYTES, BatchWriter, Statement
from realpen.study.db import STORE_ERRORS, Database, error_line, open_database, store_file
from realpen.study.tables import END_REASONS, samples, strokes
from realpen.study.tables import sessions as study_sessions

__all__ = ["StrokeStore", "StrokeRef", "export_csv", "SAMPLE_FIELDS", "STROKE_FIELDS",
           "CSV_COLUMNS", "SHUTDOWN_WAIT_S", "END_REASONS", "CLOSED_STUDY_STATES"]

SHUTDOWN_WAIT_S = 30.0  # how long a server's shutdown waits for the database to answer
# Held shared by every live store on a PostgreSQL database; a store that can take it exclusively
# is alone, so strokes left open there were left by a server that died (an arbitrary 64-bit key).
_PRESENCE_LOCK = 0x5245_414C_5045_4E02
CLOSED_STUDY_STATES = ("withdrawn", "abandoned")
"""Study-session states that take no more strokes (a finished session still takes the tail of
its last trial's stroke, which may arrive after the answer)."""

log = logging.getLogger(__name__)
# ``page`` (the page's own id, within which ``page_stroke`` counts) was ``session`` before: the
# export's one "session" is now the study export's, a participant's session of a design.
STROKE_FIELDS = ("stroke", "page", "page_stroke", "pen", "profile_version", "modality", "ink",
                 "pointer_type", "px_per_mm", "calibrated", "started_at")
"""The stroke's columns of :func:`export_csv`'s CSV, in order."""
CSV_COLUMNS = STROKE_FIELDS + ("sample",) + SAMPLE_FIELDS
"""The columns of :func:`export_csv`'s CSV: the stroke's, the sample's number, the sample."""
_SAMPLE_COLUMNS = ("stroke_id", "seq") + SAMPLE_FIELDS

# The statements of the live path (each store compiles them once for its database).
_BY_PAGE = select(strokes.c.id, strokes.c.end_reason, strokes.c.page_t0, strokes.c.pen,
                  strokes.c.modality).where(strokes.c.page == bindparam("page"),
                                            strokes.c.page_stroke == bindparam("page_stroke"))
_T0 = select(strokes.c.page_t0).where(strokes.c.id == bindparam("stroke"))
# The last number, not max + 1: PostgreSQL's INTEGER arithmetic would overflow at the last one.
_LAST_SEQ = select(func.max(samples.c.seq)).where(samples.c.stroke_id == bindparam("stroke"))
_SAMPLE_COUNT = select(strokes.c.sample_count).where(strokes.c.id == bindparam("stroke"))
_ADD_COUNT = update(strokes).where(strokes.c.id == bindparam("stroke")).values(
    sample_count=strokes.c.sample_count + bindparam("added")).returning(strokes.c.sample_count)
_INSERT_SAMPLES = {  # INSERT … ON CONFLICT DO NOTHING: a sample number already stored is kept
    "sqlite": sqlite_dialect.insert(samples).on_conflict_do_nothing(),
    "postgresql": pg_dialect.insert(samples).on_conflict_do_nothing(),
}
_COUNT = select(func.count(), func.coalesce(func.sum(strokes.c.sample_count), 0)).select_from(strokes)


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="milliseconds")


def _check_stored(name: str, value: int | None, minimum: int = 0) -> None:
    """Refuse a number the store cannot hold (None passes: no value)."""
    if value is not None and not minimum <= value <= MAX_STORED_INT:
        raise ParameterError(name, f"must be {minimum} to {MAX_STORED_INT}, got {value}")


def _check_last_sample(first: int, count: int) -> None:
    """Refuse a batch whose last sample's number the store cannot hold."""
    if count and first + count - 1 > MAX_STORED_INT:
        raise ParameterError("samples", f"the last sample would be number {first + count - 1}; "
                                        f"sample numbers go up to {MAX_STORED_INT}")


class StrokeRef(tuple):
    """A stroke found by its page and number: ``(stroke_id, end_reason, pen, modality)``."""

    __slots__ = ()

    @property
    def stroke_id(self) -> int:
        return self[0]

    @property
    def end_reason(self) -> str | None:
        return self[1]

    @property
    def pen(self) -> str:
        return self[2]

    @property
    def modality(self) -> str:
        return self[3]


class StrokeStore:
    """The store the server writes to. Every method may be called from any thread.

    Writing methods come in two forms: ``begin``/``append``/``end`` return a
    :class:`~concurrent.futures.Future` (resolved when committed; the live server awaits it),
    ``begin_stroke``/``add_samples``/``end_stroke`` wait for it.

    Args:
        target: an SQLite file or a database URL (see :func:`realpen.study.db.open_database`);
            the store is made when it does not exist.
        checkpoint_s: SQLite: the longest time between checkpoints of the journal (s).
        wal_checkpoint_bytes: SQLite: checkpoint as soon as the journal passes this (bytes).

    Attributes:
        dialect: ``"sqlite"`` or ``"postgresql"``.
        path: the SQLite file, or None for PostgreSQL.
        display: what messages call the store (a URL's password hidden).
        created: this store created its SQLite file.
        recovered: strokes found open (a server killed) and ended as ``crash``.
        writer: the store's :class:`~realpen.live.writer.BatchWriter`.
    """

    def __init__(self, target: str | os.PathLike, checkpoint_s: float = CHECKPOINT_S,
                 wal_checkpoint_bytes: int = WAL_CHECKPOINT_BYTES):
        self.database: Database = open_database(target, create=True)
        self.dialect, self.path, self.display = (self.database.dialect, self.database.path,
                                                 self.database.display)
        self.created = self.database.created
        dialect = self.database.engine.dialect
        self._sql = {name: Statement(statement, dialect) for name, statement in (
            ("by_page", _BY_PAGE), ("t0", _T0), ("last_seq", _LAST_SEQ),
            ("sample_count", _SAMPLE_COUNT), ("add_count", _ADD_COUNT),
            ("insert_samples", _INSERT_SAMPLES[self.dialect]))}
        self._t0: dict[int, float] = {}  # stroke id → page t0 (writer thread only)
        self._study_of: dict[int, int | None] = {}  # stroke id → its study session (ditto)
        # Strokes this store began and has not ended (writer thread only): on PostgreSQL other
        # servers' strokes are open too, and closing ends only these.
        self._open: set[int] = set()
        self._presence: Connection | None = None  # PostgreSQL: holds the shared presence lock
        try:
            self.recovered = self._close_crashed_strokes()
            # A batch rolled back whole: the t0 of a stroke it began is not stored.
            self.writer = BatchWriter(self.database, checkpoint_s, wal_checkpoint_bytes,
                                      name="stroke store", on_batch_lost=self._forget_strokes)
        except BaseException:
            self._release_presence()
            self.database.close()
            self.database.remove_files()
            raise

    @property
    def largest_wal(self) -> int:
        """SQLite: the largest journal seen before a checkpoint (bytes)."""
        return self.writer.largest_wal

    # ---- recovery and presence ----------------------------------------------------------

    def _release_presence(self) -> None:
        if self._presence is None:
            return
        # A pooled connection keeps its session's locks: give the presence lock back.
        with contextlib.suppress(SQLAlchemyError):
            self._presence.execute(text("SELECT pg_advisory_unlock_shared(:key)"),
                                   {"key": _PRESENCE_LOCK})
        with contextlib.suppress(SQLAlchemyError):
            self._presence.close()
        self._presence = None

    def _alone(self) -> bool:
        """Whether no other live store writes this database (PostgreSQL), and from now on hold
        the shared presence lock that tells later ones this store is here."""
        self._presence = self.database.engine.connect().execution_options(
            isolation_level="AUTOCOMMIT")
        key = {"key": _PRESENCE_LOCK}
        alone = self._presence.execute(text("SELECT pg_try_advisory_lock(:key)"), key).scalar()
        self._presence.execute(text("SELECT pg_advisory_lock_shared(:key)"), key)
        if alone:
            self._presence.execute(text("SELECT pg_advisory_unlock(:key)"), key)
        return bool(alone)

    def _close_crashed_strokes(self) -> int:
        """End strokes a killed server left open (reason ``crash``); returns how many.

        Their end time is their start plus their last sample's time: the last moment the
        stroke is known to have been drawn. On PostgreSQL only a store that is alone on the
        database does this: the open strokes of other live servers are theirs.
        """
        if self.dialect == "postgresql" and not self._alone():
            return 0
        last_t = select(func.max(samples.c.t)).where(samples.c.stroke_id == strokes.c.id)
        with self.database.engine.connect() as conn, conn.begin():
            open_strokes = conn.execute(select(
                strokes.c.id, strokes.c.started_at, last_t.scalar_subquery()).where(
                strokes.c.ended_at.is_(None))).all()
            for stroke_id, started_at, last in open_strokes:
                try:
                    ended = datetime.fromisoformat(started_at) + timedelta(seconds=last or 0.0)
                    ended_at = ended.isoformat(timespec="milliseconds")
                except (ValueError, OverflowError):
                    ended_at = started_at
                conn.execute(update(strokes).where(strokes.c.id == stroke_id).values(
                    ended_at=ended_at, end_reason="crash"))
        if open_strokes:
            log.warning("%s: %d stroke(s) left open by a server that stopped without closing "
                        "the store were ended (end_reason 'crash')", self.display,
                        len(open_strokes))
        return len(open_strokes)

    # ---- any operation, on the store's writer and readers ---------------------------------

    def submit(self, operation: Callable, *args) -> Future:
        """Run ``operation(conn, *args)`` in the writer's next transaction, in a SAVEPOINT of
        its own; the future resolves once it is committed
        (:meth:`realpen.live.writer.BatchWriter.submit`)."""
        return self.writer.submit(operation, *args)

    def read(self, operation: Callable, *args) -> Future:
        """Run ``operation(conn, *args)`` in a read transaction beside the writer
        (:meth:`realpen.live.writer.BatchWriter.read`)."""
        return self.writer.read(operation, *args)

    # ---- operations (run on the writer thread, inside a transaction) --------------------

    def _require_open_study(self, conn: Connection, study_session: int) -> None:
        """Refuse a stroke (or its samples) for a study session that is withdrawn, abandoned
        or gone: checked in the stroke's own transaction, the session row shared-locked on
        PostgreSQL, so a withdrawal on another server cannot slip between check and write."""
        row = conn.execute(select(study_sessions.c.state)
                           .where(study_sessions.c.id == study_session)
                           .with_for_update(read=True)).first()
        if row is None or row[0] in CLOSED_STUDY_STATES:
            state = "gone" if row is None else row[0]
            raise ParameterError("study_session", f"study session {study_session} is {state}: "
                                                  f"it takes no strokes")

    def _study_session_of(self, conn: Connection, stroke_id: int) -> int | None:
        if stroke_id not in self._study_of:
            found = conn.execute(select(strokes.c.study_session)
                                 .where(strokes.c.id == stroke_id)).first()
            if found is None:  # deleted with a withdrawn participant's data
                raise ParameterError("stroke", f"stroke {stroke_id} is no longer stored")
            self._study_of[stroke_id] = found[0]
        return self._study_of[stroke_id]

    def _begin(self, conn: Connection, fields: dict) -> int:
        if fields["study_session"] is not None:
            self._require_open_study(conn, fields["study_session"])
        row = self.writer.execute(conn, self._sql["by_page"], {
            "page": fields["page"], "page_stroke": fields["page_stroke"]}).fetchone()
        if row is not None:  # the page sent this pen-down before (a resend after a reconnect)
            stroke_id, reason, page_t0 = row[0], row[1], row[2]
            if reason is not None and reason != "pen_up":
                conn.execute(update(strokes).where(strokes.c.id == stroke_id).values(
                    ended_at=None, end_reason=None))
            self._t0[stroke_id] = page_t0
            self._open.add(stroke_id)
            return int(stroke_id)
        result = conn.execute(strokes.insert().values(**fields, started_at=_now()))
        stroke_id = int(result.inserted_primary_key[0])
        self._study_of[stroke_id] = fields["study_session"]
        self._t0[stroke_id] = fields["page_t0"]
        self._open.add(stroke_id)
        return stroke_id

    def _append(self, conn: Connection, stroke_id: int, rows: list[tuple],
                first: int | None) -> int:
        sql, key = self._sql, {"stroke": stroke_id}
        study_session = self._study_session_of(conn, stroke_id)
        if study_session is not None:
            self._require_open_study(conn, study_session)
        t0 = self._t0.get(stroke_id)
        if t0 is None:
            found = self.writer.execute(conn, sql["t0"], key).fetchone()
            if found is None:
                raise KeyError(f"no stroke with id {stroke_id}")
            t0 = self._t0[stroke_id] = found[0]
        if first is None:  # no numbering from the page: after the last number stored
            last = self.writer.execute(conn, sql["last_seq"], key).fetchone()[0]
            first = 0 if last is None else last + 1
            _check_last_sample(first, len(rows))
        added = 0
        if rows:
            insert = sql["insert_samples"]
            added = self.writer.execute(conn, insert, insert.bind_rows(_SAMPLE_COLUMNS, [
                (stroke_id, first + i, s[0] - t0, *s[1:]) for i, s in enumerate(rows)]),
                many=True).rowcount
        if added:
            return self.writer.execute(conn, sql["add_count"], {**key, "added": added}).fetchone()[0]
        return self.writer.execute(conn, sql["sample_count"], key).fetchone()[0]

    def _end(self, conn: Connection, stroke_id: int, reason: str) -> bool:
        # A pen-up is the stroke's true end: it replaces an end the server had to guess
        # (disconnect, crash) when the page resends it after a reconnect.
        still_open = strokes.c.ended_at.is_(None)
        if reason == "pen_up":
            still_open = still_open | (strokes.c.end_reason != "pen_up")
        result = conn.execute(update(strokes).where(strokes.c.id == stroke_id, still_open).values(
            ended_at=_now(), end_reason=reason))
        self._t0.pop(stroke_id, None)
        self._study_of.pop(stroke_id, None)
        self._open.discard(stroke_id)
        return result.rowcount > 0

    def _end_all(self, conn: Connection, reason: str) -> int:
        still_open = strokes.c.ended_at.is_(None)
        if self.dialect == "postgresql":  # only this server's: others share the database
            still_open = still_open & strokes.c.id.in_(sorted(self._open))
        result = conn.execute(update(strokes).where(still_open).values(
            ended_at=_now(), end_reason=reason))
        self._forget_strokes()
        self._open.clear()
        return result.rowcount

    def _forget_strokes(self) -> None:
        """Drop what is cached of strokes (their t0, their study session): a batch rolled back
        whole may have begun some that are not stored."""
        self._t0.clear()
        self._study_of.clear()

    def _find(self, conn: Connection, page: str, page_stroke: int) -> StrokeRef | None:
        row = self.writer.execute(conn, self._sql["by_page"],
                        {"page": page, "page_stroke": page_stroke}).fetchone()
        return None if row is None else StrokeRef((int(row[0]), row[1], row[3], row[4]))

    @staticmethod
    def _count(conn: Connection) -> tuple[int, int]:
        strokes_, samples_ = conn.execute(_COUNT).one()
        return int(strokes_), int(samples_)

    # ---- the public interface -----------------------------------------------------------

    def begin(self, *, session: str, page_stroke: int, pen: str, profile_version: str,
              modality: str, ink: str, pointer_type: str, px_per_mm: float, calibrated: bool,
              page_t0: float, page: str | None = None, study_session: int | None = None,
              trial: int | None = None) -> Future:
        """Record a pen-down (once per page and stroke number); resolves to the stroke's id.

        ``page`` is the page's own id (default: ``session``); ``page_t0`` the pen-down time in
        s on the page's clock; ``study_session`` and ``trial`` the study trial it was drawn in
        (the session's id in the store, the trial's number), if any. A pen-down the page
        already sent returns the same stroke, and reopens it if the server had ended it for
        the page (a disconnect, a crash).

        Raises:
            ParameterError: ``page_stroke`` (0 up), ``study_session`` or ``trial`` (1 up)
                above :data:`~realpen.io.limits.MAX_STORED_INT`; nothing is written.
        """
        _check_stored("page_stroke", page_stroke)
        _check_stored("study_session", study_session, 1)
        _check_stored("trial", trial, 1)
        fields = {"session": session, "page": page or session, "page_stroke": page_stroke,
                  "pen": pen, "profile_version": profile_version, "modality": modality,
                  "ink": ink, "pointer_type": pointer_type, "px_per_mm": px_per_mm,
                  "calibrated": int(calibrated), "page_t0": page_t0,
                  "study_session": study_session, "trial": trial}
        return self.writer.submit_direct(self._begin, fields)

    def append(self, stroke_id: int, samples: Sequence[StrokeSample | Sequence[float]],
               first: int | None = None) -> Future:
        """Add samples to a stroke; resolves to the stroke's sample count.

        Args:
            stroke_id: the stroke's id in the store (from :meth:`begin`).
            samples: :class:`~realpen.io.strokes.StrokeSample` rows, or tuples of their
                :data:`SAMPLE_FIELDS` (``t`` in s on the page clock, mm, mm, 0–1, degrees,
                degrees, mm/s); ``t`` is stored in s since pen down.
            first: the number of the first sample within the stroke, as the page counts
                (a sample number already stored is not stored again); None: after the last.

        Raises:
            ParameterError: a sample's number above :data:`~realpen.io.limits.MAX_STORED_INT`
                (raised here for a given ``first``; with ``first=None`` the future holds it
                when the stroke's numbers run out); nothing is written.
        """
        _check_stored("first", first)
        if first is not None:
            _check_last_sample(first, len(samples))
        rows = [sample.as_row() if isinstance(sample, StrokeSample) else tuple(sample)
                for sample in samples]
        return self.writer.submit_direct(self._append, stroke_id, rows, first)

    def end(self, stroke_id: int, reason: str = "pen_up") -> Future:
        """Record the end of a stroke (one of :data:`END_REASONS`); resolves to whether
        anything changed (an ended stroke stays ended, except that a pen-up replaces a guessed
        end)."""
        if reason not in END_REASONS:
            raise ValueError(f"reason must be one of {END_REASONS}, got {reason!r}")
        return self.writer.submit_direct(self._end, stroke_id, reason)

    def find(self, page: str, page_stroke: int) -> Future:
        """Resolves to the :class:`StrokeRef` of a page's stroke, or None."""
        return self.writer.submit_direct(self._find, page, page_stroke)

    def begin_stroke(self, **fields) -> int:
        """:meth:`begin`, waiting for the commit; returns the stroke's id."""
        return self.begin(**fields).result()

    def add_samples(self, stroke_id: int, samples: Sequence[StrokeSample | Sequence[float]],
                    first: int | None = None) -> int:
        """:meth:`append`, waiting for the commit; returns the stroke's sample count."""
        return self.append(stroke_id, samples, first).result()

    def end_stroke(self, stroke_id: int, reason: str = "pen_up") -> None:
        """:meth:`end`, waiting for the commit."""
        self.end(stroke_id, reason).result()

    def count(self, timeout: float | None = None) -> tuple[int, int]:
        """(strokes, samples) in the store (after everything submitted before).

        Raises:
            TimeoutError: no answer within ``timeout`` s (a database that stopped answering).
        """
        return self.writer.submit_direct(self._count).result(timeout)

    def close(self) -> None:
        """End strokes still open (reason ``shutdown``), commit, checkpoint, and close the
        store (once; later calls do nothing)."""
        if not self.writer.close(last=(self._end_all, ("shutdown",))):
            return
        self._release_presence()
        self.database.close()

    def discard(self) -> None:
        """Close, and remove the file if this store created it and it holds no stroke: for a
        server that fails to start, so that it leaves nothing behind (a PostgreSQL database is
        never removed)."""
        try:
            empty = not self.writer.closed and self.count(SHUTDOWN_WAIT_S) == (0, 0)
        except (*STORE_ERRORS, TimeoutError):
            empty = False  # not known to be empty: keep it
        self.close()
        if empty:
            self.database.remove_files()


def _rows(conn: Connection, stroke: int | None, include_pilot: bool = False) -> Iterable[tuple]:
    # A stroke stored before pages named themselves (a store of the first schema has no such
    # column, and is read as it is) has only its connection's id; one stored by an earlier
    # release may say "auditory-tactile": the CSV says today's name.
    named = "page" in {column["name"] for column in inspect(conn).get_columns("strokes")}
    page = func.coalesce(strokes.c.page, strokes.c.session) if named else strokes.c.session
    modality = case(OLD_MODALITY_NAMES, value=strokes.c.modality, else_=strokes.c.modality)
    query = select(strokes.c.id, page, strokes.c.page_stroke, strokes.c.pen,
                   strokes.c.profile_version, modality, strokes.c.ink,
                   strokes.c.pointer_type, strokes.c.px_per_mm, strokes.c.calibrated,
                   strokes.c.started_at, samples.c.seq,
                   *(samples.c[name] for name in SAMPLE_FIELDS)).join_from(
        strokes, samples, samples.c.stroke_id == strokes.c.id).order_by(strokes.c.id, samples.c.seq)
    if stroke is not None:
        query = query.where(strokes.c.id == stroke)
    if not include_pilot and _has_pilots(conn):
        pilots = select(study_sessions.c.id).where(study_sessions.c.pilot)
        query = query.where(strokes.c.study_session.is_(None)
                            | strokes.c.study_session.not_in(pilots))
    # In pages: a long store is never held in memory whole (a server-side cursor on PostgreSQL).
    return conn.execution_options(yield_per=4096).execute(query)


def _has_pilots(conn: Connection) -> bool:
    """Whether the store knows pilot sessions (revision 0003 on; an older one has none)."""
    inspector = inspect(conn)
    return inspector.has_table("sessions") and \
        "pilot" in {column["name"] for column in inspector.get_columns("sessions")} and \
        "study_session" in {column["name"] for column in inspector.get_columns("strokes")}


def export_csv(store: str | os.PathLike, output: str | os.PathLike,
               stroke: int | None = None, include_pilot: bool = False) -> tuple[int, int]:
    """Write one CSV row per sample (columns :data:`CSV_COLUMNS`) atomically.

    ``stroke`` is the stroke's id in the store; ``page`` the id of the page that drew it (the
    same across the page's reconnects) and ``page_stroke`` its number there; ``modality`` one
    of :data:`realpen.defaults.MODALITIES` (a stroke stored as ``auditory-tactile`` by an
    earlier release is written ``audio-tactile``). The columns ``t``, ``x``, ``y``,
    ``pressure`` (s since pen down, mm, mm, 0–1) make one stroke's rows (``stroke=ID``) a
    trajectory that ``realpen sound render`` reads.

    Args:
        store: the store: an SQLite file or a database URL.
        output: the CSV file to write.
        stroke: only this stroke (its id in the store).
        include_pilot: also the strokes of pilot study sessions (left out by default, as
            ``realpen study export`` leaves them out).

    Returns:
        (strokes, rows) written.

    Raises:
        RealPenError: no such store, not a stroke store (or a damaged one), no stroke with that
            id, or an output that cannot be written (a folder, an unwritable place, the store
            itself); nothing is written then.
    """
    output = Path(output)
    file = store_file(store)
    if file is not None and output.exists() and file.exists() and \
            output.resolve() == file.resolve():
        raise fail(output, "is the stroke store itself; give another file name for the CSV")
    database = open_database(store, create=False)
    try:
        with database.engine.connect() as conn, conn.begin():
            if stroke is not None and (not 0 <= stroke <= MAX_STORED_INT or conn.execute(
                    select(strokes.c.id).where(strokes.c.id == stroke)).first() is None):
                raise fail(database.display, f"no stroke with id {stroke}")
            written, rows = set(), 0
            with atomic_path(output) as tmp:
                with open(tmp, "w", newline="", encoding="utf-8") as handle:
                    writer = csv.writer(handle)
                    writer.writerow(CSV_COLUMNS)
                    for row in _rows(conn, stroke, include_pilot):
                        writer.writerow(row)
                        written.add(row[0])
                        rows += 1
        return len(written), rows
    except (DBAPIError, sqlite3.Error) as error:  # a damaged store: nothing is written
        raise fail(database.display, f"cannot read the stroke store ({error_line(error)})") \
            from None
    finally:
        database.close()
