"""Accelerometer captures on the host: the client's capture messages, the assembler (placement,
gaps, the rate from the pen's clock, scaling, clipping), the files and ``realpen record``.

A fake pen (:class:`SensorPen`, a transport) answers HELLO and the capture messages and sends
SAMPLES blocks of a known signal sampled at a known true rate (1344 Hz × 1.017), with the read
jitter of a real pen, blocks it could not send and a FIFO overrun whose lost samples it
estimates wrongly. No time is waited for: the blocks come as fast as the host reads them.
"""

from __future__ import annotations

import _thread
import re
import signal
import threading
import time

import numpy as np
import pytest
from conftest import assert_clean_failure, run_cli

from realpen.device import protocol as p
from realpen.device.capture import (
    STANDARD_GRAVITY,
    CaptureAssembler,
    accel_ms2,
    clipped_mask,
    record,
    write_capture,
)
from realpen.device.client import PenClient, SampleBlock
from realpen.device.transport import DeviceError, Transport
from realpen.errors import RealPenError
from realpen.io.blocks import open_stream
from realpen.io.recording import load_recording

TRUE_RATE = 1344 * 1.017
TONES_HZ = (80.0, 190.0, 333.0)  # x, y, z
MG_PER_DIGIT_2G = 1


def tone_signal(frames: int, rate: float = TRUE_RATE, clip_at: int | None = None) -> np.ndarray:
    """x, y, z tones (0.5, 0.3, 0.2 g; 1 g of gravity on z) as LIS3DH samples at ±2 g,
    with a burst beyond the range on x at ``clip_at`` (8 samples)."""
    t = np.arange(frames) / rate
    g = np.stack([0.5 * np.sin(2 * np.pi * TONES_HZ[0] * t),
                  0.3 * np.sin(2 * np.pi * TONES_HZ[1] * t),
                  1.0 + 0.2 * np.sin(2 * np.pi * TONES_HZ[2] * t)], axis=1)
    if clip_at is not None:
        g[clip_at:clip_at + 8, 0] = 2.5
    digits = np.clip(np.round(g * 1000 / MG_PER_DIGIT_2G), -2048, 2047).astype(np.int16)
    return (digits << 4).astype(np.int16)


class SensorPen(Transport):
    """A pen with a LIS3DH that plays ``signal`` (int16 (frames, 3), taken at ``rate``).

    Blocks of ``block`` samples; block numbers in ``drop`` are counted but not sent; at block
    ``overrun[0]`` the sensor loses ``overrun[1]`` samples and the pen counts ``overrun[2]``;
    at block ``hidden[0]``, ``hidden[1]`` samples are lost with no flag and not counted.
    ``stale``: it is still capturing for an earlier host (index 10⁶ on) when this one connects,
    and sends one more of those blocks just before it acknowledges the new CAPTURE_START.
    ``t_us`` is the last sample's time plus up to one sample period and a read latency (every
    37th block 3 ms late); the pen's clock starts 2 s before it wraps. ``stop_after``: after
    that many blocks sent, ``on_blocks_sent()`` is called (from the reader thread) and no more
    blocks come, so what the host stops on does not depend on the speed of either thread.
    """

    def __init__(self, signal_raw: np.ndarray | None, rate: float = TRUE_RATE, *, block: int = 16,
                 drop: tuple[int, ...] = (), overrun: tuple[int, int, int] | None = None,
                 hidden: tuple[int, int] | None = None, stale: bool = False,
                 seed: int = 7, stop_after: int | None = None, on_blocks_sent=None):
        self.name = "fake-pen"
        self.signal, self.rate, self.block = signal_raw, rate, block
        self.drop, self.overrun, self.hidden = set(drop), overrun, hidden
        self.rng = np.random.default_rng(seed)
        self.stop_after, self.on_blocks_sent = stop_after, on_blocks_sent
        self.pending = bytearray()
        # One lock for the pen's whole state: the reader thread makes blocks while the host's
        # thread starts a new capture, and a block must be made before or after, never across.
        self.lock = threading.RLock()
        self.received: list[int] = []
        self.seq = 0
        self.sent_blocks = 0
        self.paused = False
        self.position, self.index, self.number = 0, 10**6, 0
        self.capturing = stale

    def _frame(self, ftype: int, seq: int, payload: bytes) -> None:
        with self.lock:
            self.pending += p.encode_frame(ftype, seq, payload)

    def write(self, data: bytes) -> None:
        with self.lock:
            self._write(data)

    def _write(self, data: bytes) -> None:
        for ftype, seq, payload in p.FrameDecoder().feed(data):
            self.received.append(ftype)
            if ftype == p.HELLO:
                features = p.FEATURE_USB | (p.FEATURE_ACCEL if self.signal is not None else 0)
                self._frame(p.INFO, seq, p.pack_info(1, 1, 0, 0, 8000, 32768, features, "fake"))
            elif ftype == p.PING:
                self._frame(p.PONG, seq, p.pack_pong(p.unpack_ping(payload), 0))
            elif ftype == p.CAPTURE_START:
                range_g, rate_hz = p.unpack_capture_start(payload)
                if self.signal is None:
                    self._frame(p.NACK, seq, p.pack_nack(ftype, p.E_NO_SENSOR))
                    continue
                if self.capturing:  # the earlier capture's last block, then the new one
                    self._next_block()
                self.capturing, self.position, self.index, self.number = True, 0, 0, 0
                self._frame(p.ACK, seq, p.pack_ack(ftype))
            elif ftype == p.CAPTURE_STOP:
                self.capturing = False  # the blocks made so far are already queued before it
                self._frame(p.ACK, seq, p.pack_ack(ftype))

    def _next_block(self) -> None:
        flags = 0
        if self.overrun and self.number == self.overrun[0]:
            self.position += self.overrun[1]
            self.index += self.overrun[2]
            flags = p.SAMPLES_OVERRUN
        if self.hidden and self.number == self.hidden[0]:
            self.position += self.hidden[1]
        raw = self.signal[self.position:self.position + self.block]
        if len(raw) == 0:
            self.capturing = False
            return
        last_time_us = (self.position + len(raw) - 1) / self.rate * 1e6
        latency = self.rng.uniform(0, 1e6 / self.rate) + self.rng.uniform(20, 120)
        if self.number % 37 == 36:
            latency += 3000
        t_us = int(2**32 - 2_000_000 + last_time_us + latency) & 0xFFFFFFFF
        if self.number not in self.drop:
            self.seq = (self.seq + 1) & 0xFF
            self._frame(p.SAMPLES, self.seq, p.pack_samples(self.index, t_us, 2, flags,
                                                            raw.astype("<i2").tobytes()))
            self.sent_blocks += 1
            if self.sent_blocks == self.stop_after:
                self.paused = True
                self.on_blocks_sent()
        self.position += len(raw)
        self.index += len(raw)
        self.number += 1

    def read(self, timeout: float) -> bytes:
        with self.lock:
            for _ in range(4):
                if self.capturing and not self.paused:
                    self._next_block()
            data, self.pending = bytes(self.pending), bytearray()
        if not data:
            time.sleep(0.002)
        return data

    def close(self) -> None:
        pass


# --- scaling ------------------------------------------------------------------------------------

@pytest.mark.parametrize(("range_g", "mg"), [(2, 1), (16, 12)])
def test_samples_are_scaled_from_left_justified_12_bit_digits(range_g, mg):
    raw = (np.array([[1, -1, 0], [2047, -2048, 100]], dtype=np.int16) << 4).astype(np.int16)
    expected = np.array([[1, -1, 0], [2047, -2048, 100]]) * mg / 1000 * STANDARD_GRAVITY
    assert np.allclose(accel_ms2(raw, range_g), expected, rtol=1e-12, atol=0)
    # the 4 low bits are not data: they change nothing
    assert np.array_equal(accel_ms2(raw | 0xF, range_g), accel_ms2(raw, range_g))
    assert clipped_mask(raw).tolist() == [[False, False, False], [True, True, False]]


# --- the assembler against a fake pen -----------------------------------------------------------

def run_capture(seconds: float, **pen_options):
    frames = int((seconds + 0.5) * TRUE_RATE)
    pen = SensorPen(tone_signal(frames, clip_at=2000), **pen_options)
    with PenClient(pen) as client:
        capture = record(client, seconds)
    return pen, capture


def test_rate_gaps_scaling_and_clipping_of_a_capture():
    """Blocks 40 dropped; an overrun at block 100 lost 20 samples which the pen counts as 23."""
    pen, capture = run_capture(3.0, drop=(40,), overrun=(100, 20, 23))
    assert pen.received[-1] == p.CAPTURE_STOP and not pen.capturing
    # the rate: within 0.1 %, and the stated uncertainty covers the error
    error = capture.rate_hz - TRUE_RATE
    assert abs(error) < TRUE_RATE * 1e-3, capture
    assert 0 < capture.rate_sd_hz < 0.5 and abs(error) < 4 * capture.rate_sd_hz, capture
    assert capture.duration_s >= 3.0
    # the gaps: where and how many, of which kind
    dropped, overrun = capture.gaps
    assert dropped.kind == "dropped" and dropped.samples_lost == 16
    assert dropped.at_s == pytest.approx(40 * 16 / capture.rate_hz)
    # the pen counted 23 lost; its clock says 20, which places the samples after it right
    assert overrun.kind == "overrun" and overrun.samples_lost == 20
    assert overrun.at_s == pytest.approx(100 * 16 / capture.rate_hz)
    assert np.isnan(capture.samples[640:656]).all() and not np.isnan(capture.samples[656]).any()
    assert np.isnan(capture.samples[1600:1620]).all() and not np.isnan(capture.samples[1620]).any()
    # the scaling: every sample before the first gap is the signal's, in m/s²
    source = tone_signal(4000, clip_at=2000)
    assert np.array_equal(capture.samples[:640], accel_ms2(source[:640], 2))
    assert np.array_equal(capture.samples[1620:3000], accel_ms2(source[1620:3000], 2))
    assert capture.clipped == (8, 0, 0)
    assert capture.provenance["sensor"] == "LIS3DH" and capture.provenance["pen"] == "fake"
    assert capture.provenance["rate_hz"] == capture.rate_hz
    assert capture.provenance["gaps"][0][1:] == [16, "dropped"]
    assert not capture.notes  # the late reads are no loss


def test_samples_lost_with_no_flag_are_found_from_the_clock():
    _, capture = run_capture(2.0, hidden=(60, 30))
    assert abs(capture.rate_hz - TRUE_RATE) < TRUE_RATE * 1e-3
    (gap,) = capture.gaps
    assert gap.kind == "overrun" and gap.samples_lost == 30
    assert gap.at_s == pytest.approx(60 * 16 / capture.rate_hz)
    assert capture.notes == ("1 of the overrun gaps had no overrun flag: the pen's clock showed "
                             "the samples missing",)
    source = tone_signal(3000, clip_at=2000)
    assert np.array_equal(capture.samples[990:2000], accel_ms2(source[990:2000], 2))


def test_index_and_clock_wrap_at_2_32():
    assembler = CaptureAssembler(range_g=2)
    raw = np.zeros((32, 3), dtype=np.int16)
    start = 2**32 - 64  # the pen's sample counter about to wrap (as after 37 days)
    assembler._next = assembler._next_raw = start  # as if the capture had run that long
    for n in range(6):
        first = (start + 32 * n) & 0xFFFFFFFF
        t_us = (2**32 - 50_000 + round((32 * n + 31) * 1e6 / 1344)) & 0xFFFFFFFF
        assembler.feed(SampleBlock(first, t_us, 2, 0, raw, 0.0))
    assert assembler.frames == start + 6 * 32 and not assembler.gaps()
    assert assembler.rate()[0] == pytest.approx(1344, rel=1e-4)  # t_us in whole µs


def test_blocks_of_an_earlier_capture_are_not_taken_for_this_ones():
    _, capture = run_capture(0.5, stale=True)
    assert capture.gaps == [] and capture.frames >= 0.5 * TRUE_RATE


def test_a_pen_without_an_accelerometer_is_one_line():
    with PenClient(SensorPen(None)) as client:
        client.hello()
        with pytest.raises(DeviceError, match=r"^fake-pen: the pen has no accelerometer$"):
            record(client, 1.0)


def test_ctrl_c_keeps_what_was_captured_and_stops_the_pen():
    pen = SensorPen(tone_signal(3000))
    seen = []

    def interrupt(block, assembler):
        seen.append(block)
        if len(seen) == 20:
            raise KeyboardInterrupt

    with PenClient(pen) as client:
        capture = record(client, 10.0, on_block=interrupt)
    assert capture.interrupted and capture.provenance["stopped"] == "interrupted"
    assert pen.received[-1] == p.CAPTURE_STOP
    # every block the pen sent before its stop is placed, not only those read before Ctrl-C
    assert capture.blocks == pen.sent_blocks >= 20 and capture.frames == pen.position


# --- files --------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def capture():
    return run_capture(1.0, drop=(10,))[1]


@pytest.mark.parametrize("suffix", [".wav", ".npz", ".csv"])
def test_files_load_back_at_the_estimated_rate(capture, tmp_path, suffix):
    path = write_capture(capture, tmp_path / f"rec{suffix}")
    loaded = load_recording(path)
    expected = np.nan_to_num(capture.samples, nan=0.0)
    assert loaded.samples.shape == expected.shape and loaded.axes == ("x", "y", "z")
    assert np.allclose(loaded.samples, expected, rtol=1e-6, atol=1e-6)
    if suffix == ".csv":  # from the time column
        assert loaded.rate == pytest.approx(capture.rate_hz, rel=1e-5)
    else:  # exactly, from the metadata
        assert loaded.rate == pytest.approx(capture.rate_hz, rel=1e-12)
        assert loaded.units == "m/s^2"
    assert open_stream(path).rate == pytest.approx(loaded.rate, rel=1e-12)
    assert not list(tmp_path.glob(".*tmp*"))  # the temporary file is gone


def test_a_wav_keeps_its_provenance_in_the_comment(capture, tmp_path):
    import json

    import soundfile as sf

    path = write_capture(capture, tmp_path / "rec.wav")
    with sf.SoundFile(path) as handle:
        assert handle.samplerate == round(capture.rate_hz)
        meta = json.loads(handle.comment)
    assert meta["sensor"] == "LIS3DH" and meta["range_g"] == 2 and meta["firmware"] == "1.0.0"
    assert meta["rate_hz"] == capture.rate_hz and meta["gaps"][0][1:] == [16, "dropped"]


def test_an_unknown_suffix_is_refused_naming_the_file(capture, tmp_path):
    with pytest.raises(RealPenError, match=r"rec\.flac: a capture is written as"):
        write_capture(capture, tmp_path / "rec.flac")
    assert not list(tmp_path.iterdir())


# --- realpen record -----------------------------------------------------------------------------

@pytest.fixture
def fake_port(monkeypatch):
    """``--port fake`` opens the pen returned by the ``pens`` list's next factory."""
    pens = []

    def open_fake(port, **options):
        return pens.pop(0)()

    monkeypatch.setattr("realpen.device.transport.open_transport", open_fake)
    return pens


def test_record_writes_the_file_and_says_what_it_holds(fake_port, tmp_path):
    fake_port.append(lambda: SensorPen(tone_signal(2000), drop=(30,)))
    out = tmp_path / "rec.npz"
    result = run_cli("record", "--port", "fake", "--seconds", "1", "-o", out)
    assert result.returncode == 0, result.stderr
    assert "from fake on fake, range ±2 g" in result.stdout
    assert re.search(r"rate: 136\d\.\d{3} ± 0\.\d{3} Hz from the pen's clock \(nominal 1344 Hz, "
                     r"\+1\.[67]\d %\)", result.stdout), result.stdout
    assert "gaps: 1, 16 samples missing" in result.stdout and "(blocks not received)" in \
        result.stdout
    assert "clipping: none" in result.stdout and f"wrote {out}: NPZ" in result.stdout
    assert load_recording(out).rate == pytest.approx(TRUE_RATE, rel=1e-3)


def test_record_refuses_a_bad_extension_and_a_pen_without_sensor(fake_port, tmp_path):
    result = run_cli("record", "--port", "fake", "--seconds", "1", "-o", tmp_path / "rec.mp3")
    assert_clean_failure(result, "rec.mp3: record writes .wav, .npz or .csv")
    fake_port.append(lambda: SensorPen(None))
    result = run_cli("record", "--port", "fake", "--seconds", "1", "-o", tmp_path / "rec.wav")
    assert_clean_failure(result, "fake-pen: the pen has no accelerometer")
    assert not list(tmp_path.iterdir())


def test_ctrl_c_in_record_writes_what_was_captured(fake_port, tmp_path):
    def ctrl_c():  # the user presses Ctrl-C after the 30th block
        _thread.interrupt_main(signal.SIGINT)

    fake_port.append(lambda: SensorPen(tone_signal(20000), stop_after=30, on_blocks_sent=ctrl_c))
    out = tmp_path / "rec.wav"
    result = run_cli("record", "--port", "fake", "--seconds", "60", "-o", out)
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith("stopped early (Ctrl-C): kept what was captured; recorded")
    loaded = load_recording(out)
    assert len(loaded.samples) == 30 * 16


# --- acceptance: the simulated pen's own firmware and sensor model ------------------------------

def tone_at(samples: np.ndarray, rate: float, near_hz: float) -> tuple[float, float]:
    """(frequency in Hz, amplitude) of the tone near ``near_hz``: the peak of a Hann-windowed,
    8× zero-padded spectrum refined by a parabola; the amplitude from the power within ±4 Hz of
    it in a Welch spectrum of 1 s segments (the method looks at the power of short units: a
    sample misplaced at a gap shifts the phase of what follows, not its power)."""
    from scipy.signal import welch

    n = len(samples)
    spectrum = np.abs(np.fft.rfft((samples - samples.mean()) * np.hanning(n), 8 * n))
    freqs = np.fft.rfftfreq(8 * n, 1 / rate)
    band = np.flatnonzero(np.abs(freqs - near_hz) < 5)
    k = band[np.argmax(spectrum[band])]
    a, b, c = np.log(spectrum[k - 1:k + 2])
    freq = freqs[k] + (a - c) / (2 * (a - 2 * b + c)) * (freqs[1] - freqs[0])
    bins, density = welch(samples, fs=rate, nperseg=int(rate), scaling="density")
    near = np.abs(bins - freq) <= 4
    return float(freq), float(np.sqrt(2 * np.sum(density[near]) * (bins[1] - bins[0])))


@pytest.mark.firmware
def test_a_capture_from_the_simulated_pen_keeps_its_tones_and_the_sensors_true_rate(tmp_path):
    """The issue's acceptance: a source of known tones → `record` 10 s → the tones within 0.5 Hz
    and 0.5 dB, the rate within 0.1 % of the simulated sensor's true rate, no gap."""
    from realpen.device.sim import SimPen
    from realpen.device.transport import open_transport

    amplitudes_g, rate, loop_s = (0.4, 0.3, 0.2), 1344.0, 5.0  # whole cycles: it loops cleanly
    t = np.arange(round(loop_s * rate)) / rate
    source = np.stack([a * np.sin(2 * np.pi * f * t) for a, f in zip(amplitudes_g, TONES_HZ,
                                                                     strict=True)], axis=1)
    np.savez(tmp_path / "tones.npz", samples=source, rate=rate, units=np.array("g"))
    with SimPen(accelerometer=tmp_path / "tones.npz") as sim, \
            PenClient(open_transport(sim.port)) as client:
        capture = record(client, 10.0)
        true_rate = sim.sensor_rate_hz
    assert abs(capture.rate_hz - true_rate) < 1e-3 * true_rate, (capture, true_rate)
    samples = np.nan_to_num(capture.samples)
    for axis, (tone_hz, amplitude_g) in enumerate(zip(TONES_HZ, amplitudes_g, strict=True)):
        freq, amplitude = tone_at(samples[:, axis], capture.rate_hz, tone_hz)
        assert abs(freq - tone_hz) < 0.5, (axis, freq)
        level_db = 20 * np.log10(amplitude / (amplitude_g * STANDARD_GRAVITY))
        assert abs(level_db) < 0.5, (axis, level_db, capture, capture.gaps, capture.notes)
    # Last: a gap here is the simulated pen's (its FIFO overran, or lost samples unflagged while
    # it was read); the host has already placed the samples after it by the pen's clock.
    assert capture.duration_s >= 10.0 and capture.gaps == [], (capture.gaps, capture.notes)
