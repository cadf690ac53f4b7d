"""realpen.study.export: the trials CSV (one row per answer), its JSON sidecar, the strokes.

The stores are built here row by row with SQLAlchemy (:class:`StoreBuilder`), so every value the
export writes is known in advance.
"""

from __future__ import annotations

import contextlib
import csv
import json
from pathlib import Path

import pytest
from sqlalchemy import insert

from realpen.errors import RealPenError
from realpen.study import export as ex
from realpen.study import tables as t
from realpen.study.db import hide_password, open_database
from realpen.study.design import load_design

HEADER = ["study", "participant", "session", "block", "trial", "phase", "condition", "modality",
          "pen", "question", "answer", "correct", "rt_ms", "site", "started_at", "answered_at",
          "age", "gender", "handedness", "repetition", "ink", "design_version", "session_state"]

DESIGNS = {name: load_design(name) for name in ("study1", "study2")}


class StoreBuilder:
    """Rows of a study store, inserted one by one with SQLAlchemy Core."""

    def __init__(self, target):
        self.database = open_database(target, create=True)
        self.engine = self.database.engine

    def _insert(self, table, **values) -> int | None:
        with self.engine.begin() as connection:
            result = connection.execute(insert(table).values(**values))
            key = result.inserted_primary_key
            return key[0] if key else None

    def study(self, name: str) -> int:
        design = DESIGNS[name]
        return self._insert(t.studies, name=name, version=design.version, design=design.to_json(),
                            created_at="2026-11-23T09:00:00.000+00:00")

    def participant(self, study: int, code: str, site: str = "", **demographics) -> int:
        return self._insert(t.participants, study_id=study, code=code, site=site,
                            created_at="2026-11-23T09:00:00.000+00:00", **demographics)

    def session(self, study: int, participant: int, plan_index: int, site: str = "") -> int:
        return self._insert(t.sessions, study_id=study, participant_id=participant,
                            plan_index=plan_index, seed=7, site=site, state="running",
                            started_at="2026-11-23T10:00:00.000+00:00")

    def trial(self, session: int, n: int, *, block: str, phase: str, questions: list[str],
              condition: str = "", modality: str = "", pen: str = "", ink: str = "visible",
              repetition: int = 0, answered_at: str | None = None, rt_ms: float | None = None,
              answers: dict[str, tuple[str, bool | None]] | None = None) -> None:
        plan = {"n": n, "block": block, "phase": phase, "questions": questions, "task": "B"}
        self._insert(t.trials, session_id=session, n=n, block=block, block_index=0, phase=phase,
                     condition=condition, modality=modality, pen=pen, ink=ink,
                     repetition=repetition, plan=json.dumps(plan), answered_at=answered_at,
                     rt_ms=rt_ms)
        for question, (answer, correct) in (answers or {}).items():
            self._insert(t.answers, session_id=session, n=n, question=question, answer=answer,
                         correct=correct)

    def stroke(self, session: int | None, trial: int | None, page_stroke: int, samples: int,
               pen: str = "ballpoint", modality: str = "tactile") -> int:
        stroke = self._insert(
            t.strokes, session="conn", page=f"page{session}", page_stroke=page_stroke, pen=pen,
            profile_version="abc", modality=modality, ink="visible", pointer_type="pen",
            px_per_mm=4.0, calibrated=1, page_t0=0.0, started_at="2026-11-23T10:00:00.000+00:00",
            sample_count=samples, study_session=session, trial=trial)
        with self.engine.begin() as connection:
            connection.execute(insert(t.samples), [
                {"stroke_id": stroke, "seq": i, "t": i * 0.004, "x": 10.0 + i, "y": 20.5,
                 "pressure": 0.5, "tilt_x": 10.0, "tilt_y": -5.0, "speed": 48.25}
                for i in range(samples)])
        return stroke


def make_store(target) -> dict:
    """Two designs, three participants; answered, unanswered and questionnaire trials, strokes.

    Returns the ids by name.
    """
    b = StoreBuilder(target)
    s1 = b.study("study1")
    s2 = b.study("study2")
    # P02 is created first: the export still puts P01 first.
    p02 = b.participant(s1, "P02", site="Tokyo", age=31, gender="f", handedness="right")
    p01 = b.participant(s1, "P01", site="Tokyo", age=24, gender="m", handedness="left")
    q01 = b.participant(s2, "P01", site="Paris")
    ses_p02 = b.session(s1, p02, 0, site="Tokyo")
    ses_p01 = b.session(s1, p01, 1, site="Tokyo lab 2")
    ses_q01 = b.session(s2, q01, 0, site="")  # no session site: the participant's is used
    for session in (ses_p02, ses_p01):
        b.trial(session, 1, block="C", phase="experimental", condition="C", modality="tactile",
                pen="ballpoint", ink="hidden", questions=["Q1", "Q2"],
                answered_at="2026-11-23T10:11:12.345+00:00", rt_ms=1234.4,
                answers={"Q2": ("4", None), "Q1": ("3", None)})
        b.trial(session, 2, block="A", phase="experimental", condition="A", modality="tactile",
                pen="ballpoint", ink="hidden", questions=["Q1", "Q2"])  # not answered yet
    # Study 2: recognition trials, then a questionnaire whose plan order is not alphabetical.
    b.trial(ses_q01, 1, block="auditory", phase="training", condition="auditory",
            modality="auditory", pen="marker", questions=["pen"],
            answered_at="2026-11-23T10:00:01.000+00:00", rt_ms=999.99949,
            answers={"pen": ("marker", True)})
    b.trial(ses_q01, 2, block="auditory", phase="experimental", condition="auditory",
            modality="auditory", pen="pencil", repetition=1, questions=["pen"],
            answered_at="2026-11-23T10:00:03.000+00:00", rt_ms=2000.0,
            answers={"pen": ("ballpoint", False)})
    b.trial(ses_q01, 3, block="auditory", phase="questionnaire", condition="auditory",
            modality="auditory", pen="ballpoint", questions=["realism", "comfort"],
            answered_at="2026-11-23T10:01:00.000+00:00", rt_ms=0.0,
            answers={"comfort": ("5", None), "realism": ("2", None)})
    b.stroke(ses_q01, 2, 1, samples=3, pen="pencil", modality="auditory")
    b.stroke(ses_p01, 1, 1, samples=2)
    b.stroke(ses_p02, 1, 1, samples=1)
    b.stroke(None, None, 9, samples=4)  # drawn outside any study: never exported
    b.database.close()
    return {"study1": s1, "study2": s2, "ses_p01": ses_p01, "ses_p02": ses_p02,
            "ses_q01": ses_q01}


def read_csv(path: Path) -> list[list[str]]:
    with open(path, newline="", encoding="utf-8") as handle:
        return list(csv.reader(handle))


def outputs_in(folder: Path) -> list[str]:
    """The files in ``folder`` other than an SQLite store's (``s.sqlite3`` and its journals)."""
    return sorted(p.name for p in folder.iterdir() if not p.name.startswith("s.sqlite3"))


def sqlite_store(tmp_path) -> tuple[Path, dict]:
    path = tmp_path / "s.sqlite3"
    return path, make_store(path)


@pytest.fixture
def store(store_target) -> tuple[Path | str, dict]:
    """The test store on SQLite and on PostgreSQL (the test suite's own server)."""
    return store_target, make_store(store_target)


def test_trials_csv_header_order_and_values(store, tmp_path):
    target, ids = store
    out = tmp_path / "out" / "trials.csv"
    summary = ex.export_trials(target, out)
    rows = read_csv(out)
    assert rows[0] == HEADER
    assert rows[0][:13] == list(ex.KEY_COLUMNS)
    body = [dict(zip(HEADER, row)) for row in rows[1:]]
    key = [(r["study"], r["participant"], r["session"], r["trial"], r["question"]) for r in body]
    p01, p02, q01 = str(ids["ses_p01"]), str(ids["ses_p02"]), str(ids["ses_q01"])
    assert key == [
        ("study1", "P01", p01, "1", "Q1"), ("study1", "P01", p01, "1", "Q2"),
        ("study1", "P02", p02, "1", "Q1"), ("study1", "P02", p02, "1", "Q2"),
        ("study2", "P01", q01, "1", "pen"), ("study2", "P01", q01, "2", "pen"),
        # the plan's question order, not the alphabet's
        ("study2", "P01", q01, "3", "realism"), ("study2", "P01", q01, "3", "comfort"),
    ]
    assert body[0] == {
        "study": "study1", "participant": "P01", "session": p01, "block": "C", "trial": "1",
        "phase": "experimental", "condition": "C", "modality": "tactile", "pen": "ballpoint",
        "question": "Q1", "answer": "3", "correct": "", "rt_ms": "1234.400",
        "site": "Tokyo lab 2", "started_at": "2026-11-23T10:11:11.111+00:00",
        "answered_at": "2026-11-23T10:11:12.345+00:00", "age": "24", "gender": "m",
        "handedness": "left", "repetition": "0", "ink": "hidden",
        "design_version": DESIGNS["study1"].version, "session_state": "running"}
    assert [r["answer"] for r in body] == ["3", "4", "3", "4", "marker", "ballpoint", "2", "5"]
    assert [r["correct"] for r in body] == ["", "", "", "", "1", "0", "", ""]
    assert [r["rt_ms"] for r in body[4:]] == ["999.999", "2000.000", "0.000", "0.000"]
    assert body[4]["started_at"] == "2026-11-23T10:00:00.000+00:00"
    assert body[6]["started_at"] == body[6]["answered_at"] == "2026-11-23T10:01:00.000+00:00"
    assert body[4]["site"] == "Paris"  # the session has none: the participant's
    assert body[4]["age"] == body[4]["gender"] == ""
    assert body[5]["repetition"] == "1" and body[5]["phase"] == "experimental"
    assert summary.rows == 8 and summary.sessions == 3 and summary.participants == 3
    assert summary.strokes == summary.samples == 0
    assert summary.paths == (out, out.with_suffix(".json"))


def test_sidecar_describes_every_column(store, tmp_path):
    target, _ = store
    out = tmp_path / "trials.csv"
    ex.export_trials(target, out)
    sidecar = json.loads((tmp_path / "trials.json").read_text(encoding="utf-8"))
    for column in HEADER:
        assert sidecar[column]["Description"].strip(), column
    assert sidecar["rt_ms"]["Units"] == "ms" and sidecar["age"]["Units"] == "years"
    assert "answered_at minus rt_ms" in sidecar["started_at"]["Description"]
    assert set(sidecar["phase"]["Levels"]) == {"training", "experimental", "questionnaire"}
    # the designs' levels and the ones the trials use
    assert set(sidecar["modality"]["Levels"]) == {"tactile", "auditory", "audio-tactile"}
    assert set(sidecar["pen"]["Levels"]) == {"ballpoint", "marker", "pencil"}
    assert set(sidecar["condition"]["Levels"]) == {"A", "C", "auditory"}
    assert sidecar["condition"]["Levels"]["A"] == "5 frequencies, 15 sub-patterns of 100 ms"
    assert "auditory" in sidecar["condition"]["Levels"]["auditory"]
    assert set(sidecar["study"]["Levels"]) == {"study1", "study2"}
    questions = sidecar["question"]["Levels"]
    assert set(questions) == {"Q1", "Q2", "comments", "pen", "realism", "comfort", "strength",
                              "balance"}
    assert questions["Q1"] == ("Does it feel like writing with a real pen (i.e. ballpoint pen)? "
                               "(5-point: 1 = not at all … 5 = very much)")
    assert questions["pen"] == "Which pen was it? (one of pencil, ballpoint, marker)"
    assert "3 = just right" in questions["strength"]
    assert questions["comments"].endswith("(free text)")
    details = sidecar["question"]["Questions"]
    assert details["study1"]["Q2"]["Anchors"] == {"1": "not at all", "5": "very much"}
    assert details["study1"]["Q2"]["Points"] == 5
    assert details["study2"]["pen"]["Correct"] == "pen"
    assert sidecar["correct"]["Levels"] == {"1": "right", "0": "wrong"}
    assert set(sidecar["ink"]["Levels"]) == {"visible", "hidden"}
    from realpen import __version__
    assert sidecar["GeneratedBy"][0]["Name"] == "RealPen"
    assert sidecar["GeneratedBy"][0]["Version"] == __version__
    assert sidecar["Store"] == hide_password(target)
    assert sidecar["Rows"] == 8
    assert sidecar["Designs"] == [{"Name": name, "Version": DESIGNS[name].version}
                                  for name in ("study1", "study2")]
    assert sidecar["ExportedAt"].endswith("+00:00")


def test_strokes_file_and_sidecar(store, tmp_path):
    target, ids = store
    out, strokes = tmp_path / "trials.csv", tmp_path / "samples.csv"
    summary = ex.export_trials(target, out, strokes=strokes)
    rows = read_csv(strokes)
    assert rows[0] == ["session", "trial", "stroke", "sample", "pen", "modality", "t", "x", "y",
                       "pressure", "tilt_x", "tilt_y", "speed"]
    sessions = sorted([ids["ses_p02"], ids["ses_p01"], ids["ses_q01"]])
    counts = {ids["ses_p02"]: 1, ids["ses_p01"]: 2, ids["ses_q01"]: 3}
    assert [int(row[0]) for row in rows[1:]] == [s for s in sessions for _ in range(counts[s])]
    q01 = [row for row in rows[1:] if row[0] == str(ids["ses_q01"])]
    assert [row[1] for row in q01] == ["2", "2", "2"] and [row[3] for row in q01] == ["0", "1", "2"]
    assert q01[1][4:6] == ["pencil", "auditory"]
    assert [float(v) for v in q01[1][6:]] == pytest.approx([0.004, 11.0, 20.5, 0.5, 10.0, -5.0,
                                                             48.25])
    assert summary.strokes == 3 and summary.samples == 6
    assert summary.paths == (out, tmp_path / "trials.json", strokes, tmp_path / "samples.json")
    sidecar = json.loads((tmp_path / "samples.json").read_text(encoding="utf-8"))
    for column in rows[0]:
        assert sidecar[column]["Description"].strip(), column
    assert sidecar["t"]["Units"] == "s" and sidecar["x"]["Units"] == "mm"
    assert sidecar["speed"]["Units"] == "mm/s" and sidecar["tilt_x"]["Units"] == "degrees"
    assert sidecar["Rows"] == 6 and sidecar["Strokes"] == 3


def test_design_filter(store, tmp_path):
    target, ids = store
    out, strokes = tmp_path / "s2.csv", tmp_path / "s2-strokes.csv"
    summary = ex.export_trials(target, out, design="study2", strokes=strokes)
    rows = read_csv(out)[1:]
    assert {row[0] for row in rows} == {"study2"} and len(rows) == 4
    assert {row[0] for row in read_csv(strokes)[1:]} == {str(ids["ses_q01"])}
    assert (summary.rows, summary.sessions, summary.participants, summary.samples) == (4, 1, 1, 3)
    sidecar = json.loads(out.with_suffix(".json").read_text(encoding="utf-8"))
    assert sidecar["Designs"] == [{"Name": "study2", "Version": DESIGNS["study2"].version}]
    assert set(sidecar["question"]["Levels"]) == {"pen", "realism", "comfort", "strength",
                                                  "balance"}
    assert set(sidecar["condition"]["Levels"]) == {"auditory"}


def assert_one_line(error: pytest.ExceptionInfo, *names: str) -> None:
    message = str(error.value)
    assert "\n" not in message, message
    for name in names:
        assert name in message, message


def test_unknown_design_is_one_line(store, tmp_path):
    target, _ = store
    with pytest.raises(RealPenError) as error:
        ex.export_trials(target, tmp_path / "trials.csv", design="study9")
    assert_one_line(error, hide_password(target), "study9", "study1, study2")
    assert outputs_in(tmp_path) == []


def test_password_is_hidden(postgres_server, tmp_path):
    url = postgres_server.new_database()
    make_store(url)
    # The test server trusts its socket: any password connects, and none may be shown.
    with_password = url.replace("postgres@", "postgres:s3cret@")
    ex.export_trials(with_password, tmp_path / "trials.csv")
    sidecar = (tmp_path / "trials.json").read_text(encoding="utf-8")
    assert "s3cret" not in sidecar and "postgres:***@" in sidecar
    with pytest.raises(RealPenError) as error:
        ex.export_trials(with_password, tmp_path / "trials.csv", design="nope")
    assert "s3cret" not in str(error.value) and "***" in str(error.value)


def test_real_sessions_export(store_target, tmp_path):
    """Sessions made and answered by the session service itself (its plans, its answers)."""
    from realpen.study import sessions

    database = open_database(store_target, create=True)
    cache = sessions.DesignCache()
    design = DESIGNS["study2"]
    try:
        with database.engine.begin() as conn:
            progress, _ = sessions.open_session(conn, design, sessions.SessionRequest(
                "P03", site="Lab A", demographics={"age": 40}, consent=True), cache)
        session = progress["session"]
        given = []
        for _ in range(4):
            with database.engine.begin() as conn:
                trial = sessions.next_trial(conn, session, cache)
                answer = "marker" if trial["trial"] % 2 else trial["pen"]
                sessions.answer_trial(conn, session, trial["trial"], {"pen": answer},
                                      100.0 * trial["trial"], cache)
                given.append((trial, answer))
    finally:
        database.close()
    summary = ex.export_trials(store_target, tmp_path / "trials.csv")
    body = [dict(zip(HEADER, row)) for row in read_csv(tmp_path / "trials.csv")[1:]]
    assert summary.rows == 4 == len(body)
    for row, (trial, answer) in zip(body, given):
        assert (row["study"], row["participant"], row["session"], row["site"], row["age"]) == \
            ("study2", "P03", str(session), "Lab A", "40")
        assert row["trial"] == str(trial["trial"]) and row["question"] == "pen"
        assert (row["block"], row["phase"], row["modality"], row["pen"]) == \
            (trial["block"], trial["phase"], trial["modality"], trial["pen"])
        assert row["answer"] == answer
        assert row["correct"] == ("1" if answer == trial["pen"] else "0")
        assert row["rt_ms"] == f"{100.0 * trial['trial']:.3f}"


def test_missing_store_is_one_line(tmp_path):
    missing = tmp_path / "none.sqlite3"
    with pytest.raises(RealPenError) as error:
        ex.export_trials(missing, tmp_path / "trials.csv")
    assert_one_line(error, str(missing))
    assert list(tmp_path.iterdir()) == []  # neither a store nor an output was made


def test_not_a_study_store_is_one_line(tmp_path):
    import sqlite3

    other = tmp_path / "other.sqlite3"
    with contextlib.closing(sqlite3.connect(other)) as connection:
        connection.execute("CREATE TABLE something (x)")
    with pytest.raises(RealPenError) as error:
        ex.export_trials(other, tmp_path / "trials.csv")
    assert_one_line(error, str(other))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["other.sqlite3"]


@pytest.mark.parametrize("suffix", ["", "-wal", "-journal"])
def test_output_that_is_the_store_is_refused(tmp_path, suffix):
    path, _ = sqlite_store(tmp_path)
    part = Path(f"{path}{suffix}")
    before = path.read_bytes()
    with pytest.raises(RealPenError) as error:
        ex.export_trials(path, tmp_path / "trials.csv", strokes=part)
    assert_one_line(error, str(part))
    with pytest.raises(RealPenError) as error:
        ex.export_trials(path, part)
    assert_one_line(error, str(part))
    with pytest.raises(RealPenError):  # through another path to the same file
        ex.export_trials(f"sqlite:///{path}", tmp_path / "sub" / ".." / path.name)
    assert path.read_bytes() == before
    assert outputs_in(tmp_path) == []


def test_outputs_that_collide_are_refused(tmp_path):
    path, _ = sqlite_store(tmp_path)
    with pytest.raises(RealPenError) as error:  # the CSV and its sidecar would be one file
        ex.export_trials(path, tmp_path / "trials.json")
    assert_one_line(error, "trials.json")
    with pytest.raises(RealPenError) as error:  # the strokes' sidecar is the trials' sidecar
        ex.export_trials(path, tmp_path / "a.csv", strokes=tmp_path / "a.tsv")
    assert_one_line(error, "a.json")
    assert outputs_in(tmp_path) == []


def test_empty_store_writes_the_header(store_target, tmp_path):
    open_database(store_target, create=True).close()
    summary = ex.export_trials(store_target, tmp_path / "trials.csv",
                               strokes=tmp_path / "strokes.csv")
    assert read_csv(tmp_path / "trials.csv") == [HEADER]
    assert read_csv(tmp_path / "strokes.csv") == [list(ex.STROKE_COLUMNS)]
    assert (summary.rows, summary.sessions, summary.participants, summary.strokes,
            summary.samples) == (0, 0, 0, 0, 0)
    sidecar = json.loads((tmp_path / "trials.json").read_text(encoding="utf-8"))
    assert sidecar["Rows"] == 0 and sidecar["Designs"] == []
    assert all(sidecar[column]["Description"] for column in HEADER)


def test_failure_midway_leaves_no_file(tmp_path, monkeypatch):
    path, _ = sqlite_store(tmp_path)
    out = tmp_path / "trials.csv"
    out.write_text("the previous export\n", encoding="utf-8")
    calls = []

    def broken(row, *rest):  # the disk fills up after a few rows
        calls.append(row)
        if len(calls) > 3:
            raise OSError(28, "No space left on device")
        return original(row, *rest)

    original = ex._csv_row
    monkeypatch.setattr(ex, "_csv_row", broken)
    with pytest.raises(RealPenError) as error:
        ex.export_trials(path, out, strokes=tmp_path / "strokes.csv")
    assert_one_line(error, f"{out}: cannot write (No space left on device)")
    assert len(calls) == 4
    assert out.read_text(encoding="utf-8") == "the previous export\n"
    assert outputs_in(tmp_path) == ["trials.csv"]  # no staged file left either


def test_failure_in_the_strokes_leaves_no_file(tmp_path, monkeypatch):
    path, _ = sqlite_store(tmp_path)

    def broken(connection, study_ids, *rest):
        yield (1, 1, 1, 0, "pencil", "tactile", 0.0, 0.0, 0.0, 0.5, 0.0, 0.0, 0.0)
        raise OSError(5, "Input/output error")

    monkeypatch.setattr(ex, "_sample_rows", broken)
    with pytest.raises(RealPenError) as error:
        ex.export_trials(path, tmp_path / "trials.csv", strokes=tmp_path / "strokes.csv")
    assert_one_line(error, "strokes.csv: cannot write (Input/output error)")
    assert outputs_in(tmp_path) == []  # the trials CSV, written first, is not kept either


def test_export_reads_while_a_server_writes(tmp_path):
    """A server holding the store (its lock, an open write transaction on the WAL journal)
    does not stop the export, which sees only what was committed."""
    path, ids = sqlite_store(tmp_path)
    server = open_database(path, create=True)  # the writer's lock, as `realpen serve` takes it
    try:
        with server.engine.connect() as connection, connection.begin():
            connection.exec_driver_sql(
                "UPDATE trials SET answered_at='2026-11-23T11:00:00.000+00:00', rt_ms=1.0 "
                f"WHERE session_id={ids['ses_p01']} AND n=2")
            connection.exec_driver_sql(
                f"INSERT INTO answers VALUES ({ids['ses_p01']}, 2, 'Q1', '5', NULL)")
            summary = ex.export_trials(path, tmp_path / "trials.csv")
            assert summary.rows == 8  # the uncommitted answer is not there
        assert ex.export_trials(path, tmp_path / "again.csv").rows == 9
    finally:
        server.close()


def test_one_snapshot_for_all_files(store, tmp_path, monkeypatch):
    """What a server commits while the export runs is in none of its files: the answers and
    the strokes are read from one snapshot."""
    target, ids = store
    original = ex._answer_rows

    def then_a_server_writes(connection, study_ids, *rest):
        rows = original(connection, study_ids, *rest)
        writer = StoreBuilder(target)
        try:
            writer.stroke(ids["ses_p01"], 2, 2, samples=5)
        finally:
            writer.database.close()
        return rows

    monkeypatch.setattr(ex, "_answer_rows", then_a_server_writes)
    summary = ex.export_trials(target, tmp_path / "trials.csv", strokes=tmp_path / "strokes.csv")
    assert (summary.strokes, summary.samples) == (3, 6)
    monkeypatch.setattr(ex, "_answer_rows", original)
    assert ex.export_trials(target, tmp_path / "again.csv",
                            strokes=tmp_path / "again-strokes.csv").samples == 11
