"""Shared fixtures: the real-data folders beside the repository and a CLI runner."""

from __future__ import annotations

import contextlib
import io
import os
import subprocess
import sys
import traceback
from pathlib import Path
from unittest import mock

import pytest

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
HATT_DIR = SHARED / "data" / "hatt_models"
LMT_DIR = SHARED / "data" / "lmt108_sound"


def require_dir(path: Path) -> Path:
    """Skip the calling test, saying why, when a real-data folder is not there."""
    if not path.is_dir() or not any(path.iterdir()):
        pytest.skip(f"real data not available: {path} is absent (it is never bundled; "
                    f"see shared/data/README.md)")
    return path


@pytest.fixture
def hatt_dir() -> Path:
    return require_dir(HATT_DIR)


@pytest.fixture
def lmt_dir() -> Path:
    return require_dir(LMT_DIR)


def run_cli(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    """Run ``realpen ARGS`` in this interpreter and capture its output and exit code.

    The command line's own entry point (:func:`realpen.cli.main`) runs as the console script
    would, with ``sys.argv`` set and stdout/stderr captured; the result has the shape of a
    :class:`subprocess.CompletedProcess` so end-to-end tests can use :func:`run_cli_process`.
    """
    from realpen.cli import main

    stdout, stderr = io.StringIO(), io.StringIO()
    argv = ["realpen", *map(str, args)]
    code = 0
    previous = os.getcwd()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr), \
            mock.patch.object(sys, "argv", argv):
        try:
            if cwd is not None:
                os.chdir(cwd)
            main()
        except SystemExit as exit_:
            code = exit_.code if isinstance(exit_.code, int) else (0 if exit_.code is None else 1)
        except BaseException:  # a traceback escaped main(): report it like the interpreter would
            stderr.write(traceback.format_exc())
            code = 1
        finally:
            os.chdir(previous)
    return subprocess.CompletedProcess(argv, code, stdout.getvalue(), stderr.getvalue())


def run_cli_process(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    """Run ``python -m realpen ARGS`` in a fresh interpreter (for the few end-to-end tests)."""
    return subprocess.run([sys.executable, "-m", "realpen", *map(str, args)],
                          capture_output=True, text=True, cwd=cwd, timeout=300)


def assert_clean_failure(result: subprocess.CompletedProcess, names: str) -> None:
    """Exit code 2, one line on stderr that mentions ``names``, and no traceback."""
    assert result.returncode == 2, (result.returncode, result.stdout, result.stderr)
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, result.stderr
    assert names in lines[0], lines[0]
    assert "Traceback" not in result.stderr


# ---- the live app in-process (tests/test_live_*.py) ------------------------------------------

@pytest.fixture
def store_path(tmp_path):
    """Where the in-process live app's stroke store goes."""
    return tmp_path / "strokes.sqlite3"


@pytest.fixture
def client(tmp_path, store_path, monkeypatch):
    """The live app in-process (FastAPI's TestClient), loopback settings, a fresh store."""
    from fastapi.testclient import TestClient

    from realpen.live.app import LiveSettings, create_app

    monkeypatch.setenv("REALPEN_HOME", str(tmp_path / "home"))
    app = create_app(LiveSettings.loopback(store=store_path))
    with TestClient(app, base_url="http://127.0.0.1") as test_client:
        yield test_client


# ---- the store on PostgreSQL (tests/test_store_db.py and the parametrized store tests) --------

POSTGRES_MISSING = ("PostgreSQL is not installed (Debian package postgresql; scripts/test.sh "
                    "installs it as root)")


def postgres_bin() -> Path | None:
    """The folder of ``initdb``, ``pg_ctl`` and ``postgres``: on PATH, else Debian's
    ``/usr/lib/postgresql/VERSION/bin`` (the newest), else None."""
    import shutil

    found = [shutil.which(name) for name in ("initdb", "pg_ctl", "postgres")]
    if all(found):
        return Path(found[0]).parent
    versions = sorted(Path("/usr/lib/postgresql").glob("*/bin"),
                      key=lambda p: [int(x) if x.isdigit() else 0 for x in p.parent.name.split(".")])
    for folder in reversed(versions):
        if all((folder / name).exists() for name in ("initdb", "pg_ctl", "postgres")):
            return folder
    return None


class PostgresServer:
    """A PostgreSQL server of the test session: listening only on a Unix socket in ``folder``,
    as the ``postgres`` user when the tests run as root (the server refuses root)."""

    def __init__(self, folder: Path, port: int):
        self.folder, self.port = folder, port
        self._count = 0

    def url(self, database: str, driver: str = "postgresql+psycopg") -> str:
        """The URL of ``database`` on this server (user ``postgres``, no password)."""
        return f"{driver}://postgres@/{database}?host={self.folder}&port={self.port}"

    def execute(self, sql: str, database: str = "postgres") -> list[tuple]:
        """Run one statement outside a transaction (CREATE DATABASE may not run in one)."""
        import psycopg

        with psycopg.connect(host=str(self.folder), port=self.port, user="postgres",
                             dbname=database, autocommit=True) as connection:
            cursor = connection.execute(sql)
            return cursor.fetchall() if cursor.description else []

    def new_database(self, prefix: str = "realpen") -> str:
        """Create a database with a name of its own; returns its URL."""
        self._count += 1
        name = f"{prefix}_{os.getpid()}_{self._count}"
        self.execute(f'CREATE DATABASE "{name}"')
        return self.url(name)


def new_database_url(server: PostgresServer, prefix: str = "realpen") -> str:
    """The URL of a new, empty database on the session's server (see :class:`PostgresServer`)."""
    return server.new_database(prefix)


@pytest.fixture(scope="session")
def postgres_server():
    """A real PostgreSQL server for the whole test session (one ``initdb``, ~1 s), stopped at
    the end; skips, saying why, when PostgreSQL is not installed (see
    :func:`pg_support.running_postgres`)."""
    from pg_support import PostgresUnavailable, running_postgres

    try:
        server = running_postgres()
        started = server.__enter__()
    except PostgresUnavailable as reason:
        pytest.skip(str(reason))
    try:
        yield started
    finally:
        server.__exit__(None, None, None)


@pytest.fixture(params=["sqlite", "postgresql"])
def store_target(request, tmp_path):
    """A fresh store target: an SQLite file path, or the URL of a new PostgreSQL database."""
    if request.param == "sqlite":
        return tmp_path / "s.sqlite3"
    return request.getfixturevalue("postgres_server").new_database()


def store_rows(target, sql: str) -> list[tuple]:
    """The rows of ``sql`` (plain SQL, no parameters) on a store: an SQLite file or a URL."""
    if not isinstance(target, str) or "://" not in target:
        import sqlite3

        with contextlib.closing(sqlite3.connect(target)) as db:
            return db.execute(sql).fetchall()
    from sqlalchemy import create_engine
    from sqlalchemy.pool import NullPool

    engine = create_engine(target, poolclass=NullPool)
    try:
        with engine.connect() as connection:
            return [tuple(row) for row in connection.exec_driver_sql(sql)]
    finally:
        engine.dispose()
