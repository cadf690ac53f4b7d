"""The real server (uvicorn with the server's own protocols) against clients that send far
ahead, stall, or send heads without end: backpressure without a cut, a silent socket released,
bounded heads answered 431 with the security headers, uvicorn's own answers with them too.

Timings are shortened through :func:`realpen.live.server.server_config`'s keyword arguments;
every wait is for an event (an answer, a close), with a generous deadline for loaded machines.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import socket
import threading
import time

import pytest
from live_support import rows, running_server

pytest.importorskip("fastapi", reason="the live app needs the server dependencies")

import uvicorn  # noqa: E402
from websockets.asyncio.client import connect as async_connect  # noqa: E402
from websockets.exceptions import ConnectionClosed  # noqa: E402

from realpen.live.app import LiveSettings, create_app  # noqa: E402
from realpen.live.protocols import (  # noqa: E402
    MAX_HEAD_BYTES,
    WS_PING_INTERVAL_S,
    WS_PING_TIMEOUT_S,
)
from realpen.live.server import bind, server_config  # noqa: E402
from realpen.profile import resolve_profile  # noqa: E402

PING_INTERVAL_S, PING_TIMEOUT_S = 0.3, 0.6
STORE_DELAY_S = 0.02  # each stored message takes this long: the client gets far ahead


def flood_messages(count: int) -> list[str]:
    version = resolve_profile("pencil").version
    frames = [json.dumps({"type": "pen_down", "seq": 1, "stroke": 1, "t": 0.0, "pen": "pencil",
                          "profile_version": version, "modality": "none", "px_per_mm": 4.0})]
    for k in range(count):
        frames.append(json.dumps({"type": "samples", "seq": k + 2, "stroke": 1, "index": 2 * k,
                                  "samples": [{"t": 0.01 * k, "x": float(2 * k + j), "y": 0.0,
                                               "pressure": 0.5, "speed": 10.0}
                                              for j in range(2)]}))
    return frames


async def send_all_read_acks(url: str, frames: list[str]) -> tuple[int, str | None]:
    """Send every frame at once (no window), read the acks meanwhile; (acks, close reason)."""
    acked = 0
    try:
        async with async_connect(url, ping_interval=None, compression=None) as ws:
            async def read():
                nonlocal acked
                async for text in ws:
                    assert json.loads(text)["type"] == "ack", text
                    acked += 1
                    if acked == len(frames):
                        return

            reader = asyncio.create_task(read())
            for frame in frames:
                await ws.send(frame)
            await reader
    except ConnectionClosed as closed:
        return acked, f"{closed.rcvd.code if closed.rcvd else 1006} " \
                      f"{closed.rcvd.reason if closed.rcvd else ''}"
    return acked, None


def test_a_client_far_ahead_of_the_store_is_slowed_not_cut(tmp_path):
    """150 messages sent at once to a store that takes 20 ms each: 3 s of backpressure, five
    times the ping timeout, and every message is stored and acknowledged."""
    frames = flood_messages(150)
    with running_server(tmp_path, store_delay_s=STORE_DELAY_S,
                        ws_ping_interval_s=PING_INTERVAL_S,
                        ws_ping_timeout_s=PING_TIMEOUT_S) as (port, _):
        acked, closed = asyncio.run(send_all_read_acks(f"ws://127.0.0.1:{port}/ws", frames))
    assert closed is None, f"the server closed the connection ({closed}) after {acked} acks"
    assert acked == len(frames)
    stored = rows(tmp_path / "s.sqlite3", "SELECT COUNT(*) FROM samples")[0][0]
    assert stored == 2 * (len(frames) - 1)


def handshake(port: int, small_window: bool = False) -> socket.socket:
    """A raw WebSocket to the server, its handshake answered (frames are sent after it, as a
    client must); ``small_window``: a 4 KiB receive buffer, so unread replies back up fast."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    if small_window:  # before connect: the window is agreed then
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    sock.connect(("127.0.0.1", port))
    sock.sendall(f"GET /ws HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n"
                 f"Connection: Upgrade\r\nSec-WebSocket-Version: 13\r\n"
                 f"Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n\r\n".encode())
    sock.settimeout(30)
    answer = b""
    while b"\r\n\r\n" not in answer:  # byte by byte: nothing after the head is taken
        answer += sock.recv(1)
    assert answer.startswith(b"HTTP/1.1 101"), answer
    return sock


def seconds_until_closed(sock: socket.socket) -> float:
    start = time.monotonic()
    with contextlib.suppress(OSError):
        while sock.recv(4096):  # pings arrive and are never answered
            pass
    return time.monotonic() - start


def test_a_websocket_silent_after_its_handshake_is_released_but_an_idle_page_is_kept(tmp_path):
    assert WS_PING_INTERVAL_S + WS_PING_TIMEOUT_S <= 10.0  # the promise: released within 10 s
    interval, timeout = 0.3, 1.0  # the page's client shares this process: time to answer
    with running_server(tmp_path, ws_ping_interval_s=interval,
                        ws_ping_timeout_s=timeout) as (port, _):

        async def idle_page():  # answers pings (the client library does), sends nothing
            async with async_connect(f"ws://127.0.0.1:{port}/ws", ping_interval=None) as ws:
                await asyncio.sleep(2 * (interval + timeout))
                await ws.send(json.dumps({"type": "hello", "seq": 0, "client": "t"}))
                return json.loads(await ws.recv())["type"]

        with handshake(port) as silent:
            waited = seconds_until_closed(silent)
        assert waited < 4 * (interval + timeout), waited
        assert asyncio.run(idle_page()) == "ack"


def test_a_client_that_takes_no_reply_for_the_allowance_is_released(tmp_path):
    with running_server(tmp_path, ws_ping_interval_s=PING_INTERVAL_S,
                        ws_ping_timeout_s=PING_TIMEOUT_S, ws_spoken_silence_s=1.0) as (port, _):
        sock = handshake(port, small_window=True)
        hello = json.dumps({"type": "hello", "seq": 0, "client": "t"}).encode()
        frame = bytes([0x81, 0x80 | len(hello)]) + b"\0\0\0\0" + hello  # masked, key 0
        outcome: list[BaseException] = []

        def flood():  # sends and never reads: blocks once the server stops reading it
            try:
                while True:
                    sock.sendall(frame * 100)
            except OSError as error:
                outcome.append(error)

        sender = threading.Thread(target=flood, daemon=True)
        sender.start()
        sender.join(timeout=60)
        sock.close()
    assert outcome, "the server kept a client that took none of its replies for 60 s"
    assert isinstance(outcome[0], (ConnectionResetError, BrokenPipeError)), outcome


def test_a_client_that_has_spoken_is_given_longer_before_it_is_released(tmp_path):
    """A client that sent messages and then falls silent (a script whose machine is too busy
    to schedule it) is kept for ``ws_spoken_silence_s``, then released."""
    spoken_silence_s = 2 * (PING_INTERVAL_S + PING_TIMEOUT_S)
    with running_server(tmp_path, ws_ping_interval_s=PING_INTERVAL_S,
                        ws_ping_timeout_s=PING_TIMEOUT_S,
                        ws_spoken_silence_s=spoken_silence_s) as (port, _):
        with handshake(port) as sock:
            hello = json.dumps({"type": "hello", "seq": 0, "client": "t"}).encode()
            sock.sendall(bytes([0x81, 0x80 | len(hello)]) + b"\0\0\0\0" + hello)
            waited = seconds_until_closed(sock)
    # the server may close later on a loaded machine, never sooner
    assert waited >= spoken_silence_s * 0.9, waited
    assert waited < spoken_silence_s + 10, waited


def test_a_client_that_stops_reading_its_replies_for_a_while_is_not_cut(tmp_path):
    """The server cannot write to a client that does not read; it waits for it (the replies
    are backpressure too), and every reply arrives once the client reads again."""
    count = 30000
    with running_server(tmp_path, ws_ping_interval_s=PING_INTERVAL_S,
                        ws_ping_timeout_s=PING_TIMEOUT_S) as (port, _):
        sock = handshake(port, small_window=True)
        hello = json.dumps({"type": "hello", "seq": 0, "client": "t"}).encode()
        frame = bytes([0x81, 0x80 | len(hello)]) + b"\0\0\0\0" + hello  # masked, key 0
        sender = threading.Thread(target=sock.sendall, args=(frame * count,), daemon=True)
        sender.start()
        # Not reading for many ping periods: the server's replies back up into its buffers.
        time.sleep(3 * (PING_INTERVAL_S + PING_TIMEOUT_S))
        sock.settimeout(60)
        received = b""
        with contextlib.suppress(OSError):
            while received.count(b'"type":"ack"') < count:
                part = sock.recv(65536)
                if not part:
                    break
                received += part
        sender.join(timeout=60)
        sock.close()
    assert received.count(b'"type":"ack"') == count


def raw_request(port: int, data: bytes, chunk: int = 65536) -> bytes:
    """Send ``data`` (stopping if the server closes) and return its whole answer."""
    with socket.create_connection(("127.0.0.1", port)) as sock:
        sock.settimeout(30)
        with contextlib.suppress(OSError):
            for start in range(0, len(data), chunk):
                sock.sendall(data[start:start + chunk])
        answer = b""
        with contextlib.suppress(OSError):
            while part := sock.recv(65536):
                answer += part
        return answer


def assert_one_line_with_headers(answer: bytes, status: int) -> None:
    head, _, body = answer.partition(b"\r\n\r\n")
    assert head.startswith(f"HTTP/1.1 {status} ".encode()), answer[:200]
    lower = head.lower()
    assert b"x-frame-options: deny" in lower and b"content-security-policy:" in lower
    assert body.count(b"\n") == 1 and len(body) < 200, body


def test_request_heads_are_bounded_and_every_refusal_carries_the_headers(tmp_path):
    with running_server(tmp_path) as (port, _):
        huge = b"GET /api/status HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Big: " + b"a" * (8 * 2**20)
        answer = raw_request(port, huge)
        assert_one_line_with_headers(answer, 431)
        many = b"GET /api/status HTTP/1.1\r\nHost: 127.0.0.1\r\n" + \
            b"".join(b"X-%d: 1\r\n" % k for k in range(101)) + b"\r\n"
        assert_one_line_with_headers(raw_request(port, many), 431)
        assert_one_line_with_headers(raw_request(port, b"NOT HTTP AT ALL\r\n\r\n"), 400)
        # a head just under the limit is served
        filler = MAX_HEAD_BYTES - 200
        fine = b"GET /api/status HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Fill: " + b"a" * filler + \
            b"\r\nConnection: close\r\n\r\n"
        assert raw_request(port, fine).startswith(b"HTTP/1.1 200")


def test_the_token_is_not_waited_for_behind_a_huge_head(tmp_path):
    settings = LiveSettings.loopback(store=tmp_path / "s.sqlite3")
    settings.token = "t" * 32
    app = create_app(settings)
    sock = bind("127.0.0.1", 0)
    server = uvicorn.Server(server_config(app))
    thread = threading.Thread(target=lambda: asyncio.run(server.serve(sockets=[sock])))
    thread.start()
    try:
        deadline = time.monotonic() + 30
        while not server.started and time.monotonic() < deadline:
            time.sleep(0.02)
        port = sock.getsockname()[1]
        huge = b"GET /api/status HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Big: " + b"a" * (8 * 2**20)
        assert_one_line_with_headers(raw_request(port, huge), 431)
        assert raw_request(port, b"GET /api/status HTTP/1.1\r\nHost: 127.0.0.1\r\n"
                                 b"Connection: close\r\n\r\n").startswith(b"HTTP/1.1 401")
    finally:
        server.should_exit = True
        thread.join(timeout=30)
        sock.close()


def test_connections_above_the_limit_get_503_with_the_headers(tmp_path):
    with running_server(tmp_path, max_connections=2, head_timeout_s=60) as (port, _):
        held = [socket.create_connection(("127.0.0.1", port)) for _ in range(2)]
        try:
            deadline = time.monotonic() + 30
            answer = b""
            while time.monotonic() < deadline:  # until the server has accepted both
                answer = raw_request(port, b"GET /api/status HTTP/1.1\r\nHost: 127.0.0.1\r\n"
                                           b"Connection: close\r\n\r\n")
                if answer.startswith(b"HTTP/1.1 503"):
                    break
            assert_one_line_with_headers(answer, 503)
        finally:
            for sock in held:
                sock.close()


def test_the_reference_client_in_the_docs_stores_every_sample(tmp_path):
    """docs/examples/live_client.py, the rule's reference client, against a slow store."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).parents[1] / "docs" / "examples" / "live_client.py"
    spec = importlib.util.spec_from_file_location("live_client", path)
    client = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(client)
    stroke = client.one_stroke("pencil", resolve_profile("pencil").version, samples=800)
    with running_server(tmp_path, store_delay_s=STORE_DELAY_S,
                        ws_ping_interval_s=PING_INTERVAL_S,
                        ws_ping_timeout_s=PING_TIMEOUT_S) as (port, _):
        connections = asyncio.run(client.send_reliably(f"ws://127.0.0.1:{port}/ws", stroke))
    assert connections == 1
    assert rows(tmp_path / "s.sqlite3", "SELECT COUNT(*) FROM samples")[0][0] == 800
    assert rows(tmp_path / "s.sqlite3", "SELECT end_reason FROM strokes") == [("pen_up",)]


def test_a_stray_line_after_a_request_does_not_hold_the_connection(tmp_path):
    """A CRLF after an answered request cancels uvicorn's keep-alive timer without starting a
    request; the head's deadline still closes the connection."""
    with running_server(tmp_path, head_timeout_s=1.0) as (port, _):
        with socket.create_connection(("127.0.0.1", port)) as sock:
            sock.sendall(b"GET /api/status HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")
            sock.settimeout(30)
            assert sock.recv(65536).startswith(b"HTTP/1.1 200")
            sock.sendall(b"\r\n")
            assert seconds_until_closed(sock) < 20


def test_a_refusal_behind_a_pending_answer_leaves_that_answer_whole(tmp_path, caplog):
    """Garbage pipelined behind a request: the request is answered, then the connection
    closes, and the server logs no traceback."""
    with running_server(tmp_path) as (port, _):
        answer = raw_request(port, b"GET /api/status HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n"
                                   b"NOT HTTP\r\n\r\n")
    assert answer.startswith(b"HTTP/1.1 200"), answer[:100]
    assert b"400" not in answer.split(b"\r\n", 1)[0]
    assert not [r for r in caplog.records if r.exc_info], [r.getMessage() for r in caplog.records]
