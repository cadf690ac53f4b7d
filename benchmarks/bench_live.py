"""Latency of the live app on loopback: pen event → server, and → the (simulated) pen device.

Starts ``realpen serve`` in a subprocess (a fresh store in a temporary folder), opens a WebSocket
like a page, puts the pen down, and sends 1000 pen events one at a time as the page does: a
``gain`` message, then a ``samples`` batch (4 samples) that the server stores, each waiting for
its ack. For every event it measures

- event → server: the server's receive time of the gain (``ack.server_ns``) minus its send time;
- event → device: the simulated device's arrival time (``/api/device/log``) minus the send time;
- round trips: until the gain's ack, and the samples' ack (after the SQLite commit), are back.

Both processes read ``time.monotonic_ns()`` (CLOCK_MONOTONIC, shared by all processes on Linux),
so the one-way figures need no clock sync. Target: p99 < 5 ms on the device path.

Then, with Chromium at /usr/bin/chromium and Playwright, it opens the page, draws a 300-event
pen stroke through the DevTools protocol and prints the page's own WebSocket round trips and its
AudioContext's sample rate, base latency and output latency (as reported; headless Chromium has
no sound card, so the output latency is its nominal figure).

Usage: python benchmarks/bench_live.py [--events 1000] [--no-browser]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import select
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx
import numpy as np
from websockets.sync.client import connect

from realpen.profile import resolve_profile

TARGET_MS = 5.0
CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                 "--no-first-run", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync",
                 "--autoplay-policy=no-user-gesture-required"]


def start_server(folder: Path) -> tuple[subprocess.Popen, str]:
    env = {**os.environ, "REALPEN_HOME": str(folder / "home"), "PYTHONUNBUFFERED": "1"}
    process = subprocess.Popen([sys.executable, "-m", "realpen.cli", "serve", "--port", "0",
                                "--store", str(folder / "bench.sqlite3")],
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
              "profile_version": pencil.version, "modality": "auditory-tactile",
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
    log = httpx.get(base + "api/device/log", params={"limit": 100_000}).json()["entries"]
    to_device = [e["at_ns"] - gain_sent[e["seq"]] for e in log
                 if e["session"] == session and e["kind"] == "gain" and e["seq"] in gain_sent]
    assert len(to_device) == events, (len(to_device), events)
    return {"to_server": to_server, "to_device": to_device, "gain_rtt": gain_rtt,
            "samples_rtt": samples_rtt}


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
        page.wait_for_function("window.realpen && realpen.ready && realpen.link.state === 'open'")
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
        page.wait_for_function("!realpen.down && realpen.link.acked === realpen.link.sent")
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
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        process, url = start_server(Path(folder))
        try:
            figures = measure(url, args.events)
            print(f"{args.events} events on loopback (one at a time, after a 50-event warm-up):")
            print(f"  event -> server            {percentiles(figures['to_server'])}")
            print(f"  event -> simulated device  {percentiles(figures['to_device'])}")
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
