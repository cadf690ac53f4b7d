"""Helpers for the live-app tests: a real ``realpen serve`` in a subprocess, pen messages."""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import re
import select
import signal
import sqlite3
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from realpen.exports.base import resample_loop
from realpen.profile import PenProfile, resolve_profile, save_profile

URL_LINE = re.compile(r"RealPen live: (http://\S+)")
LOCAL = "http://127.0.0.1"
WS = "ws://127.0.0.1/ws"


def talk(ws, message: dict) -> dict:
    """Send one message on a TestClient WebSocket and return the reply."""
    ws.send_text(json.dumps(message))
    return json.loads(ws.receive_text())


def rows(path, sql: str, *args) -> list[tuple]:
    """The rows of ``sql`` on the SQLite file at ``path``."""
    with sqlite3.connect(path) as db:
        return db.execute(sql, args).fetchall()


@dataclass
class Served:
    """A running server: its printed URL, base URL (no query), token, and process."""

    url: str
    base: str
    token: str | None
    process: subprocess.Popen
    output: list[str]
    stderr: Path | None = None

    def errors(self) -> str:
        """What the server wrote to stderr (when started with ``stderr_to``)."""
        return self.stderr.read_text() if self.stderr else ""

    def stop(self, sig: int = signal.SIGINT, timeout: float = 20) -> str:
        """Send ``sig``, wait for exit, return the rest of stdout."""
        if self.process.poll() is None:
            self.process.send_signal(sig)
        self.process.wait(timeout=timeout)
        self.output.append(self.process.stdout.read())  # buffered lines included
        return "".join(self.output)


# ``python -m realpen`` held back: it imports what ``realpen serve`` imports (most of a server's
# start-up) and then waits for a line on stdin before it reads its arguments or opens the store.
WARM_REALPEN = """
import sys
import realpen.cli, realpen.live.app, realpen.live.device, realpen.live.server, realpen.study.db
import alembic.command, alembic.config, scipy.signal
sys.stdin.readline()
from realpen.cli import main
main()
"""


@dataclass
class Spare:
    """A ``realpen serve`` started ahead of time (:func:`spare_server`), waiting to be run by
    :func:`serve`."""

    process: subprocess.Popen
    errors: object | None
    stderr_to: Path | None


def _launch(tmp_path: Path, args: tuple[str, ...], stderr_to: Path | None,
            program: list[str] | None, held: bool = False):
    env = {**os.environ, "REALPEN_HOME": str(tmp_path / "home"), "PYTHONUNBUFFERED": "1"}
    if program is not None:
        env.pop("PYTHONPATH", None)
    store = [] if "--store" in args else ["--store", str(tmp_path / "strokes.sqlite3")]
    if held:
        realpen = [sys.executable, "-c", WARM_REALPEN]
    else:
        realpen = program if program is not None else [sys.executable, "-m", "realpen"]
    command = [*realpen, "serve", "--port", "0", *store, *args]
    errors = open(stderr_to, "w") if stderr_to else None
    process = subprocess.Popen(command, stdout=subprocess.PIPE,
                               stdin=subprocess.PIPE if held else None,
                               stderr=errors if errors else subprocess.STDOUT, text=True, env=env)
    return process, errors


@contextlib.contextmanager
def spare_server(tmp_path: Path, *args: str, stderr_to: Path | None = None) -> Iterator[Spare]:
    """Start ``realpen serve`` (the arguments of :func:`serve`) now, to be run later in the block
    by ``serve(tmp_path, spare=...)``: the new interpreter imports the server's modules meanwhile
    and touches neither the store nor a port until then. A test that restarts a server after a
    crash thus waits only for what a restart does after Python's imports, the same store
    recovery included. A spare left unused is killed when the block ends."""
    process, errors = _launch(tmp_path, args, stderr_to, None, held=True)
    try:
        yield Spare(process, errors, stderr_to)
    finally:
        if process.stdin is not None:  # never served
            process.kill()
            process.communicate()
            if errors:
                errors.close()


@contextlib.contextmanager
def serve(tmp_path: Path, *args: str, timeout: float = 30,
          stderr_to: Path | None = None, program: list[str] | None = None,
          spare: Spare | None = None) -> Iterator[Served]:
    """Run ``realpen serve --port 0 --store tmp/strokes.sqlite3 ARGS`` until the block ends.

    stderr goes with stdout, or to the file ``stderr_to`` (:meth:`Served.errors`). ``program``
    is the ``realpen`` to run (default: this interpreter's, ``python -m realpen``); another one
    (an installed wheel's script) runs without this process's ``PYTHONPATH``. ``spare``: run
    that server, started before by :func:`spare_server` with its arguments, instead.
    """
    if spare is None:
        process, errors = _launch(tmp_path, args, stderr_to, program)
    else:
        assert not args and stderr_to is None and program is None, "the spare has its own"
        process, errors, stderr_to = spare.process, spare.errors, spare.stderr_to
        with contextlib.suppress(BrokenPipeError):  # it died: said below, with its output
            process.stdin.write("go\n")
            process.stdin.flush()
        with contextlib.suppress(BrokenPipeError):
            process.stdin.close()
        process.stdin = None  # communicate() at the end must not flush it
    lines: list[str] = []
    deadline = time.monotonic() + timeout
    match = None
    # Raw reads of the pipe: a buffered readline() would take two lines that arrive together
    # and leave the second where select() no longer sees it.
    pipe, pending = process.stdout.fileno(), ""
    try:
        while match is None:
            if process.poll() is not None or time.monotonic() > deadline:
                rest = process.stdout.read() if process.poll() is not None else ""
                raise RuntimeError(f"realpen serve did not start: {''.join(lines)}{pending}"
                                   f"{rest}")
            ready, _, _ = select.select([pipe], [], [], 0.2)
            if ready:
                chunk = os.read(pipe, 65536).decode("utf-8", errors="replace")
                *complete, pending = (pending + chunk).split("\n")
                for line in complete:
                    lines.append(line + "\n")
                    match = match or URL_LINE.search(line)
        if pending:
            lines.append(pending)
        url = match.group(1)
        token = url.split("?token=")[1] if "?token=" in url else None
        served = Served(url, url.split("?")[0], token, process, lines, stderr_to)
        yield served
    finally:
        if process.poll() is None:
            process.send_signal(signal.SIGINT)
            try:
                process.communicate(timeout=20)
            except subprocess.TimeoutExpired:
                process.kill()
                process.communicate()
        if errors:
            errors.close()


def low_rate_profile(folder: Path, name: str = "slowpen", rate: int = 2000) -> Path:
    """Save a copy of the pencil whose tactile pattern is at ``rate`` Hz (like ``realpen profile
    build --rate 2000``): below the 3 kHz that browsers' decodeAudioData accepts."""
    pencil = resolve_profile("pencil")
    tactile = resample_loop(pencil.tactile, pencil.meta.tactile.rate, rate)
    tactile = (tactile / np.max(np.abs(tactile))).astype(np.float32)
    section = dataclasses.replace(pencil.meta.tactile, rate=rate)  # save_profile hashes the WAVs
    meta = pencil.meta.model_copy(update={"name": name, "tool": "slow pen", "tactile": section})
    return save_profile(PenProfile(meta, tactile, pencil.sound), folder / name)


def stroke_messages(pen: str = "pencil", stroke: int = 1, modality: str = "audio-tactile",
                    n: int = 20, t0: float = 10.0, seq0: int = 1, pressure: float = 0.6,
                    speed: float = 60.0) -> list[dict]:
    """pen_down, then per sample a gain and a one-sample batch, then pen_up."""
    profile = resolve_profile(pen)
    coupling = profile.meta.coupling
    messages = [{"type": "pen_down", "stroke": stroke, "t": t0, "pen": pen,
                 "profile_version": profile.version, "modality": modality, "ink": "visible",
                 "pointer_type": "pen", "px_per_mm": 4.0, "calibrated": True}]
    for i in range(n):
        t = t0 + i * 0.005
        v = 0.0 if i == 0 else speed
        target = float(coupling.gain_raw(pressure, v))
        messages.append({"type": "gain", "stroke": stroke, "t": t, "target": target})
        messages.append({"type": "samples", "stroke": stroke, "samples": [
            {"t": t, "x": 10 + i * speed * 0.005, "y": 20.0, "pressure": pressure,
             "tilt_x": 12.0, "tilt_y": -3.0, "speed": v}]})
    messages.append({"type": "pen_up", "stroke": stroke, "t": t0 + n * 0.005})
    for i, message in enumerate(messages):
        message["seq"] = seq0 + i
    return messages


def study_answers(trial: dict) -> dict:
    """A valid answer to every question of a study trial (as ``GET …/next`` gives it), varied
    by the trial's number: a choice, a Likert point, a line of text."""
    n, given = trial["trial"], {}
    for question in trial["questions"]:
        if question["type"] == "choice":
            given[question["id"]] = question["choices"][n % len(question["choices"])]
        elif question["type"] == "likert":
            given[question["id"]] = 1 + n % question["points"]
        else:
            given[question["id"]] = f"trial {n}"
    return given


# A process that opens a store, leaves one stroke open with two samples, says "ready" and
# waits (to be killed): argv[1] is the store's path or URL.
CRASHER = """
import sys
from realpen.live.store import StrokeStore
store = StrokeStore(sys.argv[1])
sid = store.begin_stroke(session="s", page_stroke=1, pen="pencil", profile_version="0" * 12,
                         modality="none", ink="visible", pointer_type="pen", px_per_mm=4.0,
                         calibrated=False, page_t0=2.0)
store.add_samples(sid, [(2.0, 0, 0, 0.5, 0, 0, 0), (3.5, 1, 0, 0.5, 0, 0, 0)])
print("ready", flush=True)
sys.stdin.read()
"""

# Debian's Chromium, headless, as the browser tests start it (without the background
# networking this machine's closed network refuses). Frames are not held to 60 Hz: a pen
# event sent through the DevTools protocol is acknowledged at the next frame, so a 190-point
# stroke would take 190 frames (3 s) of waiting; unthrottled it takes a third less.
CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                 "--no-first-run", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync",
                 "--autoplay-policy=no-user-gesture-required",
                 "--disable-frame-rate-limit", "--disable-gpu-vsync"]
CHROMIUM_MISSING = ("browser tests need Debian's chromium at /usr/bin/chromium (apt-get install "
                    "chromium; scripts/test.sh installs it when run as root)")

# The stroke store's schemas before Alembic (versions 1 and 2), as those RealPens wrote them.
LEGACY_V1 = """
CREATE TABLE strokes (id INTEGER PRIMARY KEY AUTOINCREMENT, session TEXT NOT NULL,
  page_stroke INTEGER NOT NULL, pen TEXT NOT NULL, profile_version TEXT NOT NULL,
  modality TEXT NOT NULL, ink TEXT NOT NULL, pointer_type TEXT NOT NULL,
  px_per_mm REAL NOT NULL, calibrated INTEGER NOT NULL, page_t0 REAL NOT NULL,
  started_at TEXT NOT NULL, ended_at TEXT, end_reason TEXT,
  sample_count INTEGER NOT NULL DEFAULT 0);
CREATE TABLE samples (stroke_id INTEGER NOT NULL REFERENCES strokes(id),
  seq INTEGER NOT NULL, t REAL NOT NULL, x REAL NOT NULL, y REAL NOT NULL,
  pressure REAL NOT NULL, tilt_x REAL NOT NULL, tilt_y REAL NOT NULL,
  speed REAL NOT NULL, PRIMARY KEY (stroke_id, seq)) WITHOUT ROWID;
PRAGMA user_version = 1;
"""
LEGACY_V2 = """
CREATE TABLE IF NOT EXISTS strokes (
    id INTEGER PRIMARY KEY AUTOINCREMENT, session TEXT NOT NULL, page_stroke INTEGER NOT NULL,
    pen TEXT NOT NULL, profile_version TEXT NOT NULL, modality TEXT NOT NULL, ink TEXT NOT NULL,
    pointer_type TEXT NOT NULL, px_per_mm REAL NOT NULL, calibrated INTEGER NOT NULL,
    page_t0 REAL NOT NULL, started_at TEXT NOT NULL, ended_at TEXT, end_reason TEXT,
    sample_count INTEGER NOT NULL DEFAULT 0, page TEXT);
CREATE TABLE IF NOT EXISTS samples (
    stroke_id INTEGER NOT NULL REFERENCES strokes(id) ON DELETE CASCADE, seq INTEGER NOT NULL,
    t REAL NOT NULL, x REAL NOT NULL, y REAL NOT NULL, pressure REAL NOT NULL,
    tilt_x REAL NOT NULL, tilt_y REAL NOT NULL, speed REAL NOT NULL,
    PRIMARY KEY (stroke_id, seq)) WITHOUT ROWID;
CREATE UNIQUE INDEX IF NOT EXISTS strokes_by_page ON strokes (page, page_stroke);
PRAGMA user_version = 2;
"""


@contextlib.contextmanager
def running_server(tmp_path, store_delay_s: float = 0.0, prepare=None, **limits):
    """The live app under uvicorn with ``server_config(**limits)``, in a thread of this process,
    on a free port; yields (port, app). ``prepare(app)``, if given, runs before it serves (e.g.
    to add a route)."""
    import asyncio
    import concurrent.futures
    import threading

    import uvicorn

    from realpen.live.app import LiveSettings, create_app
    from realpen.live.server import bind, server_config

    app = create_app(LiveSettings.loopback(store=tmp_path / "s.sqlite3"))
    if store_delay_s:
        store = app.state.live.store
        original = store.append

        def slow_append(*args, **kwargs):
            inner = original(*args, **kwargs)
            outer: concurrent.futures.Future = concurrent.futures.Future()

            def finish():
                try:
                    outer.set_result(inner.result())
                except BaseException as error:  # noqa: BLE001 - handed to the caller
                    outer.set_exception(error)

            threading.Timer(store_delay_s, finish).start()
            return outer

        store.append = slow_append
    if prepare is not None:
        prepare(app)
    sock = bind("127.0.0.1", 0)
    server = uvicorn.Server(server_config(app, **limits))
    thread = threading.Thread(target=lambda: asyncio.run(server.serve(sockets=[sock])))
    thread.start()
    deadline = time.monotonic() + 30
    while not server.started and time.monotonic() < deadline:
        time.sleep(0.02)
    try:
        yield sock.getsockname()[1], app
    finally:
        server.should_exit = True
        thread.join(timeout=30)
        sock.close()
