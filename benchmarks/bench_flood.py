"""Reliability under abuse: clients that just send, heads that never end, sockets that stall.

Starts ``realpen serve`` in a subprocess (a fresh SQLite store in a temporary folder) and runs:

- **raw flood** (``--clients``, default 200; ``--messages``, default 3000 each): every client
  connects, sends all its messages back to back with no window (as a script that "just sends"
  does), reads the acks as they come, and is done when every message is acknowledged. A client
  whose connection is closed does not send again: what was not acknowledged is lost. It prints
  samples sent, stored and lost, and how many connections were closed and with which code. The
  clients run in ``--client-processes`` processes (default 4), and each yields to the others
  after every send, as separate programs would.
- **one long flood** (``--long``, default 0 messages; e.g. 100000): one raw client alone.
- **head probes** (``--heads``): one 128 MB header while a page asks ``/api/status`` every
  100 ms (the page's longest wait and the answer the big head gets), then twenty 64 MB heads at
  once and the server's peak RSS; a WebSocket that stops after its handshake, and how long the
  server keeps it.

``--load N`` keeps N busy processes spinning during the runs (the issue's "at load" figures;
the machine's 1-minute load average is printed).

Usage: python benchmarks/bench_flood.py [--clients 200] [--messages 3000] [--long 0]
       [--client-processes 4] [--heads] [--load 0] [--lan]
"""

from __future__ import annotations

import argparse
import asyncio
import collections
import concurrent.futures
import contextlib
import json
import multiprocessing
import os
import signal
import socket
import sqlite3
import tempfile
import time
from pathlib import Path
from urllib.parse import urlsplit

from bench_live import start_server  # the same server start as the page benchmark
from websockets.asyncio.client import connect as async_connect
from websockets.exceptions import ConnectionClosed

from realpen.profile import resolve_profile

SAMPLES_PER_BATCH = 4
MESSAGES_PER_STROKE = 100


def client_messages(client: int, count: int, version: str) -> tuple[list[str], int]:
    """The frames one raw client sends (``seq`` 1…count), and how many samples they carry.
    A sample's ``x`` is its client-wide number and ``y`` the client, so losses are counted."""
    frames, samples, stroke, index = [], 0, 0, 0
    for i in range(count):
        position = i % MESSAGES_PER_STROKE
        if position == 0:
            stroke, index = stroke + 1, 0
            message = {"type": "pen_down", "stroke": stroke, "t": i * 0.004, "pen": "pencil",
                       "profile_version": version, "modality": "tactile", "px_per_mm": 4.0}
        elif position == MESSAGES_PER_STROKE - 1 or i == count - 1:
            message = {"type": "pen_up", "stroke": stroke, "t": i * 0.004 + 0.003}
        else:
            batch = [{"t": i * 0.004 + j * 0.001, "x": float(samples + j), "y": float(client),
                      "pressure": 0.5, "speed": 50.0} for j in range(SAMPLES_PER_BATCH)]
            message = {"type": "samples", "stroke": stroke, "index": index, "samples": batch}
            samples += SAMPLES_PER_BATCH
            index += SAMPLES_PER_BATCH
        frames.append(json.dumps({**message, "seq": i + 1}))
    return frames, samples


async def raw_client(ws_url: str, client: int, frames: list[str], outcome: dict) -> None:
    """Send every frame at once, read acks meanwhile; never resend (a script that just sends)."""
    acked = 0
    try:
        async with async_connect(ws_url, ping_interval=None, compression=None,
                                 open_timeout=300, close_timeout=5, max_size=2**22) as ws:
            await ws.send(json.dumps({"type": "hello", "seq": 0, "client": "flood",
                                      "page": f"flood-{client:05d}"}))

            async def read_acks():
                nonlocal acked
                async for text in ws:
                    reply = json.loads(text)
                    if reply["type"] != "ack":
                        outcome["errors"][reply.get("code", "?")] += 1
                    elif reply.get("seq", 0) > 0:
                        acked += 1
                        if acked == len(frames):
                            return

            reader = asyncio.create_task(read_acks())
            try:
                for frame in frames:
                    await ws.send(frame)
                    # A send the kernel takes at once does not yield: without this, one client
                    # writes all its messages while the others, just connected, cannot even
                    # send their first, and a server cannot tell them from stalled sockets.
                    await asyncio.sleep(0)
            finally:
                await asyncio.gather(reader, return_exceptions=True)
            if reader.exception() is not None:
                raise reader.exception()
    except ConnectionClosed as closed:
        code = closed.rcvd.code if closed.rcvd else (closed.sent.code if closed.sent else 1006)
        reason = closed.rcvd.reason if closed.rcvd else ""
        outcome["closed"][f"{code} {reason}".strip()] += 1
    except OSError as error:
        outcome["closed"][f"connect failed: {error}"] += 1
    outcome["acked"] += acked


async def flood_part(ws_url: str, first: int, clients: int, messages: int,
                     version: str) -> dict:
    plans = [client_messages(n, messages, version) for n in range(first, first + clients)]
    outcome = {"acked": 0, "closed": collections.Counter(), "errors": collections.Counter()}
    await asyncio.gather(*(raw_client(ws_url, first + k, frames, outcome)
                           for k, (frames, _) in enumerate(plans)))
    outcome["samples_sent"] = sum(n for _, n in plans)
    return outcome


def flood_process(ws_url: str, first: int, clients: int, messages: int, version: str) -> dict:
    """:func:`flood_part` in a process of its own."""
    return asyncio.run(flood_part(ws_url, first, clients, messages, version))


def flood(ws_url: str, clients: int, messages: int, version: str, processes: int) -> dict:
    """``clients`` raw clients spread over ``processes`` client processes (one process of
    200 clients is itself the bottleneck on a loaded machine: a client not scheduled for
    seconds is one that has stalled, as far as any server can tell)."""
    spawn = multiprocessing.get_context("spawn")
    shares = [clients // processes + (k < clients % processes) for k in range(processes)]
    firsts = [sum(shares[:k]) for k in range(processes)]
    start = time.perf_counter()
    with concurrent.futures.ProcessPoolExecutor(processes, mp_context=spawn) as pool:
        parts = list(pool.map(flood_process, [ws_url] * processes, firsts, shares,
                              [messages] * processes, [version] * processes))
    outcome = {"acked": 0, "closed": collections.Counter(), "errors": collections.Counter(),
               "samples_sent": 0, "elapsed": time.perf_counter() - start}
    for part in parts:
        for key in ("acked", "samples_sent"):
            outcome[key] += part[key]
        outcome["closed"].update(part["closed"])
        outcome["errors"].update(part["errors"])
    return outcome


def stored(store: Path, first_client: int = 0) -> tuple[int, int]:
    """(distinct samples stored for the flood's clients, duplicated rows)."""
    with contextlib.closing(sqlite3.connect(store)) as db:
        rows = db.execute(
            "SELECT s.page, p.x, COUNT(*) FROM samples p JOIN strokes s ON s.id = p.stroke_id "
            "WHERE s.page LIKE 'flood-%' GROUP BY s.page, p.x").fetchall()
    return len(rows), sum(count - 1 for _, _, count in rows)


def print_flood(title: str, outcome: dict, distinct: int, duplicated: int, messages: int) -> None:
    sent = outcome["samples_sent"]
    print(f"{title}  (load average {os.getloadavg()[0]:.1f})")
    print(f"  {outcome['acked']:,} messages acknowledged in {outcome['elapsed']:.1f} s")
    print(f"  samples sent {sent:,}   stored {distinct:,}   lost {sent - distinct:,}   "
          f"duplicated {duplicated:,}")
    closed = ", ".join(f"{n} × {why}" for why, n in outcome["closed"].most_common()) or "none"
    print(f"  connections closed before the end: {closed}")
    if outcome["errors"]:
        print(f"  error replies: {dict(outcome['errors'])}")


def spin(stop) -> None:
    while not stop.is_set():
        sum(range(10_000))


def head_probe(url: str, header_bytes: int, concurrent: int) -> dict:
    """Send ``concurrent`` requests whose one header is ``header_bytes`` long; meanwhile poll
    ``/api/status`` and time the slowest answer. Returns the big heads' first answer lines and
    the slowest poll in ms."""
    parts = urlsplit(url)
    host, port = parts.hostname, parts.port
    token = dict(p.split("=", 1) for p in parts.query.split("&") if "=" in p).get("token")
    answers, slowest = [], 0.0
    stop = asyncio.Event()

    async def big(n: int):
        reader, writer = await asyncio.open_connection(host, port)
        writer.write(b"GET /api/status HTTP/1.1\r\nHost: x\r\nX-Big: ")
        chunk = b"a" * 65536
        sent = 0
        try:
            while sent < header_bytes:
                writer.write(chunk)
                await writer.drain()
                sent += len(chunk)
            writer.write(b"\r\n\r\n")
            await writer.drain()
        except (ConnectionError, OSError):
            pass
        try:
            line = await asyncio.wait_for(reader.readline(), 30)
        except (TimeoutError, ConnectionError, OSError):
            line = b""
        answers.append(line.decode("latin-1").strip() or "(connection closed, no answer)")
        writer.close()

    async def poll():
        nonlocal slowest
        query = f"?token={token}" if token else ""
        while not stop.is_set():
            start = time.perf_counter()
            reader, writer = await asyncio.open_connection(host, port)
            writer.write(f"GET /api/status{query} HTTP/1.1\r\nHost: {host}:{port}\r\n"
                         f"Connection: close\r\n\r\n".encode())
            await reader.read()
            writer.close()
            slowest = max(slowest, (time.perf_counter() - start) * 1000)
            await asyncio.sleep(0.1)

    async def run():
        poller = asyncio.create_task(poll())
        await asyncio.gather(*(big(n) for n in range(concurrent)))
        stop.set()
        await poller

    asyncio.run(run())
    return {"answers": collections.Counter(answers), "slowest_ms": slowest}


def stalled_websocket(url: str) -> float:
    """Open a WebSocket by hand, then neither send nor read: seconds until the server closes."""
    parts = urlsplit(url)
    sock = socket.create_connection((parts.hostname, parts.port))
    query = f"?{parts.query}" if parts.query else ""
    sock.sendall(f"GET /ws{query} HTTP/1.1\r\nHost: {parts.hostname}:{parts.port}\r\n"
                 f"Upgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Version: 13\r\n"
                 f"Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n\r\n".encode())
    start = time.monotonic()
    sock.settimeout(120)
    with contextlib.suppress(OSError):
        while sock.recv(65536):  # the handshake answer and pings arrive; none is answered
            pass
    sock.close()
    return time.monotonic() - start


def rss_mib(pid: int) -> float:
    with open(f"/proc/{pid}/status") as status:
        for line in status:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clients", type=int, default=200)
    parser.add_argument("--messages", type=int, default=3000)
    parser.add_argument("--client-processes", type=int, default=4,
                        help="processes the raw clients are spread over")
    parser.add_argument("--long", type=int, default=0, help="messages of one raw client alone")
    parser.add_argument("--heads", action="store_true", help="run the head and stall probes")
    parser.add_argument("--load", type=int, default=0, help="busy processes during the runs")
    parser.add_argument("--lan", action="store_true", help="serve with --lan (a token)")
    args = parser.parse_args()
    stop = multiprocessing.Event()
    spinners = [multiprocessing.Process(target=spin, args=(stop,), daemon=True)
                for _ in range(args.load)]
    for spinner in spinners:
        spinner.start()
    version = resolve_profile("pencil").version
    with tempfile.TemporaryDirectory() as folder:
        process, url = start_server(Path(folder), *(["--lan"] if args.lan else []))
        query = urlsplit(url).query
        ws_url = url.split("?")[0].replace("http://", "ws://") + "ws" + (f"?{query}" if query
                                                                        else "")
        store = Path(folder) / "bench.sqlite3"
        try:
            if args.clients and args.messages:
                outcome = flood(ws_url, args.clients, args.messages, version,
                                args.client_processes)
                print_flood(f"raw flood: {args.clients} clients × {args.messages} messages, "
                            f"no window, in {args.client_processes} client processes, "
                            f"{args.load} busy processes", outcome,
                            *stored(store), args.messages)
            if args.long:
                with contextlib.closing(sqlite3.connect(store)) as db:
                    db.execute("DELETE FROM samples")
                    db.execute("DELETE FROM strokes")
                    db.commit()
                outcome = flood(ws_url, 1, args.long, version, 1)
                print_flood(f"one raw client × {args.long} messages, {args.load} busy processes",
                            outcome, *stored(store), args.long)
            if args.heads:
                one = head_probe(url, 128 * 2**20, 1)
                print(f"one 128 MB header: answered {dict(one['answers'])}; a page's slowest "
                      f"/api/status meanwhile {one['slowest_ms']:.0f} ms")
                twenty = head_probe(url, 64 * 2**20, 20)
                print(f"twenty 64 MB headers: answered {dict(twenty['answers'])}; slowest "
                      f"/api/status {twenty['slowest_ms']:.0f} ms; server peak RSS "
                      f"{rss_mib(process.pid):.0f} MiB")
                print(f"a WebSocket silent after its handshake was closed after "
                      f"{stalled_websocket(url):.1f} s")
        finally:
            process.send_signal(signal.SIGINT)
            log = process.communicate(timeout=30)[0].strip().splitlines()
            stop.set()
    if log:
        print(f"the server's log ({len(log)} lines, the last 5):")
        for line in log[-25:]:
            print(f"  {line[:200]}")


if __name__ == "__main__":
    main()
