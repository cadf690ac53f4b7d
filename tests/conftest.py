"""Shared fixtures: the real-data folders beside the repository, a CLI runner, the live app,
PostgreSQL and Chromium; and the test tiers.

Tiers (markers, registered in pyproject.toml; ``scripts/test.sh --fast`` leaves out all four):
``browser`` (Chromium through Playwright: every test that uses the :func:`chromium` fixture),
``postgres`` (every test that uses :func:`postgres_server`, and :func:`store_target`'s
PostgreSQL case), ``firmware`` (the pen firmware under the MicroPython Unix port, or the Due's
C core compiled with cc: marked in the test modules) and ``slow`` (a ``realpen serve`` or Python
subprocess, or seconds of computing: marked in the test modules). The first two follow from the
fixtures here (:func:`pytest_collection_modifyitems`), so a new test cannot forget them.
"""

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


@pytest.fixture(params=["sqlite", pytest.param("postgresql", marks=pytest.mark.postgres)])
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


# ---- Chromium, one per worker (tests/test_live_browser.py and the other browser tests) -------

class _ChromiumPool:
    """Playwright and the Chromium browsers launched through it, one per set of arguments,
    shared by every browser test of a worker (each test opens contexts and pages of its own).

    Playwright's sync API marks the worker's thread as running its event loop for as long as it
    is started, which would break a later test's ``asyncio.run``; the pool is therefore stopped
    after the last of a run of consecutive browser tests (:func:`pytest_runtest_teardown`).
    Under xdist the browser modules are handed out first (:func:`pytest_collection_modifyitems`),
    so each worker runs its share of them in a row, on one Chromium.
    """

    def __init__(self):
        self._playwright = None
        self._browsers: dict[tuple[str, ...], object] = {}

    @property
    def started(self) -> bool:
        return self._playwright is not None

    def launch(self, args=None):
        """The worker's Chromium started with ``args`` (default ``live_support.CHROMIUM_ARGS``),
        launched on first use."""
        from live_support import CHROMIUM, CHROMIUM_ARGS

        key = tuple(CHROMIUM_ARGS if args is None else args)
        if key not in self._browsers:
            if self._playwright is None:
                from playwright.sync_api import sync_playwright

                self._playwright = sync_playwright().start()
            self._browsers[key] = self._playwright.chromium.launch(
                executable_path=str(CHROMIUM), args=list(key))
        return self._browsers[key]

    def stop(self) -> None:
        """Close every browser and stop Playwright (the next :meth:`launch` starts them again)."""
        try:
            for browser in self._browsers.values():
                with contextlib.suppress(Exception):  # already gone with a crashed driver
                    browser.close()
        finally:
            self._browsers.clear()
            playwright, self._playwright = self._playwright, None
            if playwright is not None:
                playwright.stop()


_CHROMIUM = _ChromiumPool()


@pytest.fixture(scope="session")
def chromium():
    """``chromium(args=None)``: the worker's Debian Chromium under Playwright, launched with
    ``args`` (default ``live_support.CHROMIUM_ARGS``) the first time and shared after; tests
    open their own contexts and pages. Call it in each test (or a function-scoped fixture), not
    once per module: the pool closes between runs of browser tests. It is the only way a test
    may start Chromium: a second Playwright in the worker would refuse to start while this one
    runs. Marks the tests of its module ``browser``."""
    yield _CHROMIUM.launch
    _CHROMIUM.stop()


@pytest.hookimpl(wrapper=True)
def pytest_runtest_teardown(item, nextitem):
    """Stop the shared Chromium once the next test is not a browser test (see
    :class:`_ChromiumPool`), after the test's own fixtures are finalized."""
    result = yield
    if _CHROMIUM.started and (nextitem is None or nextitem.get_closest_marker("browser") is None):
        _CHROMIUM.stop()
    return result


# ---- tiers, and the order in which pytest-xdist hands out the modules -------------------------

def _weight(items) -> int:
    """0 for a module with browser tests, 1 for one with other marked (long) tests, else 2."""
    if any(item.get_closest_marker("browser") for item in items):
        return 0
    if any(item.get_closest_marker(mark) for item in items
           for mark in ("postgres", "firmware", "slow")):
        return 1
    return 2


@pytest.hookimpl(tryfirst=True)  # before -m deselects: the tiers must be known
def pytest_collection_modifyitems(config, items):
    """Mark the tiers that follow from the fixtures; under xdist, order the modules longest
    first.

    ``scripts/test.sh`` runs ``--dist loadfile --no-loadscope-reorder``: a module's tests run on
    one worker (its module-scoped servers and analyses are built once) and the modules are
    handed out in collection order, so the modules that take longest start first and the many
    short ones fill the end evenly; consecutive browser modules share a worker's Chromium.
    """
    modules: dict[str, list] = {}
    for item in items:
        modules.setdefault(item.nodeid.split("::")[0], []).append(item)
    # A module that drives Chromium is a browser module as a whole: its other tests share its
    # module-scoped servers, so they run with it (and are skipped with it without Chromium).
    for module_items in modules.values():
        browser = any("chromium" in getattr(item, "fixturenames", ()) for item in module_items)
        for item in module_items:
            if browser:
                item.add_marker(pytest.mark.browser)
            if "postgres_server" in getattr(item, "fixturenames", ()):
                item.add_marker(pytest.mark.postgres)
    if hasattr(config, "workerinput"):  # an xdist worker: every worker sorts alike
        ordered = sorted(modules.values(), key=_weight)  # stable: same order within a weight
        items[:] = [item for module_items in ordered for item in module_items]
