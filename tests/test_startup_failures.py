"""Starting on a full disk: ``realpen serve`` and the commands that open the store say so in one
line (exit code 2) and leave nothing half-written.

The disk is made full portably: SQLite's own ``PRAGMA max_page_count`` (set on every connection
the store opens) makes SQLite answer SQLITE_FULL, "database or disk is full", exactly as a full
disk does. A journal index SQLite cannot grow (it then says "disk I/O error") and a data folder
the system cannot make are injected at the lowest seam, the error and the free space the system
reports, since filling a real disk needs a mount the tests may not have.
"""

from __future__ import annotations

import errno
import os
import sqlite3
from pathlib import Path

import pytest
from conftest import assert_clean_failure, run_cli
from sqlalchemy import event
from sqlalchemy.engine import Engine

pytest.importorskip("fastapi", reason="the live app needs the server dependencies")

from realpen.live.store import StrokeStore  # noqa: E402
from realpen.study.db import store_error  # noqa: E402

STROKE_FIELDS = dict(pen="pencil", profile_version="0" * 12, modality="none", ink="visible",
                     pointer_type="pen", px_per_mm=4.0, calibrated=False)
OPEN_STROKES = 200  # ending them grows the strokes table by several pages
FULL = "the disk is full (database or disk is full)"


class FullDisk:
    """While on, every SQLite connection opened may not grow its database by a page."""

    @staticmethod
    def _no_room(dbapi_connection, record) -> None:
        if isinstance(dbapi_connection, sqlite3.Connection):
            dbapi_connection.execute("PRAGMA max_page_count=1")  # 1: as large as it is now

    def __enter__(self) -> None:
        event.listen(Engine, "connect", self._no_room)

    def __exit__(self, *exc_info) -> None:
        event.remove(Engine, "connect", self._no_room)


def store_left_open(path: Path) -> None:
    """A store as a killed server leaves it: :data:`OPEN_STROKES` strokes never ended."""
    store = StrokeStore(path)
    stroke = store.begin_stroke(session="s", page_stroke=0, page_t0=0.0, **STROKE_FIELDS)
    store.add_samples(stroke, [(k / 100, k, 0, 0.5, 0, 0, 0) for k in range(10)])
    store.close()
    with sqlite3.connect(path) as db:
        columns = [row[1] for row in db.execute("PRAGMA table_info(strokes)") if row[1] != "id"]
        copied = ", ".join("page_stroke + n" if name == "page_stroke" else name
                           for name in columns)
        db.execute(f"WITH RECURSIVE k(n) AS (SELECT 1 UNION ALL SELECT n + 1 FROM k "
                   f"WHERE n < {OPEN_STROKES - 1}) INSERT INTO strokes ({', '.join(columns)}) "
                   f"SELECT {copied} FROM strokes, k")
        db.execute("UPDATE strokes SET ended_at = NULL, end_reason = NULL")
    db.close()
    with sqlite3.connect(path) as db:
        db.execute("VACUUM")  # no free pages left inside the file either
    db.close()


def dump(path: Path) -> list[str]:
    """The store's schema and rows as SQL."""
    with sqlite3.connect(path) as db:
        lines = list(db.iterdump())
    db.close()
    return lines


def test_a_server_restarted_on_a_full_disk_says_so_in_one_line(tmp_path):
    path = tmp_path / "strokes.sqlite3"
    store_left_open(path)
    with sqlite3.connect(path) as db:  # ending the strokes needs room: the start must fail
        db.execute("PRAGMA max_page_count=1")
        with pytest.raises(sqlite3.OperationalError, match="database or disk is full"):
            db.execute("UPDATE strokes SET ended_at = started_at, end_reason = 'crash'")
        db.rollback()
    db.close()
    before = dump(path)
    with FullDisk():
        result = run_cli("serve", "--port", "0", "--store", str(path))
    assert_clean_failure(result, f"{path}: {FULL}; free some space on it and try again")
    assert "RealPen live" not in result.stdout  # refused before any URL is printed
    assert dump(path) == before  # nothing half-written: the failed change was rolled back
    store = StrokeStore(path)  # with room again the start ends the strokes, every sample kept
    assert store.recovered == OPEN_STROKES
    assert store.count() == (OPEN_STROKES, OPEN_STROKES * 10)
    store.close()


def test_a_new_store_on_a_full_disk_is_one_line_and_leaves_no_file(tmp_path, monkeypatch):
    monkeypatch.setenv("REALPEN_HOME", str(tmp_path / "home"))
    path = tmp_path / "home" / "strokes.sqlite3"  # the default store, in the data folder
    with FullDisk():
        result = run_cli("serve", "--port", "0")
    assert_clean_failure(result, f"{path}: {FULL}; free some space on it and try again")
    assert list((tmp_path / "home").iterdir()) == []  # no store file, no journal


def test_a_data_folder_that_cannot_be_made_on_a_full_disk(tmp_path, monkeypatch):
    monkeypatch.setenv("REALPEN_HOME", str(tmp_path / "home"))
    real_mkdir = Path.mkdir

    def mkdir(self, *args, **kwargs):
        if self == tmp_path / "home":
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(self))
        return real_mkdir(self, *args, **kwargs)

    monkeypatch.setattr(Path, "mkdir", mkdir)
    result = run_cli("serve", "--port", "0")
    assert_clean_failure(result, f"{tmp_path / 'home' / 'strokes.sqlite3'}: the disk is full "
                                 f"({os.strerror(errno.ENOSPC)}); free some space on it")
    assert not (tmp_path / "home").exists()


def test_study_export_says_a_full_disk_as_serve_does(tmp_path, monkeypatch):
    path = tmp_path / "strokes.sqlite3"
    StrokeStore(path).close()
    # On a full disk SQLite cannot grow the journal's index (the -shm file) and says "disk I/O
    # error" (SQLITE_IOERR_SHMSIZE); the folder has no room left.
    shm_full = sqlite3.OperationalError("disk I/O error")
    shm_full.sqlite_errorcode, shm_full.sqlite_errorname = 4874, "SQLITE_IOERR_SHMSIZE"

    def no_index(dbapi_connection, record) -> None:
        raise shm_full

    class NoRoom:
        f_bavail, f_frsize = 0, 4096

    real_statvfs = os.statvfs
    monkeypatch.setattr(os, "statvfs", lambda folder: NoRoom() if Path(folder) == tmp_path
                        else real_statvfs(folder))
    event.listen(Engine, "connect", no_index)
    try:
        result = run_cli("study", "export", "--store", str(path), "-o", str(tmp_path / "t.csv"))
    finally:
        event.remove(Engine, "connect", no_index)
    assert_clean_failure(result, f"{path}: the disk is full (disk I/O error); free some space")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["strokes.sqlite3"]


def test_a_database_server_with_a_full_disk_is_named_with_its_password_hidden():
    from sqlalchemy.exc import OperationalError

    class DiskFull(Exception):  # what psycopg raises: the SQLSTATE names the problem
        sqlstate = "53100"

    error = OperationalError("INSERT …", {}, DiskFull("could not extend file: No space left"))
    assert str(store_error("postgresql://ann:s3cret@db/realpen", error)) == (
        "postgresql://ann:***@db/realpen: the database server's disk is full (could not extend "
        "file: No space left); free some space on it and try again")
    assert str(store_error("s.sqlite3", sqlite3.OperationalError("database is locked"))) == \
        "s.sqlite3: cannot use the store (database is locked)"
