"""Latency of the live app on loopback: pen event → server, and → the device seam (its log).

Starts ``realpen serve`` in a subprocess (a fresh store in a temporary folder), opens a WebSocket
like a page, puts the pen down, and sends 1000 pen events one at a time as the page does: a
``gain`` message, then a ``samples`` batch (4 samples) that the server stores, each waiting for
its ack. For every event it measures

- event → server: the server's receive time of the gain (``ack.server_ns``) minus its send time;
- event → device: the device command log's arrival time (``/api/device/log``) minus the send time;
- round trips: until the gain's ack, and the samples' ack (after the SQLite commit), are back.

Both processes read ``time.monotonic_ns()`` (CLOCK_MONOTONIC, shared by all processes on Linux),
so the one-way figures need no clock sync. Target: p99 < 5 ms on the device path.

Then, with Chromium at /usr/bin/chromium and Playwright, it opens the page, draws a 300-event
pen stroke through the DevTools protocol and prints the page's own WebSocket round trips and its
AudioContext's sample rate, base latency and output latency (as reported; headless Chromium has
no sound card, so the output latency is its nominal figure).

Under load (``--pages``, default 200): that many pages connect at once and each sends
``--messages`` (default 1000) as the page's ``link.js`` does — pen-downs, gains and numbered
sample batches, at most 64 unacknowledged, everything kept until acknowledged. Every tenth page
loses its connection once halfway (the socket is aborted) and, like the page, reconnects and
sends again what was not acknowledged. Meanwhile ``--hostile`` (default 20) pages flood the
server and never read a reply, and a newcomer page connects and sends 20 gains one at a time.
It prints messages and samples sent, samples stored, lost (sent, never stored) and duplicated
(stored more than once), the newcomer's connect time and round trips, and the largest WAL
journal seen during the run (polled every 20 ms; goal under 64 MB).

Usage: python benchmarks/bench_live.py [--events 1000] [--pages 200] [--messages 1000]
       [--hostile 20] [--no-browser] [--no-load]
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
import re
import select
import signal
import sqlite3
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx
import numpy as np
from websockets.asyncio.client import connect as async_connect
from websockets.sync.client import connect

from realpen.profile import resolve_profile

TARGET_MS = 5.0
WAL_GOAL_BYTES = 64 * 1024 * 1024
WINDOW = 64  # as link.js
SAMPLES_PER_BATCH = 4
MESSAGES_PER_STROKE = 100
CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                 "--no-first-run", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync",
                 "--autoplay-policy=no-user-gesture-required"]


def start_server(folder: Path, *options: str) -> tuple[subprocess.Popen, str]:
    """``realpen serve`` on a free port with the store ``folder/bench.sqlite3`` (and
    ``options``); returns the process and the URL it printed."""
    env = {**os.environ, "REALPEN_HOME": str(folder / "home"), "PYTHONUNBUFFERED": "1"}
    process = subprocess.Popen([sys.executable, "-m", "realpen.cli", "serve", "--port", "0",
                                "--store", str(folder / "bench.sqlite3"), *options],
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                               env=env)
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and process.poll() is None:
        if select.select([process.stdout], [], [], 0.2)[0]:
            match = re.search(r"RealPen live: (http://\S+)", process.stdout.readline())
            if match:
                return process, match.group(1)
    process.kill()
    raise SystemExit(f"realpen serve did not start: {process.stdout.read()}")


def percentiles(values_ns) -> str:
    ms = np.asarray(values_ns, dtype=np.float64) / 1e6
    return (f"p50 {np.percentile(ms, 50):6.3f} ms   p99 {np.percentile(ms, 99):6.3f} ms   "
            f"max {ms.max():6.3f} ms")


def measure(url: str, events: int, warmup: int = 50) -> dict:
    pencil = resolve_profile("pencil")
    base = url.split("?")[0]
    with connect(base.replace("http://", "ws://") + "ws") as ws:
        def call(message: dict) -> tuple[int, dict, int]:
            sent = time.monotonic_ns()
            ws.send(json.dumps(message))
            reply = json.loads(ws.recv(timeout=5))
            return sent, reply, time.monotonic_ns()

        _, hello, _ = call({"type": "hello", "seq": 0, "client": "bench_live"})
        session = hello["session"]
        call({"type": "pen_down", "seq": 1, "stroke": 1, "t": 0.0, "pen": "pencil",
              "profile_version": pencil.version, "modality": "audio-tactile",
              "px_per_mm": 4.0})
        gain_sent, to_server, gain_rtt, samples_rtt = {}, [], [], []
        for i in range(warmup + events):  # as the page does: a gain, then the samples
            seq = 2 + 2 * i
            sent, reply, back = call({"type": "gain", "seq": seq, "stroke": 1, "t": i * 0.004,
                                      "target": (i % 200) / 100})
            assert reply["type"] == "ack", reply
            batch = [{"t": i * 0.004 + j * 0.001, "x": 10.0 + i * 0.1, "y": 20.0, "pressure": 0.5,
                      "tilt_x": 10.0, "tilt_y": 0.0, "speed": 50.0} for j in range(4)]
            stored_sent, stored, stored_back = call({"type": "samples", "seq": seq + 1,
                                                     "stroke": 1, "samples": batch})
            assert stored["type"] == "ack", stored
            if i >= warmup:
                gain_sent[seq] = sent
                to_server.append(reply["server_ns"] - sent)
                gain_rtt.append(back - sent)
                samples_rtt.append(stored_back - stored_sent)
        call({"type": "pen_up", "seq": 2 + 2 * (warmup + events), "stroke": 1, "t": 9.0})
    log = device_log(base)
    to_device = [e["at_ns"] - gain_sent[e["seq"]] for e in log
                 if e["session"] == session and e["kind"] == "gain" and e["seq"] in gain_sent]
    assert len(to_device) == events, (len(to_device), events)
    return {"to_server": to_server, "to_device": to_device, "gain_rtt": gain_rtt,
            "samples_rtt": samples_rtt}


def device_log(base: str) -> list[dict]:
    """Every entry of the device log, page by page."""
    entries, since = [], 0
    while True:
        page = httpx.get(base + "api/device/log", params={"since": since}).json()
        entries += page["entries"]
        if not page["entries"] or page["next"] >= page["count"]:
            return entries
        since = page["next"]


def page_messages(page_no: int, count: int, version: str) -> tuple[list[dict], int]:
    """The messages one page sends (without ``seq``), and how many samples they carry.

    Strokes of :data:`MESSAGES_PER_STROKE` messages: a pen-down, then gains and sample batches
    in turn, then a pen-up. A sample's ``x`` is its page-wide number, so a duplicate is seen.
    """
    messages, samples, stroke, index = [], 0, 0, 0
    for i in range(count):
        position = i % MESSAGES_PER_STROKE
        if position == 0:
            stroke, index = stroke + 1, 0
            messages.append({"type": "pen_down", "stroke": stroke, "t": i * 0.004, "pen": "pencil",
                             "profile_version": version, "modality": "audio-tactile",
                             "px_per_mm": 4.0})
        elif position == MESSAGES_PER_STROKE - 1 or i == count - 1:
            messages.append({"type": "pen_up", "stroke": stroke, "t": i * 0.004 + 0.003})
        elif position % 2:
            messages.append({"type": "gain", "stroke": stroke, "t": i * 0.004, "target": 0.5})
        else:
            batch = [{"t": i * 0.004 + j * 0.001, "x": float(samples + j), "y": float(page_no),
                      "pressure": 0.5, "tilt_x": 0.0, "tilt_y": 0.0, "speed": 50.0}
                     for j in range(SAMPLES_PER_BATCH)]
            messages.append({"type": "samples", "stroke": stroke, "index": index,
                             "samples": batch})
            samples += SAMPLES_PER_BATCH
            index += SAMPLES_PER_BATCH
    return messages, samples


async def run_page(ws_url: str, page_no: int, messages: list[dict], drop_at: int | None,
                   counters: dict) -> None:
    """Send ``messages`` as link.js does: a window of unacknowledged messages, each kept until
    acknowledged, and everything unacknowledged sent again after a reconnect."""
    page_id = f"bench-page-{page_no:05d}"
    texts = [json.dumps({**m, "seq": seq + 1}) for seq, m in enumerate(messages)]
    next_to_send, acked = 0, set()
    connections = 0
    while len(acked) < len(texts):
        connections += 1
        async with async_connect(ws_url, max_size=2**22, ping_interval=None,
                                 open_timeout=120, compression=None) as ws:
            await ws.send(json.dumps({"type": "hello", "seq": 0, "client": "bench",
                                      "page": page_id}))
            reply = json.loads(await ws.recv())
            assert reply["type"] == "ack", reply
            # Everything not acknowledged goes again, in order.
            queue = collections.deque(i for i in range(next_to_send) if i not in acked)
            counters["resent"] += len(queue)
            in_flight: set[int] = set()
            try:
                while len(acked) < len(texts):
                    while len(in_flight) < WINDOW and (queue or next_to_send < len(texts)):
                        i = queue.popleft() if queue else next_to_send
                        if i == next_to_send:
                            next_to_send += 1
                        await ws.send(texts[i])
                        counters["sent"] += 1
                        in_flight.add(i)
                        if drop_at is not None and i == drop_at and connections == 1:
                            ws.transport.abort()  # the network goes away mid-stroke
                            counters["drops"] += 1
                            raise ConnectionError
                    reply = json.loads(await ws.recv())
                    if reply["type"] != "ack":
                        raise SystemExit(f"page {page_no}: {reply}")
                    acked.add(reply["seq"] - 1)
                    in_flight.discard(reply["seq"] - 1)
            except Exception:  # the connection went away: reconnect and resend
                continue


async def run_hostile(ws_url: str, number: int, version: str, stop: asyncio.Event) -> int:
    """Flood without ever reading a reply; returns messages sent."""
    sent = 0
    try:
        async with async_connect(ws_url, ping_interval=None, compression=None,
                                 open_timeout=120, max_queue=1) as ws:
            await ws.send(json.dumps({"type": "pen_down", "seq": 0, "stroke": 1, "t": 0.0,
                                      "pen": "pencil", "profile_version": version,
                                      "modality": "none", "px_per_mm": 4.0}))
            batch = [{"t": 0.0, "x": 0.0, "y": 0.0, "pressure": 0.5, "speed": 0.0}] * 64
            while not stop.is_set():
                sent += 1
                await asyncio.wait_for(ws.send(json.dumps(
                    {"type": "samples", "seq": sent, "stroke": 1, "samples": batch})), 1.0)
    except (TimeoutError, OSError, Exception):
        pass  # the server stopped reading this page (backpressure) or closed it
    return sent


async def newcomer(ws_url: str, delay_s: float) -> dict:
    """Connect while the others flood, then 20 gains one at a time (ms figures)."""
    await asyncio.sleep(delay_s)
    start = time.perf_counter()
    async with async_connect(ws_url, ping_interval=None, compression=None,
                             open_timeout=60) as ws:
        await ws.send(json.dumps({"type": "hello", "seq": 0, "client": "newcomer"}))
        await ws.recv()
        connect_ms = (time.perf_counter() - start) * 1000
        version = resolve_profile("pencil").version
        await ws.send(json.dumps({"type": "pen_down", "seq": 1, "stroke": 1, "t": 0.0,
                                  "pen": "pencil", "profile_version": version,
                                  "modality": "tactile", "px_per_mm": 4.0}))
        await ws.recv()
        rtts = []
        for k in range(20):
            sent = time.perf_counter()
            await ws.send(json.dumps({"type": "gain", "seq": 2 + k, "stroke": 1, "t": k * 0.01,
                                      "target": 0.5}))
            await ws.recv()
            rtts.append((time.perf_counter() - sent) * 1000)
    return {"connect_ms": connect_ms, "rtt_ms": rtts}


def newcomer_process(ws_url: str, delay_s: float) -> dict:
    """:func:`newcomer` in a process of its own."""
    return asyncio.run(newcomer(ws_url, delay_s))


async def overload(url: str, store: Path, pages: int, messages: int, hostile: int) -> dict:
    ws_url = url.split("?")[0].replace("http://", "ws://") + "ws"
    version = resolve_profile("pencil").version
    plans = [page_messages(n, messages, version) for n in range(pages)]
    counters = {"sent": 0, "resent": 0, "drops": 0}
    largest_wal, stop = 0, asyncio.Event()

    async def watch_wal():
        nonlocal largest_wal
        while not stop.is_set():
            with contextlib.suppress(OSError):
                largest_wal = max(largest_wal, os.stat(f"{store}-wal").st_size)
            await asyncio.sleep(0.02)

    watcher = asyncio.create_task(watch_wal())
    hostiles = [asyncio.create_task(run_hostile(ws_url, n, version, stop))
                for n in range(hostile)]
    # The newcomer runs in its own process: in this one it would wait for the flooding pages'
    # coroutines, and the figure would be the client's delay, not the server's.
    spawn = multiprocessing.get_context("spawn")
    pool = concurrent.futures.ProcessPoolExecutor(1, mp_context=spawn)
    late = asyncio.get_running_loop().run_in_executor(pool, newcomer_process, ws_url, 2.0)
    start = time.perf_counter()
    await asyncio.gather(*(run_page(ws_url, n, plan, messages // 2 if n % 10 == 0 else None,
                                    counters) for n, (plan, _) in enumerate(plans)))
    elapsed = time.perf_counter() - start
    late_figures = await late
    pool.shutdown()
    stop.set()
    hostile_sent = sum(await asyncio.gather(*hostiles))
    await watcher
    return {"elapsed": elapsed, "counters": counters, "largest_wal": largest_wal,
            "samples_sent": sum(n for _, n in plans), "newcomer": late_figures,
            "hostile_sent": hostile_sent}


def stored_samples(store: Path, pages: int) -> tuple[int, int]:
    """(distinct samples stored for the load's pages, duplicated rows)."""
    with contextlib.closing(sqlite3.connect(store)) as db:
        rows = db.execute(
            "SELECT s.page, p.x, COUNT(*) FROM samples p JOIN strokes s ON s.id = p.stroke_id "
            "WHERE s.page LIKE 'bench-page-%' GROUP BY s.page, p.x").fetchall()
    return len(rows), sum(count - 1 for _, _, count in rows)


def print_overload(figures: dict, distinct: int, duplicated: int, pages: int,
                   messages: int) -> None:
    counters, late = figures["counters"], figures["newcomer"]
    sent = figures["samples_sent"]
    rtt = np.asarray(late["rtt_ms"])
    print(f"overload: {pages} pages x {messages} messages at once (window {WINDOW}, "
          f"{counters['drops']} pages lost their connection once and resent), "
          f"{figures['hostile_sent']} messages from hostile pages that never read")
    print(f"  messages sent {counters['sent']:,} ({counters['resent']:,} of them resent) in "
          f"{figures['elapsed']:.1f} s = {counters['sent'] / figures['elapsed']:,.0f} messages/s")
    print(f"  samples sent {sent:,}   stored {distinct:,}   lost {sent - distinct:,}   "
          f"duplicated {duplicated:,}")
    print(f"  newcomer under load: connect {late['connect_ms']:.0f} ms, gain round trip "
          f"median {np.median(rtt):.1f} ms, max {rtt.max():.1f} ms")
    wal = figures["largest_wal"]
    verdict = "met" if wal < WAL_GOAL_BYTES else "MISSED"
    print(f"  largest WAL journal during the run: {wal / 2**20:.1f} MB "
          f"(goal < {WAL_GOAL_BYTES / 2**20:.0f} MB: {verdict})")


def browser_figures(url: str) -> None:
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        print("browser: playwright is not installed; skipped")
        return
    if not CHROMIUM.exists():
        print(f"browser: {CHROMIUM} is missing; skipped")
        return
    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        page = browser.new_page(viewport={"width": 1180, "height": 820})
        page.goto(url)
        page.wait_for_function("() => window.realpen && realpen.ready && realpen.link.state === 'open'")
        cdp = page.context.new_cdp_session(page)
        box = page.locator("#ink").bounding_box()
        t0 = time.time()

        def pen(kind, i):
            cdp.send("Input.dispatchMouseEvent", {
                "type": kind, "x": box["x"] + 50 + i, "y": box["y"] + 200, "button": "left",
                "buttons": 0 if kind == "mouseReleased" else 1, "clickCount": 1,
                "pointerType": "pen", "force": 0.6, "timestamp": t0 + i * 0.004})

        pen("mousePressed", 0)
        for i in range(1, 300):
            pen("mouseMoved", i)
        pen("mouseReleased", 300)
        page.wait_for_function("() => !realpen.down && realpen.link.acked === realpen.link.sent")
        audio = page.evaluate("realpen.audio")
        rtt = np.array(page.evaluate("realpen.link.rtt"), dtype=np.float64)
        browser.close()
    print(f"page WebSocket round trip (last {len(rtt)} messages, ms, 0.1 ms timer): "
          f"p50 {np.percentile(rtt, 50):.2f}  p99 {np.percentile(rtt, 99):.2f}")
    base = audio["baseLatency"]
    output = audio["outputLatency"]
    print(f"AudioContext (latencyHint 'interactive', state {audio['state']}): "
          f"{audio['sampleRate']} Hz, baseLatency {base * 1000:.1f} ms, "
          f"outputLatency {output * 1000:.1f} ms")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--events", type=int, default=1000)
    parser.add_argument("--no-browser", action="store_true")
    parser.add_argument("--no-load", action="store_true", help="skip the overload run")
    parser.add_argument("--pages", type=int, default=200)
    parser.add_argument("--messages", type=int, default=1000)
    parser.add_argument("--hostile", type=int, default=20)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        process, url = start_server(Path(folder))
        try:
            if not args.no_load:
                store = Path(folder) / "bench.sqlite3"
                load = asyncio.run(overload(url, store, args.pages, args.messages,
                                            args.hostile))
                distinct, duplicated = stored_samples(store, args.pages)
                print_overload(load, distinct, duplicated, args.pages, args.messages)
            figures = measure(url, args.events)
            print(f"{args.events} events on loopback (one at a time, after a 50-event warm-up):")
            print(f"  event -> server            {percentiles(figures['to_server'])}")
            print(f"  event -> device (log)      {percentiles(figures['to_device'])}")
            print(f"  gain round trip (ack)      {percentiles(figures['gain_rtt'])}")
            print(f"  samples round trip, stored {percentiles(figures['samples_rtt'])}"
                  f"   (4 samples, SQLite commit)")
            p99 = np.percentile(np.asarray(figures["to_device"]) / 1e6, 99)
            verdict = "met" if p99 < TARGET_MS else "MISSED"
            print(f"  target p99 < {TARGET_MS:g} ms on the device path: {verdict} ({p99:.3f} ms)")
            if not args.no_browser:
                browser_figures(url)
        finally:
            process.send_signal(signal.SIGINT)
            process.wait(timeout=20)


if __name__ == "__main__":
    main()
