"""The live app's pen: PenBridge with a fake client, the routes, `serve --device`, and the
simulated pen end to end (the page's WebSocket → the server → the firmware's trace)."""

from __future__ import annotations

import json
import threading
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("fastapi")
pytest.importorskip("httpx")
with warnings.catch_warnings():  # starlette's note about a future httpx successor
    warnings.simplefilter("ignore")
    from fastapi.testclient import TestClient  # noqa: E402

import httpx  # noqa: E402
from conftest import run_cli  # noqa: E402
from live_support import LOCAL, stroke_messages  # noqa: E402

from realpen.device.bridge import HEARTBEAT_S, PenBridge, fade_ms, gain_fraction  # noqa: E402
from realpen.device.sim import read_trace as trace_events  # noqa: E402
from realpen.errors import ParameterError, RealPenError  # noqa: E402
from realpen.live.app import LiveSettings, create_app  # noqa: E402
from realpen.live.device import (  # noqa: E402
    CommandLog,
    Origin,
    device_status,
    open_device,
    parse_device,
)
from realpen.profile import resolve_profile  # noqa: E402

PENCIL, BALLPOINT = resolve_profile("pencil"), resolve_profile("ballpoint")
ORIGIN = Origin("s", 1, 0)
INFO = {"protocol": 1, "fw_major": 1, "fw_minor": 0, "fw_patch": 0, "sample_rate": 8000,
        "max_pattern_bytes": 32768, "features": 1, "name": "fake pen"}


def tiny_pattern(profile, rate):
    """A cheap stand-in for pen_pattern: different pens, different samples."""
    return np.rint(profile.tactile[: rate // 100] * 32767).astype(np.int16)


class FakePen:
    """What a fake link sees, shared by the clients the bridge opens (one per connection)."""

    def __init__(self):
        self.calls: list[tuple] = []
        self.lock = threading.Lock()
        self.down = False  # the link is gone: every call raises, connecting too
        self.gate = threading.Event()  # set_state waits for it (a slow link)
        self.gate.set()
        self.events: list[tuple] = []
        self.refuse = False  # upload raises a RealPenError (the pen's NACK)
        self.connects = 0
        self.attempts: list[float] = []  # time.monotonic() of each connection attempt

    def record(self, *call) -> None:
        with self.lock:
            self.calls.append(call)

    def of(self, kind: str) -> list[tuple]:
        with self.lock:
            return [call for call in self.calls if call[0] == kind]

    def connect(self):
        self.connects += 1
        self.attempts.append(time.monotonic())
        if self.down:
            raise OSError("fake port: no such device")
        return FakeClient(self)


class FakeClient:
    def __init__(self, pen: FakePen):
        self.pen = pen
        self.closed = False

    def _check(self):
        if self.pen.down or self.closed:
            raise OSError("fake port: input/output error")

    def hello(self):
        self._check()
        self.pen.record("hello")
        return dict(INFO)

    def upload(self, samples, rate, *, pattern_id=None, progress=None):
        self._check()
        if self.pen.refuse:
            raise RealPenError("fake port: the pen refused the pattern (CRC-32 mismatch)")
        self.pen.record("upload", samples.tobytes(), rate)
        return len(self.pen.of("upload"))

    def set_state(self, playing, gain, rate=1.0, fade_ms=5):
        self.pen.gate.wait(5)
        self._check()
        self.pen.record("set_state", int(playing), round(gain, 6), rate, fade_ms)

    def ping(self):
        self._check()
        return 0.001, 0

    def read_event(self, timeout=None):
        self._check()
        return self.pen.events.pop(0) if self.pen.events else None

    def close(self):
        self.closed = True
        self.pen.gate.set()  # a closed port unblocks a write that hangs


def wait_for(predicate, timeout=5.0, what="condition"):
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.005)


@pytest.fixture
def fake():
    pen = FakePen()
    bridge = PenBridge(pen.connect, name="fake", kind="test", log=CommandLog(),
                       pattern=tiny_pattern, heartbeat_s=0.05, close_wait_s=1.0)
    wait_for(lambda: bridge.status()["connected"], what="connected")
    yield pen, bridge
    bridge.close()


def states(pen):
    return [call[1:3] for call in pen.of("set_state")]


# ---- PenBridge with a fake client -----------------------------------------------------------

def test_commands_become_uploads_and_set_states_in_order(fake):
    pen, bridge = fake
    a_max = PENCIL.meta.coupling.a_max
    bridge.pen_down(ORIGIN, PENCIL, True)
    bridge.gain(ORIGIN, a_max / 2)
    bridge.pen_up(ORIGIN)
    wait_for(lambda: len(pen.of("set_state")) == 3)
    assert [call[0] for call in pen.calls] == ["hello", "upload", "set_state", "set_state",
                                               "set_state"]
    assert states(pen) == [(1, 0.0), (1, 0.5), (0, 0.0)]
    fade = fade_ms(PENCIL.meta.coupling.smoothing_ms)
    assert {call[4] for call in pen.of("set_state")} == {fade}
    assert pen.of("upload")[0][1:] == (tiny_pattern(PENCIL, 8000).tobytes(), 8000)
    # The same pen again: the pen holds its pattern (by content), nothing is uploaded.
    bridge.pen_down(ORIGIN, PENCIL, True)
    bridge.pen_up(ORIGIN)
    # A change of pen uploads its pattern; a modality without touch plays nothing.
    bridge.pen_down(ORIGIN, BALLPOINT, False)
    bridge.pen_up(ORIGIN)
    bridge.pen_down(ORIGIN, BALLPOINT, True)
    bridge.pen_up(ORIGIN)
    wait_for(lambda: len(pen.of("set_state")) == 7)
    assert [call[1] for call in pen.of("upload")] == [tiny_pattern(PENCIL, 8000).tobytes(),
                                                      tiny_pattern(BALLPOINT, 8000).tobytes()]
    assert states(pen)[3:] == [(1, 0.0), (0, 0.0), (1, 0.0), (0, 0.0)]
    status = bridge.status()
    assert status["pattern"]["pen"] == "ballpoint" and status["set_states"] == 7
    assert status["info"]["sample_rate"] == 8000 and status["connected"] is True
    # The command log is kept as before.
    assert [e.kind for e in bridge.entries()][:3] == ["pen_down", "gain", "pen_up"]
    assert bridge.count == 9


def test_calls_never_block_and_waiting_gains_coalesce(fake):
    pen, bridge = fake
    a_max = PENCIL.meta.coupling.a_max
    bridge.pen_down(ORIGIN, PENCIL, True)
    wait_for(lambda: pen.of("upload"))
    pen.gate.clear()  # the link hangs on the pen-down's SET_STATE
    time.sleep(0.05)
    worst = 0.0
    for k in range(1, 201):
        start = time.perf_counter()
        bridge.gain(ORIGIN, a_max * k / 200)
        worst = max(worst, time.perf_counter() - start)
    start = time.perf_counter()
    bridge.pen_up(ORIGIN)
    worst = max(worst, time.perf_counter() - start)
    assert worst < 0.5  # microseconds in fact; a blocked link would be seconds (5, the gate)
    assert bridge.status()["connected"]  # status answers at once, too
    pen.gate.set()
    wait_for(lambda: len(pen.of("set_state")) >= 3)
    time.sleep(0.05)
    assert states(pen) == [(1, 0.0), (1, 1.0), (0, 0.0)]  # 200 gains → the latest
    assert bridge.count == 202


def test_a_pen_lost_mid_stroke_is_reconnected_and_hears_the_state_again(fake):
    pen, bridge = fake
    a_max = PENCIL.meta.coupling.a_max
    bridge.pen_down(ORIGIN, PENCIL, True)
    bridge.gain(ORIGIN, a_max * 0.25)
    wait_for(lambda: len(pen.of("set_state")) == 2)
    pen.down = True  # unplugged, mid-stroke: the idle PING notices
    wait_for(lambda: not bridge.status()["connected"], what="disconnected")
    assert "mid-stroke" in bridge.status()["message"]
    bridge.gain(ORIGIN, a_max * 0.75)  # while away: still returns at once, remembered
    time.sleep(0.3)
    assert len(pen.of("set_state")) == 2
    pen.down = False
    wait_for(lambda: bridge.status()["connected"], what="reconnected")
    # The wait between attempts doubles up to 1 s, never more (the attempts' own time aside:
    # a fake connect takes microseconds, so the slack only covers a loaded machine).
    gaps = np.diff(pen.attempts)
    assert len(gaps) >= 3 and gaps.max() < 1.0 + 0.5, gaps
    wait_for(lambda: len(pen.of("set_state")) == 3)
    assert [call[0] for call in pen.calls] == ["hello", "upload", "set_state", "set_state",
                                               "hello", "upload", "set_state"]
    assert states(pen)[-1] == (1, 0.75)  # the current state, not the one before the loss
    status = bridge.status()
    assert status["reconnects"] == 1
    seen = [h["connected"] for h in status["history"]]
    changes = [c for i, c in enumerate(seen) if i == 0 or c != seen[i - 1]]
    assert changes[-3:] == [True, False, True]
    assert any("mid-stroke" in h["message"] for h in status["history"])
    bridge.pen_up(ORIGIN)
    wait_for(lambda: states(pen)[-1] == (0, 0.0))


def test_a_pen_that_reports_a_boot_gets_its_pattern_again(fake):
    pen, bridge = fake
    bridge.pen_down(ORIGIN, PENCIL, True)
    wait_for(lambda: len(pen.of("set_state")) == 1)
    pen.events.append((1, 0))  # EV_BOOT: the pen restarted without the link noticing
    wait_for(lambda: len(pen.of("upload")) == 2, what="re-upload")
    wait_for(lambda: len(pen.of("set_state")) == 2)
    assert states(pen)[-1] == (1, 0.0) and len(pen.of("hello")) == 2


def test_a_refused_pattern_is_said_once_and_the_stroke_still_plays(fake):
    pen, bridge = fake
    pen.refuse = True
    bridge.pen_down(ORIGIN, PENCIL, True)
    bridge.pen_up(ORIGIN)
    bridge.pen_down(ORIGIN, PENCIL, True)
    wait_for(lambda: len(pen.of("set_state")) == 3)
    status = bridge.status()
    assert status["connected"] and "refused pencil's pattern" in status["message"]
    assert "CRC-32" in status["message"] and pen.of("upload") == []


def test_after_a_failed_upload_the_pens_pattern_is_unknown_and_sent_again(fake):
    # On the Pico a PATTERN_BEGIN drops a pattern committed but not yet swapped in: once an
    # upload fails, the pen may play neither, so the next stroke with a pen uploads its pattern.
    pen, bridge = fake
    bridge.pen_down(ORIGIN, PENCIL, True)
    bridge.pen_up(ORIGIN)
    wait_for(lambda: len(pen.of("set_state")) == 2)
    pen.refuse = True
    bridge.pen_down(ORIGIN, BALLPOINT, True)
    bridge.pen_up(ORIGIN)
    wait_for(lambda: len(pen.of("set_state")) == 4)
    assert "refused ballpoint's pattern" in bridge.status()["message"]
    assert bridge.status()["pattern"] is None  # what the pen holds is not known
    pen.refuse = False
    bridge.pen_down(ORIGIN, PENCIL, True)
    wait_for(lambda: len(pen.of("set_state")) == 5)
    assert [call[1] for call in pen.of("upload")] == [tiny_pattern(PENCIL, 8000).tobytes()] * 2
    assert bridge.status()["pattern"]["pen"] == "pencil"


def test_a_pattern_the_pen_cannot_play_is_said_and_the_link_stays(fake):
    pen, bridge = fake

    def unplayable(profile, rate):
        raise ParameterError("rate", f"the loop is not a whole number of samples at {rate} Hz")

    bridge._pattern = unplayable
    bridge.pen_down(ORIGIN, PENCIL, True)
    wait_for(lambda: len(pen.of("set_state")) == 1)
    status = bridge.status()
    assert "pencil's pattern cannot be played at 8000 Hz" in status["message"]
    assert status["connected"] and status["reconnects"] == 0 and pen.of("upload") == []


def test_nothing_raises_into_the_server(fake):
    pen, bridge = fake

    def broken(profile, rate):
        raise ZeroDivisionError("a bug")

    bridge._pattern = broken
    bridge.pen_down(ORIGIN, PENCIL, True)  # the worker fails; the caller never sees it
    wait_for(lambda: bridge.status()["reconnects"] >= 1, what="reconnect after the bug")
    bridge._pattern = tiny_pattern
    bridge.gain(ORIGIN, 0.1)
    wait_for(lambda: pen.of("upload"), what="upload after the bug")


def test_close_sends_what_is_queued_then_silence_then_stops_the_pen():
    pen, stopped = FakePen(), []
    bridge = PenBridge(pen.connect, name="fake", kind="test", log=CommandLog(),
                       pattern=tiny_pattern, on_close=[lambda: stopped.append(1)])
    bridge.pen_down(ORIGIN, PENCIL, True)
    bridge.gain(ORIGIN, PENCIL.meta.coupling.a_max)
    bridge.close()
    assert states(pen)[-2:] == [(1, 1.0), (0, 0.0)] and stopped == [1]
    assert bridge.status()["message"] == "closed"
    bridge.close()  # twice is fine
    bridge.pen_down(ORIGIN, PENCIL, True)  # and a late command does nothing


def test_close_does_not_hang_on_a_dead_link():
    pen = FakePen()
    bridge = PenBridge(pen.connect, name="fake", kind="test", pattern=tiny_pattern,
                       close_wait_s=0.2)
    wait_for(lambda: bridge.status()["connected"])
    pen.gate.clear()
    bridge.pen_down(ORIGIN, PENCIL, True)
    start = time.monotonic()
    bridge.close()
    # ~0.2 s (close_wait_s, then the link is closed under the hung write); one that waited
    # for the write would take the gate's 5 s
    assert time.monotonic() - start < 4


def test_a_pen_never_there_is_said_and_tried_again():
    pen = FakePen()
    pen.down = True
    bridge = PenBridge(pen.connect, name="serial:/dev/nothing", kind="serial",
                       pattern=tiny_pattern)
    try:
        assert bridge.wait_attempted(2)
        status = bridge.status()
        assert not status["connected"] and "not connected (fake port: no such device)" in \
            status["message"]
        wait_for(lambda: pen.connects >= 3, what="retries")
        # Attempts that fail alike are one line of the history, not one each.
        history = bridge.status()["history"]
        assert len(history) == 1 and "no such device" in history[0]["message"], history
    finally:
        bridge.close()


@pytest.mark.slow
def test_an_idle_link_is_pinged_once_a_second():
    # A PING wakes a battery pen's radio over Bluetooth: an idle link is checked gently.
    pen, pings = FakePen(), []
    bridge = PenBridge(pen.connect, name="fake", kind="test", pattern=tiny_pattern)
    try:
        wait_for(lambda: bridge.status()["connected"])
        client = bridge._client
        ping = client.ping
        client.ping = lambda: pings.append(time.monotonic()) or ping()
        time.sleep(1.3)
        assert len(pings) <= 2, np.diff(pings)  # 0.25 s apart before: 5
    finally:
        bridge.close()


def test_gain_and_fade_mapping():
    assert gain_fraction(0.5, 2.0) == 0.25 and gain_fraction(3, 2) == 1.0
    assert gain_fraction(-1, 2) == 0.0 and gain_fraction(1, 0) == 0.0
    assert gain_fraction(float("nan"), 1) == 0.0
    assert fade_ms(0) == 5 and fade_ms(12.4) == 12 and fade_ms(1e9) == 65535


# ---- device strings, the routes, the command line -------------------------------------------

def test_device_strings():
    assert parse_device("sim") == ("sim", "")
    assert parse_device("serial:/dev/ttyACM0") == ("serial", "/dev/ttyACM0")
    assert parse_device("ble:RealPen 1") == ("ble", "RealPen 1")
    for bad in ("", "simulated", "serial:", "ble: ", "usb:/dev/x", "sim:x"):
        with pytest.raises(ParameterError, match="expected sim, serial:PORT or ble:NAME"):
            parse_device(bad)
    log = open_device(None)
    assert isinstance(log, CommandLog) and device_status(log)["connected"] is False


def test_device_route_and_pen_pattern_route(tmp_path, monkeypatch):
    from realpen.device.pattern import pen_pattern

    monkeypatch.setenv("REALPEN_HOME", str(tmp_path / "home"))
    app = create_app(LiveSettings.loopback(store=tmp_path / "s.sqlite3"))
    with TestClient(app, base_url=LOCAL) as client:
        status = client.get("/api/device").json()
        assert status["kind"] == "log" and status["connected"] is False
        assert "only logged" in status["message"]
        response = client.get("/api/pens/pencil/pen-pattern", params={"rate": 8000})
        assert response.status_code == 200
        assert response.headers["content-type"] == "application/octet-stream"
        expected = pen_pattern(PENCIL, 8000)
        assert np.array_equal(np.frombuffer(response.content, "<i2"), expected)
        again = client.get("/api/pens/pencil/pen-pattern", params={"rate": 8000})
        assert again.content == response.content
        assert client.get("/api/pens/nobody/pen-pattern?rate=8000").status_code == 404
        for bad in ("0", "abc", "10000000"):
            refused = client.get(f"/api/pens/pencil/pen-pattern?rate={bad}")
            assert refused.status_code == 422 and "rate" in refused.json()["detail"]
        assert client.get("/api/pens/pencil/pen-pattern").status_code == 422


def test_serve_refuses_a_bad_device_in_one_line(tmp_path, monkeypatch):
    monkeypatch.setenv("REALPEN_HOME", str(tmp_path / "home"))
    for value, said in (("usb", "unknown device 'usb'"), ("serial:", "names no port"),
                        ("ble:", "names no name or address")):
        result = run_cli("serve", "--port", "0", "--store", str(tmp_path / "s.sqlite3"),
                         "--device", value)
        assert result.returncode == 2, result.stderr
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("realpen: error: --device: ")
        assert said in lines[0] and "sim, serial:PORT or ble:NAME" in lines[0]
    assert not (tmp_path / "s.sqlite3").exists()
    help_text = " ".join(run_cli("serve", "--help").stdout.split())
    assert "--device" in help_text and "serial:PORT" in help_text


# ---- the simulated pen end to end: page WebSocket → real server → firmware trace -----------



def wait_trace(path: Path, predicate, what: str, timeout: float = 5.0) -> list[dict]:
    found: list[dict] = []

    def check():
        found[:] = trace_events(path)
        return predicate(found)

    wait_for(check, timeout, what)
    return found


@pytest.fixture
def sim_server(tmp_path, monkeypatch):
    """The live app under uvicorn on a real socket, driving a simulated pen with a trace."""
    import uvicorn

    from realpen.live.server import bind, server_config

    monkeypatch.setenv("REALPEN_HOME", str(tmp_path / "home"))
    trace = tmp_path / "trace.jsonl"
    device = open_device("sim", trace=trace)
    app = create_app(LiveSettings.loopback(store=tmp_path / "s.sqlite3", device=device))
    sock = bind("127.0.0.1", 0)
    server = uvicorn.Server(server_config(app))
    thread = threading.Thread(target=server.run, kwargs={"sockets": [sock]}, daemon=True)
    thread.start()
    wait_for(lambda: server.started, 10, "the server")
    try:
        yield f"http://127.0.0.1:{sock.getsockname()[1]}/", device, trace
    finally:
        server.should_exit = True
        thread.join(15)
        sock.close()
    assert not device.sim.alive  # the server's stop stopped the firmware


def u16(fraction: float) -> int:
    return round(fraction * 65535)


@pytest.mark.firmware
def test_the_page_drives_the_simulated_pen_through_the_server(sim_server):
    """Each step waits for the firmware to apply it: the trace has the SET_STATE a block of the
    player applied (several decoded within one block: the last), so steps are not hurried."""
    from websockets.sync.client import connect

    base, device, trace = sim_server
    a_max = PENCIL.meta.coupling.a_max
    fade = fade_ms(PENCIL.meta.coupling.smoothing_ms)
    wait_for(lambda: httpx.get(base + "api/device").json()["connected"], 10, "the sim pen")
    seq = iter(range(1, 1000))

    def states(events, since_ns=0):
        return [e for e in events if e["event"] == "set_state" and e["t_ns"] >= since_ns]

    def swaps(events):
        return [e for e in events if e["event"] == "swap"]

    def now(playing, gain, n_swaps=None, since_ns=0):
        """The pen's state is (playing, gain u16) now, after n_swaps patterns swapped in."""
        def check(events):
            found = states(events, since_ns)
            return bool(found) and (found[-1]["playing"], found[-1]["gain"]) == \
                (playing, gain) and (n_swaps is None or len(swaps(events)) == n_swaps)
        return check

    with connect(base.replace("http", "ws") + "ws") as ws:
        def send(kind, stroke, **fields):
            message = {"type": kind, "seq": next(seq), "stroke": stroke, **fields}
            if kind != "samples":
                message["t"] = 10.0
            if kind == "pen_down":
                pen = fields["pen"]
                message = {**stroke_messages(pen, stroke)[0], **message,
                           "profile_version": resolve_profile(pen).version}
            ws.send(json.dumps(message))
            reply = json.loads(ws.recv(timeout=5))
            assert reply["type"] == "ack", reply

        ws.send(json.dumps({"type": "hello", "seq": 0, "client": "test", "page": "page-0001"}))
        assert json.loads(ws.recv(timeout=5))["type"] == "ack"
        # Stroke 1, pencil: the pattern is uploaded (swap 1), SET_STATE plays, a gain, stop.
        send("pen_down", 1, pen="pencil")
        wait_trace(trace, now(1, 0, 1), "pen down: the pattern, then playing")
        send("gain", 1, target=a_max * 0.3)
        send("samples", 1, samples=[{"t": 10.0, "x": 1.0, "y": 2.0, "pressure": 0.5,
                                     "tilt_x": 0.0, "tilt_y": 0.0, "speed": 50.0}])
        wait_trace(trace, now(1, u16(0.3)), "the gain")
        send("pen_up", 1)
        events = wait_trace(trace, now(0, 0), "pen up")
        assert {(e["fade_ms"], e["rate"]) for e in states(events)} == {(fade, 4096)}
        # Stroke 2, ballpoint: a change of pen uploads its pattern (swap 2, another id).
        send("pen_down", 2, pen="ballpoint")
        events = wait_trace(trace, now(1, 0, 2), "a change of pen: its pattern")
        assert swaps(events)[0]["id"] != swaps(events)[1]["id"]
        # The pen was idle when the upload was committed: the new pattern plays from the
        # stroke's first sample, not from the old pattern's next wrap (1.5 s later).
        new_pen_at = (swaps(events)[1]["sample"], states(events)[-1]["sample"])
        assert httpx.get(base + "api/device").json()["pattern"]["pen"] == "ballpoint"
        send("pen_up", 2)
        wait_trace(trace, now(0, 0), "pen up")
        # Stroke 3, pencil again (swap 3), and the pen reboots mid-stroke.
        send("pen_down", 3, pen="pencil")
        send("gain", 3, target=a_max * 0.25)
        wait_trace(trace, now(1, u16(0.25), 3), "stroke 3 playing")
        restarted = time.time_ns()
        device.sim.restart()
        send("gain", 3, target=a_max * 0.5)  # the page keeps working: acknowledged as ever
        wait_for(lambda: httpx.get(base + "api/device").json()["reconnects"] == 1, 5,
                 "the reconnection")
        status = httpx.get(base + "api/device").json()
        assert status["connected"] is True and status["message"].startswith("connected")
        lost = [h for h in status["history"] if not h["connected"] and h["t"] * 1e9 >= restarted]
        assert lost and any("mid-stroke" in h["message"] for h in lost)
        # After the reboot: the pattern again, and the current state (playing, the new gain).
        events = wait_trace(trace, now(1, u16(0.5), 4, restarted), "the state resent")
        boots = [e for e in events if e["event"] == "boot" and e["t_ns"] >= restarted]
        assert len(boots) == 1 and swaps(events)[-1]["sample"] >= boots[0]["sample"]
        assert httpx.get(base + "api/device").json()["pattern"]["pen"] == "pencil"
        send("pen_up", 3)
        wait_trace(trace, now(0, 0, 4, restarted), "pen up after the reboot")
        time.sleep(HEARTBEAT_S + 0.2)  # a heartbeat: a boot event from before the HELLO is not news
        status = httpx.get(base + "api/device").json()
        assert status["reconnects"] == 1, status["history"]
    assert [e.kind for e in device.entries()][:2] == ["pen_down", "gain"]
    assert new_pen_at[0] <= new_pen_at[1], (
        f"the ballpoint's pattern swapped in at sample {new_pen_at[0]}, after its stroke began "
        f"at sample {new_pen_at[1]}: a COMMIT and the SET_STATE decoded before one block")


@pytest.mark.firmware
def test_a_simulated_pen_whose_firmware_dies_is_restarted_and_hears_the_state(
        tmp_path, monkeypatch):
    import os
    import signal

    monkeypatch.setenv("REALPEN_HOME", str(tmp_path / "home"))
    device = open_device("sim", trace=tmp_path / "trace.jsonl")
    app = create_app(LiveSettings.loopback(store=tmp_path / "s.sqlite3", device=device))
    a_max = PENCIL.meta.coupling.a_max

    def playing_half(since_ns=0):
        found = [e for e in device.sim.events()
                 if e["event"] == "set_state" and e["t_ns"] >= since_ns]
        return bool(found) and (found[-1]["playing"], found[-1]["gain"]) == (1, u16(0.5))

    with TestClient(app, base_url=LOCAL) as client:
        def status():
            return client.get("/api/device").json()

        wait_for(lambda: status()["connected"], 10, "the sim pen")
        device.pen_down(ORIGIN, PENCIL, True)
        device.gain(ORIGIN, a_max * 0.5)
        wait_for(playing_half, 5, "the stroke playing")
        killed = time.time_ns()
        os.kill(device.sim.pid, signal.SIGKILL)  # the firmware dies by itself, mid-stroke
        wait_for(lambda: status()["reconnects"] == 1, 10, "the firmware restarted")
        now = status()
        assert now["connected"] and device.sim.alive, now
        since = [h for h in now["history"] if h["t"] * 1e9 >= killed]
        assert since[0]["connected"] is False and since[-1]["connected"] is True, since
        assert any("the simulated pen's firmware exited (code -9); restarted" in h["message"]
                   for h in since), since
        wait_for(lambda: playing_half(killed), 5, "the state resent to the restarted firmware")
    assert not device.sim.alive  # the app's shutdown stopped it


@pytest.mark.firmware
def test_serve_with_the_simulated_pen_says_so_and_stops_it(tmp_path, monkeypatch):
    import realpen.live.server

    monkeypatch.setenv("REALPEN_HOME", str(tmp_path / "home"))
    served = []

    def serve_briefly(app, sock, log_level="warning"):  # the summary is out: stop at once
        served.extend([app.state.live.device, app.state.live.device.status()])

    monkeypatch.setattr(realpen.live.server, "run", serve_briefly)
    result = run_cli("serve", "--port", "0", "--store", str(tmp_path / "s.sqlite3"),
                     "--device", "sim")
    assert result.returncode == 0, result.stderr
    assert "  pen device: sim: connected: RealPen, firmware " in result.stdout, result.stdout
    device, status = served
    assert status["kind"] == "sim" and status["connected"] and status["info"]["sample_rate"]
    assert not device.sim.alive and device.status()["message"] == "closed"
