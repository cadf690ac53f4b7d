"""The stroke store: one SQLite file (stdlib ``sqlite3``), written as strokes are drawn.

Two tables. ``strokes``: one row per stroke — the page connection (``session``), the page that
drew it (``page``: the page's own id, the same across its reconnects), the page's stroke number,
the pen (profile name and content version), modality, ink, pointer type, the page's calibration,
start and end times (UTC, server clock) and why it ended (``pen_up``, ``disconnect``,
``replaced`` by a new pen-down, ``shutdown``, or ``crash``: found open when the store was opened
again after the server was killed). ``samples``: one row per pen sample, numbered within its
stroke (``seq``) — the fields of the one stroke-sample definition
(:class:`realpen.io.strokes.StrokeSample`, :data:`SAMPLE_FIELDS` in that order): ``t`` in s
since pen down, ``x``, ``y`` in mm, ``pressure`` 0–1, ``tilt_x``, ``tilt_y`` in degrees,
``speed`` in mm/s.

Nothing is stored twice: a stroke is known by its page and stroke number, a sample by its stroke
and number, so a page that resends what it is not sure arrived (after a reconnect) changes
nothing that is already stored.

All writes run on one writer thread, in batches: whatever arrived while the last batch was
being written goes into the next transaction, so many pages cost one commit, and the server's
event loop (which also drives the pen's actuator) never waits for the disk. Each operation
returns a :class:`concurrent.futures.Future` that resolves once its batch is committed (WAL
journal, ``synchronous=NORMAL``: a crash of the server loses nothing committed). Between
batches the writer checkpoints the journal back into the database and truncates it (every
:data:`CHECKPOINT_S` or when it passes :data:`WAL_CHECKPOINT_BYTES`), so the journal stays small
however long pages write. One server at a time may write a store (an exclusive ``flock`` on the
file): a second is refused in one line. The SQL is plain so that a SQLAlchemy URL for
PostgreSQL can stand in for the file when a lab outgrows one machine (a later issue).
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
from concurrent.futures import Future, InvalidStateError
from datetime import UTC, datetime, timedelta
from pathlib import Path

from realpen.errors import fail
from realpen.io.files import atomic_path
from realpen.io.strokes import SAMPLE_FIELDS, StrokeSample

try:  # advisory locks: POSIX only; elsewhere two servers on one store are not prevented
    import fcntl
except ImportError:  # pragma: no cover
    fcntl = None

__all__ = ["StrokeStore", "StrokeRef", "export_csv", "SAMPLE_FIELDS", "STROKE_FIELDS",
           "CSV_COLUMNS", "SCHEMA", "SCHEMA_VERSION", "CHECKPOINT_S", "WAL_CHECKPOINT_BYTES",
           "END_REASONS"]

SCHEMA_VERSION = 2
CHECKPOINT_S = 1.0
WAL_CHECKPOINT_BYTES = 8 * 1024 * 1024
"""The journal is checkpointed and truncated as soon as it passes this size (bytes)."""
BUSY_TIMEOUT_MS = 5000  # how long a write waits for another process's lock
MAX_BATCH = 1024  # operations per transaction: bounds how long one commit holds the writer
END_REASONS = ("pen_up", "disconnect", "replaced", "shutdown", "crash")
log = logging.getLogger(__name__)
STROKE_FIELDS = ("stroke", "session", "page_stroke", "pen", "profile_version", "modality", "ink",
                 "pointer_type", "px_per_mm", "calibrated", "started_at")
CSV_COLUMNS = STROKE_FIELDS + ("sample",) + SAMPLE_FIELDS

SCHEMA = """
CREATE TABLE IF NOT EXISTS strokes (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    session TEXT NOT NULL,
    page_stroke INTEGER NOT NULL,
    pen TEXT NOT NULL,
    profile_version TEXT NOT NULL,
    modality TEXT NOT NULL,
    ink TEXT NOT NULL,
    pointer_type TEXT NOT NULL,
    px_per_mm REAL NOT NULL,
    calibrated INTEGER NOT NULL,
    page_t0 REAL NOT NULL,
    started_at TEXT NOT NULL,
    ended_at TEXT,
    end_reason TEXT,
    sample_count INTEGER NOT NULL DEFAULT 0,
    page TEXT
);
CREATE TABLE IF NOT EXISTS samples (
    stroke_id INTEGER NOT NULL REFERENCES strokes(id) ON DELETE CASCADE,
    seq INTEGER NOT NULL,
""" + "".join(f"    {name} REAL NOT NULL,\n" for name in SAMPLE_FIELDS) + """\
    PRIMARY KEY (stroke_id, seq)
) WITHOUT ROWID;
CREATE UNIQUE INDEX IF NOT EXISTS strokes_by_page ON strokes (page, page_stroke);
"""
# Version 1 had no page column: each connection was its own page. It took a stroke number twice
# on one connection; such a later stroke keeps its own page id, so none is merged.
_UPGRADE_FROM_1 = """
ALTER TABLE strokes ADD COLUMN page TEXT;
UPDATE strokes SET page = session;
UPDATE strokes SET page = session || '#' || id
    WHERE id NOT IN (SELECT MIN(id) FROM strokes GROUP BY session, page_stroke);
CREATE UNIQUE INDEX IF NOT EXISTS strokes_by_page ON strokes (page, page_stroke);
"""
_INSERT_SAMPLE = (f"INSERT OR IGNORE INTO samples (stroke_id, seq, {', '.join(SAMPLE_FIELDS)}) "
                  f"VALUES ({', '.join('?' * (len(SAMPLE_FIELDS) + 2))})")
_STOP = object()


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="milliseconds")


def _check_place(path: Path, create: bool) -> None:
    """Refuse a store path that is missing (unless ``create``), a folder, or under a file."""
    if not create and not path.exists():
        raise fail(path, "no such stroke store")
    if path.is_dir():
        raise fail(path, "is a folder, not a stroke store file")
    existing = next((parent for parent in path.parents if parent.exists()), None)
    if existing is not None and not existing.is_dir():
        raise fail(path, f"{existing} is a file, not a folder")


def _connect(path: Path, create: bool) -> sqlite3.Connection:
    """Open (or create) a store, check that it is one, and bring its schema up to date.

    Raises:
        RealPenError: one line naming ``path``: no such store, a folder, a place where no file
            can be made or opened, a file that is not a RealPen stroke store, or a damaged one.
    """
    _check_place(path, create)
    try:
        if create:
            path.parent.mkdir(parents=True, exist_ok=True)
        connection = sqlite3.connect(path, check_same_thread=False,
                                     timeout=BUSY_TIMEOUT_MS / 1000, isolation_level=None)
    except (OSError, sqlite3.Error) as error:
        raise fail(path, f"cannot open or create the stroke store here "
                         f"({getattr(error, 'strerror', None) or error})") from None
    try:
        version = connection.execute("PRAGMA user_version").fetchone()[0]
        if version > SCHEMA_VERSION:
            raise fail(path, f"stroke store version {version} is newer than this RealPen "
                             f"reads ({SCHEMA_VERSION})")
        if version == 0 and not create:
            raise fail(path, "not a RealPen stroke store (empty or another SQLite file)")
        connection.execute("PRAGMA journal_mode=WAL")
        # FULL: a commit is on disk before the page hears its ack (batching keeps the cost of
        # the fsync to one per batch, ~0.4 ms here).
        connection.execute("PRAGMA synchronous=FULL")
        connection.execute("PRAGMA foreign_keys=ON")
        if version > 0:
            problem = connection.execute("PRAGMA quick_check(1)").fetchone()[0]
            if problem != "ok":
                problem = " ".join(problem.replace("*** in database main ***", "").split())
                raise fail(path, f"the stroke store is damaged ({problem}); keep a copy and "
                                 f"start with a new store")
        if version == 0:
            tables = {row[0] for row in connection.execute(
                "SELECT name FROM sqlite_master WHERE type='table'")}
            if tables - {"strokes", "samples", "sqlite_sequence"}:
                raise fail(path, "an SQLite file that is not a RealPen stroke store")
        if version < SCHEMA_VERSION and create:
            connection.execute("BEGIN IMMEDIATE")
            for statement in (SCHEMA if version == 0 else _UPGRADE_FROM_1).split(";"):
                if statement.strip():
                    connection.execute(statement)
            connection.execute(f"PRAGMA user_version={SCHEMA_VERSION}")
            connection.execute("COMMIT")
    except sqlite3.OperationalError as error:  # unreadable, read-only, locked, out of space
        connection.close()
        raise fail(path, f"cannot use the stroke store ({error})") from None
    except sqlite3.DatabaseError as error:  # e.g. "file is not a database", a damaged page
        connection.close()
        raise fail(path, f"not a RealPen stroke store, or a damaged one ({error})") from None
    except BaseException:
        connection.close()
        raise
    return connection


def _resolve(future: Future, value=None, error: BaseException | None = None) -> None:
    """Give a future its outcome, unless its caller cancelled it or it already has one."""
    with contextlib.suppress(InvalidStateError):
        if error is None:
            future.set_result(value)
        else:
            future.set_exception(error)


def _lock(path: Path) -> tuple[int | None, bool]:
    """Open (creating it if need be) and lock the store file for this process.

    Returns:
        (the locked descriptor, or None where there are no advisory locks; whether this call
        created the file).

    Raises:
        RealPenError: the file cannot be opened for writing, or another server holds it.
    """
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        try:
            fd, created = os.open(path, os.O_RDWR | os.O_CREAT | os.O_EXCL, 0o666), True
        except FileExistsError:
            fd, created = os.open(path, os.O_RDWR), False
    except OSError as error:
        raise fail(path, f"cannot open or create the stroke store here "
                         f"({error.strerror or error})") from None
    if fcntl is None:
        os.close(fd)
        return None, created
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        os.close(fd)
        raise fail(path, "is in use by another RealPen server; stop it or use another store "
                         "file") from None
    return fd, created


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
    """

    def __init__(self, path: str | os.PathLike, checkpoint_s: float = CHECKPOINT_S,
                 wal_checkpoint_bytes: int = WAL_CHECKPOINT_BYTES):
        self.path = Path(path)
        _check_place(self.path, create=True)
        # The lock comes first: files are only ever removed (a failed start) by their owner,
        # and ``created`` is decided by O_EXCL, not by a check another process could race.
        self._lock_fd, self.created = _lock(self.path)
        self._db = None
        try:
            self._db = _connect(self.path, create=True)
            self.recovered = self._close_crashed_strokes()
            self._db.execute("PRAGMA wal_autocheckpoint=0")
            self._db.execute(f"PRAGMA journal_size_limit={wal_checkpoint_bytes}")
        except BaseException:
            if self._db is not None:
                self._db.close()
            if self.created:
                _remove_store_files(self.path)
            self._release_lock()
            raise
        self._checkpoint_s = checkpoint_s
        self._wal_checkpoint_bytes = wal_checkpoint_bytes
        self.largest_wal = 0  # bytes: the largest journal seen before a checkpoint
        self._t0: dict[int, float] = {}  # stroke id → page t0 (writer thread only)
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._closed = False
        self._close_lock = threading.Lock()
        self._writer = threading.Thread(target=self._write_loop, name="realpen-store-writer",
                                        daemon=True)
        self._writer.start()

    # ---- ownership and recovery ---------------------------------------------------------

    def _release_lock(self) -> None:
        if self._lock_fd is not None:
            os.close(self._lock_fd)  # closing the descriptor releases the flock
            self._lock_fd = None

    def _close_crashed_strokes(self) -> int:
        """End strokes a killed server left open (reason ``crash``); returns how many.

        Their end time is their start plus their last sample's time: the last moment the
        stroke is known to have been drawn.
        """
        open_strokes = self._db.execute(
            "SELECT s.id, s.started_at, (SELECT MAX(t) FROM samples WHERE stroke_id = s.id) "
            "FROM strokes s WHERE s.ended_at IS NULL").fetchall()
        if not open_strokes:
            return 0
        self._db.execute("BEGIN IMMEDIATE")
        for stroke_id, started_at, last_t in open_strokes:
            try:
                ended = datetime.fromisoformat(started_at) + timedelta(seconds=last_t or 0.0)
                ended_at = ended.isoformat(timespec="milliseconds")
            except (ValueError, OverflowError):
                ended_at = started_at
            self._db.execute("UPDATE strokes SET ended_at=?, end_reason='crash' WHERE id=?",
                             (ended_at, stroke_id))
        self._db.execute("COMMIT")
        log.warning("%s: %d stroke(s) left open by a server that stopped without closing the "
                    "store were ended (end_reason 'crash')", self.path, len(open_strokes))
        return len(open_strokes)

    # ---- the writer thread --------------------------------------------------------------

    def _submit(self, operation: Callable, *args) -> Future:
        future: Future = Future()
        with self._close_lock:  # nothing is queued behind the writer's stop
            if self._closed:
                future.set_exception(sqlite3.ProgrammingError("the stroke store is closed"))
            else:
                self._queue.put((future, operation, args))
        return future

    def _write_loop(self) -> None:
        db, last_checkpoint, stopping = self._db, time.monotonic(), False
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
                    self._write_batch(db, batch)
                if stopping or time.monotonic() - last_checkpoint >= self._checkpoint_s or \
                        self._wal_size() >= self._wal_checkpoint_bytes:
                    self._checkpoint(db)
                    last_checkpoint = time.monotonic()
            except Exception as error:  # a bug here must not stop every later write
                log.exception("%s: stroke store writer", self.path)
                for future, _, _ in batch:
                    _resolve(future, error=error)

    def _write_batch(self, db: sqlite3.Connection, batch: list) -> None:
        """Run a batch's operations in one transaction; resolve every future, whatever fails.

        An operation's own error rolls back that operation only. An error of the transaction
        itself (BEGIN cannot get the lock, the disk is full at COMMIT) rolls back all, and every
        operation of the batch gets it. A caller that stopped waiting (a cancelled future) does
        not cancel its write: a pen-up queued by a closing connection is still recorded.
        """
        outcomes = []
        try:
            db.execute("BEGIN IMMEDIATE")
            for future, operation, args in batch:
                future.set_running_or_notify_cancel()
                db.execute("SAVEPOINT operation")
                try:
                    outcomes.append((future, operation(db, *args), None))
                except Exception as error:  # this operation only; the batch goes on
                    if not db.in_transaction:  # SQLite aborted the whole transaction
                        raise
                    db.execute("ROLLBACK TO operation")
                    outcomes.append((future, None, error))
                db.execute("RELEASE operation")
            db.execute("COMMIT")
        except Exception as error:  # nothing of the batch is stored
            log.error("%s: stroke store: %s", self.path, error)
            if db.in_transaction:
                with contextlib.suppress(sqlite3.Error):
                    db.execute("ROLLBACK")
            self._t0.clear()
            for future, _, _ in batch:
                _resolve(future, error=error)
            return
        for future, value, error in outcomes:
            _resolve(future, value, error)

    def _wal_size(self) -> int:
        try:
            size = os.stat(f"{self.path}-wal").st_size
        except OSError:
            return 0
        self.largest_wal = max(self.largest_wal, size)
        return size

    def _checkpoint(self, db: sqlite3.Connection) -> None:
        """Copy the journal into the database and truncate it (the writer is idle here).

        Readers (an export, a database browser) are never waited for: with one open the
        journal cannot be reset, so the copy is done as far as it can go (PASSIVE) and the
        truncation is tried again next time; meanwhile the writes go on.
        """
        self._wal_size()
        try:
            db.execute("PRAGMA busy_timeout=0")
            busy = db.execute("PRAGMA wal_checkpoint(TRUNCATE)").fetchone()[0]
            if busy:
                db.execute("PRAGMA wal_checkpoint(PASSIVE)")
        except sqlite3.Error as error:
            log.debug("checkpoint: %s", error)
        finally:
            with contextlib.suppress(sqlite3.Error):
                db.execute(f"PRAGMA busy_timeout={BUSY_TIMEOUT_MS}")

    # ---- operations (run on the writer thread, inside a transaction) --------------------

    def _begin(self, db, fields: dict) -> int:
        row = db.execute("SELECT id, end_reason, page_t0 FROM strokes WHERE page=? AND "
                         "page_stroke=?", (fields["page"], fields["page_stroke"])).fetchone()
        if row is not None:  # the page sent this pen-down before (a resend after a reconnect)
            stroke_id, reason, page_t0 = row
            if reason is not None and reason != "pen_up":
                db.execute("UPDATE strokes SET ended_at=NULL, end_reason=NULL WHERE id=?",
                           (stroke_id,))
            self._t0[stroke_id] = page_t0
            return int(stroke_id)
        names = list(fields) + ["started_at"]
        cursor = db.execute(
            f"INSERT INTO strokes ({', '.join(names)}) VALUES ({', '.join('?' * len(names))})",
            (*fields.values(), _now()))
        stroke_id = int(cursor.lastrowid)
        self._t0[stroke_id] = fields["page_t0"]
        return stroke_id

    def _append(self, db, stroke_id: int, rows: list[tuple], first: int | None) -> int:
        t0 = self._t0.get(stroke_id)
        if t0 is None:
            found = db.execute("SELECT page_t0 FROM strokes WHERE id=?", (stroke_id,)).fetchone()
            if found is None:
                raise KeyError(f"no stroke with id {stroke_id}")
            t0 = self._t0[stroke_id] = found[0]
        if first is None:  # no numbering from the page: after the last number stored
            first = db.execute("SELECT COALESCE(MAX(seq) + 1, 0) FROM samples WHERE stroke_id=?",
                               (stroke_id,)).fetchone()[0]
        cursor = db.executemany(_INSERT_SAMPLE, [(stroke_id, first + i, s[0] - t0, *s[1:])
                                                 for i, s in enumerate(rows)])
        if cursor.rowcount:
            db.execute("UPDATE strokes SET sample_count = sample_count + ? WHERE id=?",
                       (cursor.rowcount, stroke_id))
        return db.execute("SELECT sample_count FROM strokes WHERE id=?",
                          (stroke_id,)).fetchone()[0]

    def _end(self, db, stroke_id: int, reason: str) -> bool:
        # A pen-up is the stroke's true end: it replaces an end the server had to guess
        # (disconnect, crash) when the page resends it after a reconnect.
        condition = "(ended_at IS NULL OR end_reason != 'pen_up')" if reason == "pen_up" \
            else "ended_at IS NULL"
        cursor = db.execute(f"UPDATE strokes SET ended_at=?, end_reason=? WHERE id=? AND "
                            f"{condition}", (_now(), reason, stroke_id))
        self._t0.pop(stroke_id, None)
        return cursor.rowcount > 0

    def _end_all(self, db, reason: str) -> int:
        cursor = db.execute("UPDATE strokes SET ended_at=?, end_reason=? WHERE ended_at IS NULL",
                            (_now(), reason))
        self._t0.clear()
        return cursor.rowcount

    @staticmethod
    def _find(db, page: str, page_stroke: int) -> StrokeRef | None:
        row = db.execute("SELECT id, end_reason, pen, modality FROM strokes WHERE page=? AND "
                         "page_stroke=?", (page, page_stroke)).fetchone()
        return None if row is None else StrokeRef((int(row[0]), *row[1:]))

    @staticmethod
    def _count(db) -> tuple[int, int]:
        strokes, samples = db.execute(
            "SELECT COUNT(*), COALESCE(SUM(sample_count), 0) FROM strokes").fetchone()
        return int(strokes), int(samples)

    # ---- the public interface -----------------------------------------------------------

    def begin(self, *, session: str, page_stroke: int, pen: str, profile_version: str,
              modality: str, ink: str, pointer_type: str, px_per_mm: float, calibrated: bool,
              page_t0: float, page: str | None = None) -> Future:
        """Record a pen-down (once per page and stroke number); resolves to the stroke's id.

        ``page`` is the page's own id (default: ``session``); ``page_t0`` the pen-down time in
        s on the page's clock. A pen-down the page already sent returns the same stroke, and
        reopens it if the server had ended it for the page (a disconnect, a crash).
        """
        fields = {"session": session, "page": page or session, "page_stroke": page_stroke,
                  "pen": pen, "profile_version": profile_version, "modality": modality,
                  "ink": ink, "pointer_type": pointer_type, "px_per_mm": px_per_mm,
                  "calibrated": int(calibrated), "page_t0": page_t0}
        return self._submit(self._begin, fields)

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
        return self._submit(self._append, stroke_id, rows, first)

    def end(self, stroke_id: int, reason: str = "pen_up") -> Future:
        """Record the end of a stroke (one of :data:`END_REASONS`); resolves to whether
        anything changed (an ended stroke stays ended, except that a pen-up replaces a guessed
        end)."""
        if reason not in END_REASONS:
            raise ValueError(f"reason must be one of {END_REASONS}, got {reason!r}")
        return self._submit(self._end, stroke_id, reason)

    def find(self, page: str, page_stroke: int) -> Future:
        """Resolves to the :class:`StrokeRef` of a page's stroke, or None."""
        return self._submit(self._find, page, page_stroke)

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

    def count(self) -> tuple[int, int]:
        """(strokes, samples) in the store (after everything submitted before)."""
        return self._submit(self._count).result()

    def close(self) -> None:
        """End strokes still open (reason ``shutdown``), commit, checkpoint, and close the file
        (once; later calls do nothing)."""
        with self._close_lock:
            if self._closed:
                return
            self._queue.put((Future(), self._end_all, ("shutdown",)))
            self._queue.put(_STOP)
            self._closed = True
        self._writer.join()
        self._db.close()
        self._release_lock()

    def discard(self) -> None:
        """Close, and remove the file if this store created it and it holds no stroke: for a
        server that fails to start, so that it leaves nothing behind."""
        empty = not self._closed and self.count() == (0, 0)
        self.close()
        if self.created and empty:
            _remove_store_files(self.path)


def _remove_store_files(path: Path) -> None:
    """Remove a store file and its journal files (``-wal``, ``-shm``, ``-journal``)."""
    for suffix in ("", "-wal", "-shm", "-journal"):
        with contextlib.suppress(OSError):
            Path(f"{path}{suffix}").unlink()


def _rows(connection: sqlite3.Connection, stroke: int | None) -> Iterable[tuple]:
    where, args = ("WHERE s.id = ?", (stroke,)) if stroke is not None else ("", ())
    return connection.execute(
        "SELECT s.id, s.session, s.page_stroke, s.pen, s.profile_version, s.modality, s.ink, "
        "s.pointer_type, s.px_per_mm, s.calibrated, s.started_at, p.seq, "
        f"{', '.join(f'p.{name}' for name in SAMPLE_FIELDS)} FROM strokes s JOIN samples p "
        f"ON p.stroke_id = s.id {where} ORDER BY s.id, p.seq", args)


def export_csv(store: str | os.PathLike, output: str | os.PathLike,
               stroke: int | None = None) -> tuple[int, int]:
    """Write one CSV row per sample (columns :data:`CSV_COLUMNS`) atomically.

    The columns ``t``, ``x``, ``y``, ``pressure`` (s since pen down, mm, mm, 0–1) make one
    stroke's rows (``stroke=ID``) a trajectory that ``realpen sound render`` reads.

    Returns:
        (strokes, rows) written.

    Raises:
        RealPenError: no such store, not a stroke store (or a damaged one), no stroke with that
            id, or an output that cannot be written (a folder, an unwritable place, the store
            itself); nothing is written then.
    """
    store, output = Path(store), Path(output)
    connection = _connect(store, create=False)
    try:
        if output.exists() and output.resolve() == store.resolve():
            raise fail(output, "is the stroke store itself; give another file name for the CSV")
        if stroke is not None and (not 0 <= stroke < 2**63 or connection.execute(
                "SELECT 1 FROM strokes WHERE id = ?", (stroke,)).fetchone() is None):
            raise fail(store, f"no stroke with id {stroke}")
        strokes, rows = set(), 0
        with atomic_path(output) as tmp:
            with open(tmp, "w", newline="", encoding="utf-8") as handle:
                writer = csv.writer(handle)
                writer.writerow(CSV_COLUMNS)
                for row in _rows(connection, stroke):
                    writer.writerow(row)
                    strokes.add(row[0])
                    rows += 1
        return len(strokes), rows
    except sqlite3.DatabaseError as error:  # a damaged store: nothing is written
        raise fail(store, f"cannot read the stroke store ({error})") from None
    finally:
        connection.close()
