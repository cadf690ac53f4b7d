"""The stroke store: one SQLite file (stdlib ``sqlite3``), written as strokes are drawn.

Two tables. ``strokes``: one row per stroke — the page connection (``session``), the page's
stroke number, the pen (profile name and content version), modality, ink, pointer type, the
page's calibration, start and end times (UTC, server clock) and why it ended (``pen_up``,
``disconnect``, ``replaced`` by a new pen-down, or ``shutdown``). ``samples``: one row per
pen sample — the fields of the one stroke-sample definition
(:class:`realpen.io.strokes.StrokeSample`, :data:`SAMPLE_FIELDS` in that order): ``t`` in s
since pen down, ``x``, ``y`` in mm, ``pressure`` 0–1, ``tilt_x``, ``tilt_y`` in degrees,
``speed`` in mm/s.

Every pen-down, sample batch and pen-up is committed when it arrives (WAL journal,
``synchronous=NORMAL``: a crash of the server loses nothing committed; closing checkpoints the
journal back into the one file). A commit only appends to the journal; the checkpoints that
copy it into the database, and fsync, run on a background thread every second, so the server's
event loop (which also drives the pen's actuator) never waits for the disk. The SQL is plain so
that a SQLAlchemy URL for PostgreSQL can stand in for the file when a lab outgrows one machine
(a later issue).
"""

from __future__ import annotations

import contextlib
import csv
import logging
import os
import sqlite3
import threading
from collections.abc import Iterable, Sequence
from datetime import UTC, datetime
from pathlib import Path

from realpen.errors import fail
from realpen.io.files import atomic_path
from realpen.io.strokes import SAMPLE_FIELDS, StrokeSample

__all__ = ["StrokeStore", "export_csv", "SAMPLE_FIELDS", "STROKE_FIELDS", "CSV_COLUMNS",
           "SCHEMA", "SCHEMA_VERSION", "CHECKPOINT_S"]

SCHEMA_VERSION = 1
CHECKPOINT_S = 1.0
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
    sample_count INTEGER NOT NULL DEFAULT 0
);
CREATE TABLE IF NOT EXISTS samples (
    stroke_id INTEGER NOT NULL REFERENCES strokes(id) ON DELETE CASCADE,
    seq INTEGER NOT NULL,
""" + "".join(f"    {name} REAL NOT NULL,\n" for name in SAMPLE_FIELDS) + """\
    PRIMARY KEY (stroke_id, seq)
) WITHOUT ROWID;
"""
_INSERT_SAMPLE = (f"INSERT INTO samples (stroke_id, seq, {', '.join(SAMPLE_FIELDS)}) "
                  f"VALUES ({', '.join('?' * (len(SAMPLE_FIELDS) + 2))})")


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="milliseconds")


def _connect(path: Path, create: bool) -> sqlite3.Connection:
    """Open (or create) a store and check that it is one.

    Raises:
        RealPenError: one line naming ``path``: no such store, a folder, a place where no file
            can be made or opened, or a file that is not a RealPen stroke store.
    """
    if not create and not path.exists():
        raise fail(path, "no such stroke store")
    if path.is_dir():
        raise fail(path, "is a folder, not a stroke store file")
    existing = next((parent for parent in path.parents if parent.exists()), None)
    if existing is not None and not existing.is_dir():
        raise fail(path, f"{existing} is a file, not a folder")
    try:
        if create:
            path.parent.mkdir(parents=True, exist_ok=True)
        connection = sqlite3.connect(path, check_same_thread=False, timeout=5.0)
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
        connection.execute("PRAGMA synchronous=NORMAL")
        connection.execute("PRAGMA foreign_keys=ON")
        if version == 0:
            tables = {row[0] for row in connection.execute(
                "SELECT name FROM sqlite_master WHERE type='table'")}
            if tables - {"strokes", "samples", "sqlite_sequence"}:
                raise fail(path, "an SQLite file that is not a RealPen stroke store")
            connection.executescript(SCHEMA)
            connection.execute(f"PRAGMA user_version={SCHEMA_VERSION}")
            connection.commit()
    except sqlite3.OperationalError as error:  # unreadable, read-only, locked, out of space
        connection.close()
        raise fail(path, f"cannot use the stroke store ({error})") from None
    except sqlite3.DatabaseError as error:  # e.g. "file is not a database"
        connection.close()
        raise fail(path, f"not a RealPen stroke store ({error})") from None
    except BaseException:
        connection.close()
        raise
    return connection


class StrokeStore:
    """The store the server writes to. Safe to share between threads (one lock)."""

    def __init__(self, path: str | os.PathLike, checkpoint_s: float = CHECKPOINT_S):
        self.path = Path(path)
        self.created = not self.path.exists()  # this store made the file (see discard)
        try:
            self._db = _connect(self.path, create=True)
        except BaseException:
            if self.created:
                _remove_store_files(self.path)
            raise
        self._db.execute("PRAGMA wal_autocheckpoint=0")
        self._lock = threading.Lock()
        self._open: dict[int, tuple[float, int]] = {}  # stroke id → (page t0, samples so far)
        self._stop = threading.Event()
        self._checkpointer = threading.Thread(target=self._checkpoints, args=(checkpoint_s,),
                                              name="realpen-store-checkpoint", daemon=True)
        self._checkpointer.start()

    def _checkpoints(self, every_s: float) -> None:
        """Copy the journal into the database now and then, off the event loop."""
        connection = sqlite3.connect(self.path, timeout=5.0)
        try:
            while not self._stop.wait(every_s):
                try:
                    connection.execute("PRAGMA wal_checkpoint(PASSIVE)")
                except sqlite3.Error as error:  # e.g. busy: the next round catches up
                    log.debug("checkpoint: %s", error)
        finally:
            connection.close()

    def begin_stroke(self, *, session: str, page_stroke: int, pen: str, profile_version: str,
                     modality: str, ink: str, pointer_type: str, px_per_mm: float,
                     calibrated: bool, page_t0: float) -> int:
        """Record a pen-down; returns the stroke's id in the store."""
        with self._lock:
            cursor = self._db.execute(
                "INSERT INTO strokes (session, page_stroke, pen, profile_version, modality, ink, "
                "pointer_type, px_per_mm, calibrated, page_t0, started_at) "
                "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                (session, page_stroke, pen, profile_version, modality, ink, pointer_type,
                 px_per_mm, int(calibrated), page_t0, _now()))
            self._db.commit()
            stroke_id = int(cursor.lastrowid)
            self._open[stroke_id] = (page_t0, 0)
            return stroke_id

    def add_samples(self, stroke_id: int,
                    samples: Sequence[StrokeSample | Sequence[float]]) -> int:
        """Append samples to an open stroke; returns the stroke's sample count.

        Args:
            stroke_id: the stroke's id in the store (from :meth:`begin_stroke`).
            samples: :class:`~realpen.io.strokes.StrokeSample` rows, or tuples of their
                :data:`SAMPLE_FIELDS` (``t`` in s on the page clock, mm, mm, 0–1, degrees,
                degrees, mm/s); ``t`` is stored in s since pen down.
        """
        rows = [sample.as_row() if isinstance(sample, StrokeSample) else tuple(sample)
                for sample in samples]
        with self._lock:
            t0, count = self._open[stroke_id]
            rows = [(stroke_id, count + i, s[0] - t0, *s[1:]) for i, s in enumerate(rows)]
            self._db.executemany(_INSERT_SAMPLE, rows)
            count += len(rows)
            self._db.execute("UPDATE strokes SET sample_count=? WHERE id=?", (count, stroke_id))
            self._db.commit()
            self._open[stroke_id] = (t0, count)
            return count

    def end_stroke(self, stroke_id: int, reason: str = "pen_up") -> None:
        """Record the end of a stroke (once; later calls do nothing)."""
        with self._lock:
            if self._open.pop(stroke_id, None) is None:
                return
            self._db.execute("UPDATE strokes SET ended_at=?, end_reason=? WHERE id=?",
                             (_now(), reason, stroke_id))
            self._db.commit()

    def count(self) -> tuple[int, int]:
        """(strokes, samples) in the store."""
        with self._lock:
            strokes = self._db.execute("SELECT COUNT(*) FROM strokes").fetchone()[0]
            samples = self._db.execute("SELECT COUNT(*) FROM samples").fetchone()[0]
            return int(strokes), int(samples)

    def close(self) -> None:
        """End strokes still open (reason ``shutdown``), commit, and close the file."""
        for stroke_id in list(self._open):
            self.end_stroke(stroke_id, "shutdown")
        self._stop.set()
        self._checkpointer.join()
        with self._lock:
            if self._db is not None:
                self._db.commit()
                self._db.close()
                self._db = None


    def discard(self) -> None:
        """Close, and remove the file if this store created it and it holds no stroke: for a
        server that fails to start, so that it leaves nothing behind."""
        empty = self._db is not None and self.count() == (0, 0)
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
        if stroke is not None and connection.execute(
                "SELECT 1 FROM strokes WHERE id = ?", (stroke,)).fetchone() is None:
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
