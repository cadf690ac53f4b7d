"""Designs as researchers write them, run through the study API in-process; and the one name of
the audio-tactile modality.

The two variant designs (tests/data/designs): ``own-pen`` (pen ids that differ from the profiles
they play, labelled for the participant, varied within a block with a recognition and a Likert
question) and ``pen-per-condition`` (each condition fixes one pen; unlabelled). The live page
loads each trial's pen by its profile; answers, trials and the export keep the pen's id.
"""

from __future__ import annotations

import csv
import sqlite3
from pathlib import Path

import pytest
from live_support import WS, stroke_messages, study_answers, talk

DESIGNS = Path(__file__).resolve().parent / "data" / "designs"
OWN_PEN = DESIGNS / "own_pen.yaml"
PEN_PER_CONDITION = DESIGNS / "pen_per_condition.yaml"
PROFILE_OF = {"own": "pencil", "bp": "ballpoint"}  # both designs' pens and their profiles


@pytest.fixture
def variants(tmp_path, store_path, monkeypatch):
    """The live app in-process offering both variant designs."""
    from fastapi.testclient import TestClient

    from realpen.live.app import LiveSettings, create_app

    monkeypatch.setenv("REALPEN_HOME", str(tmp_path / "home"))
    app = create_app(LiveSettings.loopback(store=store_path,
                                           designs=[OWN_PEN, PEN_PER_CONDITION]))
    with TestClient(app, base_url="http://127.0.0.1") as client:
        yield client


def start(client, design: str, participant: str = "P01") -> int:
    reply = client.post("/api/sessions", json={"design": design, "participant": participant})
    assert reply.status_code == 201, reply.text
    return reply.json()["session"]


def run_to_the_end(client, session: int, answer=study_answers) -> list[dict]:
    """Answer every trial as the page would; the trials as ``…/next`` gave them."""
    seen = []
    while not (trial := client.get(f"/api/sessions/{session}/next").json()).get("done"):
        seen.append(trial)
        reply = client.post(f"/api/sessions/{session}/trials/{trial['trial']}",
                            json={"answers": answer(trial), "rt_ms": 900.0})
        assert reply.status_code == 201, reply.text
        trial["reply"] = reply.json()
    assert client.get(f"/api/sessions/{session}").json()["state"] == "finished"
    return seen


def store_rows(path, sql: str, *args) -> list[tuple]:
    with sqlite3.connect(path) as db:
        return db.execute(sql, args).fetchall()


def profile_version(client, name: str) -> str:
    return next(p["version"] for p in client.get("/api/profiles").json()["profiles"]
                if p["name"] == name)


def test_pens_with_their_own_ids_play_their_profiles_and_answers_keep_the_ids(
        variants, store_path, tmp_path):
    session = start(variants, "own-pen")
    first = variants.get(f"/api/sessions/{session}/next").json()
    # What the page loads (the profile) and what it may show (the label) beside the pen's id.
    assert (first["pen"], first["profile"], first["pen_label"]) == ("own", "pencil", "Pen A")
    assert first["modality"] == first["live_modality"] == "audio-tactile"
    (which,) = first["questions"]
    assert which["choices"] == ["own", "bp"] and which["labels"] == ["Pen A", "Pen B"]
    # The trial's tactile pattern is the profile's own (the design sets no condition pattern).
    wav = variants.get(first["tactile_url"])
    assert wav.status_code == 200
    assert wav.content == variants.get("/api/profiles/pencil/tactile.wav").content
    # A stroke of the trial is sent as the page sends it: the profile's name and version.
    with variants.websocket_connect(WS) as ws:
        for message in stroke_messages("pencil", n=4):
            if message["type"] == "pen_down":
                assert message["profile_version"] == profile_version(variants, "pencil")
                message.update(study_session=session, trial=first["trial"])
            assert talk(ws, message)["type"] == "ack"

    trials = run_to_the_end(variants, session, lambda trial: {
        question["id"]: trial["pen"] if question["type"] == "choice" else 4
        for question in trial["questions"]})
    assert [(t["pen"], t["profile"], t["pen_label"]) for t in trials] == [
        (pen, PROFILE_OF[pen], {"own": "Pen A", "bp": "Pen B"}[pen])
        for pen in ("own", "bp", "own", "bp")]
    assert [t["reply"].get("feedback") for t in trials[:2]] == [
        {"which": {"correct": True, "answer": pen}} for pen in ("own", "bp")]
    assert [[q["id"] for q in t["questions"]] for t in trials[2:]] == [["which", "realism"]] * 2
    assert set(store_rows(store_path, "SELECT pen FROM trials")) == {("own",), ("bp",)}
    assert store_rows(store_path, "SELECT DISTINCT answer FROM answers WHERE question = 'which' "
                                  "ORDER BY answer") == [("bp",), ("own",)]
    assert store_rows(store_path, "SELECT pen, modality, trial FROM strokes") == [
        ("pencil", "audio-tactile", 1)]

    from realpen.study.export import export_trials

    export_trials(store_path, tmp_path / "trials.csv", design="own-pen")
    with open(tmp_path / "trials.csv", newline="", encoding="utf-8") as handle:
        exported = list(csv.DictReader(handle))
    assert {row["pen"] for row in exported} == {"own", "bp"}
    assert all(row["correct"] == "1" for row in exported if row["question"] == "which")


def test_conditions_that_fix_a_pen_run_to_the_end(variants, store_path):
    session = start(variants, "pen-per-condition")
    trials = run_to_the_end(variants, session)
    assert sorted((t["condition"], t["pen"], t["profile"]) for t in trials) == [
        ("own", "own", "pencil"), ("ref", "bp", "ballpoint")]
    # Unlabelled pens: nothing the participant may be shown names them.
    assert {t["pen_label"] for t in trials} == {""}
    for trial in trials:
        assert variants.get(trial["tactile_url"]).status_code == 200
    assert sorted(store_rows(store_path, "SELECT condition, pen FROM trials")) == [
        ("own", "own"), ("ref", "bp")]


def test_the_built_in_designs_label_no_pen():
    """Study 2's choices are its pen ids, shown as written (the page's "It was the pencil.")."""
    from realpen.study.design import load_design
    from realpen.study.sessions import _question_json, pen_label, pen_profile

    study2 = load_design("study2")
    assert _question_json(study2, "pen")["labels"] == ["pencil", "ballpoint", "marker"]
    assert (pen_profile(study2, "marker"), pen_label(study2, "marker")) == ("marker", "")
    assert (pen_profile(study2, ""), pen_label(study2, "")) == ("", "")


# ---- one name: audio-tactile (the old auditory-tactile still read) -----------------------------

def test_the_old_modality_name_is_read_as_today_s(client, store_path):
    from realpen.defaults import modality_name

    assert modality_name("auditory-tactile") == "audio-tactile"
    assert modality_name("auditory") == "auditory" and modality_name("x") == "x"
    assert client.get("/api/config").json()["modalities"] == ["tactile", "auditory",
                                                              "audio-tactile", "none"]
    with client.websocket_connect(WS) as ws:
        for modality, stroke in (("auditory-tactile", 1), ("audio-tactile", 2)):
            for message in stroke_messages("pencil", stroke=stroke, n=3, seq0=10 * stroke,
                                           modality=modality):
                assert talk(ws, message)["type"] == "ack"
        refused = talk(ws, stroke_messages("pencil", stroke=3, seq0=40, modality="tactile-ish")[0])
    assert refused["type"] == "error" and "'audio-tactile'" in refused["message"]
    assert "auditory-tactile" not in refused["message"]  # the refusal lists today's names
    assert store_rows(store_path, "SELECT modality FROM strokes ORDER BY id") == [
        ("audio-tactile",), ("audio-tactile",)]


def test_the_strokes_export_names_the_page_and_today_s_modality(client, store_path, tmp_path):
    """Its ``page`` column (once ``session``) is the page's own id; rows an earlier release
    stored (the old modality name, no page id) are written as today's."""
    from realpen.live.store import CSV_COLUMNS, export_csv

    assert CSV_COLUMNS[:3] == ("stroke", "page", "page_stroke") and "session" not in CSV_COLUMNS
    with client.websocket_connect(WS) as ws:
        talk(ws, {"type": "hello", "seq": 0, "client": "test", "page": "page-0001"})
        for message in stroke_messages("pencil", n=3):
            talk(ws, message)
    with sqlite3.connect(store_path) as db:  # as an earlier release left it
        db.execute("UPDATE strokes SET modality = 'auditory-tactile'")
        db.execute("INSERT INTO strokes (session, page_stroke, pen, profile_version, modality, "
                   "ink, pointer_type, px_per_mm, calibrated, page_t0, started_at) SELECT "
                   "'conn-0002', 1, pen, profile_version, modality, ink, pointer_type, px_per_mm, "
                   "calibrated, page_t0, started_at FROM strokes")
        db.execute("INSERT INTO samples SELECT 2, seq, t, x, y, pressure, tilt_x, tilt_y, speed "
                   "FROM samples WHERE stroke_id = 1")
    assert export_csv(store_path, tmp_path / "strokes.csv") == (2, 6)
    with open(tmp_path / "strokes.csv", newline="", encoding="utf-8") as handle:
        table = list(csv.DictReader(handle))
    assert tuple(table[0]) == CSV_COLUMNS
    assert {(row["stroke"], row["page"], row["modality"]) for row in table} == {
        ("1", "page-0001", "audio-tactile"), ("2", "conn-0002", "audio-tactile")}


@pytest.mark.parametrize("design, path, analysis", [
    ("own-pen", OWN_PEN, "wilcoxon/pen"),
    ("pen-per-condition", PEN_PER_CONDITION, "wilcoxon/condition")])
def test_each_variant_run_by_participants_exports_and_analyses(variants, store_path, tmp_path,
                                                              design, path, analysis):
    from conftest import run_cli

    from realpen.study.export import export_trials

    for index in range(6):
        session = start(variants, design, f"P{index + 1:02d}")

        def answer(trial, index=index):
            own = trial["pen"] == "own"
            return {question["id"]: (trial["pen"] if (index + trial["trial"]) % 3 else "bp")
                    if question["type"] == "choice" else 1 + (index + 2 * own) % 5
                    for question in trial["questions"]}

        run_to_the_end(variants, session, answer)
    export_trials(store_path, tmp_path / "trials.csv", design=design)
    out = tmp_path / "report"
    result = run_cli("stats", str(path), str(tmp_path / "trials.csv"), "-o", str(out),
                     "--power-sims", "0", "--likert-ci", "t")
    assert result.returncode == 0, result.stderr
    with open(out / "results.csv", newline="", encoding="utf-8") as handle:
        rows = list(csv.DictReader(handle))
    tested = {(row["analysis"], row["outcome"]) for row in rows}
    assert (analysis, "realism") in tested
    assert all(row["apa"] for row in rows if row["statistic"])  # every test that gave a number
    # every trial took 900 ms: the mixed model of log RT has nothing to fit, and says so
    assert all(not row["statistic"] and "no test" in row["method"]
               for row in rows if row["analysis"].startswith("mixedlm/"))
    html = (out / "report.html").read_text()
    assert "Factors, from the cells the design plans" in html
    if design == "pen-per-condition":
        assert "pen nested in condition" in html
    else:  # recognition of the labelled pens, against chance (1/2)
        assert any(row["analysis"].startswith("chance/") for row in rows)
