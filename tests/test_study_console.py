"""What the operator console reads from the study API, in-process (FastAPI's TestClient on a
real SQLite store): each session's current trial, in the list without a query per session, and
the participant screen's address as a QR code with the LAN token."""

from __future__ import annotations

import io
import re
from pathlib import Path

import pytest
import segno
from sqlalchemy import event

from realpen.live.routes import qr
from realpen.live.routes.pages import STATIC_DIR
from realpen.study import sessions as study
from realpen.study.db import open_database
from realpen.study.design import load_design
from realpen.study.tables import ENDED_STATES, SESSION_STATES

TOKEN = "console-test-token-0123456789"
LAN_BASE = "http://10.0.0.2:8765"  # the address a tablet on the network reaches the server at
OWN_PEN = Path(__file__).parent / "data" / "designs" / "own_pen.yaml"  # pen ids ≠ profiles
PENS = {"own": ("pencil", "Pen A"), "bp": ("ballpoint", "Pen B")}  # id: (profile, label)
PLACE = ("block", "phase", "condition", "modality", "pen")


@pytest.fixture
def lan_client(tmp_path, monkeypatch):
    """The live app as ``realpen serve --lan`` runs it (a token on every request), with the
    own-pen design, reached at :data:`LAN_BASE`."""
    from fastapi.testclient import TestClient

    from realpen.live.app import LiveSettings, create_app

    monkeypatch.setenv("REALPEN_HOME", str(tmp_path / "home"))
    app = create_app(LiveSettings(store=tmp_path / "strokes.sqlite3", token=TOKEN,
                                  designs=[OWN_PEN]))
    with TestClient(app, base_url=LAN_BASE,
                    headers={"Authorization": f"Bearer {TOKEN}"}) as client:
        yield client


def start(client, design: str, participant: str) -> dict:
    reply = client.post("/api/sessions", json={"design": design, "participant": participant,
                                               "consent": True})
    assert reply.status_code == 201, reply.text
    return reply.json()


def assert_at_next_trial(client, session: dict) -> None:
    """The session's ``current`` is the trial the participant screen gets next."""
    upcoming = client.get(f"/api/sessions/{session['session']}/next").json()
    current = session["current"]
    assert (current["n"], current["of"]) == (upcoming["trial"], upcoming["total"])
    assert {key: current[key] for key in PLACE} == {key: upcoming[key] for key in PLACE}
    assert (current["profile"], current["pen_label"]) == PENS[current["pen"]]
    assert 1 <= current["block_n"] <= current["block_of"]


def test_a_session_shows_its_current_trial_until_it_ends(lan_client):
    session = start(lan_client, "own-pen", "P01")
    assert session["pilot"] is False and session["current"]["n"] == 1
    assert_at_next_trial(lan_client, session)
    id_ = session["session"]
    answered = lan_client.post(f"/api/sessions/{id_}/trials/1",
                               json={"answers": {"which": "own"}, "rt_ms": 1200.0})
    assert answered.status_code == 201, answered.text
    session = lan_client.get(f"/api/sessions/{id_}").json()
    assert session["current"]["n"] == 2
    assert_at_next_trial(lan_client, session)
    # The list says the same of every session as each one's own progress.
    other = start(lan_client, "study1", "P02")
    listed = {item["session"]: item for item in lan_client.get("/api/sessions").json()["sessions"]}
    assert listed[id_] == session and listed[other["session"]]["current"] == other["current"]
    assert other["current"]["condition_label"]  # study 1's conditions are labelled (A: "5 …")
    # Paused, it stays at its trial; ended, it has none.
    paused = lan_client.post(f"/api/sessions/{id_}/state", json={"state": "paused"}).json()
    assert paused["current"] == session["current"]
    ended = lan_client.post(f"/api/sessions/{id_}/state", json={"state": "abandoned"}).json()
    assert ended["state"] == "abandoned" and ended["current"] is None and ended["next"] is None


def test_the_session_list_reads_every_current_trial_in_two_queries(tmp_path):
    database = open_database(tmp_path / "store.sqlite3", create=True)
    try:
        cache = study.DesignCache()
        with database.engine.begin() as conn:
            for design, code in (("study1", "P01"), ("study2", "P02"), ("study2", "P03")):
                study.open_session(conn, load_design(design),
                                   study.SessionRequest(code, consent=True), cache)
        statements = []
        event.listen(database.engine, "before_cursor_execute",
                     lambda *args: statements.append(args[2]))
        with database.engine.connect() as conn:
            listed = study.list_sessions(conn, cache)
        assert len([sql for sql in statements if sql.startswith("SELECT")]) == 2, statements
        assert [item["current"]["n"] for item in listed] == [1, 1, 1]
        assert [item["current"]["block"] for item in listed] == ["auditory", "tactile", "A"]
    finally:
        database.close()


def segno_svg(url: str, session: int) -> bytes:
    """segno's own SVG of ``url``, as the QR route is documented to make it."""
    buffer = io.BytesIO()
    segno.make_qr(url, error=qr.ERROR_LEVEL).save(
        buffer, kind="svg", title=f"The participant screen of session {session}",
        **qr.SVG_OPTIONS)
    return buffer.getvalue()


def test_the_participant_qr_code_holds_the_address_with_the_token(lan_client):
    session = start(lan_client, "own-pen", "P01")["session"]
    reply = lan_client.get(f"/api/sessions/{session}/participant-qr.svg")
    assert reply.status_code == 200
    assert reply.headers["content-type"] == "image/svg+xml"
    assert "frame-ancestors 'none'" in reply.headers["content-security-policy"]
    assert reply.headers["x-content-type-options"] == "nosniff"
    assert reply.headers["cache-control"] == "no-store"  # it holds the token
    address = f"{LAN_BASE}/study/participant?session={session}&token={TOKEN}"
    assert reply.content == segno_svg(address, session)
    assert reply.content.startswith(b"<svg") and b"<script" not in reply.content
    # Like every route, it needs the token (it would otherwise hand it out).
    refused = lan_client.get(f"/api/sessions/{session}/participant-qr.svg",
                             headers={"Authorization": "Bearer wrong-token-0123456789"})
    assert refused.status_code == 401


def test_without_a_token_the_qr_code_holds_the_plain_address(client):
    assert client.get("/api/sessions/7/participant-qr.svg").status_code == 404  # no session 7
    session = client.post("/api/sessions", json={"design": "study1", "participant": "P01",
                                                 "consent": True}).json()["session"]
    reply = client.get(f"/api/sessions/{session}/participant-qr.svg")
    assert reply.status_code == 200
    assert reply.content == segno_svg(
        f"http://127.0.0.1/study/participant?session={session}", session)
    assert client.get("/api/sessions/7x/participant-qr.svg").status_code == 422


def test_the_console_knows_every_session_state():
    """operator.js names each state of the store, and treats the ended ones as ended."""
    script = (STATIC_DIR / "study" / "operator.js").read_text(encoding="utf-8")
    names = re.search(r"const STATE_TEXT = \{(.*?)\};", script, re.S).group(1)
    assert re.findall(r"(\w+): '", names) == list(SESSION_STATES)
    active = re.search(r"const ACTIVE = new Set\(\[(.*?)\]\)", script).group(1)
    assert re.findall(r"'(\w+)'", active) == [s for s in SESSION_STATES if s not in ENDED_STATES]
