"""Administering a study: pilot sessions, withdrawals, abandoned sessions; in the store (SQLite
and PostgreSQL), the HTTP API, the command line and the export."""

from __future__ import annotations

import csv
import json
from datetime import UTC, datetime, timedelta

import pytest
from conftest import run_cli, store_rows
from live_support import study_answers
from sqlalchemy import insert

from realpen.errors import RealPenError
from realpen.study import admin
from realpen.study import sessions as study
from realpen.study import tables as t
from realpen.study.db import open_database
from realpen.study.design import load_design

CODE = "Zq-417"  # a participant ID found nowhere else in a store
CONSENT = {"consent": True}
STUDY1 = load_design("study1")


def start(client, participant, **fields):
    return client.post("/api/sessions", json={"design": "study1", "participant": participant,
                                              **CONSENT, **fields})


def answer_next(client, session: int) -> int:
    trial = client.get(f"/api/sessions/{session}/next").json()
    reply = client.post(f"/api/sessions/{session}/trials/{trial['trial']}",
                        json={"answers": study_answers(trial), "rt_ms": 12.5})
    assert reply.status_code == 201, reply.text
    return trial["trial"]


def test_a_pilot_uses_no_plan_row(client):
    pilots = [start(client, f"PILOT{i}", pilot=True).json() for i in (1, 2)]
    # A pilot runs the row the next participant gets, without taking it.
    assert [(p["index"], p["pilot"]) for p in pilots] == [(0, True), (0, True)]
    first = start(client, "P01").json()
    assert (first["index"], first["pilot"]) == (0, False)
    assert start(client, "PILOT3", pilot=True).json()["index"] == 1
    assert start(client, "P02").json()["index"] == 1
    # A pilot may run a row a participant holds; a participant may not.
    assert start(client, "PILOT4", pilot=True, index=0).status_code == 201
    assert start(client, "P03", index=0).status_code == 422
    listed = client.get("/api/sessions").json()["sessions"]
    assert {s["participant"]: s["pilot"] for s in listed}["PILOT4"] is True
    assert client.get(f"/api/sessions/{first['session']}").json()["pilot"] is False


def test_abandoned_sessions_keep_their_answers_and_cannot_be_resumed(client):
    session = start(client, "P01").json()["session"]
    answer_next(client, session)
    url = f"/api/sessions/{session}/state"
    ended = client.post(url, json={"state": "abandoned"})
    assert ended.status_code == 200 and ended.json()["state"] == "abandoned"
    assert ended.json()["answered"] == 1 and ended.json()["next"] is None
    assert client.get(f"/api/sessions/{session}/next").json() == \
        {"done": True, "session": session, "state": "abandoned"}
    for state in ("running", "paused", "finished"):
        refused = client.post(url, json={"state": state})
        assert refused.status_code == 409 and "abandoned" in refused.json()["detail"]
    late = client.post(f"/api/sessions/{session}/trials/2",
                       json={"answers": {"Q1": 1, "Q2": 1}, "rt_ms": 1.0})
    assert late.status_code == 409
    assert client.post(url, json={"state": "withdrawn"}).status_code == 422  # its own route


def test_withdrawal_through_the_api(client):
    session = start(client, CODE).json()["session"]
    answer_next(client, session)
    url = f"/api/sessions/{session}/withdraw"
    wrong = client.post(url, json={"confirm": "P01"})
    assert wrong.status_code == 422
    assert wrong.json()["detail"].startswith("confirm: type the participant's ID of session")
    assert client.post(url, json={}).status_code == 422
    done = client.post(url, json={"confirm": CODE})
    assert done.status_code == 200, done.text
    record = done.json()
    assert (record["state"], record["trials"], record["answered"]) == ("withdrawn", 0, 0)
    assert record["participant"] == admin.withdrawn_code(session)
    assert client.post(url, json={"confirm": CODE}).status_code == 409
    assert client.post("/api/sessions/999/withdraw", json={"confirm": CODE}).status_code == 404
    assert client.get(f"/api/sessions/{session}/next").json()["done"] is True
    # The row is free again, and the same ID would start a new session.
    again = start(client, CODE)
    assert again.status_code == 201 and again.json()["index"] == 0


def _stroke(target, session: int, trial: int) -> None:
    """A stroke with samples drawn in a study trial, as the live app stores it."""
    database = open_database(target, create=False, lock=False)
    try:
        with database.engine.begin() as conn:
            stroke = conn.execute(insert(t.strokes).values(
                session="conn", page=f"page-{session}", page_stroke=trial, pen="ballpoint",
                profile_version="abc", modality="tactile", ink="hidden", pointer_type="pen",
                px_per_mm=4.0, calibrated=1, page_t0=0.0,
                started_at="2026-11-28T10:00:00.000+00:00", sample_count=3,
                study_session=session, trial=trial).returning(t.strokes.c.id)).scalar_one()
            conn.execute(insert(t.samples), [
                {"stroke_id": stroke, "seq": i, "t": i * 0.004, "x": 1.0, "y": 2.0,
                 "pressure": 0.5, "tilt_x": 0.0, "tilt_y": 0.0, "speed": 10.0}
                for i in range(3)])
    finally:
        database.close()


def _rows_naming(target, session: int, code: str) -> dict[str, list]:
    """Every row of every table that holds the session's id in a column that refers to a
    session, or the participant's ID in any column."""
    found: dict[str, list] = {}
    for table in t.metadata.sorted_tables:
        for row in store_rows(target, f"SELECT * FROM {table.name}"):
            values = dict(zip(table.columns.keys(), row, strict=True))
            by_id = any(values.get(name) == session for name in ("session_id", "study_session"))
            by_code = any(isinstance(value, str) and code in value for value in values.values())
            if by_id or by_code:
                found.setdefault(table.name, []).append(values)
    return found


def test_a_withdrawal_leaves_no_data_of_the_participant(store_target):
    cache = study.DesignCache()
    request = study.SessionRequest(CODE, "Lab A", {"age": 31, "gender": "f",
                                                   "handedness": "left"}, True)
    other = study.SessionRequest("P02", consent=True)
    mine, _ = admin.on_store(store_target, study.open_session, STUDY1, request, cache,
                             create=True)
    theirs, _ = admin.on_store(store_target, study.open_session, STUDY1, other, cache)
    for session in (mine["session"], theirs["session"]):
        for n in (1, 2):
            admin.on_store(store_target, study.answer_trial, session, n, {"Q1": 3, "Q2": 4},
                           100.0, cache)
        _stroke(store_target, session, 1)
    session = mine["session"]
    assert set(_rows_naming(store_target, session, CODE)) == \
        {"participants", "trials", "answers", "strokes"}

    record = admin.on_store(store_target, admin.withdraw, session, f" {CODE} ", cache)

    assert record["state"] == "withdrawn" and record["trials"] == 0
    assert _rows_naming(store_target, session, CODE) == {}
    assert store_rows(store_target, f"SELECT state, withdrawn_at IS NOT NULL FROM sessions "
                                    f"WHERE id = {session}") == [("withdrawn", True)]
    assert store_rows(store_target, "SELECT p.code, p.age, p.gender, p.handedness, p.consent "
                                    "FROM participants p JOIN sessions s ON s.participant_id = "
                                    f"p.id WHERE s.id = {session}") == \
        [(admin.withdrawn_code(session), None, None, None, False)]
    # Only the withdrawn participant's samples went; the other participant keeps everything.
    assert store_rows(store_target, "SELECT COUNT(*) FROM samples") == [(3,)]
    assert store_rows(store_target, "SELECT COUNT(*) FROM answers WHERE session_id = "
                                    f"{theirs['session']}") == [(4,)]
    # The plan row goes to the next participant.
    nxt, _ = admin.on_store(store_target, study.open_session, STUDY1,
                            study.SessionRequest("P03", consent=True), cache)
    assert nxt["index"] == mine["index"] == 0


def test_stale_sessions_are_abandoned(store_target):
    target, cache = store_target, study.DesignCache()
    made = [admin.on_store(target, study.open_session, STUDY1,
                           study.SessionRequest(code, consent=True), cache, create=True)[0]
            for code in ("P01", "P02", "P03")]
    admin.on_store(target, study.set_state, made[2]["session"], "finished", cache)
    later = datetime.now(UTC) + timedelta(hours=3)
    assert admin.on_store(target, admin.abandon_stale, 5, cache, None, later) == []
    ended = admin.on_store(target, admin.abandon_stale, 2, cache, "study1", later)
    assert [(p["session"], p["state"]) for p in ended] == \
        [(made[0]["session"], "abandoned"), (made[1]["session"], "abandoned")]
    with pytest.raises(study.StudyInvalid):
        admin.on_store(target, admin.abandon_stale, 0, cache)


def _csv(path) -> list[dict]:
    with open(path, newline="", encoding="utf-8") as handle:
        return list(csv.DictReader(handle))


def test_the_command_line_and_the_export(tmp_path):
    store = tmp_path / "s.sqlite3"

    def cli(*args):
        result = run_cli("study", *args, "--store", store)
        assert result.returncode == 0, result.stderr
        return result.stdout

    assert "pilot): plan row 0" in cli("start", "study1", "-p", "PILOT1", "--pilot",
                                         "--consent")
    assert "(P01): plan row 0" in cli("start", "study1", "-p", "P01", "--consent")
    cli("start", "study1", "-p", CODE, "--consent")
    cli("start", "study1", "-p", "P03", "--consent")
    cache = study.DesignCache()
    for session in (1, 2, 3, 4):  # each answers its first trial
        admin.on_store(store, study.answer_trial, session, 1, {"Q1": 3, "Q2": 4}, 10.0, cache)
    refused = run_cli("study", "withdraw", "3", "--store", store)
    assert refused.returncode == 2 and "--confirm" in refused.stderr
    assert "plan row 1 is free" in cli("withdraw", CODE, "--study", "study1")
    assert "abandoned session 4" in cli("abandon", "P03", "--study", "study1")

    cli("export", "-o", tmp_path / "t.csv", "--sessions", tmp_path / "s.csv")
    trials, sessions = _csv(tmp_path / "t.csv"), _csv(tmp_path / "s.csv")
    assert {(r["participant"], r["session_state"]) for r in trials} == \
        {("P01", "running"), ("P03", "abandoned")}
    assert "pilot" not in trials[0] and "pilot" not in sessions[0]
    assert [(r["participant"], r["state"], r["answered"]) for r in sessions] == [
        ("P01", "running", "1"), ("P03", "abandoned", "1"), ("withdrawn-3", "withdrawn", "0")]
    assert sessions[2]["withdrawn_at"] and not sessions[1]["withdrawn_at"]

    cli("export", "-o", tmp_path / "all.csv", "--sessions", tmp_path / "all-s.csv",
        "--include-pilot")
    trials = _csv(tmp_path / "all.csv")
    assert {(r["participant"], r["pilot"]) for r in trials} == \
        {("P01", "0"), ("P03", "0"), ("PILOT1", "1")}
    assert list(trials[0])[-2:] == ["session_state", "pilot"]
    assert {r["participant"]: r["pilot"] for r in _csv(tmp_path / "all-s.csv")}["PILOT1"] == "1"
    sidecar = json.loads((tmp_path / "all.json").read_text(encoding="utf-8"))
    assert set(sidecar["pilot"]["Levels"]) == {"0", "1"}
    assert "abandoned" in sidecar["session_state"]["Levels"]
    assert json.loads((tmp_path / "s.json").read_text(encoding="utf-8"))["Rows"] == 3


def test_the_store_gives_a_plan_row_to_one_participant(store_target):
    """The partial unique index: one session per study and plan row among those that hold a
    row (not pilots, not withdrawn), even for a writer that skips the sessions' own check."""
    cache = study.DesignCache()
    first, _ = admin.on_store(store_target, study.open_session, STUDY1,
                              study.SessionRequest("P01", consent=True), cache, create=True)

    def another(conn, code, pilot=False):
        participant = conn.execute(insert(t.participants).values(
            study_id=1, code=code, created_at=study.now()).returning(t.participants.c.id)).scalar()
        conn.execute(insert(t.sessions).values(
            study_id=1, participant_id=participant, plan_index=0, seed=1,
            started_at=study.now(), pilot=pilot))

    admin.on_store(store_target, another, "PILOT", True)
    with pytest.raises(RealPenError, match="(?i)unique"):  # the store's error, in one line
        admin.on_store(store_target, another, "P02")
    admin.on_store(store_target, admin.withdraw, first["session"], "P01", cache)
    admin.on_store(store_target, another, "P02")
    assert store_rows(store_target, "SELECT COUNT(*) FROM sessions WHERE plan_index = 0") == [(3,)]
