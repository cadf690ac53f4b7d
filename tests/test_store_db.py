"""The store on SQLAlchemy + Alembic: opening and migrating on SQLite and on a real PostgreSQL
server, old SQLite stores upgraded in place, refusals in one line, and the writer's ``submit``."""

from __future__ import annotations

import signal
import sqlite3
import subprocess
import sys
import threading

import pytest
from conftest import assert_clean_failure, run_cli, store_rows
from live_support import CRASHER, LEGACY_V1, LEGACY_V2
from sqlalchemy import Float, create_engine, insert, make_url, select, text
from sqlalchemy.exc import DBAPIError, IntegrityError, OperationalError, ResourceClosedError
from sqlalchemy.pool import NullPool

from realpen.errors import ParameterError, RealPenError
from realpen.live.store import StrokeStore, export_csv
from realpen.study.db import SQLITE_USER_VERSION, head_revision, hide_password, open_database
from realpen.study.export import export_trials
from realpen.study.tables import metadata, studies

STROKE = dict(pen="pencil", profile_version="0" * 12, modality="none", ink="visible",
              pointer_type="pen", px_per_mm=4.0, calibrated=False)
TABLES = {"strokes", "samples", "studies", "participants", "sessions", "trials", "answers",
          "alembic_version"}


def _float_family(context, inspected, metadata_column, inspected_type, metadata_type):
    """SQLite's REAL and FLOAT are one storage class (8-byte IEEE), as are PostgreSQL's FLOAT
    and DOUBLE PRECISION; any other type difference is left to Alembic's comparison."""
    if isinstance(inspected_type, Float) and isinstance(metadata_type, Float):
        return False
    return None


def schema_differences(target) -> list:
    """Alembic's autogenerate comparison of :mod:`realpen.study.tables` with the database."""
    from alembic.autogenerate import compare_metadata
    from alembic.migration import MigrationContext

    database = open_database(target, create=False, lock=False)
    try:
        with database.engine.connect() as connection:
            context = MigrationContext.configure(connection, opts={"compare_type": _float_family})
            return compare_metadata(context, metadata)
    finally:
        database.close()


def one_line(error: BaseException) -> str:
    message = str(error)
    assert "\n" not in message and "Traceback" not in message, message
    return message


# ---- opening and migrating ------------------------------------------------------------------

def test_a_new_store_is_made_at_the_newest_revision(store_target):
    database = open_database(store_target, create=True)
    try:
        assert database.dialect == ("sqlite" if database.path else "postgresql")
        assert "secret" not in database.display
    finally:
        database.close()
    names = {row[0] for row in store_rows(store_target, (
        "SELECT name FROM sqlite_master WHERE type='table'" if database.path else
        "SELECT tablename FROM pg_tables WHERE schemaname='public'"))}
    assert TABLES <= names
    assert store_rows(store_target, "SELECT version_num FROM alembic_version") == \
        [(head_revision(),)] == [("0003",)]
    if database.path is not None:
        assert store_rows(store_target, "PRAGMA user_version") == [(SQLITE_USER_VERSION,)]
    again = open_database(store_target, create=False)  # current: opened without migrating
    again.close()


def test_the_migrations_make_exactly_the_tables_of_tables_py(store_target):
    open_database(store_target, create=True).close()
    assert schema_differences(store_target) == []


def test_strokes_carry_their_study_trial(store_target):
    from realpen.study.tables import participants, sessions

    def add_session(conn) -> int:
        study = add_study(conn, "study1")
        participant = conn.execute(insert(participants).values(
            study_id=study, code="P01", created_at="t")).inserted_primary_key[0]
        return conn.execute(insert(sessions).values(
            study_id=study, participant_id=participant, plan_index=0, seed=1,
            started_at="t")).inserted_primary_key[0]

    store = StrokeStore(store_target)
    try:
        session = store.submit(add_session).result(timeout=30)
        plain = store.begin_stroke(session="s", page_stroke=1, page_t0=0.0, **STROKE)
        study = store.begin_stroke(session="s", page_stroke=2, page_t0=0.0, study_session=session,
                                   trial=3, **STROKE)
        assert plain != study
        # A session that does not exist is refused before the insert, on both databases.
        with pytest.raises(ParameterError, match=f"study session {session + 1} is gone"):
            store.begin_stroke(session="s", page_stroke=3, page_t0=0.0, study_session=session + 1,
                               trial=1, **STROKE)
    finally:
        store.close()
    assert store_rows(store_target, "SELECT page_stroke, study_session, trial FROM strokes "
                                    "ORDER BY id") == [(1, None, None), (2, session, 3)]


@pytest.mark.parametrize("version", [1, 2])
def test_an_old_sqlite_store_is_upgraded_in_place_with_its_rows(tmp_path, version):
    path = tmp_path / "old.sqlite3"
    page = "" if version == 1 else ", 'abc'"
    with sqlite3.connect(path) as db:
        db.executescript(LEGACY_V1 if version == 1 else LEGACY_V2)
        for stroke_id in (1, 2):
            db.execute(f"INSERT INTO strokes VALUES ({stroke_id}, 'abc', {stroke_id}, 'pencil', "
                       f"'000000000000', 'none', 'visible', 'pen', 4.0, 0, 0.0, "
                       f"'2026-01-01T00:00:00.000+00:00', '2026-01-01T00:00:01.000+00:00', "
                       f"'pen_up', 2{page})")
            db.executemany("INSERT INTO samples VALUES (?, ?, ?, 1, 2, 0.5, 0, 0, 0)",
                           [(stroke_id, 0, 0.0), (stroke_id, 1, 0.01)])
    db.close()
    # Reading never changes a file: an export reads the old schema as it is; the study
    # export, which needs the study tables, says how to upgrade.
    assert export_csv(path, tmp_path / "old.csv") == (2, 4)
    with pytest.raises(RealPenError, match="start realpen serve on it once to upgrade it"):
        export_trials(path, tmp_path / "trials.csv")
    assert not (tmp_path / "trials.csv").exists()
    assert store_rows(path, "PRAGMA user_version") == [(version,)]
    reader = open_database(path, create=False)
    assert reader.revision is None
    reader.close()
    store = StrokeStore(path)
    try:
        assert store.count() == (2, 4)
        assert store.database.revision == "0003"
        # The old rows are found again by their page (version 1: the connection's session).
        assert store.begin_stroke(session="abc", page_stroke=2, page_t0=0.0, **STROKE) == 2
        assert store.begin_stroke(session="abc", page_stroke=3, page_t0=0.0, **STROKE) == 3
    finally:
        store.close()
    assert store_rows(path, "PRAGMA user_version") == [(3,)]
    assert store_rows(path, "SELECT version_num FROM alembic_version") == [("0003",)]
    assert store_rows(path, "SELECT id, page, sample_count, study_session, trial FROM strokes "
                            "ORDER BY id") == [(1, "abc", 2, None, None), (2, "abc", 2, None, None),
                                               (3, "abc", 0, None, None)]
    assert store_rows(path, "SELECT stroke_id, seq, t FROM samples ORDER BY stroke_id, seq") == \
        [(1, 0, 0.0), (1, 1, 0.01), (2, 0, 0.0), (2, 1, 0.01)]
    assert store_rows(path, "PRAGMA foreign_key_check") == []
    # Two differences from a new store stay, both without effect, since removing them would
    # copy the samples, the store's largest table: samples' foreign key has no name (and, from
    # version 1, no ON DELETE CASCADE: strokes are never deleted), and strokes.id is not
    # declared NOT NULL (an INTEGER PRIMARY KEY is SQLite's rowid, never NULL).
    differences = [d[0] if isinstance(d, tuple) else d[0][:4] for d in schema_differences(path)]
    assert differences == ["remove_fk", "add_fk",
                           ("modify_nullable", None, "strokes", "id")], differences


def test_an_older_realpen_would_refuse_the_migrated_store(tmp_path):
    # What the RealPen before Alembic checked: user_version above 2 is "newer than it reads".
    open_database(tmp_path / "s.sqlite3", create=True).close()
    assert store_rows(tmp_path / "s.sqlite3", "PRAGMA user_version")[0][0] > 2


def test_a_newer_schema_is_refused_in_one_line(store_target, tmp_path):
    open_database(store_target, create=True).close()
    engine = create_engine(store_target if isinstance(store_target, str) else
                           f"sqlite:///{store_target}", poolclass=NullPool)
    with engine.begin() as connection:
        connection.execute(text("UPDATE alembic_version SET version_num = '9999'"))
    engine.dispose()
    with pytest.raises(RealPenError, match="revision 9999.*newer than this RealPen knows") as caught:
        StrokeStore(store_target)
    assert one_line(caught.value).startswith(f"{hide_password(store_target)}: ")
    with pytest.raises(RealPenError, match="newer"):
        export_csv(store_target, tmp_path / "unused.csv")
    assert not (tmp_path / "unused.csv").exists()


def test_a_newer_sqlite_user_version_is_refused(tmp_path):
    path = tmp_path / "s.sqlite3"
    open_database(path, create=True).close()
    with sqlite3.connect(path) as db:
        db.execute("PRAGMA user_version = 4")
    db.close()
    with pytest.raises(RealPenError, match="version 4 is newer than this RealPen reads") as caught:
        StrokeStore(path)
    assert one_line(caught.value).startswith(f"{path}: ")


# ---- PostgreSQL refusals --------------------------------------------------------------------

def test_a_postgresql_database_of_another_app_is_refused(postgres_server, tmp_path):
    url = postgres_server.new_database("other_app")
    name = make_url(url).database
    postgres_server.execute("CREATE TABLE accounts (id integer PRIMARY KEY)", database=name)
    with pytest.raises(RealPenError, match="not a RealPen database") as caught:
        StrokeStore(url)
    assert one_line(caught.value) == f"{url}: not a RealPen database (it holds other tables: " \
                                     f"accounts)"
    assert postgres_server.execute("SELECT tablename FROM pg_tables WHERE schemaname='public'",
                                   database=name) == [("accounts",)]  # nothing was added
    empty = postgres_server.new_database("empty")
    with pytest.raises(RealPenError, match="not a RealPen database \\(it is empty\\)"):
        export_csv(empty, tmp_path / "unused.csv")


@pytest.mark.parametrize("url, words", [
    ("postgresql://ann:s3cr3t@/realpen?host=/nonexistent-realpen-socket", "cannot connect"),
    ("postgresql+psycopg2://ann:s3cr3t@localhost/realpen", "unsupported PostgreSQL driver"),
    ("mysql://ann:s3cr3t@localhost/realpen", "unsupported database 'mysql'"),
    ("postgresql://ann:s3cr3t@localhost:port/realpen", "not a database URL"),
    ("postgresql://ann:s3cr3t@localhost", "names no database"),
    ("sqlite://", "must be a file"),
])
def test_a_bad_or_unreachable_url_is_one_line_with_the_password_hidden(url, words, tmp_path):
    with pytest.raises(RealPenError, match=words) as caught:
        open_database(url, create=True)
    message = one_line(caught.value)
    assert "s3cr3t" not in message and ("ann:***@" in message or "ann" not in url), message
    result = run_cli("strokes", "export", "--store", url, "-o", tmp_path / "out.csv")
    assert_clean_failure(result, words)
    assert "s3cr3t" not in result.stderr
    assert not (tmp_path / "out.csv").exists()


def test_a_server_that_refuses_the_login_is_one_line(postgres_server):
    missing = postgres_server.url("no_such_database").replace("postgres@", "postgres:pw1234@")
    with pytest.raises(RealPenError, match="cannot connect to the database") as caught:
        StrokeStore(missing)
    message = one_line(caught.value)
    assert "pw1234" not in message and "no_such_database" in message


# ---- submit: durable results, one failing operation ------------------------------------------

def add_study(conn, name: str, version: str = "1") -> int:
    return conn.execute(insert(studies).values(name=name, version=version, design="{}",
                                               created_at="2026-01-01T00:00:00.000+00:00")
                         ).inserted_primary_key[0]


def test_a_submitted_result_arrives_after_its_commit(store_target):
    store = StrokeStore(store_target)
    seen = []
    try:
        future = store.submit(add_study, "study1")
        # Run by the writer as it resolves the future: another connection already sees the row.
        future.add_done_callback(lambda _: seen.append(store_rows(
            store_target, "SELECT name FROM studies")))
        study_id = future.result(timeout=30)
        assert isinstance(study_id, int)
        assert store.read(lambda conn: conn.execute(select(studies.c.name)).scalars().all()
                          ).result(timeout=30) == ["study1"]
    finally:
        store.close()
    assert seen == [[("study1",)]]


def test_one_failing_operation_does_not_fail_the_others_of_its_batch(store_target):
    store = StrokeStore(store_target)
    gate = threading.Event()
    try:
        started = threading.Event()
        held = store.submit(lambda conn: (started.set(), gate.wait(30)))
        assert started.wait(30)  # the writer is held: the next ones queue up, one batch
        futures = [store.submit(add_study, "a"),
                   store.submit(add_study, "a"),  # the same name and version: refused
                   store.submit(lambda conn: (add_study(conn, "b"), 1 / 0)),  # written, then fails
                   store.submit(add_study, "c"),
                   store.begin(session="s", page_stroke=1, page_t0=0.0, **STROKE)]
        gate.set()
        held.result(timeout=30)
        assert isinstance(futures[0].result(timeout=30), int)
        with pytest.raises(IntegrityError):
            futures[1].result(timeout=30)
        with pytest.raises(ZeroDivisionError):
            futures[2].result(timeout=30)
        assert isinstance(futures[3].result(timeout=30), int)
        assert futures[4].result(timeout=30) == 1
    finally:
        store.close()
    assert sorted(store_rows(store_target, "SELECT name FROM studies")) == [("a",), ("c",)]
    with pytest.raises(ResourceClosedError, match="closed"):
        store.submit(add_study, "d").result(timeout=5)


def test_an_error_an_operation_swallows_fails_its_whole_batch(store_target):
    """On PostgreSQL a caught statement error leaves the transaction aborted, and COMMIT would
    silently roll back what earlier operations were told was stored."""
    from sqlalchemy import text

    def swallow(conn):
        try:
            conn.execute(text("SELECT 1 / 0"))
        except DBAPIError:
            pass
        return "swallowed"

    store = StrokeStore(store_target)
    gate = threading.Event()
    try:
        started = threading.Event()
        held = store.submit(lambda conn: (started.set(), gate.wait(30)))
        assert started.wait(30)
        futures = [store.submit(add_study, "first"), store.submit(swallow),
                   store.submit(add_study, "third")]
        gate.set()
        held.result(timeout=30)
        outcomes = []
        for future in futures:
            try:
                outcomes.append(future.result(timeout=30))
            except Exception as error:  # noqa: BLE001 - what each got is the point
                outcomes.append(type(error).__name__)
        assert isinstance(store.submit(add_study, "after").result(timeout=30), int)
    finally:
        store.close()
    names = sorted(name for (name,) in store_rows(store_target, "SELECT name FROM studies"))
    if "://" in str(store_target):  # PostgreSQL: the aborted batch fails whole, nothing claimed
        assert outcomes[0] == outcomes[1] == outcomes[2] == "_BatchLost" and names == ["after"]
    else:  # SQLite's transaction survives a failed statement: all three are stored
        assert outcomes[1] == "swallowed" and names == ["after", "first", "third"]


def test_a_lost_postgresql_connection_fails_its_batch_and_the_next_reconnects(postgres_server):
    url = postgres_server.new_database()
    store = StrokeStore(url)
    started, first, second, backend = threading.Event(), threading.Event(), threading.Event(), []
    try:
        held = store.submit(lambda conn: (started.set(), first.wait(30)))
        assert started.wait(30)
        # Queued while the writer is held: these three are the next batch.
        doomed = [store.submit(lambda conn: (backend.append(conn.exec_driver_sql(
                      "SELECT pg_backend_pid()").scalar()), second.wait(30))),
                  store.submit(add_study, "lost"),
                  store.begin(session="s", page_stroke=1, page_t0=0.0, **STROKE)]
        first.set()
        held.result(timeout=30)
        for _ in range(300):
            if backend:
                break
            threading.Event().wait(0.1)
        assert postgres_server.execute(f"SELECT pg_terminate_backend({backend[0]})",
                                       database=make_url(url).database) == [(True,)]
        second.set()
        for future in doomed:
            with pytest.raises(OperationalError):
                future.result(timeout=30)
        assert store.begin_stroke(session="s", page_stroke=1, page_t0=0.0, **STROKE) > 0
        assert store.submit(add_study, "kept").result(timeout=30) > 0
        assert store.count() == (1, 0)
    finally:
        store.close()
    assert store_rows(url, "SELECT name FROM studies") == [("kept",)]


# ---- PostgreSQL: several servers, a crash ----------------------------------------------------


def test_postgresql_strokes_of_a_killed_server_are_closed_but_not_a_live_one(postgres_server):
    url = postgres_server.new_database()
    process = subprocess.Popen([sys.executable, "-c", CRASHER, url], text=True,
                               stdin=subprocess.PIPE, stdout=subprocess.PIPE)
    try:
        assert process.stdout.readline().strip() == "ready"
        other = StrokeStore(url)  # several servers share one database: no refusal
        assert other.recovered == 0  # the first one is alive: its stroke is its own
        other.close()
        assert store_rows(url, "SELECT end_reason FROM strokes") == [(None,)]
    finally:
        process.send_signal(signal.SIGKILL)
        process.wait(timeout=10)
    # The killed client's backend ends as soon as it sees the socket closed.
    for _ in range(100):
        if not postgres_server.execute("SELECT 1 FROM pg_locks WHERE locktype = 'advisory'"):
            break
        threading.Event().wait(0.1)
    store = StrokeStore(url)  # alone now: the killed server's stroke is ended
    try:
        assert store.recovered == 1 and store.count() == (1, 2)
    finally:
        store.close()
    ((started, ended, reason),) = store_rows(url, "SELECT started_at, ended_at, end_reason "
                                                  "FROM strokes")
    from datetime import datetime
    assert reason == "crash"
    lasted = datetime.fromisoformat(ended) - datetime.fromisoformat(started)
    assert lasted.total_seconds() == pytest.approx(1.5)


def test_discard_never_removes_a_postgresql_database(postgres_server):
    url = postgres_server.new_database()
    store = StrokeStore(url)
    assert store.path is None and store.dialect == "postgresql" and store.display == url
    store.discard()
    again = StrokeStore(url)
    assert again.count() == (0, 0)
    again.close()


def test_strokes_export_and_serve_take_a_postgresql_url(postgres_server, tmp_path):
    from live_support import serve

    url = postgres_server.new_database()
    with_password = url.replace("postgres@", "postgres:hunter2@")  # trust: the password is unused
    store = StrokeStore(with_password)
    sid = store.begin_stroke(session="s", page_stroke=1, page_t0=1.0, **STROKE)
    store.add_samples(sid, [(1.0 + k / 100, k, 0, 0.5, 0, 0, 0) for k in range(5)])
    store.close()
    out = tmp_path / "strokes.csv"
    result = run_cli("strokes", "export", "--store", with_password, "-o", out)
    assert result.returncode == 0, result.stderr
    assert "5 samples of 1 strokes" in result.stdout and "hunter2" not in result.stdout
    assert len(out.read_text().splitlines()) == 6
    with serve(tmp_path, "--store", with_password) as served:
        import httpx

        status = httpx.get(served.base + "api/status").json()
        assert status["strokes"] == 1 and status["samples"] == 5
        assert status["store"] == hide_password(with_password) and "hunter2" not in status["store"]
        printed = served.stop()
    assert f"store: {hide_password(with_password)}" in printed and "postgres:***@" in printed
    assert "stopped: the store holds 1 strokes, 5 samples" in printed and "hunter2" not in printed


def _migrate(target, direction: str, revision: str) -> None:
    from realpen.study.db import _alembic

    database = open_database(target, create=False)
    try:
        with database.engine.connect() as conn:
            conn.connection.driver_connection.execute("PRAGMA foreign_keys=OFF")
            with conn.begin():
                _alembic(conn, direction, revision)
    finally:
        database.close()


def test_revision_0003_goes_down_and_up_with_sessions_but_refuses_to_lose_pilots(tmp_path):
    from realpen.study import admin
    from realpen.study import sessions as study
    from realpen.study.design import load_design

    target, cache, design = tmp_path / "s.sqlite3", study.DesignCache(), load_design("study1")
    admin.on_store(target, study.open_session, design,
                   study.SessionRequest("P01", consent=True), cache, create=True)
    _migrate(target, "downgrade", "0002")
    assert store_rows(target, "SELECT version_num FROM alembic_version") == [("0002",)]
    _migrate(target, "upgrade", "0003")  # a store of 0002 with a session in it
    assert store_rows(target, "SELECT id, plan_index, pilot, withdrawn_at, state FROM sessions") \
        == [(1, 0, 0, None, "running")]
    admin.on_store(target, study.open_session, design,
                   study.SessionRequest("PILOT1", consent=True, pilot=True), cache)
    with pytest.raises(RuntimeError, match="holds 1 pilot session"):
        _migrate(target, "downgrade", "0002")
    assert store_rows(target, "SELECT version_num FROM alembic_version") == [("0003",)]
    assert store_rows(target, "SELECT COUNT(*) FROM sessions") == [(2,)]
