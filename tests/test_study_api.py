"""The study HTTP API, in-process (FastAPI's TestClient on a real SQLite store)."""

from __future__ import annotations

import io
import sqlite3
import sys
from pathlib import Path

import numpy as np
import pytest
import soundfile
from live_support import WS, running_server, study_answers, talk

CONSENT = {"consent": True}


def start(client, design="study1", participant="P01", **fields):
    return client.post("/api/sessions", json={"design": design, "participant": participant,
                                              **CONSENT, **fields})


def count(path, sql: str, *args):
    with sqlite3.connect(path) as db:
        return db.execute(sql, args).fetchone()[0]


def test_designs_are_offered(client):
    designs = client.get("/api/studies").json()["designs"]
    names = [design["name"] for design in designs]
    assert {"study1", "study2"} <= set(names)
    study1 = next(design for design in designs if design["name"] == "study1")
    assert study1["participants"] == 12 and len(study1["version"]) == 64
    assert client.get("/api/studies/study1").json()["name"] == "study1"
    assert client.get("/api/studies/nope").status_code == 404


def test_a_session_resumes_by_design_and_participant(client):
    first = start(client, site="Lab A", demographics={"age": 31, "handedness": "left"})
    assert first.status_code == 201, first.text
    body = first.json()
    assert body["participant"] == "P01" and body["index"] == 0 and body["next"] == 1
    assert body["trials"] == 7 and len(body["blocks"]) == 7  # A-F, then the comments
    again = start(client, site="elsewhere")
    assert again.status_code == 200 and again.json()["session"] == body["session"]
    other = start(client, participant="P02")
    assert other.status_code == 201 and other.json()["index"] == 1
    listed = client.get("/api/sessions").json()["sessions"]
    assert [item["participant"] for item in listed] == ["P02", "P01"]


def test_session_requests_are_checked(client):
    refused = client.post("/api/sessions", json={"design": "study1", "participant": "P09"})
    assert refused.status_code == 422 and refused.json()["detail"].startswith("consent")
    unknown = start(client, design="study9")
    assert unknown.status_code == 422 and "study9" in unknown.json()["detail"]
    assert start(client, participant="   ").status_code == 422
    assert start(client, demographics={"age": -3}).json()["detail"].startswith("demographics.age")
    bad = client.post("/api/sessions", json={"design": "study1", "participant": "P1", "x": 1})
    assert bad.status_code == 422 and isinstance(bad.json()["detail"], str)
    assert start(client, participant="P03", index=4).json()["index"] == 4
    taken = start(client, participant="P04", index=4)
    assert taken.status_code == 422 and "index" in taken.json()["detail"]


def test_answers_are_stored_once_and_in_order(client, store_path):
    session = start(client).json()["session"]
    trial = client.get(f"/api/sessions/{session}/next").json()
    assert trial["trial"] == 1 and [q["id"] for q in trial["questions"]] == ["Q1", "Q2"]
    assert trial["modality"] == "tactile" and trial["ink"] == "hidden"
    assert trial["pen"] == "ballpoint" and trial["tactile_url"].endswith("/trials/1/tactile.wav")
    url = f"/api/sessions/{session}/trials/1"
    # invalid answers name the question
    for given, name in (({"Q1": 6, "Q2": 3}, "Q1"), ({"Q1": 3}, "Q2"), ({"Q1": "3", "Q2": 3}, "Q1"),
                        ({"Q1": 3, "Q2": 3, "Q7": 1}, "Q7")):
        reply = client.post(url, json={"answers": given, "rt_ms": 1000.0})
        assert reply.status_code == 422 and reply.json()["detail"].startswith(name), reply.text
    assert client.post(url, json={"answers": {"Q1": 4, "Q2": 5}, "rt_ms": -1}).status_code == 422
    # not the next trial
    ahead = client.post(f"/api/sessions/{session}/trials/2",
                        json={"answers": {"Q1": 4, "Q2": 5}, "rt_ms": 900.0})
    assert ahead.status_code == 409 and ahead.json()["next"] == 1
    stored = client.post(url, json={"answers": {"Q1": 4, "Q2": 5}, "rt_ms": 1234.5})
    assert stored.status_code == 201 and stored.json() == {"trial": 1, "next": 2}
    again = client.post(url, json={"answers": {"Q1": 1, "Q2": 1}, "rt_ms": 99.0})
    assert again.status_code == 409
    assert again.json()["answers"] == {"Q1": "4", "Q2": "5"} and again.json()["rt_ms"] == 1234.5
    assert count(store_path, "SELECT COUNT(*) FROM answers WHERE session_id=?", session) == 2
    assert client.get(f"/api/sessions/{session}/next").json()["trial"] == 2
    assert client.get("/api/sessions/999/next").status_code == 404
    assert client.post(f"/api/sessions/{session}/trials/999",
                       json={"answers": {}, "rt_ms": 1.0}).status_code == 404


def test_a_whole_study1_session_through_the_api(client, store_path):
    session = start(client).json()["session"]
    seen, trial_kinds = [], []
    while not (trial := client.get(f"/api/sessions/{session}/next").json()).get("done"):
        seen.append((trial["block"], trial["phase"]))
        trial_kinds.append(trial["writing"])
        assert trial["feedback"] is False
        reply = client.post(f"/api/sessions/{session}/trials/{trial['trial']}",
                            json={"answers": study_answers(trial), "rt_ms": 1500.0})
        assert reply.status_code == 201, reply.text
    assert trial_kinds == [True] * 6 + [False]  # the comments are asked without writing
    conditions = [block for block, phase in seen if phase == "experimental"]
    assert sorted(conditions) == list("ABCDEF") and seen[-1][1] == "questionnaire"
    progress = client.get(f"/api/sessions/{session}").json()
    assert progress["state"] == "finished" and progress["answered"] == progress["trials"]
    assert progress["finished_at"] is not None and progress["next"] is None
    assert count(store_path, "SELECT COUNT(*) FROM answers") == 6 * 2 + 1


def test_recognition_answers_know_whether_they_are_right(client, store_path):
    session = start(client, design="study2").json()["session"]
    right = wrong = 0
    for _ in range(6):
        trial = client.get(f"/api/sessions/{session}/next").json()
        assert trial["phase"] == "training" and trial["questions"][0]["id"] == "pen"
        choices = trial["questions"][0]["choices"]
        chosen = trial["pen"] if trial["trial"] % 2 else next(c for c in choices if c != trial["pen"])
        right, wrong = right + (chosen == trial["pen"]), wrong + (chosen != trial["pen"])
        reply = client.post(f"/api/sessions/{session}/trials/{trial['trial']}",
                            json={"answers": {"pen": chosen}, "rt_ms": 800.0})
        assert reply.status_code == 201 and trial["feedback"] is True
        # a training trial names the right pen
        assert reply.json()["feedback"] == {"pen": {"correct": chosen == trial["pen"],
                                                    "answer": trial["pen"]}}
    assert count(store_path, "SELECT COUNT(*) FROM answers WHERE correct") == right
    assert count(store_path, "SELECT COUNT(*) FROM answers WHERE NOT correct") == wrong
    bad = client.get(f"/api/sessions/{session}/next").json()
    reply = client.post(f"/api/sessions/{session}/trials/{bad['trial']}",
                        json={"answers": {"pen": "crayon"}, "rt_ms": 800.0})
    assert reply.status_code == 422 and reply.json()["detail"].startswith("pen")


def test_pause_resume_finish(client):
    session = start(client).json()["session"]
    url = f"/api/sessions/{session}/state"
    assert client.post(url, json={"state": "paused"}).json()["state"] == "paused"
    assert client.get(f"/api/sessions/{session}/next").json()["state"] == "paused"
    assert client.post(url, json={"state": "running"}).json()["state"] == "running"
    assert client.post(url, json={"state": "sleeping"}).status_code == 422
    finished = client.post(url, json={"state": "finished"}).json()
    assert finished["state"] == "finished" and finished["next"] is None
    assert client.get(f"/api/sessions/{session}/next").json()["done"] is True
    assert client.post(url, json={"state": "running"}).status_code == 409
    late = client.post(f"/api/sessions/{session}/trials/1",
                       json={"answers": {"Q1": 1, "Q2": 1}, "rt_ms": 1.0})
    assert late.status_code == 409


def _pattern(client, session, n):
    reply = client.get(f"/api/sessions/{session}/trials/{n}/tactile.wav")
    assert reply.status_code == 200 and reply.headers["content-type"] == "audio/wav"
    samples, rate = soundfile.read(io.BytesIO(reply.content), dtype="float32")
    return samples, rate


def test_each_condition_gets_its_own_pattern(client):
    session = start(client).json()["session"]
    patterns = {}
    n = 1
    while not (trial := client.get(f"/api/sessions/{session}/next").json()).get("done"):
        if trial["phase"] == "experimental":
            patterns[trial["condition"]] = _pattern(client, session, n)
        client.post(f"/api/sessions/{session}/trials/{n}",
                    json={"answers": study_answers(trial), "rt_ms": 10.0})
        n += 1
    assert sorted(patterns) == list("ABCDEF")
    rates = {rate for _, rate in patterns.values()}
    assert len(rates) == 1
    for a, b in (("A", "B"), ("B", "E"), ("D", "F")):
        assert not np.allclose(patterns[a][0], patterns[b][0], atol=1e-3), (a, b)
    # B is the bundled ballpoint's own pattern: rebuilt from its model source, the same
    own = client.get("/api/profiles/ballpoint/tactile.wav").content
    own_samples, _ = soundfile.read(io.BytesIO(own), dtype="float32")
    assert np.allclose(own_samples, patterns["B"][0], atol=1e-4)


def test_strokes_are_stored_with_their_trial(client, store_path):
    session = start(client).json()["session"]
    pen = next(p for p in client.get("/api/profiles").json()["profiles"] if p["name"] == "ballpoint")
    with client.websocket_connect(WS) as ws:
        assert talk(ws, {"type": "hello", "seq": 0, "client": "test", "protocol": 1})["type"] == "ack"
        down = {"type": "pen_down", "seq": 1, "stroke": 0, "t": 1.0, "pen": "ballpoint",
                "profile_version": pen["version"], "modality": "tactile", "ink": "hidden",
                "px_per_mm": 4.0, "study_session": session, "trial": 1}
        assert talk(ws, down)["type"] == "ack"
        assert talk(ws, {"type": "pen_up", "seq": 2, "stroke": 0, "t": 1.2})["type"] == "ack"
        missing = talk(ws, {**down, "seq": 3, "stroke": 1, "trial": 99})
        assert missing["type"] == "error" and "no trial 99" in missing["message"]
        half = talk(ws, {**down, "seq": 4, "stroke": 2, "trial": None})
        assert half["type"] == "error" and "both" in half["message"]
    stored = count(store_path, "SELECT COUNT(*) FROM strokes WHERE study_session=? AND trial=1",
                   session)
    assert stored == 1


def test_the_lan_token_covers_the_study_api(tmp_path, monkeypatch):
    from fastapi.testclient import TestClient

    from realpen.live.app import LiveSettings, create_app

    monkeypatch.setenv("REALPEN_HOME", str(tmp_path / "home"))
    app = create_app(LiveSettings(store=tmp_path / "s.sqlite3", token="secret-token"))
    with TestClient(app, base_url="http://127.0.0.1") as lan:
        assert lan.get("/api/sessions").status_code == 401
        assert lan.get("/study").status_code == 401
        body = {"design": "study1", "participant": "P01", "consent": True}
        assert lan.post("/api/sessions", json=body).status_code == 401
        ok = lan.post("/api/sessions?token=secret-token", json=body)
        assert ok.status_code == 201


@pytest.mark.parametrize("headers", [{"Sec-Fetch-Site": "cross-site"},
                                     {"Origin": "http://evil.example"}])
def test_other_sites_cannot_answer(client, headers):
    session = start(client).json()["session"]
    reply = client.post(f"/api/sessions/{session}/trials/1",
                        json={"answers": {"Q1": 1, "Q2": 1}, "rt_ms": 1.0}, headers=headers)
    assert reply.status_code == 403
    assert client.get(f"/api/sessions/{session}").json()["answered"] == 0


def test_large_bodies_are_refused_unread(client):
    huge = {"design": "study1", "participant": "P01", "site": "x" * 70_000}
    reply = client.post("/api/sessions", json=huge)
    assert reply.status_code == 413 and "65,536 bytes" in reply.json()["detail"]
    assert reply.headers["x-frame-options"] == "DENY"
    assert client.get("/api/sessions").json()["sessions"] == []


def _asgi(middleware, messages: list[dict], pause_s: float = 0.0) -> tuple[list[dict], bytes]:
    """Run one POST through ``middleware``; returns (what was sent, the body the app got)."""
    import asyncio

    got = bytearray()

    async def app(scope, receive, send):
        message = await receive()
        got.extend(message["body"])
        await send({"type": "http.response.start", "status": 204, "headers": []})
        await send({"type": "http.response.body", "body": b""})

    middleware.app = app
    queue = list(messages)
    sent: list[dict] = []

    async def receive():
        if pause_s:
            await asyncio.sleep(pause_s)
        return queue.pop(0) if queue else {"type": "http.disconnect"}

    async def send(message):
        sent.append(message)

    scope = {"type": "http", "method": "POST", "headers": [], "path": "/api/sessions"}
    asyncio.run(middleware(scope, receive, send))
    return sent, bytes(got)


def test_bodies_arrive_whole_and_in_time():
    from realpen.live.bodies import BodyLimit

    parts = [{"type": "http.request", "body": b'{"a":', "more_body": True},
             {"type": "http.request", "body": b' 1}', "more_body": False}]
    sent, body = _asgi(BodyLimit(None), parts)
    assert body == b'{"a": 1}' and sent[0]["status"] == 204
    trickle = [{"type": "http.request", "body": b"x", "more_body": True}] * 50
    sent, body = _asgi(BodyLimit(None, timeout_s=0.2), trickle, pause_s=0.02)
    assert sent[0]["status"] == 408 and body == b""
    chunks = [{"type": "http.request", "body": b"x" * 40, "more_body": True}] * 3
    sent, body = _asgi(BodyLimit(None, max_bytes=100), chunks)
    assert sent[0]["status"] == 413 and body == b""


def test_values_are_taken_as_sent_and_storable(client, store_path):
    session = start(client).json()["session"]
    url = f"/api/sessions/{session}/trials/1"
    for body, name in (({"answers": {"Q1": True, "Q2": 4}, "rt_ms": 5.0}, "answers.Q1"),
                       ({"answers": {"Q1": 4.0, "Q2": 4}, "rt_ms": 5.0}, "answers.Q1"),
                       ({"answers": {"Q1": 4, "Q2": 4}, "rt_ms": "7"}, "rt_ms"),
                       ({"answers": {"Q1": 4, "Q2": 4}, "rt_ms": True}, "rt_ms")):
        reply = client.post(url, json=body)
        assert reply.status_code == 422 and name in reply.json()["detail"], (body, reply.text)
    assert client.post("/api/sessions", json={"design": "study1", "participant": "P2",
                                              "consent": "yes"}).status_code == 422
    for gender in ("a\x00b", "\ud800"):
        body = {"design": "study1", "participant": "P3", "consent": True,
                "demographics": {"gender": gender}}
        reply = client.post("/api/sessions", content=json_bytes(body),
                            headers={"content-type": "application/json"})
        assert reply.status_code == 422 and reply.json()["detail"].startswith("demographics"), \
            reply.text
    for n in (2**31, 2**53):  # ids are 32-bit in the store
        assert client.get(f"/api/sessions/{n}").status_code == 422
        assert client.get(f"/api/sessions/{session}/trials/{n}/tactile.wav").status_code == 422
    # an optional question left empty is stored as "" (its trial keeps its row)
    while (trial := client.get(f"/api/sessions/{session}/next").json()).get("trial"):
        given = study_answers(trial)
        if "comments" in given:
            given["comments"] = ""
            nul = client.post(f"/api/sessions/{session}/trials/{trial['trial']}",
                              json={"answers": {"comments": "a\x00b"}, "rt_ms": 1.0})
            assert nul.status_code == 422 and nul.json()["detail"].startswith("comments")
        assert client.post(f"/api/sessions/{session}/trials/{trial['trial']}",
                           json={"answers": given, "rt_ms": 1.0}).status_code == 201
    assert count(store_path, "SELECT COUNT(*) FROM answers WHERE question='comments' "
                             "AND answer=''") == 1


def json_bytes(value) -> bytes:
    """JSON with lone surrogates escaped as \\uXXXX (as a browser may send them)."""
    import json

    return json.dumps(value, ensure_ascii=True).encode()


def test_a_store_failure_is_a_503_with_one_line(client, monkeypatch):
    from concurrent.futures import Future

    from sqlalchemy.exc import OperationalError

    store = client.app.state.live.store

    def failing(operation, *args):
        future = Future()
        future.set_exception(OperationalError("SELECT 1", {}, Exception("disk I/O error")))
        return future

    monkeypatch.setattr(store, "read", failing)
    reply = client.get("/api/sessions")
    assert reply.status_code == 503 and "disk I/O error" in reply.json()["detail"]
    assert "\n" not in reply.json()["detail"]


def test_the_documented_python_example_runs_a_whole_session_on_the_standard_library(
        tmp_path, monkeypatch):
    # A Quickstart install has no HTTP client library: the example must not need one.
    for name in ("httpx", "requests"):
        monkeypatch.setitem(sys.modules, name, None)
    monkeypatch.setenv("REALPEN_HOME", str(tmp_path / "home"))
    doc = (Path(__file__).resolve().parents[1] / "docs" / "studies.md").read_text()
    code = doc.split("### Driving RealPen from Python")[1].split("```python\n")[1].split("```")[0]
    assert 'SERVER = "http://127.0.0.1:8765"' in code
    with running_server(tmp_path) as (port, _app):
        code = code.replace('SERVER = "http://127.0.0.1:8765"', f'SERVER = "http://127.0.0.1:{port}"')
        exec(compile(code, "docs/studies.md", "exec"), {"__name__": "example"})
    store = tmp_path / "s.sqlite3"
    assert count(store, "SELECT COUNT(*) FROM trials WHERE answered_at IS NOT NULL") == 93
    assert count(store, "SELECT COUNT(*) FROM sessions WHERE state = 'finished'") == 1


def test_a_shutdown_while_the_database_cannot_answer_still_closes_the_store(tmp_path, monkeypatch):
    from sqlalchemy.exc import OperationalError

    from realpen.live.app import LiveSettings, create_app

    monkeypatch.setenv("REALPEN_HOME", str(tmp_path / "home"))
    state = create_app(LiveSettings.loopback(store=tmp_path / "s.sqlite3")).state.live

    def no_answer(timeout=None):
        raise OperationalError("SELECT count(*)", {}, Exception("server closed the connection"))

    monkeypatch.setattr(state.store, "count", no_answer)
    state.shutdown()
    assert state.stopped and state.final_counts is None
    assert "server closed the connection" in state.count_problem
    assert state.store.submit(lambda conn: 1).exception(timeout=5) is not None  # closed
