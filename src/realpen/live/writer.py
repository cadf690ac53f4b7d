"""A store's one writer thread: operations batched into transactions, readers beside it.

All writes of a store run on one thread, in batches: whatever arrived while the last batch was
being written goes into the next transaction, so many callers cost one commit, and the
server's event loop (which also drives the pen's actuator) never waits for the disk. Each
operation runs in its own SAVEPOINT (its failure rolls back that operation only) and returns a
:class:`concurrent.futures.Future` that resolves once its batch is committed (SQLite: WAL
journal, ``synchronous=FULL``; a crash of the server loses nothing committed). Reads run on a
small pool of their own threads, never behind the writer's commits.

On SQLite the writer keeps one connection and, between batches, checkpoints the journal back
into the database and truncates it (every ``checkpoint_s`` or when it passes
``wal_checkpoint_bytes``), so the journal stays small however long pages write. On PostgreSQL
each batch takes a connection from the pool; a connection lost fails the batch that was using
it, and the next batch connects again.

:class:`BatchWriter` knows nothing of strokes or studies: :class:`realpen.live.store.StrokeStore`
runs its stroke operations on one, and the study routes run :mod:`realpen.study.sessions`'
operations on the same one (through :meth:`BatchWriter.submit` and :meth:`BatchWriter.read`).
"""

from __future__ import annotations

import contextlib
import logging
import os
import queue
import sqlite3
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future, InvalidStateError, ThreadPoolExecutor

from sqlalchemy import Connection
from sqlalchemy.exc import DBAPIError, ResourceClosedError, SQLAlchemyError

from realpen.study import db as store_db
from realpen.study.db import Database, error_line

__all__ = ["BatchWriter", "Statement", "CHECKPOINT_S", "WAL_CHECKPOINT_BYTES", "MAX_BATCH",
           "READERS"]

CHECKPOINT_S = 1.0
"""SQLite: the longest time between checkpoints of the journal (s)."""
WAL_CHECKPOINT_BYTES = 8 * 1024 * 1024
"""The journal is checkpointed and truncated as soon as it passes this size (bytes)."""
MAX_BATCH = 1024  # operations per transaction: bounds how long one commit holds the writer
READERS = 2  # threads (and connections) that run read operations beside the writer
_STOP = object()
_SAVEPOINT, _ROLLBACK_TO, _RELEASE = ("SAVEPOINT writer_op", "ROLLBACK TO SAVEPOINT writer_op",
                                      "RELEASE SAVEPOINT writer_op")
log = logging.getLogger(__name__)


class Statement:
    """A Core statement compiled once for a dialect, run on the driver's own cursor by
    :meth:`BatchWriter.execute`.

    A hot path runs a few statements per operation. Through SQLAlchemy's execution layer each
    cost ~50 µs here and a ``begin_nested`` savepoint ~140 µs, where the statements themselves
    take 2–10 µs: an append of 4 samples went from ~20 µs to ~260 µs. So direct operations skip
    that layer; their SQL is still SQLAlchemy's, for either database.

    Args:
        statement: a SQLAlchemy Core statement with named bind parameters.
        dialect: the engine's dialect (``engine.dialect``).
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


def _resolve(future: Future, value=None, error: BaseException | None = None) -> None:
    """Give a future its outcome, unless its caller cancelled it or it already has one."""
    with contextlib.suppress(InvalidStateError):
        if error is None:
            future.set_result(value)
        else:
            future.set_exception(error)


class BatchWriter:
    """The writer thread (and readers) of an open store. Every method may be called from any
    thread.

    Args:
        database: the open store (:func:`realpen.study.db.open_database`); the writer does not
            close it.
        checkpoint_s: SQLite: the longest time between checkpoints of the journal (s).
        wal_checkpoint_bytes: SQLite: checkpoint as soon as the journal passes this (bytes).
        name: what messages call the store (``"stroke store"``).
        on_batch_lost: called on the writer thread when a batch is rolled back whole (what its
            operations remembered of the rows they wrote is then no longer true).

    Attributes:
        largest_wal: SQLite: the largest journal seen before a checkpoint (bytes).
    """

    def __init__(self, database: Database, checkpoint_s: float = CHECKPOINT_S,
                 wal_checkpoint_bytes: int = WAL_CHECKPOINT_BYTES, name: str = "store",
                 on_batch_lost: Callable[[], None] | None = None):
        self.database, self.name = database, name
        self._on_batch_lost = on_batch_lost
        self._checkpoint_s = checkpoint_s
        self._wal_checkpoint_bytes = wal_checkpoint_bytes
        self._busy_timeout_ms = store_db.BUSY_TIMEOUT_MS  # read now: tests shorten it
        self._dialect = database.engine.dialect
        self._dbapi = self._dialect.loaded_dbapi
        self._conn: Connection | None = None  # SQLite: the writer's one connection
        self._driver = None  # the driver's connection of the batch being written
        if database.dialect == "sqlite":
            self._conn = self._sqlite_connection()
        self.largest_wal = 0
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._closed = False
        self._close_lock = threading.Lock()
        self._writer = threading.Thread(target=self._write_loop, name="realpen-store-writer",
                                        daemon=True)
        self._writer.start()
        self._readers = ThreadPoolExecutor(READERS, thread_name_prefix="realpen-store-reader")

    @property
    def closed(self) -> bool:
        """Whether :meth:`close` was called (nothing more is taken)."""
        return self._closed

    # ---- what callers run -----------------------------------------------------------------

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
            :data:`realpen.study.db.STORE_ERRORS` error when the batch itself could not be
            written (every operation of that batch then fails, none is stored). Cancelling the
            future does not cancel the write.
        """
        return self._enqueue(operation, args, direct=False)

    def submit_direct(self, operation: Callable, *args) -> Future:
        """As :meth:`submit`, for an operation that runs its statements with :meth:`execute`
        and never nests transactions: its SAVEPOINT is the driver's own, cheaper than
        SQLAlchemy's ``begin_nested`` (~0.1 ms here)."""
        return self._enqueue(operation, args, direct=True)

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
                future.set_exception(ResourceClosedError(f"the {self.name} is closed"))
                return future
            return self._readers.submit(self._read_one, operation, args)

    def execute(self, conn: Connection, statement: Statement | str, params=None, many=False):
        """Run a :class:`Statement` (or plain SQL) of a direct operation on the driver's cursor
        of ``conn``, in its transaction; returns the cursor. The driver's errors come out as
        SQLAlchemy's, as from ``conn.execute``, and a lost connection invalidates ``conn``."""
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

    def close(self, last: tuple[Callable, tuple] | None = None) -> bool:
        """Run ``last`` (a direct operation and its arguments) after everything queued, commit,
        checkpoint, and stop (once; later calls do nothing and return False).

        Returns:
            True when this call closed the writer.
        """
        with self._close_lock:
            if self._closed:
                return False
            if last is not None:
                operation, args = last
                self._queue.put((Future(), operation, args, True))
            self._queue.put(_STOP)
            self._closed = True
        self._writer.join()
        self._readers.shutdown(wait=True)
        self.close_connection()
        return True

    def close_connection(self) -> None:
        """Close the writer's own connection (SQLite), if it has one."""
        if self._conn is not None:
            with contextlib.suppress(SQLAlchemyError):
                self._conn.close()
        self._conn = None

    # ---- the writer thread ----------------------------------------------------------------

    def _read_one(self, operation: Callable, args: tuple):
        with self.database.engine.connect() as conn:
            if self.database.dialect == "sqlite":
                conn = conn.execution_options(sqlite_begin="DEFERRED")
            with conn.begin():
                return operation(conn, *args)

    def _enqueue(self, operation: Callable, args: tuple, direct: bool) -> Future:
        future: Future = Future()
        with self._close_lock:  # nothing is queued behind the writer's stop
            if self._closed:
                future.set_exception(ResourceClosedError(f"the {self.name} is closed"))
            else:
                self._queue.put((future, operation, args, direct))
        return future

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
                if self.database.dialect == "sqlite" and (
                        stopping or time.monotonic() - last_checkpoint >= self._checkpoint_s or
                        self._wal_size() >= self._wal_checkpoint_bytes):
                    self._checkpoint()
                    last_checkpoint = time.monotonic()
            except Exception as error:  # a bug here must not stop every later write
                log.exception("%s: %s writer", self.database.display, self.name)
                for future, *_ in batch:
                    _resolve(future, error=error)

    @contextlib.contextmanager
    def _connection(self):
        """The writer's connection for one batch: SQLite keeps its one; PostgreSQL takes one
        from the pool (checked by a ping, so a connection the server dropped is replaced)."""
        if self.database.dialect == "sqlite":
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
        if self.database.dialect == "sqlite":
            return not conn.connection.driver_connection.in_transaction
        return False

    def _left_unusable(self, conn: Connection) -> bool:
        """After an operation returned: whether the transaction can no longer commit what the
        batch did (gone, or on PostgreSQL aborted by an error the operation caught and did not
        roll back; COMMIT would then silently roll everything back)."""
        if self._transaction_lost(conn):
            return True
        if self.database.dialect == "postgresql":
            from psycopg.pq import TransactionStatus

            status = conn.connection.driver_connection.info.transaction_status
            return status != TransactionStatus.INTRANS
        return False

    def _run_one(self, conn: Connection, operation: Callable, args: tuple, direct: bool):
        """One operation in its own SAVEPOINT; its error rolls back that savepoint only, unless
        the transaction itself is gone (then the error ends the batch)."""
        if not direct:
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
        self.execute(conn, _SAVEPOINT)
        try:
            value = operation(conn, *args)
        except Exception:
            if self._transaction_lost(conn):
                raise
            self.execute(conn, _ROLLBACK_TO)
            self.execute(conn, _RELEASE)
            raise
        self.execute(conn, _RELEASE)
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
                self._driver = conn.connection.driver_connection  # for execute, this batch
                for future, operation, args, direct in batch:
                    future.set_running_or_notify_cancel()
                    try:
                        outcomes.append((future, self._run_one(conn, operation, args, direct),
                                         None))
                    except Exception as error:  # this operation only; the batch goes on
                        if isinstance(error, _BatchLost) or self._transaction_lost(conn):
                            raise
                        outcomes.append((future, None, error))
        except Exception as error:  # nothing of the batch is stored
            log.error("%s: %s: %s", self.database.display, self.name, error_line(error))
            if self._on_batch_lost is not None:
                self._on_batch_lost()
            for future, *_ in batch:
                _resolve(future, error=error)
            return
        for future, value, error in outcomes:
            _resolve(future, value, error)

    def _wal_size(self) -> int:
        try:
            size = os.stat(f"{self.database.path}-wal").st_size
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
