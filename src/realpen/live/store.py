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

All writes run on one writer thread, in batches: whatever arrived while the last batch was
being written goes into the next transaction, so many pages cost one commit, and the server's
event loop (which also drives the pen's actuator) never waits for the disk. Each operation runs
in its own SAVEPOINT (its failure rolls back that operation only) and returns a
:class:`concurrent.futures.Future` that resolves once its batch is committed (SQLite: WAL
journal, ``synchronous=FULL``; a crash of the server loses nothing committed).
:meth:`StrokeStore.submit` runs any operation that way, e.g. the study sessions' answers.

On SQLite, one server at a time may write a store (an exclusive ``flock`` on the file; a second
is refused in one line), and between batches the writer checkpoints the journal back into the
database and truncates it (every :data:`CHECKPOINT_S` or when it passes
:data:`WAL_CHECKPOINT_BYTES`), so the journal stays small however long pages write. On
PostgreSQL several servers may write one database; a connection lost fails the batch that was
using it, and the next batch connects again.
"""

from __future__ import annotations

import contextlib
import csv
import logging
import os
import queue
import sqlite3
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import Future, InvalidStateError, ThreadPoolExecutor
from datetime import UTC, datetime, timedelta
from pathlib import Path

from sqlalchemy import Connection, bindparam, func, select, text, update
from sqlalchemy.dialects import postgresql as pg_dialect
from sqlalchemy.dialects import sqlite as sqlite_dialect
from sqlalchemy.exc import DBAPIError, ResourceClosedError, SQLAlchemyError

from realpen.errors import fail
from realpen.io.files import atomic_path
from realpen.io.strokes import SAMPLE_FIELDS, StrokeSample
from realpen.study.db import Database, open_database, store_file
from realpen.study.tables import END_REASONS, samples, strokes

__all__ = ["StrokeStore", "StrokeRef", "export_csv", "SAMPLE_FIELDS", "STROKE_FIELDS",
           "CSV_COLUMNS", "SHUTDOWN_WAIT_S", "CHECKPOINT_S", "WAL_CHECKPOINT_BYTES",
           "END_REASONS", "STORE_ERRORS", "error_line"]

CHECKPOINT_S = 1.0
WAL_CHECKPOINT_BYTES = 8 * 1024 * 1024
"""The journal is checkpointed and truncated as soon as it passes this size (bytes)."""
BUSY_TIMEOUT_MS = 5000  # how long an SQLite write waits for another process's lock
MAX_BATCH = 1024  # operations per transaction: bounds how long one commit holds the writer
SHUTDOWN_WAIT_S = 30.0  # how long a server's shutdown waits for the database to answer
READERS = 2  # threads (and connections) that run read operations beside the writer
STORE_ERRORS = (SQLAlchemyError, sqlite3.Error)
"""What a store operation's future may fail with when the database cannot do it (the driver's
errors come wrapped by SQLAlchemy; ``sqlite3.Error`` from operations that use the driver)."""
# Held shared by every live store on a PostgreSQL database; a store that can take it exclusively
# is alone, so strokes left open there were left by a server that died (an arbitrary 64-bit key).
_PRESENCE_LOCK = 0x5245_414C_5045_4E02
log = logging.getLogger(__name__)
STROKE_FIELDS = ("stroke", "session", "page_stroke", "pen", "profile_version", "modality", "ink",
                 "pointer_type", "px_per_mm", "calibrated", "started_at")
CSV_COLUMNS = STROKE_FIELDS + ("sample",) + SAMPLE_FIELDS
_STOP = object()
_SAMPLE_COLUMNS = ("stroke_id", "seq") + SAMPLE_FIELDS
_SAVEPOINT, _ROLLBACK_TO, _RELEASE = ("SAVEPOINT stroke_op", "ROLLBACK TO SAVEPOINT stroke_op",
                                      "RELEASE SAVEPOINT stroke_op")

# The statements of the live path (each store compiles them once for its database).
_BY_PAGE = select(strokes.c.id, strokes.c.end_reason, strokes.c.page_t0, strokes.c.pen,
                  strokes.c.modality).where(strokes.c.page == bindparam("page"),
                                            strokes.c.page_stroke == bindparam("page_stroke"))
_T0 = select(strokes.c.page_t0).where(strokes.c.id == bindparam("stroke"))
_NEXT_SEQ = select(func.coalesce(func.max(samples.c.seq) + 1, 0)).where(
    samples.c.stroke_id == bindparam("stroke"))
_SAMPLE_COUNT = select(strokes.c.sample_count).where(strokes.c.id == bindparam("stroke"))
_ADD_COUNT = update(strokes).where(strokes.c.id == bindparam("stroke")).values(
    sample_count=strokes.c.sample_count + bindparam("added")).returning(strokes.c.sample_count)
_INSERT_SAMPLES = {  # INSERT … ON CONFLICT DO NOTHING: a sample number already stored is kept
    "sqlite": sqlite_dialect.insert(samples).on_conflict_do_nothing(),
    "postgresql": pg_dialect.insert(samples).on_conflict_do_nothing(),
}
_COUNT = select(func.count(), func.coalesce(func.sum(strokes.c.sample_count), 0)).select_from(strokes)


class _Statement:
    """A Core statement compiled once for a dialect, run on the driver's own cursor.

    The live path runs a few statements per batch of samples. Through SQLAlchemy's execution
    layer each cost ~50 µs here and a ``begin_nested`` savepoint ~140 µs, where the statements
    themselves take 2–10 µs: an append of 4 samples went from ~20 µs to ~260 µs. So the
    writer's own statements skip that layer; their SQL is still SQLAlchemy's, from the tables
    of :mod:`realpen.study.tables`, for either database.
    """

    def __init__(self, statement, dialect):
        compiled = statement.compile(dialect=dialect)
        self.sql = compiled.string
        # Literals in the statement (``max(seq) + 1``) are bound parameters with values.
        self.defaults = {name: value for name, value in compiled.params.items()
                         if value is not None}
        self.positions = tuple(compiled.positiontup) if dialect.positional else None

    def bind(self, params: dict) -> tuple | dict:
        """The driver's parameters for ``params`` (by name)."""
        if self.defaults:
            params = {**self.defaults, **params}
        if self.positions is None:
            return params
        return tuple(params[name] for name in self.positions)

    def bind_rows(self, names: tuple[str, ...], rows: list[tuple]) -> list:
        """The driver's parameters for an executemany of ``rows`` (values in ``names`` order)."""
        if self.positions == names and not self.defaults:
            return rows
        return [self.bind(dict(zip(names, row))) for row in rows]


class _BatchLost(SQLAlchemyError):
    """The batch's transaction cannot be committed: every operation of it fails."""


def error_line(error: BaseException) -> str:
    """A store error in one line: the driver's message (SQLAlchemy's wrapper adds the SQL, its
    parameters and a link on further lines)."""
    return " ".join(str(getattr(error, "orig", None) or error).split())


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="milliseconds")


def _resolve(future: Future, value=None, error: BaseException | None = None) -> None:
    """Give a future its outcome, unless its caller cancelled it or it already has one."""
    with contextlib.suppress(InvalidStateError):
        if error is None:
            future.set_result(value)
        else:
            future.set_exception(error)


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
        largest_wal: SQLite: the largest journal seen before a checkpoint (bytes).
    """

    def __init__(self, target: str | os.PathLike, checkpoint_s: float = CHECKPOINT_S,
                 wal_checkpoint_bytes: int = WAL_CHECKPOINT_BYTES):
        self.database: Database = open_database(target, create=True)
        self.dialect, self.path, self.display = (self.database.dialect, self.database.path,
                                                 self.database.display)
        self.created = self.database.created
        self._checkpoint_s = checkpoint_s
        self._wal_checkpoint_bytes = wal_checkpoint_bytes
        self._busy_timeout_ms = BUSY_TIMEOUT_MS  # read now: tests shorten it
        self._dialect = self.database.engine.dialect
        self._dbapi = self._dialect.loaded_dbapi
        self._sql = {name: _Statement(statement, self._dialect) for name, statement in (
            ("by_page", _BY_PAGE), ("t0", _T0), ("next_seq", _NEXT_SEQ),
            ("sample_count", _SAMPLE_COUNT), ("add_count", _ADD_COUNT),
            ("insert_samples", _INSERT_SAMPLES[self.dialect]))}
        self._conn: Connection | None = None  # SQLite: the writer's one connection
        self._driver = None  # the driver's connection of the batch being written
        self._presence: Connection | None = None  # PostgreSQL: holds the shared presence lock
        try:
            self.recovered = self._close_crashed_strokes()
            if self.dialect == "sqlite":
                self._conn = self._sqlite_connection()
        except BaseException:
            self._close_connections()
            self.database.close()
            self.database.remove_files()
            raise
        self.largest_wal = 0
        self._t0: dict[int, float] = {}  # stroke id → page t0 (writer thread only)
        # Strokes this store began and has not ended (writer thread only): on PostgreSQL other
        # servers' strokes are open too, and closing ends only these.
        self._open: set[int] = set()
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._closed = False
        self._close_lock = threading.Lock()
        self._writer = threading.Thread(target=self._write_loop, name="realpen-store-writer",
                                        daemon=True)
        self._writer.start()
        self._readers = ThreadPoolExecutor(READERS, thread_name_prefix="realpen-store-reader")

    # ---- connections and recovery -------------------------------------------------------

    def _sqlite_connection(self) -> Connection:
        """The writer's connection: checkpoints are the writer's own (not SQLite's automatic
        ones, which would run inside a commit the page is waiting for)."""
        conn = self.database.engine.connect()
        dbapi = conn.connection.driver_connection
        for pragma in ("wal_autocheckpoint=0",
                       f"journal_size_limit={self._wal_checkpoint_bytes}",
                       f"busy_timeout={self._busy_timeout_ms}"):
            dbapi.execute(f"PRAGMA {pragma}")
        return conn

    def _close_connections(self) -> None:
        if self._presence is not None:
            # A pooled connection keeps its session's locks: give the presence lock back.
            with contextlib.suppress(SQLAlchemyError):
                self._presence.execute(text("SELECT pg_advisory_unlock_shared(:key)"),
                                       {"key": _PRESENCE_LOCK})
        for conn in (self._conn, self._presence):
            if conn is not None:
                with contextlib.suppress(SQLAlchemyError):
                    conn.close()
        self._conn = self._presence = None

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

    # ---- the writer thread --------------------------------------------------------------

    def submit(self, operation: Callable, *args) -> Future:
        """Run ``operation(conn, *args)`` on the writer thread, in the next batch's transaction.

        ``conn`` is a SQLAlchemy :class:`~sqlalchemy.Connection` inside that transaction; the
        operation runs in its own SAVEPOINT (``conn.begin_nested()``), so its error rolls back
        its own writes only (a unique key refused, a serialization failure) and the rest of the
        batch commits. It should return plain values (rows fetched, not a result to iterate
        later).

        Returns:
            A future that resolves with the operation's return value once the batch is
            committed (durable: on disk, or in PostgreSQL), or with its exception; with a
            :data:`STORE_ERRORS` error when the batch itself could not be written (every
            operation of that batch then fails, none is stored). Cancelling the future does not
            cancel the write.
        """
        return self._enqueue(operation, args, own=False)

    def read(self, operation: Callable, *args) -> Future:
        """Run ``operation(conn, *args)`` in a read transaction of its own, on a reader
        thread: reads never wait behind the writer's commits (SQLite's WAL and PostgreSQL let
        readers and the writer run at once).

        The operation sees every write whose future had resolved before this call (committed);
        it must not write. Returns a future of its return value or its exception.
        """
        future: Future = Future()
        with self._close_lock:
            if self._closed:
                future.set_exception(ResourceClosedError("the stroke store is closed"))
                return future
            return self._readers.submit(self._read_one, operation, args)

    def _read_one(self, operation: Callable, args: tuple):
        with self.database.engine.connect() as conn:
            if self.dialect == "sqlite":
                conn = conn.execution_options(sqlite_begin="DEFERRED")
            with conn.begin():
                return operation(conn, *args)

    def _enqueue(self, operation: Callable, args: tuple, own: bool) -> Future:
        """Queue ``operation`` for the writer. ``own``: one of this store's operations, which
        run their statements with :meth:`_run` and never nest transactions; their SAVEPOINT is
        the driver's own, cheaper than SQLAlchemy's ``begin_nested`` (~0.1 ms here)."""
        future: Future = Future()
        with self._close_lock:  # nothing is queued behind the writer's stop
            if self._closed:
                future.set_exception(ResourceClosedError("the stroke store is closed"))
            else:
                self._queue.put((future, operation, args, own))
        return future

    def _write_loop(self) -> None:
        last_checkpoint, stopping = time.monotonic(), False
        while not stopping:
            batch = []
            item = self._queue.get()
            while True:
                if item is _STOP:
                    stopping = True
                    break
                batch.append(item)
                if len(batch) >= MAX_BATCH:
                    break
                try:
                    item = self._queue.get_nowait()
                except queue.Empty:
                    break
            try:
                if batch:
                    self._write_batch(batch)
                if self.dialect == "sqlite" and (
                        stopping or time.monotonic() - last_checkpoint >= self._checkpoint_s or
                        self._wal_size() >= self._wal_checkpoint_bytes):
                    self._checkpoint()
                    last_checkpoint = time.monotonic()
            except Exception as error:  # a bug here must not stop every later write
                log.exception("%s: stroke store writer", self.display)
                for future, *_ in batch:
                    _resolve(future, error=error)

    @contextlib.contextmanager
    def _connection(self):
        """The writer's connection for one batch: SQLite keeps its one; PostgreSQL takes one
        from the pool (checked by a ping, so a connection the server dropped is replaced)."""
        if self.dialect == "sqlite":
            if self._conn is None or self._conn.closed or self._conn.invalidated:
                self._conn = self._sqlite_connection()
            yield self._conn
        else:
            with self.database.engine.connect() as conn:
                yield conn

    def _transaction_lost(self, conn: Connection) -> bool:
        """Whether the database ended the whole transaction (SQLite does on a full disk or an
        I/O error; a lost connection) so that no savepoint can be rolled back to."""
        if conn.invalidated:
            return True
        if self.dialect == "sqlite":
            return not conn.connection.driver_connection.in_transaction
        return False

    def _left_unusable(self, conn: Connection) -> bool:
        """After an operation returned: whether the transaction can no longer commit what the
        batch did (gone, or on PostgreSQL aborted by an error the operation caught and did not
        roll back; COMMIT would then silently roll everything back)."""
        if self._transaction_lost(conn):
            return True
        if self.dialect == "postgresql":
            from psycopg.pq import TransactionStatus

            status = conn.connection.driver_connection.info.transaction_status
            return status != TransactionStatus.INTRANS
        return False

    def _run_one(self, conn: Connection, operation: Callable, args: tuple, own: bool):
        """One operation in its own SAVEPOINT; its error rolls back that savepoint only, unless
        the transaction itself is gone (then the error ends the batch)."""
        if not own:
            savepoint = conn.begin_nested()
            try:
                value = operation(conn, *args)
            except Exception:
                if self._transaction_lost(conn):
                    raise
                savepoint.rollback()
                raise
            if self._left_unusable(conn):  # an error swallowed inside the operation
                raise _BatchLost("an operation left the transaction aborted; nothing of the "
                                 "batch was stored")
            savepoint.commit()
            return value
        self._run(conn, _SAVEPOINT)
        try:
            value = operation(conn, *args)
        except Exception:
            if self._transaction_lost(conn):
                raise
            self._run(conn, _ROLLBACK_TO)
            self._run(conn, _RELEASE)
            raise
        self._run(conn, _RELEASE)
        return value

    def _write_batch(self, batch: list) -> None:
        """Run a batch's operations in one transaction; resolve every future, whatever fails.

        An operation's own error rolls back that operation only. An error of the transaction
        itself (BEGIN cannot get the lock, the disk is full at COMMIT, the connection is lost)
        rolls back all, and every operation of the batch gets it. A caller that stopped waiting
        (a cancelled future) does not cancel its write: a pen-up queued by a closing connection
        is still recorded.
        """
        outcomes = []
        try:
            with self._connection() as conn, conn.begin():
                self._driver = conn.connection.driver_connection  # for _run, this batch
                for future, operation, args, own in batch:
                    future.set_running_or_notify_cancel()
                    try:
                        outcomes.append((future, self._run_one(conn, operation, args, own), None))
                    except Exception as error:  # this operation only; the batch goes on
                        if isinstance(error, _BatchLost) or self._transaction_lost(conn):
                            raise
                        outcomes.append((future, None, error))
        except Exception as error:  # nothing of the batch is stored
            log.error("%s: stroke store: %s", self.display, error_line(error))
            self._t0.clear()
            for future, *_ in batch:
                _resolve(future, error=error)
            return
        for future, value, error in outcomes:
            _resolve(future, value, error)

    def _run(self, conn: Connection, statement: _Statement | str, params=None, many=False):
        """Run one of the store's own statements on the driver's cursor of ``conn`` (in its
        transaction); returns the cursor. The driver's errors come out as SQLAlchemy's, as
        from ``conn.execute``, and a lost connection invalidates ``conn``."""
        dbapi_connection = self._driver
        cursor = dbapi_connection.cursor()
        sql = statement if isinstance(statement, str) else statement.sql
        try:
            if many:
                cursor.executemany(sql, params)
            elif params is None:
                cursor.execute(sql)
            else:
                cursor.execute(sql, statement.bind(params))
        except self._dbapi.Error as error:
            lost = self._dialect.is_disconnect(error, dbapi_connection, cursor)
            if lost:
                conn.invalidate(error)
            raise DBAPIError.instance(sql, params, error, self._dbapi.Error,
                                      connection_invalidated=lost, dialect=self._dialect,
                                      ismulti=many) from None
        return cursor

    def _wal_size(self) -> int:
        try:
            size = os.stat(f"{self.path}-wal").st_size
        except OSError:
            return 0
        self.largest_wal = max(self.largest_wal, size)
        return size

    def _checkpoint(self) -> None:
        """Copy the journal into the database and truncate it (the writer is idle here).

        Readers (an export, a database browser) are never waited for: with one open the
        journal cannot be reset, so the copy is done as far as it can go (PASSIVE) and the
        truncation is tried again next time; meanwhile the writes go on.
        """
        self._wal_size()
        try:
            with self._connection() as conn:
                # The driver's own connection: outside any transaction SQLAlchemy would begin.
                db = conn.connection.driver_connection
                try:
                    db.execute("PRAGMA busy_timeout=0")
                    busy = db.execute("PRAGMA wal_checkpoint(TRUNCATE)").fetchone()[0]
                    if busy:
                        db.execute("PRAGMA wal_checkpoint(PASSIVE)")
                finally:
                    db.execute(f"PRAGMA busy_timeout={self._busy_timeout_ms}")
        except (sqlite3.Error, SQLAlchemyError) as error:
            log.debug("checkpoint: %s", error)

    # ---- operations (run on the writer thread, inside a transaction) --------------------

    def _begin(self, conn: Connection, fields: dict) -> int:
        row = self._run(conn, self._sql["by_page"], {
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
        self._t0[stroke_id] = fields["page_t0"]
        self._open.add(stroke_id)
        return stroke_id

    def _append(self, conn: Connection, stroke_id: int, rows: list[tuple],
                first: int | None) -> int:
        sql, key = self._sql, {"stroke": stroke_id}
        t0 = self._t0.get(stroke_id)
        if t0 is None:
            found = self._run(conn, sql["t0"], key).fetchone()
            if found is None:
                raise KeyError(f"no stroke with id {stroke_id}")
            t0 = self._t0[stroke_id] = found[0]
        if first is None:  # no numbering from the page: after the last number stored
            first = self._run(conn, sql["next_seq"], key).fetchone()[0]
        added = 0
        if rows:
            insert = sql["insert_samples"]
            added = self._run(conn, insert, insert.bind_rows(_SAMPLE_COLUMNS, [
                (stroke_id, first + i, s[0] - t0, *s[1:]) for i, s in enumerate(rows)]),
                many=True).rowcount
        if added:
            return self._run(conn, sql["add_count"], {**key, "added": added}).fetchone()[0]
        return self._run(conn, sql["sample_count"], key).fetchone()[0]

    def _end(self, conn: Connection, stroke_id: int, reason: str) -> bool:
        # A pen-up is the stroke's true end: it replaces an end the server had to guess
        # (disconnect, crash) when the page resends it after a reconnect.
        still_open = strokes.c.ended_at.is_(None)
        if reason == "pen_up":
            still_open = still_open | (strokes.c.end_reason != "pen_up")
        result = conn.execute(update(strokes).where(strokes.c.id == stroke_id, still_open).values(
            ended_at=_now(), end_reason=reason))
        self._t0.pop(stroke_id, None)
        self._open.discard(stroke_id)
        return result.rowcount > 0

    def _end_all(self, conn: Connection, reason: str) -> int:
        still_open = strokes.c.ended_at.is_(None)
        if self.dialect == "postgresql":  # only this server's: others share the database
            still_open = still_open & strokes.c.id.in_(sorted(self._open))
        result = conn.execute(update(strokes).where(still_open).values(
            ended_at=_now(), end_reason=reason))
        self._t0.clear()
        self._open.clear()
        return result.rowcount

    def _find(self, conn: Connection, page: str, page_stroke: int) -> StrokeRef | None:
        row = self._run(conn, self._sql["by_page"],
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
        """
        fields = {"session": session, "page": page or session, "page_stroke": page_stroke,
                  "pen": pen, "profile_version": profile_version, "modality": modality,
                  "ink": ink, "pointer_type": pointer_type, "px_per_mm": px_per_mm,
                  "calibrated": int(calibrated), "page_t0": page_t0,
                  "study_session": study_session, "trial": trial}
        return self._enqueue(self._begin, (fields,), own=True)

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
        """
        rows = [sample.as_row() if isinstance(sample, StrokeSample) else tuple(sample)
                for sample in samples]
        return self._enqueue(self._append, (stroke_id, rows, first), own=True)

    def end(self, stroke_id: int, reason: str = "pen_up") -> Future:
        """Record the end of a stroke (one of :data:`END_REASONS`); resolves to whether
        anything changed (an ended stroke stays ended, except that a pen-up replaces a guessed
        end)."""
        if reason not in END_REASONS:
            raise ValueError(f"reason must be one of {END_REASONS}, got {reason!r}")
        return self._enqueue(self._end, (stroke_id, reason), own=True)

    def find(self, page: str, page_stroke: int) -> Future:
        """Resolves to the :class:`StrokeRef` of a page's stroke, or None."""
        return self._enqueue(self._find, (page, page_stroke), own=True)

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
        return self._enqueue(self._count, (), own=True).result(timeout)

    def close(self) -> None:
        """End strokes still open (reason ``shutdown``), commit, checkpoint, and close the
        store (once; later calls do nothing)."""
        with self._close_lock:
            if self._closed:
                return
            self._queue.put((Future(), self._end_all, ("shutdown",), True))
            self._queue.put(_STOP)
            self._closed = True
        self._writer.join()
        self._readers.shutdown(wait=True)
        self._close_connections()
        self.database.close()

    def discard(self) -> None:
        """Close, and remove the file if this store created it and it holds no stroke: for a
        server that fails to start, so that it leaves nothing behind (a PostgreSQL database is
        never removed)."""
        try:
            empty = not self._closed and self.count(SHUTDOWN_WAIT_S) == (0, 0)
        except (*STORE_ERRORS, TimeoutError):
            empty = False  # not known to be empty: keep it
        self.close()
        if empty:
            self.database.remove_files()


def _rows(conn: Connection, stroke: int | None) -> Iterable[tuple]:
    query = select(strokes.c.id, strokes.c.session, strokes.c.page_stroke, strokes.c.pen,
                   strokes.c.profile_version, strokes.c.modality, strokes.c.ink,
                   strokes.c.pointer_type, strokes.c.px_per_mm, strokes.c.calibrated,
                   strokes.c.started_at, samples.c.seq,
                   *(samples.c[name] for name in SAMPLE_FIELDS)).join_from(
        strokes, samples, samples.c.stroke_id == strokes.c.id).order_by(strokes.c.id, samples.c.seq)
    if stroke is not None:
        query = query.where(strokes.c.id == stroke)
    # In pages: a long store is never held in memory whole (a server-side cursor on PostgreSQL).
    return conn.execution_options(yield_per=4096).execute(query)


def export_csv(store: str | os.PathLike, output: str | os.PathLike,
               stroke: int | None = None) -> tuple[int, int]:
    """Write one CSV row per sample (columns :data:`CSV_COLUMNS`) atomically.

    The columns ``t``, ``x``, ``y``, ``pressure`` (s since pen down, mm, mm, 0–1) make one
    stroke's rows (``stroke=ID``) a trajectory that ``realpen sound render`` reads.

    Args:
        store: the store: an SQLite file or a database URL.
        output: the CSV file to write.
        stroke: only this stroke (its id in the store).

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
            if stroke is not None and (not 0 <= stroke < 2**31 or conn.execute(
                    select(strokes.c.id).where(strokes.c.id == stroke)).first() is None):
                raise fail(database.display, f"no stroke with id {stroke}")
            written, rows = set(), 0
            with atomic_path(output) as tmp:
                with open(tmp, "w", newline="", encoding="utf-8") as handle:
                    writer = csv.writer(handle)
                    writer.writerow(CSV_COLUMNS)
                    for row in _rows(conn, stroke):
                        writer.writerow(row)
                        written.add(row[0])
                        rows += 1
        return len(written), rows
    except (DBAPIError, sqlite3.Error) as error:  # a damaged store: nothing is written
        raise fail(database.display, f"cannot read the stroke store ({error_line(error)})") \
            from None
    finally:
        database.close()
