"""Opening the store: one SQLite file (WAL) or a PostgreSQL database, schema by Alembic.

A store is named by a *target*: a file path (SQLite, the default: one file beside the user's
data), an ``sqlite:///FILE`` URL, or a ``postgresql://USER:PASSWORD@HOST/NAME`` URL (psycopg 3;
``postgresql+psycopg://`` is the same) when several machines or labs write to one database.
:func:`open_database` checks that the target is a RealPen store (or makes one), brings its
schema to the newest revision of the Alembic migrations in ``migrations/`` and hands back a
:class:`Database`: a SQLAlchemy engine and what to call the store in messages.

The SQLite file is guarded as the stroke store always was: the writer takes an exclusive
``flock`` on the file before anything touches it (a second server is refused in one line);
a file is created with ``O_EXCL``, so only the process that created it removes it after a
failed start; ``PRAGMA quick_check`` refuses a damaged file; WAL journal, ``synchronous=FULL``
(a commit is on disk before it is acknowledged), foreign keys on, a busy timeout. Its
``PRAGMA user_version`` is :data:`SQLITE_USER_VERSION` once migrated, so that an older RealPen
(which reads versions 1 and 2) refuses it in one line instead of writing to a schema it does not
know; stores of those versions (before Alembic) are upgraded in place.

Every problem is one :class:`~realpen.errors.RealPenError` line naming the file, or the URL with
its password hidden: cannot connect, not a RealPen store, a schema newer than this RealPen, or
a full disk (:func:`disk_full`: opening a store writes — the journal, its index, a migration —
so a full disk is said as such, whichever of them met it).
"""

from __future__ import annotations

import contextlib
import errno
import functools
import os
import re
import sqlite3
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal, NoReturn

from sqlalchemy import URL, Engine, create_engine, event, inspect, make_url, text
from sqlalchemy.exc import ArgumentError, DBAPIError, SQLAlchemyError
from sqlalchemy.pool import QueuePool

from realpen.errors import RealPenError, fail

try:  # advisory locks: POSIX only; elsewhere two servers on one store are not prevented
    import fcntl
except ImportError:  # pragma: no cover
    fcntl = None

__all__ = ["Database", "open_database", "store_file", "hide_password", "head_revision",
           "SQLITE_USER_VERSION", "BUSY_TIMEOUT_MS", "MIGRATIONS", "STORE_ERRORS", "error_line",
           "disk_full", "store_error", "DISK_FULL_ROOM_BYTES"]

SQLITE_USER_VERSION = 3
"""``PRAGMA user_version`` of a migrated SQLite store (1 and 2: the stroke store before Alembic)."""
BUSY_TIMEOUT_MS = 5000
"""How long an SQLite statement waits for another process's lock (ms)."""
STORE_ERRORS = (SQLAlchemyError, sqlite3.Error)
"""What an operation on an open store may fail with when the database cannot do it (the
driver's errors come wrapped by SQLAlchemy; ``sqlite3.Error`` from code that uses the driver)."""
CONNECT_TIMEOUT_S = 10
"""How long opening a PostgreSQL connection may take (s)."""
DISK_FULL_ROOM_BYTES = 1024 * 1024
"""Below this much free space in the store's folder (bytes), an SQLite I/O error is taken for a
full disk: SQLite reports a journal index it cannot grow as "disk I/O error", not as full."""
MIGRATIONS = Path(__file__).with_name("migrations")
"""The Alembic script folder (``env.py`` and ``versions/``)."""
_LEGACY_REVISION = "0001"  # the schema of user_version 2: strokes and samples
# Serialises migrations across the servers that share one PostgreSQL database (an arbitrary
# key of RealPen's own, a signed 64-bit integer).
_MIGRATION_LOCK = 0x5245_414C_5045_4E01
_ALEMBIC = threading.Lock()  # Alembic's `context` is process-global: one migration at a time

# Version 1 (the first stroke store) had no page column: each connection was its own page. It
# took a stroke number twice on one connection; such a later stroke keeps its own page id, so
# none is merged.
_UPGRADE_FROM_1 = (
    "ALTER TABLE strokes ADD COLUMN page TEXT",
    "UPDATE strokes SET page = session",
    "UPDATE strokes SET page = session || '#' || id "
    "WHERE id NOT IN (SELECT MIN(id) FROM strokes GROUP BY session, page_stroke)",
    "CREATE UNIQUE INDEX IF NOT EXISTS strokes_by_page ON strokes (page, page_stroke)",
)


def error_line(error: BaseException) -> str:
    """A store error in one line: the driver's message (SQLAlchemy's wrapper adds the SQL, its
    parameters and a link on further lines).

    >>> error_line(sqlite3.OperationalError("database is locked"))
    'database is locked'
    """
    return " ".join(str(getattr(error, "orig", None) or error).split())


_DISK_FULL_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT})
_SQLITE_FULL, _SQLITE_IOERR = 13, 10  # primary result codes (the low byte of an extended one)
_POSTGRESQL_DISK_FULL = "53100"  # SQLSTATE disk_full


def disk_full(error: BaseException, folder: str | os.PathLike | None = None) -> bool:
    """Whether ``error`` means that the disk holding the store has no room left.

    Args:
        error: an :class:`OSError` (``ENOSPC``, ``EDQUOT``), an SQLite error (SQLITE_FULL:
            "database or disk is full"), a PostgreSQL one (SQLSTATE 53100), or SQLAlchemy's
            wrapper of either.
        folder: the SQLite file's folder: an SQLite I/O error counts as a full disk when it
            has less than :data:`DISK_FULL_ROOM_BYTES` free (SQLite says "disk I/O error" when
            it cannot grow the journal's index, the ``-shm`` file); None: it never does.

    >>> disk_full(sqlite3.OperationalError("database or disk is full"))
    True
    >>> disk_full(OSError(errno.ENOSPC, "No space left on device"))
    True
    >>> disk_full(sqlite3.OperationalError("database is locked"))
    False
    """
    orig = getattr(error, "orig", None) or error
    if isinstance(orig, OSError):
        return orig.errno in _DISK_FULL_ERRNOS
    if isinstance(orig, sqlite3.Error):
        code = getattr(orig, "sqlite_errorcode", None)
        if code is None:  # made by code rather than by the driver: only its words tell
            return str(orig) == "database or disk is full"
        if code & 0xFF == _SQLITE_FULL:
            return True
        return (code & 0xFF == _SQLITE_IOERR and folder is not None
                and _free_bytes(folder) < DISK_FULL_ROOM_BYTES)
    return getattr(orig, "sqlstate", None) == _POSTGRESQL_DISK_FULL


def _free_bytes(folder: str | os.PathLike) -> float:
    """Bytes this process may still write in ``folder`` (infinite when it cannot be asked)."""
    try:
        stats = os.statvfs(folder)
    except (OSError, AttributeError):  # no statvfs (Windows), or the folder is gone
        return float("inf")
    return stats.f_bavail * stats.f_frsize


def _disk_full_line(where: object, error: BaseException | str,
                    disk: str = "the disk") -> RealPenError:
    """``"<where>: the disk is full (<the system's words>); free some space on it and try
    again"`` (``disk``: whose disk, e.g. the database server's)."""
    orig = getattr(error, "orig", None) or error
    words = orig.strerror if isinstance(orig, OSError) and orig.strerror else error_line(orig)
    return fail(where, f"{disk} is full ({words}); free some space on it and try again")


def store_error(target: str | os.PathLike, error: BaseException) -> RealPenError:
    """A store operation's failure (:data:`STORE_ERRORS`, or an :class:`OSError`) as one line
    naming the store: that the disk is full (:func:`disk_full`), or the driver's words.

    Args:
        target: the store as :func:`open_database` took it (a URL's password is hidden).
        error: what the operation raised.

    >>> str(store_error("s.sqlite3", sqlite3.OperationalError("database or disk is full")))
    's.sqlite3: the disk is full (database or disk is full); free some space on it and try again'
    """
    shown = hide_password(target)
    file = store_file(target)
    if disk_full(error, None if file is None else Path(os.path.abspath(file)).parent):
        return _disk_full_line(shown, error, "the disk" if file else "the database server's disk")
    return fail(shown, f"cannot use the store ({error_line(error)})")


@dataclass(eq=False)
class Database:
    """An open store.

    Attributes:
        engine: the SQLAlchemy engine (SQLite connections begin with ``BEGIN IMMEDIATE`` when
            this process is the store's writer, so a write transaction never has to upgrade its
            lock midway; ``BEGIN`` otherwise).
        dialect: ``"sqlite"`` or ``"postgresql"``.
        path: the SQLite file, or None for PostgreSQL.
        display: what messages call the store: the file, or the URL with its password hidden.
        created: this call created the SQLite file (only then may a failed start remove it).
        revision: the schema's Alembic revision (:func:`head_revision` once migrated; an older
            one when opened without ``create``; None for an SQLite store from before Alembic,
            whose tables are those of revision ``0001``, without ``page`` in version 1).
    """

    engine: Engine
    dialect: Literal["sqlite", "postgresql"]
    path: Path | None
    display: str
    created: bool = False
    revision: str | None = None
    _lock_fd: int | None = field(default=None, repr=False)

    def close(self) -> None:
        """Close every connection and release the file lock (once; later calls do nothing)."""
        self.engine.dispose()
        if self._lock_fd is not None:
            os.close(self._lock_fd)  # closing the descriptor releases the flock
            self._lock_fd = None

    def remove_files(self) -> None:
        """Remove the SQLite file and its journal files if this process created it (a start
        that failed leaves nothing behind); nothing for PostgreSQL. Call after :meth:`close`."""
        if self.created and self.path is not None:
            _remove_store_files(self.path)


def hide_password(target: str | os.PathLike) -> str:
    """``target`` as it may be shown: as given, with a URL's password replaced by ``***``.

    >>> hide_password("postgresql://ann:s3cret@db.lab.example/realpen")
    'postgresql://ann:***@db.lab.example/realpen'
    >>> hide_password("postgresql://ann@/realpen?host=/run&password=s3cret&port=1")
    'postgresql://ann@/realpen?host=/run&password=***&port=1'
    """
    shown = os.fspath(target)
    if "://" not in shown:
        return shown
    # A password ends at the first "@" (one inside it must be written %40); one may also be
    # given in the query (``?password=…``).
    shown = re.sub(r"^([^:/?#]+://[^:/?#@]*:)[^@]*@", r"\1***@", shown)
    return re.sub(r"([?&]password=)[^&#]*", r"\1***", shown, flags=re.IGNORECASE)


def store_file(target: str | os.PathLike) -> Path | None:
    """The SQLite file a target names (a path or an ``sqlite:///`` URL), or None for a server
    URL (or a URL that is not valid; :func:`open_database` says what is wrong with it)."""
    if isinstance(target, os.PathLike) or "://" not in str(target):
        return Path(target)
    try:
        url = make_url(str(target))
    except (ArgumentError, ValueError):
        return None
    if url.get_backend_name() == "sqlite" and url.database and url.database != ":memory:":
        return Path(url.database)
    return None


@functools.cache
def _script():
    from alembic.script import ScriptDirectory

    return ScriptDirectory(str(MIGRATIONS))


def head_revision() -> str:
    """The newest schema revision this RealPen knows (``"0002"``, …)."""
    return _script().get_current_head()


def _known_revisions() -> set[str]:
    return {script.revision for script in _script().walk_revisions()}


def open_database(target: str | os.PathLike, *, create: bool, lock: bool | None = None) -> Database:
    """Open a store, check that it is one, and (``create``) bring its schema to
    :func:`head_revision`.

    Args:
        target: an SQLite file path, an ``sqlite:///FILE`` URL, or a PostgreSQL URL
            (``postgresql://`` or ``postgresql+psycopg://``; psycopg 3).
        create: make the store (the SQLite file, or the tables in an empty PostgreSQL
            database) when it does not exist, and bring an older one to the newest revision
            (the writer does); without it a missing store is an error, and an older schema is
            read as it is (:attr:`Database.revision`), so that reading never changes a file.
        lock: take the SQLite file's exclusive lock for this process (the one writer); default:
            ``create``. Readers (an export) leave it so that they can read while a server writes.

    Returns:
        The open :class:`Database`; :meth:`Database.close` it.

    Raises:
        RealPenError: one line naming the file or the URL (password hidden): no such store, a
            place where none can be made, in use by another server, cannot connect, not a
            RealPen store, a damaged file, or a schema newer than this RealPen.
    """
    lock = create if lock is None else lock
    if isinstance(target, os.PathLike) or "://" not in str(target):
        return _open_sqlite(Path(target), create, lock)
    shown = hide_password(target)
    try:
        url = make_url(str(target))
    except (ArgumentError, ValueError):
        raise RealPenError(f"{shown}: not a database URL (give an SQLite file, sqlite:///FILE or "
                           f"postgresql://USER:PASSWORD@HOST/DATABASE)") from None
    backend = url.get_backend_name()
    if backend == "sqlite":
        path = store_file(str(target))
        if path is None:
            raise RealPenError(f"{shown}: an SQLite store must be a file (sqlite:///FILE)")
        if url.drivername not in ("sqlite", "sqlite+pysqlite"):
            raise RealPenError(f"{shown}: unsupported SQLite driver {url.get_driver_name()!r} "
                               f"(use sqlite:///FILE)")
        return _open_sqlite(path, create, lock)
    if backend == "postgresql":
        if url.drivername == "postgresql":
            url = url.set(drivername="postgresql+psycopg")
        elif url.drivername != "postgresql+psycopg":
            raise RealPenError(f"{shown}: unsupported PostgreSQL driver {url.get_driver_name()!r} "
                               f"(use postgresql:// or postgresql+psycopg://, psycopg 3)")
        if not url.database:
            raise RealPenError(f"{shown}: the URL names no database (postgresql://…/DATABASE)")
        return _open_postgresql(url, shown, create)
    raise RealPenError(f"{shown}: unsupported database {backend!r} (give an SQLite file, "
                       f"sqlite:///FILE or postgresql://…)")


# ---- SQLite -------------------------------------------------------------------------------------

def _check_place(path: Path, create: bool) -> None:
    """Refuse a store path that is missing (unless ``create``), a folder, or under a file."""
    if not create and not path.exists():
        raise fail(path, "no such stroke store")
    if path.is_dir():
        raise fail(path, "is a folder, not a stroke store file")
    existing = next((parent for parent in path.parents if parent.exists()), None)
    if existing is not None and not existing.is_dir():
        raise fail(path, f"{existing} is a file, not a folder")


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
        if disk_full(error):
            raise _disk_full_line(path, error) from None
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


def _remove_store_files(path: Path) -> None:
    """Remove a store file and its journal files (``-wal``, ``-shm``, ``-journal``)."""
    for suffix in ("", "-wal", "-shm", "-journal"):
        with contextlib.suppress(OSError):
            Path(f"{path}{suffix}").unlink()


def _sqlite_engine(path: Path, writer: bool) -> Engine:
    """An engine whose connections keep the store's settings and begin as :class:`Database`
    says; the execution option ``sqlite_begin`` (``"IMMEDIATE"``, ``"DEFERRED"``) overrides."""
    engine = create_engine(URL.create("sqlite+pysqlite", database=str(path)), poolclass=QueuePool,
                           connect_args={"check_same_thread": False,
                                         "timeout": BUSY_TIMEOUT_MS / 1000})
    default_begin = "IMMEDIATE" if writer else "DEFERRED"

    @event.listens_for(engine, "connect")
    def _configure(dbapi_connection, record) -> None:
        # SQLAlchemy emits BEGIN itself (below): the driver's own transaction handling would
        # leave SAVEPOINTs and DDL outside the transaction.
        dbapi_connection.isolation_level = None
        # FULL: a commit is on disk before the page hears its ack (batching keeps the cost of
        # the fsync to one per batch, ~0.4 ms here).
        for pragma in ("synchronous=FULL", "foreign_keys=ON", f"busy_timeout={BUSY_TIMEOUT_MS}"):
            dbapi_connection.execute(f"PRAGMA {pragma}")

    @event.listens_for(engine, "begin")
    def _begin(connection) -> None:
        mode = connection.get_execution_options().get("sqlite_begin", default_begin)
        connection.exec_driver_sql(f"BEGIN {mode}")

    return engine


def _open_sqlite(path: Path, create: bool, lock: bool) -> Database:
    _check_place(path, create)
    # The lock comes first: files are only ever removed (a failed start) by their owner, and
    # ``created`` is decided by O_EXCL, not by a check another process could race.
    fd, created = _lock(path) if lock else (None, False)
    if create and not lock:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as error:
            if disk_full(error):
                raise _disk_full_line(path, error) from None
            raise fail(path, f"cannot open or create the stroke store here "
                             f"({error.strerror or error})") from None
    database = Database(_sqlite_engine(path, writer=lock), "sqlite", path, str(path), created,
                        _lock_fd=fd)
    try:
        _prepare_sqlite(database, create)
    except BaseException:
        database.close()
        database.remove_files()
        raise
    return database


def _sqlite_state(dbapi_connection) -> tuple[int, set[str], str | None]:
    """(user_version, table names, the Alembic revision or None)."""
    version = dbapi_connection.execute("PRAGMA user_version").fetchone()[0]
    tables = {row[0] for row in dbapi_connection.execute(
        "SELECT name FROM sqlite_master WHERE type='table'")}
    revision = None
    if "alembic_version" in tables:
        found = dbapi_connection.execute("SELECT version_num FROM alembic_version").fetchall()
        revision = found[0][0] if len(found) == 1 else "?"
    return version, tables, revision


def _refuse_sqlite_state(path: Path, create: bool, version: int, tables: set[str],
                         revision: str | None) -> None:
    if version > SQLITE_USER_VERSION:
        raise fail(path, f"stroke store version {version} is newer than this RealPen reads "
                         f"({SQLITE_USER_VERSION}); use a newer RealPen")
    if version == 0:
        if tables - {"sqlite_sequence"}:
            raise fail(path, "an SQLite file that is not a RealPen stroke store")
        if not create:
            raise fail(path, "not a RealPen stroke store (empty or another SQLite file)")
    if version == SQLITE_USER_VERSION and revision is None:
        raise fail(path, "not a RealPen stroke store (no schema revision)")
    if revision is not None and revision not in _known_revisions():
        raise fail(path, f"the store's schema (revision {revision}) is newer than this RealPen "
                         f"knows ({head_revision()}); use a newer RealPen")


def _prepare_sqlite(database: Database, create: bool) -> None:
    """Check the file, switch it to WAL and migrate it (see :func:`open_database`); sets
    ``database.revision``."""
    path = database.path
    try:
        raw = database.engine.raw_connection()
    except (DBAPIError, sqlite3.Error) as error:
        orig = getattr(error, "orig", None) or error
        if disk_full(orig, path.parent):
            raise _disk_full_line(path, orig) from None
        if isinstance(orig, sqlite3.OperationalError):
            raise fail(path, f"cannot open or create the stroke store here ({orig})") from None
        _raise_sqlite(path, error)
    try:
        dbapi = raw.driver_connection
        version, tables, revision = _sqlite_state(dbapi)
        _refuse_sqlite_state(path, create, version, tables, revision)
        dbapi.execute("PRAGMA journal_mode=WAL")
        if version > 0:
            problem = dbapi.execute("PRAGMA quick_check(1)").fetchone()[0]
            if problem != "ok":
                problem = " ".join(problem.replace("*** in database main ***", "").split())
                raise fail(path, f"the stroke store is damaged ({problem}); keep a copy and "
                                 f"start with a new store")
        current = version == SQLITE_USER_VERSION and revision == head_revision()
        database.revision = revision
    except (DBAPIError, sqlite3.Error) as error:
        _raise_sqlite(path, error)
    finally:
        raw.close()
    if not current and create:
        try:
            _migrate_sqlite(database, create)
        except (DBAPIError, sqlite3.Error) as error:
            _raise_sqlite(path, error)
        database.revision = head_revision()


def _raise_sqlite(path: Path, error: BaseException) -> NoReturn:
    orig = getattr(error, "orig", None) or error
    if disk_full(orig, path.parent):
        raise _disk_full_line(path, orig) from None
    if isinstance(orig, sqlite3.OperationalError):  # unreadable, read-only, locked
        raise fail(path, f"cannot use the stroke store ({orig})") from None
    # e.g. "file is not a database", a damaged page
    raise fail(path, f"not a RealPen stroke store, or a damaged one ({orig})") from None


def _migrate_sqlite(database: Database, create: bool) -> None:
    """Bring the file to the head revision in one transaction (an old store first through the
    pre-Alembic v1→v2 SQL and a stamp of revision ``0001``)."""
    with database.engine.connect() as connection:
        dbapi = connection.connection.driver_connection
        # Rebuilding a table (batch mode) drops it: with foreign keys on, that would delete
        # the rows that refer to it. They are checked again before the commit.
        dbapi.execute("PRAGMA foreign_keys=OFF")
        try:
            connection = connection.execution_options(sqlite_begin="IMMEDIATE")
            with connection.begin():
                # Again inside the write lock: another process may have migrated meanwhile.
                version, tables, revision = _sqlite_state(dbapi)
                _refuse_sqlite_state(database.path, create, version, tables, revision)
                if version in (1, 2) and revision is None:
                    if version == 1:
                        for statement in _UPGRADE_FROM_1:
                            connection.exec_driver_sql(statement)
                    _alembic(connection, "stamp", _LEGACY_REVISION)
                _alembic(connection, "upgrade", "head")
                broken = connection.exec_driver_sql("PRAGMA foreign_key_check").fetchall()
                if broken:
                    raise fail(database.path, f"the upgrade would break {len(broken)} reference(s) "
                                              f"between rows; nothing was changed")
                connection.exec_driver_sql(f"PRAGMA user_version={SQLITE_USER_VERSION}")
        finally:
            dbapi.execute("PRAGMA foreign_keys=ON")


def _alembic(connection, command_name: str, revision: str) -> None:
    """Run an Alembic command (``upgrade``, ``stamp``) on ``connection``, inside its
    transaction, without an ``alembic.ini``."""
    from alembic import command
    from alembic.config import Config

    config = Config()
    config.set_main_option("script_location", str(MIGRATIONS))
    config.attributes["connection"] = connection
    with _ALEMBIC:
        getattr(command, command_name)(config, revision)


# ---- PostgreSQL ---------------------------------------------------------------------------------

def _postgresql_message(error: BaseException, url: URL) -> str:
    """The driver's message in one line, without the password should it quote it."""
    message = " ".join(str(getattr(error, "orig", None) or error).split())
    secrets = [url.password, url.query.get("password")]
    for secret in secrets:
        for text_ in ([secret] if isinstance(secret, str) else list(secret or ())):
            if text_:
                message = message.replace(str(text_), "***")
    return message


def _open_postgresql(url: URL, shown: str, create: bool) -> Database:
    # A database that stops answering (a network gone quiet) is noticed within about half a
    # minute rather than the kernel's quarter of an hour: the writer's batch then fails and the
    # pages and the API say so, instead of waiting for ever.
    engine = create_engine(url, pool_pre_ping=True,
                           connect_args={"connect_timeout": CONNECT_TIMEOUT_S,
                                         "application_name": "realpen",
                                         "keepalives": 1, "keepalives_idle": 10,
                                         "keepalives_interval": 5, "keepalives_count": 3,
                                         "tcp_user_timeout": 30_000})
    try:
        try:
            connection = engine.connect()
        except SQLAlchemyError as error:
            raise RealPenError(f"{shown}: cannot connect to the database "
                               f"({_postgresql_message(error, url)})") from None
        try:
            with connection.begin():
                revision = _prepare_postgresql(connection, shown, create)
        except SQLAlchemyError as error:
            if disk_full(error):
                raise _disk_full_line(shown, _postgresql_message(error, url),
                                      "the database server's disk") from None
            raise RealPenError(f"{shown}: cannot use the database "
                               f"({_postgresql_message(error, url)})") from None
        finally:
            connection.close()
    except BaseException:
        engine.dispose()
        raise
    return Database(engine, "postgresql", None, shown, revision=revision)


def _prepare_postgresql(connection, shown: str, create: bool) -> str:
    """Check that the database is empty or a RealPen store, and migrate it (in the caller's
    transaction); returns the revision it is at."""
    # One server migrates at a time; the others then find the schema current.
    connection.execute(text("SELECT pg_advisory_xact_lock(:key)"), {"key": _MIGRATION_LOCK})
    tables = set(inspect(connection).get_table_names())
    revision = None
    if "alembic_version" in tables:
        found = connection.exec_driver_sql("SELECT version_num FROM alembic_version").fetchall()
        revision = found[0][0] if len(found) == 1 else "?"
    if revision is None and tables:
        listed = ", ".join(sorted(tables)[:5]) + (", …" if len(tables) > 5 else "")
        raise RealPenError(f"{shown}: not a RealPen database (it holds other tables: {listed})")
    if revision is None and not create:
        raise RealPenError(f"{shown}: not a RealPen database (it is empty)")
    if revision is not None and revision not in _known_revisions():
        raise RealPenError(f"{shown}: the database's schema (revision {revision}) is newer than "
                           f"this RealPen knows ({head_revision()}); use a newer RealPen")
    if revision != head_revision() and create:
        _alembic(connection, "upgrade", "head")
        return head_revision()
    return revision
