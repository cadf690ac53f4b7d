"""Latency to the pen: the page's pen_down message → SET_STATE at the pen, and a 24 KB upload.

The live app runs in a child process (the same app ``realpen serve --device sim`` builds,
:func:`realpen.live.device.open_device`, under uvicorn on loopback), driving the simulated pen:
the real firmware (``firmware/pico``) under the MicroPython Unix port on a pseudo-terminal, with
a trace. A WebSocket client does what the page does on a pointer-down: it sends ``pen_down``,
then a ``gain`` and a ``pen_up``, each waiting for its ack and ``--gap-ms`` apart, for
``--strokes`` strokes (after a warm-up stroke, which uploads the pattern). The firmware's trace
has the SET_STATE each block of its player (16 samples, 2 ms) applied, with the time its frame
was decoded; the gap keeps every frame in a block of its own. For every stroke

- page message (pen_down) → SET_STATE: the firmware's receipt of the stroke's
  ``SET_STATE(playing=1)`` (``t_ns`` in its trace) minus the time the page's ``pen_down``
  WebSocket message was sent;
- page message (gain) → SET_STATE: the same for the stroke's gain;
- the warm-up stroke's page message (pen_down) → SET_STATE, which waited for the pattern's
  upload (what a change of pen costs: the new pen's pattern is uploaded at its first pen-down).

The clock starts when the WebSocket message is sent: there is no browser, so the pointer event's
way through the browser to the page's send is not in these figures. Both sides read
``time.time_ns()`` (CLOCK_REALTIME, one clock on one machine), so the one-way figures need no
clock sync. The path: WebSocket → the server's session → the bridge's queue → its worker thread
→ pyserial → the pseudo-terminal → the firmware's decoder.

Then the time to upload a 24 KB pattern (1.5 s at 8 kHz, int16: the pencil's) with
:meth:`realpen.device.client.PenClient.upload` straight over the pseudo-terminal (BEGIN, 134
chunks of 180 bytes, a PING every 16 chunks, COMMIT, each ACK awaited), ``--uploads`` times.

Usage: python benchmarks/bench_device.py [--strokes 1000] [--uploads 10] [--gap-ms 10]
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import signal
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from websockets.sync.client import connect

from realpen.device.sim import read_trace
from realpen.profile import resolve_profile


def serve_sim(trace: str, store: str, home: str, ports) -> None:
    """The child process: the live app with ``--device sim`` (and a trace) on a free port."""
    os.environ["REALPEN_HOME"] = home
    from realpen.live.app import LiveSettings, create_app
    from realpen.live.device import open_device
    from realpen.live.server import bind, run

    device = open_device("sim", trace=Path(trace))
    app = create_app(LiveSettings.loopback(store=Path(store), device=device))
    sock = bind("127.0.0.1", 0)
    device.wait_attempted(10)
    ports.put((sock.getsockname()[1], device.status()))
    try:
        run(app, sock)  # until SIGINT: the app's shutdown stops the firmware
    except KeyboardInterrupt:  # uvicorn re-raises the signal after its graceful stop
        pass
    finally:
        sock.close()




def percentiles(values_ns: list[int]) -> str:
    ms = np.asarray(values_ns, dtype=np.float64) / 1e6
    return (f"p50 {np.percentile(ms, 50):.3f} ms, p99 {np.percentile(ms, 99):.3f} ms, "
            f"max {ms.max():.3f} ms (n={len(ms)})")


def stroke_latency(strokes: int, gap_ms: float, folder: Path) -> dict:
    """pen_down → SET_STATE(playing=1) and gain → SET_STATE(gain) over ``strokes`` strokes."""
    trace = folder / "trace.jsonl"
    context = multiprocessing.get_context("spawn")
    ports = context.Queue()
    child = context.Process(target=serve_sim, args=(str(trace), str(folder / "s.sqlite3"),
                                                    str(folder / "home"), ports))
    child.start()
    try:
        port, status = ports.get(timeout=60)
        if not status["connected"]:
            raise SystemExit(f"the simulated pen did not connect: {status['message']}")
        pencil = resolve_profile("pencil")
        coupling = pencil.meta.coupling
        target = coupling.a_max * 0.5
        down_sent, gain_sent, up_sent = [], [], []
        seq = 0
        with connect(f"ws://127.0.0.1:{port}/ws", max_size=None) as ws:
            def send(message: dict) -> int:
                nonlocal seq
                seq += 1
                message["seq"] = seq
                text = json.dumps(message)
                sent = time.time_ns()
                ws.send(text)
                reply = json.loads(ws.recv(timeout=10))
                if reply["type"] != "ack":
                    raise SystemExit(f"the server refused {message['type']}: {reply}")
                return sent

            send({"type": "hello", "client": "bench_device", "page": "bench-page"})
            for stroke in range(strokes + 1):  # stroke 0: the warm-up (it uploads the pattern)
                t = 10.0 + stroke
                down = send({"type": "pen_down", "stroke": stroke + 1, "t": t, "pen": "pencil",
                             "profile_version": pencil.version, "modality": "audio-tactile",
                             "ink": "visible", "pointer_type": "pen", "px_per_mm": 4.0,
                             "calibrated": True})
                time.sleep(gap_ms / 1000 if stroke else 0.5)  # the warm-up's upload
                gain = send({"type": "gain", "stroke": stroke + 1, "t": t + 0.004,
                             "target": target})
                time.sleep(gap_ms / 1000)
                up = send({"type": "pen_up", "stroke": stroke + 1, "t": t + 0.008})
                time.sleep(gap_ms / 1000)
                down_sent.append(down)
                gain_sent.append(gain)
                up_sent.append(up)
        deadline = time.monotonic() + 10
        while True:  # the last SET_STATEs reach the trace within milliseconds
            states = [e for e in read_trace(trace) if e["event"] == "set_state"]
            if (states and states[-1]["playing"] == 0 and states[-1]["t_ns"] >= up_sent[-1]) \
                    or time.monotonic() > deadline:
                break
            time.sleep(0.05)
    finally:
        if child.is_alive():
            os.kill(child.pid, signal.SIGINT)
        child.join(30)
    return match(states, down_sent, gain_sent, up_sent) | {"info": status["info"]}


def match(states: list[dict], down_sent: list[int], gain_sent: list[int],
          up_sent: list[int]) -> dict:
    """Each stroke's pen-down SET_STATE (playing, gain 0: the first after its pen_down and
    before its pen_up) and gain SET_STATE (playing, gain > 0: the first after its gain and
    before the next stroke), in ns after the message was sent.

    Stroke 0 is the warm-up: its pen-down delay is ``first`` (None when hidden) and its gain is
    left out. A SET_STATE decoded in the same player block as the next one is not in the trace
    (the block applies the last); such strokes are counted as ``hidden`` and left out.
    """
    times = np.asarray([e["t_ns"] for e in states], dtype=np.int64)
    found = {"down": [], "gain": [], "hidden_down": 0, "hidden_gain": 0, "first": None}
    for k in range(len(down_sent)):
        after = down_sent[k + 1] if k + 1 < len(down_sent) else 2**62
        for kind, start, stop, wanted in (("down", down_sent[k], up_sent[k], True),
                                          ("gain", gain_sent[k], after, False)):
            lo, hi = np.searchsorted(times, [start, stop])
            hits = [e for e in states[lo:hi] if e["playing"] == 1 and
                    (e["gain"] == 0 if wanted else e["gain"] != 0)]
            delay = hits[0]["t_ns"] - start if hits else None
            if k == 0:  # the warm-up: its own figure, never one of the strokes'
                if kind == "down":
                    found["first"] = delay
            elif delay is not None:
                found[kind].append(delay)
            else:
                found[f"hidden_{kind}"] += 1
    if not found["down"] or not found["gain"]:
        raise SystemExit("the trace has no SET_STATE of the strokes")
    return found


def upload_time(uploads: int) -> dict:
    """Seconds to upload the pencil's pattern at the pen's rate, straight over the pty."""
    from realpen.device.client import PenClient
    from realpen.device.pattern import pen_pattern
    from realpen.device.sim import SimPen
    from realpen.device.transport import open_transport

    pencil, ballpoint = resolve_profile("pencil"), resolve_profile("ballpoint")
    with SimPen() as pen, PenClient(open_transport(pen.port)) as client:
        info = client.hello()
        patterns = [pen_pattern(p, info.sample_rate) for p in (pencil, ballpoint)]
        seconds = []
        for k in range(uploads):
            samples = patterns[k % 2]  # a different pattern each time, as a change of pen
            start = time.perf_counter()
            client.upload(samples, info.sample_rate)
            seconds.append(time.perf_counter() - start)
    return {"seconds": seconds, "bytes": patterns[0].nbytes, "rate": info.sample_rate}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--strokes", type=int, default=1000)
    parser.add_argument("--uploads", type=int, default=10)
    parser.add_argument("--gap-ms", type=float, default=10.0,
                        help="pause after each message (ms); the trace has the SET_STATE each "
                             "2 ms block of the player applied, so messages closer than two "
                             "blocks would hide each other")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="bench_device_") as tmp:
        figures = stroke_latency(args.strokes, args.gap_ms, Path(tmp))
    info = figures["info"]
    print(f"simulated pen: {info['name']} firmware {'.'.join(map(str, info['firmware']))}, "
          f"{info['sample_rate']} Hz, MicroPython Unix port on a pseudo-terminal")
    print(f"{args.strokes} strokes through the live server (WebSocket → bridge → pty → "
          f"firmware), after a warm-up stroke; the clock starts at the page's WebSocket send "
          f"(a script, no browser):")
    print(f"  page message (pen_down) → SET_STATE at the pen  {percentiles(figures['down'])}")
    print(f"  page message (gain)     → SET_STATE at the pen  {percentiles(figures['gain'])}")
    hidden = figures["hidden_down"] + figures["hidden_gain"]
    if hidden:
        print(f"  ({figures['hidden_down']} pen-down and {figures['hidden_gain']} gain SET_STATEs "
              f"left out: decoded in the same 2 ms block as the next, the trace has only that)")
    first = figures["first"]
    first_text = (f"{first / 1e6:.1f} ms" if first is not None
                  else "not in the trace (decoded in the block of the next)")
    print(f"  the warm-up stroke, a new pen: page message (pen_down) → SET_STATE at the pen "
          f"behind the 24 KB upload: {first_text}")
    upload = upload_time(args.uploads)
    seconds = upload["seconds"]
    median = statistics.median(seconds)
    print(f"upload of {upload['bytes']} bytes ({upload['bytes'] / 2 / upload['rate']:g} s at "
          f"{upload['rate']} Hz) over the pty, {len(seconds)} times: median {median * 1e3:.1f} "
          f"ms, min {min(seconds) * 1e3:.1f} ms, max {max(seconds) * 1e3:.1f} ms "
          f"({upload['bytes'] / median / 1024:.0f} KiB/s)")
    sys.stdout.flush()


if __name__ == "__main__":
    main()
