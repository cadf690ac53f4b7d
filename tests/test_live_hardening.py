"""The live server under a careless user and a hostile web page: nothing lost, nothing stored
twice, strokes closed after a crash, one server per store, security headers, other sites
refused, a paged device log, and timeouts for slow clients."""

from __future__ import annotations

import json
import logging
import os
import signal
import socket
import sqlite3
import subprocess
import sys
import threading
import time

import pytest
import sqlalchemy.exc
from conftest import run_cli, store_rows
from live_support import CRASHER, LEGACY_V1, LOCAL, WS, rows, running_server, talk

pytest.importorskip("fastapi", reason="the live app needs the server dependencies")

from fastapi.testclient import TestClient  # noqa: E402
from websockets.sync.client import connect  # noqa: E402

from realpen.errors import RealPenError  # noqa: E402
from realpen.live.app import LiveSettings, create_app  # noqa: E402
from realpen.live.auth import CONTENT_SECURITY_POLICY, content_security_policy  # noqa: E402
from realpen.live.device import CommandLog, Origin  # noqa: E402
from realpen.live.routes.device import DEVICE_LOG_PAGE  # noqa: E402
from realpen.live.store import StrokeStore  # noqa: E402
from realpen.profile import resolve_profile  # noqa: E402

PAGE = "page-0123456789abcdef"
STROKE_FIELDS = dict(pen="pencil", profile_version="0" * 12, modality="none", ink="visible",
                     pointer_type="pen", px_per_mm=4.0, calibrated=False)


def batch(first: int, n: int = 4) -> list[dict]:
    """``n`` samples whose ``x`` is their number within the stroke (a duplicate shows)."""
    return [{"t": 10.0 + (first + k) / 100, "x": float(first + k), "y": 1.0, "pressure": 0.5,
             "speed": 20.0} for k in range(n)]


def pen_down(seq: int, stroke: int = 1) -> dict:
    return {"type": "pen_down", "seq": seq, "stroke": stroke, "t": 10.0, "pen": "pencil",
            "profile_version": resolve_profile("pencil").version, "modality": "tactile",
            "px_per_mm": 4.0}


# ---- nothing lost, nothing stored twice ----------------------------------------------------

def test_a_page_that_reconnects_and_resends_stores_every_sample_once(client, store_path):
    hello = {"type": "hello", "seq": 0, "client": "t", "page": PAGE}
    with client.websocket_connect(WS) as ws:
        assert talk(ws, hello)["type"] == "ack"
        stroke_id = talk(ws, pen_down(1))["stroke_id"]
        for seq, first in ((2, 0), (3, 4)):
            assert talk(ws, {"type": "samples", "seq": seq, "stroke": 1, "index": first,
                             "samples": batch(first)})["type"] == "ack"
    # The connection dropped mid-stroke: the server had to end it (committed once a request
    # through the store's writer, queued after it, has answered).
    assert client.get("/api/status").json()["samples"] == 8
    assert rows(store_path, "SELECT end_reason FROM strokes") == [("disconnect",)]
    with client.websocket_connect(WS) as ws:  # the page is back and resends what it was unsure of
        assert talk(ws, {**hello, "seq": 7})["type"] == "ack"
        assert talk(ws, pen_down(1))["stroke_id"] == stroke_id
        for seq, first in ((3, 4), (4, 8), (4, 8)):
            reply = talk(ws, {"type": "samples", "seq": seq, "stroke": 1, "index": first,
                              "samples": batch(first)})
            assert reply["type"] == "ack", reply
        assert talk(ws, {"type": "pen_up", "seq": 5, "stroke": 1, "t": 11.0})["type"] == "ack"
    assert rows(store_path, "SELECT id, page, sample_count, end_reason FROM strokes") == \
        [(stroke_id, PAGE, 12, "pen_up")]
    assert [x for (x,) in rows(store_path, "SELECT x FROM samples ORDER BY seq")] == \
        [float(k) for k in range(12)]
    assert client.get("/api/status").json()["samples"] == 12


def test_samples_and_pen_up_resent_for_a_stroke_the_server_ended_are_taken(client, store_path):
    hello = {"type": "hello", "seq": 0, "client": "t", "page": PAGE}
    with client.websocket_connect(WS) as ws:
        talk(ws, hello)
        talk(ws, pen_down(1))
    with client.websocket_connect(WS) as ws:  # pen_down was acknowledged: not resent
        talk(ws, hello)
        assert talk(ws, {"type": "samples", "seq": 2, "stroke": 1, "index": 0,
                         "samples": batch(0)})["type"] == "ack"
        assert talk(ws, {"type": "gain", "seq": 3, "stroke": 1, "t": 10.1,
                         "target": 0.5})["type"] == "ack"
        assert talk(ws, {"type": "pen_up", "seq": 4, "stroke": 1, "t": 11.0})["type"] == "ack"
        # Another page's stroke, or one never drawn, is not this page's to write to.
        reply = talk(ws, {"type": "samples", "seq": 5, "stroke": 2, "samples": batch(0)})
        assert reply["code"] == "protocol" and "not down" in reply["message"]
    assert rows(store_path, "SELECT sample_count, end_reason FROM strokes") == [(4, "pen_up")]
    with client.websocket_connect(WS) as ws:
        talk(ws, {**hello, "page": "another-page-000"})
        reply = talk(ws, {"type": "pen_up", "seq": 1, "stroke": 1, "t": 11.0})
        assert reply["code"] == "protocol"


def test_store_numbers_samples_and_ignores_a_number_it_has(store_target):
    store = StrokeStore(store_target)
    sid = store.begin_stroke(session="s", page_stroke=1, page_t0=1.0, **STROKE_FIELDS)
    assert store.begin_stroke(session="other", page="s", page_stroke=1, page_t0=9.0,
                              **STROKE_FIELDS) == sid  # same page, same stroke
    rows_ = [(1.0 + k / 10, k, 0, 0.5, 0, 0, 0) for k in range(5)]
    assert store.add_samples(sid, rows_[:3], first=0) == 3
    assert store.add_samples(sid, rows_[1:5], first=1) == 5  # 1 and 2 again: ignored
    assert store.add_samples(sid, rows_[:1]) == 6  # unnumbered: after the last
    store.close()
    assert store_rows(store_target, "SELECT seq, x FROM samples ORDER BY seq") == \
        [(0, 0.0), (1, 1.0), (2, 2.0), (3, 3.0), (4, 4.0), (5, 0.0)]


def test_a_page_back_on_a_new_connection_takes_over_its_stroke(client, store_path):
    hello = {"type": "hello", "seq": 0, "client": "t", "page": PAGE}
    with client.websocket_connect(WS) as old:
        talk(old, hello)
        old_session = talk(old, pen_down(1))
        with client.websocket_connect(WS) as new:  # the old one is not yet known to be dead
            new_session = talk(new, hello)["session"]
            assert talk(new, {"type": "samples", "seq": 2, "stroke": 1, "index": 0,
                              "samples": batch(0)})["type"] == "ack"
            assert talk(new, {"type": "gain", "seq": 3, "stroke": 1, "t": 10.1,
                              "target": 0.5})["type"] == "ack"
            old.close()  # closing later, it leaves the pen and the stroke alone
            assert client.get("/api/status").json()["samples"] == 4
            assert rows(store_path, "SELECT end_reason FROM strokes") == [(None,)]
            assert talk(new, {"type": "pen_up", "seq": 4, "stroke": 1, "t": 11.0})["type"] == \
                "ack"
    assert old_session["stroke_id"] == 1
    log = client.get("/api/device/log").json()["entries"]
    assert [(e["kind"], e["session"] == new_session) for e in log] == [
        ("pen_down", False), ("pen_down", True), ("gain", True), ("pen_up", True)]
    assert rows(store_path, "SELECT sample_count, end_reason FROM strokes") == [(4, "pen_up")]


def test_a_message_the_store_cannot_record_closes_the_socket_for_an_ordered_resend(
        client, monkeypatch):
    from starlette.websockets import WebSocketDisconnect

    store = client.app.state.live.store
    real_begin, failures = store._begin, []

    def full_disk_once(db, fields):
        if not failures:
            failures.append(1)
            raise sqlite3.OperationalError("database or disk is full")
        return real_begin(db, fields)

    monkeypatch.setattr(store, "_begin", full_disk_once)
    with client.websocket_connect(WS) as ws:
        talk(ws, {"type": "hello", "seq": 0, "client": "t", "page": PAGE})
        reply = talk(ws, pen_down(1))
        assert reply["code"] == "store" and reply["seq"] == 1
        with pytest.raises(WebSocketDisconnect) as closed:
            ws.receive_text()
        assert closed.value.code == 1011
    log = client.get("/api/device/log").json()["entries"]
    assert [e["kind"] for e in log] == ["pen_down", "pen_up"]  # not left down on the pen
    with client.websocket_connect(WS) as ws:  # the page resends from the pen-down on
        talk(ws, {"type": "hello", "seq": 2, "client": "t", "page": PAGE})
        assert talk(ws, pen_down(1))["type"] == "ack"


# ---- the store: crashes, a second server, damage, the journal, old stores ------------------

def test_a_refused_second_store_leaves_the_first_untouched(tmp_path):
    path = tmp_path / "s.sqlite3"
    first = StrokeStore(path)  # it created the file
    with pytest.raises(RealPenError, match="in use"):
        StrokeStore(path)
    assert first.begin_stroke(session="s", page_stroke=1, page_t0=0.0, **STROKE_FIELDS) == 1
    first.close()
    assert rows(path, "SELECT COUNT(*) FROM strokes") == [(1,)]


def test_writes_that_cannot_begin_fail_and_later_ones_succeed(tmp_path, monkeypatch):
    from realpen.study import db as store_module

    monkeypatch.setattr(store_module, "BUSY_TIMEOUT_MS", 200)
    path = tmp_path / "s.sqlite3"
    store = StrokeStore(path)
    other = sqlite3.connect(path, isolation_level=None)
    other.execute("BEGIN IMMEDIATE")  # another process holds the write lock
    try:
        futures = [store.begin(session="s", page_stroke=k, page_t0=0.0, **STROKE_FIELDS)
                   for k in (1, 2)]
        for future in futures:  # every future of the batch resolves, none hangs
            with pytest.raises(sqlalchemy.exc.OperationalError, match="locked"):
                future.result(timeout=10)
    finally:
        other.execute("ROLLBACK")
        other.close()
    assert store.begin_stroke(session="s", page_stroke=3, page_t0=0.0, **STROKE_FIELDS) > 0
    store.close()
    with pytest.raises(sqlalchemy.exc.ResourceClosedError, match="closed"):
        store.begin(session="s", page_stroke=4, page_t0=0.0, **STROKE_FIELDS).result(timeout=5)


def test_a_write_whose_caller_stopped_waiting_is_still_made(store_target):
    store = StrokeStore(store_target)
    sid = store.begin_stroke(session="s", page_stroke=1, page_t0=0.0, **STROKE_FIELDS)
    gate = threading.Event()
    held = store.submit(lambda db: gate.wait(10))  # the writer is busy with this
    ended = store.end(sid, "disconnect")
    assert ended.cancel()  # the connection's task was cancelled while the end was queued
    gate.set()
    held.result(timeout=10)
    store.close()
    assert store_rows(store_target, "SELECT end_reason FROM strokes") == [("disconnect",)]




@pytest.mark.slow
def test_a_killed_server_leaves_its_store_to_the_next_which_closes_its_strokes(tmp_path):
    path = tmp_path / "s.sqlite3"
    process = subprocess.Popen([sys.executable, "-c", CRASHER, str(path)], text=True,
                               stdin=subprocess.PIPE, stdout=subprocess.PIPE)
    try:
        assert process.stdout.readline().strip() == "ready"
        with pytest.raises(RealPenError, match="in use by another RealPen server") as caught:
            StrokeStore(path)
        assert str(caught.value).startswith(f"{path}: ") and "\n" not in str(caught.value)
    finally:
        process.send_signal(signal.SIGKILL)
        process.wait(timeout=10)
    assert rows(path, "SELECT end_reason FROM strokes") == [(None,)]  # open, as the kill left it
    store = StrokeStore(path)
    assert store.recovered == 1 and store.count() == (1, 2)
    store.close()
    ((started, ended, reason),) = rows(path, "SELECT started_at, ended_at, end_reason FROM strokes")
    assert reason == "crash"
    from datetime import datetime
    lasted = datetime.fromisoformat(ended) - datetime.fromisoformat(started)
    assert lasted.total_seconds() == pytest.approx(1.5)  # its last sample, 1.5 s after pen down


def test_a_damaged_store_is_refused_in_one_line(tmp_path):
    path = tmp_path / "s.sqlite3"
    store = StrokeStore(path)
    sid = store.begin_stroke(session="s", page_stroke=1, page_t0=0.0, **STROKE_FIELDS)
    store.add_samples(sid, [(k / 100, k, 0, 0.5, 0, 0, 0) for k in range(3000)])
    store.close()
    data = bytearray(path.read_bytes())
    assert len(data) > 8 * 4096
    data[3 * 4096:6 * 4096] = b"\x5a" * (3 * 4096)  # pages of the samples' b-tree
    path.write_bytes(bytes(data))
    with pytest.raises(RealPenError, match="damaged") as caught:
        StrokeStore(path)
    assert str(caught.value).startswith(f"{path}: ") and "\n" not in str(caught.value)
    result = run_cli("serve", "--port", "0", "--store", str(path))
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert result.stderr.strip().count("\n") == 0 and str(path) in result.stderr
    assert "RealPen live" not in result.stdout  # refused before any URL is printed


def test_the_journal_is_checkpointed_and_truncated_while_pages_write(tmp_path):
    path = tmp_path / "s.sqlite3"
    store = StrokeStore(path, checkpoint_s=60.0, wal_checkpoint_bytes=256 * 1024)
    sid = store.begin_stroke(session="s", page_stroke=1, page_t0=0.0, **STROKE_FIELDS)
    wal = []
    for k in range(400):  # ~400 commits of ~10 KB of journal each: ~4 MB unchecked
        store.add_samples(sid, [(k + j / 10, j, 0, 0.5, 0, 0, 0) for j in range(10)])
        wal.append(os.stat(f"{path}-wal").st_size)
    assert store.count() == (1, 4000)
    assert max(wal) < 1024 * 1024, max(wal)
    assert min(wal[200:]) < 64 * 1024  # truncated again and again, not only at close
    store.close()


def test_a_version_1_store_is_upgraded_in_place(tmp_path):
    path = tmp_path / "old.sqlite3"
    with sqlite3.connect(path) as db:
        db.executescript(LEGACY_V1 + """
            INSERT INTO strokes VALUES (1, 'abc', 1, 'pencil', '000000000000', 'none', 'visible',
              'pen', 4.0, 0, 0.0, '2026-01-01T00:00:00.000+00:00', '2026-01-01T00:00:01.000+00:00',
              'pen_up', 0);
            INSERT INTO strokes VALUES (2, 'abc', 1, 'pencil', '000000000000', 'none', 'visible',
              'pen', 4.0, 0, 0.0, '2026-01-01T00:00:02.000+00:00', '2026-01-01T00:00:03.000+00:00',
              'pen_up', 0);
        """)
    store = StrokeStore(path)
    assert store.begin_stroke(session="abc", page_stroke=1, page_t0=0.0, **STROKE_FIELDS) == 1
    store.close()
    # Version 1 took a stroke number twice on one connection: the later stroke stays its own.
    assert rows(path, "SELECT page, end_reason FROM strokes") == [("abc", "pen_up"),
                                                                   ("abc#2", "pen_up")]
    assert rows(path, "PRAGMA user_version") == [(3,)]  # 3: migrated by Alembic


# ---- the web side ----------------------------------------------------------------------------

@pytest.mark.parametrize("path, status", [
    ("/", 200), ("/static/app.js", 200), ("/static/style.css", 200), ("/api/config", 200),
    ("/api/profiles", 200), ("/api/profiles/pencil/sound.wav", 200), ("/api/status", 200),
    ("/api/device/log", 200), ("/nowhere", 404), ("/api/profiles/nobody/sound.wav", 404),
])
def test_every_response_carries_the_security_headers(client, path, status):
    response = client.get(path)
    assert response.status_code == status
    headers = response.headers
    assert headers["content-security-policy"] == content_security_policy("127.0.0.1")
    assert "connect-src 'self' ws://127.0.0.1 wss://127.0.0.1;" in \
        headers["content-security-policy"]
    assert "frame-ancestors 'none'" in CONTENT_SECURITY_POLICY
    assert "script-src 'self';" in CONTENT_SECURITY_POLICY and "unsafe" not in \
        CONTENT_SECURITY_POLICY
    assert headers["x-frame-options"] == "DENY"
    assert headers["x-content-type-options"] == "nosniff"
    assert headers["referrer-policy"] == "no-referrer"


def test_refusals_carry_the_headers_too(tmp_path, monkeypatch):
    monkeypatch.setenv("REALPEN_HOME", str(tmp_path / "home"))
    app = create_app(LiveSettings(store=tmp_path / "s.sqlite3", token="secret-token"))
    with TestClient(app, base_url=LOCAL) as lan:
        refused = lan.get("/api/config")
        assert refused.status_code == 401
        assert refused.headers["x-frame-options"] == "DENY"
        assert refused.headers["content-security-policy"] == content_security_policy("127.0.0.1")
        odd = lan.get("/api/config", headers={"host": "x; script-src *"})
        assert odd.headers["content-security-policy"] == CONTENT_SECURITY_POLICY


@pytest.mark.parametrize("headers, path, allowed", [
    ({}, "/api/status", True),  # not a browser (curl, scripts)
    ({"sec-fetch-site": "same-origin"}, "/api/status", True),
    ({"sec-fetch-site": "none"}, "/", True),  # typed or bookmarked
    ({"sec-fetch-site": "cross-site"}, "/api/status", False),
    ({"sec-fetch-site": "same-site"}, "/api/profiles", False),  # another port of this machine
    ({"sec-fetch-site": "cross-site", "sec-fetch-mode": "no-cors",
      "sec-fetch-dest": "script"}, "/static/app.js", False),
    ({"sec-fetch-site": "cross-site", "sec-fetch-mode": "cors"},
     "/api/profiles/pencil/sound.wav", False),
    ({"sec-fetch-site": "cross-site", "sec-fetch-mode": "navigate",
      "sec-fetch-dest": "document"}, "/", True),  # following a link to the page
    ({"sec-fetch-site": "cross-site", "sec-fetch-mode": "navigate",
      "sec-fetch-dest": "iframe"}, "/", False),
    ({"sec-fetch-site": "cross-site", "sec-fetch-mode": "navigate",
      "sec-fetch-dest": "document"}, "/api/device/log", False),
    ({"origin": "http://evil.example"}, "/api/status", False),
    ({"origin": "http://127.0.0.1"}, "/api/status", True),
])
def test_other_sites_are_refused(client, headers, path, allowed):
    response = client.get(path, headers=headers)
    assert (response.status_code == 200) == allowed, (response.status_code, response.text)
    if not allowed:
        assert response.status_code == 403 and "other sites" in response.text


def test_the_device_log_comes_in_pages(tmp_path, monkeypatch):
    monkeypatch.setenv("REALPEN_HOME", str(tmp_path / "home"))
    device = CommandLog()
    for k in range(2 * DEVICE_LOG_PAGE + 500):
        device.gain(Origin("s", 1, k), 0.5)
    app = create_app(LiveSettings.loopback(store=tmp_path / "s.sqlite3", device=device))
    with TestClient(app, base_url=LOCAL) as client:
        seen, since, pages = [], 0, 0
        while True:
            page = client.get("/api/device/log", params={"since": since}).json()
            assert len(page["entries"]) <= DEVICE_LOG_PAGE
            seen += [entry["seq"] for entry in page["entries"]]
            pages += 1
            if page["next"] >= page["count"]:
                break
            since = page["next"]
        assert seen == list(range(2 * DEVICE_LOG_PAGE + 500)) and pages == 3
        too_many = client.get("/api/device/log", params={"limit": 100_000})
        assert too_many.status_code == 422


# ---- a real uvicorn: slow clients and bad frames ---------------------------------------------

@pytest.fixture(scope="module")
def uvicorn_server(tmp_path_factory):
    """The live app under uvicorn with the server's own configuration, head timeout 0.5 s,
    and a route with a bug (``/boom``); one for the module, as its tests only read."""
    folder = tmp_path_factory.mktemp("uvicorn")
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("REALPEN_HOME", str(folder / "home"))  # no user profiles of this machine
        yield from _uvicorn_server(folder)


def _uvicorn_server(tmp_path):
    def boom():
        raise RuntimeError("a bug")

    with running_server(tmp_path, prepare=lambda app: app.add_api_route("/boom", boom),
                        head_timeout_s=0.5) as (port, _app):
        yield port


def closed_within(connection: socket.socket, seconds: float) -> bool:
    connection.settimeout(seconds)
    try:
        return connection.recv(1024) == b""
    except TimeoutError:
        return False


def test_slow_and_silent_clients_are_timed_out(uvicorn_server):
    port = uvicorn_server
    with socket.create_connection(("127.0.0.1", port)) as silent, \
            socket.create_connection(("127.0.0.1", port)) as half:
        half.sendall(b"GET /api/status HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Slow: ")
        assert closed_within(silent, 5.0) and closed_within(half, 5.0)
    with socket.create_connection(("127.0.0.1", port)) as polite:  # a whole request is answered
        polite.sendall(b"GET /api/status HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")
        polite.settimeout(5.0)
        assert polite.recv(1024).startswith(b"HTTP/1.1 200")


def test_even_the_page_of_an_unexpected_error_carries_the_headers(uvicorn_server):
    import httpx

    response = httpx.get(f"http://127.0.0.1:{uvicorn_server}/boom")
    assert response.status_code == 500
    assert response.headers["x-frame-options"] == "DENY"
    assert "frame-ancestors 'none'" in response.headers["content-security-policy"]
    ok = httpx.get(f"http://127.0.0.1:{uvicorn_server}/api/status")
    assert ok.headers.get_list("x-frame-options") == ["DENY"]  # not twice


def test_a_frame_that_is_not_utf8_is_logged_in_one_line(uvicorn_server, caplog):
    port = uvicorn_server
    caplog.set_level(logging.WARNING, logger="uvicorn.error")
    with connect(f"ws://127.0.0.1:{port}/ws") as ws:
        ws.send(b"\xff\xfe not text", text=True)
        with pytest.raises(Exception):  # noqa: B017 - the server closes the connection (1007)
            ws.recv(timeout=5)
    deadline = time.monotonic() + 5
    while not any("UTF-8" in r.getMessage() for r in caplog.records) and \
            time.monotonic() < deadline:
        time.sleep(0.05)
    (record,) = [r for r in caplog.records if "UTF-8" in r.getMessage()]
    assert "\n" not in record.getMessage() and record.exc_info is None
    with connect(f"ws://127.0.0.1:{port}/ws") as ws:  # the server is fine
        ws.send(json.dumps({"type": "hello", "seq": 0, "client": "after"}))
        assert json.loads(ws.recv(timeout=5))["type"] == "ack"
