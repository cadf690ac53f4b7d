"""The pen's accelerometer capture: the firmware's LIS3DH driver and capture against the
register-level model under the MicroPython Unix port, the capture's timing on a virtual clock
(10 simulated minutes), and the capture over the protocol from the simulated pen.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import serial

from realpen.device import protocol as P
from realpen.device.sim import SimPen, find_micropython

pytestmark = pytest.mark.firmware

FIRMWARE = Path(__file__).resolve().parents[1] / "firmware" / "pico"

# Runs under the MicroPython Unix port: each check prints one JSON line.
REGISTER_CHECKS = r"""
import json
from array import array
from rp_lis3dh import Lis3dh
from sim_lis3dh import SimI2C, SimLis3dh, VirtualClock

out = {}
clock = VirtualClock()
half_g = array("f", [0.5, -0.25, 3.0] * 4)  # x 0.5 g, y -0.25 g, z past ±2 g
model = SimLis3dh(clock, 0.02, half_g)
bus = SimI2C(model, clock, 400000, 0)
driver = Lis3dh(bus, chunk=5)
out["present"] = driver.present()
out["absent"] = Lis3dh(bus, address=0x19).present()
one = bytearray(1)
bus.readfrom_mem_into(0x18, 0x0F, one)
out["who_am_i"] = one[0]
driver.start(2, 1344, 16)
out["ctrl1"] = model.regs[0x20]
out["ctrl4"] = model.regs[0x23]
out["ctrl5"] = model.regs[0x24]
out["fifo_ctrl"] = model.regs[0x2E]
out["status_empty"] = driver.fifo_status()
clock.spend(10000)  # 10 ms: 13.7 samples at 1344 × 1.02 Hz
out["status_10ms"] = driver.fifo_status()
clock.spend(5000)
out["status_15ms"] = driver.fifo_status()
clock.spend(100000)
out["status_full"] = driver.fifo_status()
out["lost_full"] = model.lost
buf = bytearray(12)
bus.readfrom_mem_into(0x18, 0x28 | 0x80, buf)  # two samples through the wrap at 0x2D
out["two_samples"] = list(buf)
out["count_after_two"] = model.count
bus.readfrom_mem_into(0x18, 0x28, buf)  # no auto-increment: OUT_X_L twelve times
out["no_increment"] = list(buf)
out["count_after_repeat"] = model.count
transfers = bus.transfers
view = memoryview(bytearray(6 * 32))
driver.read_fifo(view, 12)
out["transfers_for_12"] = bus.transfers - transfers
driver.start(4, 1344, 16)
clock.spend(5000)
bus.readfrom_mem_into(0x18, 0x28 | 0x80, buf)
out["range4"] = list(buf[:6])
model.regs[0x23] &= ~0x08  # high resolution off: 10-bit normal mode
model.sample_loaded = -1
bus.readfrom_mem_into(0x18, 0x28 | 0x80, buf)
out["normal10"] = list(buf[:6])
driver.start(2, 1344, 16)
clock.spend(1000000)
driver.fifo_status()  # the model takes its samples when it is read
out["produced_1s"] = model.produced
driver.stop()
out["after_stop"] = driver.fifo_status()
try:
    driver.start(3, 1344)
    out["bad_range"] = "accepted"
except ValueError:
    out["bad_range"] = "refused"
print(json.dumps(out))
"""


def run_micropython(source: str, *args: str, timeout: float = 60) -> dict:
    script = FIRMWARE / ".test_capture_script.py"
    script.write_text(source)
    try:
        result = subprocess.run([find_micropython(), script.name, *args], cwd=FIRMWARE,
                                capture_output=True, text=True, timeout=timeout)
    finally:
        script.unlink()
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def registers() -> dict:
    return run_micropython(REGISTER_CHECKS)


def test_driver_configures_the_sensor_for_stream_mode_at_1344_hz(registers):
    assert registers["present"] is True and registers["absent"] is False
    assert registers["who_am_i"] == 0x33
    assert registers["ctrl1"] == 0x97  # ODR 0b1001 (1.344 kHz), X, Y, Z on, not low power
    assert registers["ctrl4"] == 0x88  # block data update, ±2 g, high resolution
    assert registers["ctrl5"] == 0x40  # FIFO on
    assert registers["fifo_ctrl"] == 0x80 | 15  # stream mode, watermark above 15
    assert registers["bad_range"] == "refused"


def test_fifo_status_counts_watermark_and_overrun(registers):
    # The clock moves by the bus's time too: 72 µs for the CTRL_REG1 write that starts the
    # sensor, 95 µs for each FIFO_SRC read. At 1344 × 1.02 = 1370.88 Hz a sample every 729 µs.
    assert registers["status_empty"] == [0, 0, 0]  # 72 µs after power-up
    assert registers["status_10ms"] == [13, 0, 0]  # 10.167 ms: 13.9 periods
    assert registers["status_15ms"] == [20, 0, 1]  # 15.262 ms: 20.9, watermark (> 15) reached
    assert registers["status_full"] == [32, 1, 1]  # 115.357 ms: 158 taken, 32 kept
    assert registers["lost_full"] == 158 - 32
    assert registers["after_stop"] == [0, 0, 0]


def test_fifo_reads_wrap_and_data_are_left_justified_and_scaled(registers):
    # ±2 g, 12 bits: 1 mg a digit; x = 500, y = −250, z clipped at 2047, each << 4, LE.
    x, y, z = 500 << 4, (-250 << 4) & 0xFFFF, 2047 << 4
    sample = [x & 0xFF, x >> 8, y & 0xFF, y >> 8, z & 0xFF, z >> 8]
    assert registers["two_samples"] == sample * 2
    assert registers["count_after_two"] == 30
    assert registers["no_increment"] == [x & 0xFF] * 12  # OUT_X_L again and again
    assert registers["count_after_repeat"] == 30  # no OUT_Z_H read: nothing left the FIFO
    assert registers["transfers_for_12"] == 3  # 5 + 5 + 2 samples
    x4, y4 = 250 << 4, (-125 << 4) & 0xFFFF
    assert registers["range4"][:4] == [x4 & 0xFF, x4 >> 8, y4 & 0xFF, y4 >> 8]
    x10 = 63 << 6  # normal mode at ±4 g: 10 bits, 8 mg a digit: 62.5 rounds to 63
    assert registers["normal10"][:2] == [x10 & 0xFF, x10 >> 8]


def test_the_sensor_runs_off_its_nominal_rate(registers):
    assert registers["produced_1s"] == 1370  # 1.000072 s at 1344 × 1.02 Hz


def timing(**options) -> dict:
    sys.path.insert(0, str(FIRMWARE))
    try:
        import sim_timing
    finally:
        sys.path.remove(str(FIRMWARE))
    words = [f"{key}={value}" for key, value in options.items()]
    return sim_timing.run(sim_timing.options_from(words))


def test_ten_simulated_minutes_of_capture_beside_the_audio_lose_nothing():
    result = timing(minutes=10)
    assert result["simulated_s"] >= 600
    assert result["overruns"] == 0 and result["lost"] == 0 and result["gaps"] == 0
    assert result["samples"] - result["read"] < 32  # all but the FIFO's last few were read
    assert result["late_refills"] == 0
    assert result["longest_refill_wait_us"] < 1000  # one 5-sample transfer at 400 kHz
    assert 16 <= result["largest_block"] <= 20


def test_a_slow_drain_overruns_and_says_so():
    result = timing(minutes=0.5, look_every_us=40000)  # 54 samples arrive between looks
    assert result["lost"] > 0
    assert result["overruns"] > 0 and result["gaps"] == result["overruns"]
    # The pen's estimate of what it lost, from the time between looks at the nominal rate.
    assert abs(result["lost_estimated"] - result["lost"]) < 0.1 * result["lost"]


def test_the_unix_port_and_cpython_time_the_capture_alike():
    micropython = subprocess.run([find_micropython(), "sim_timing.py", "minutes=0.5"],
                                 cwd=FIRMWARE, capture_output=True, text=True, timeout=60)
    assert micropython.returncode == 0, micropython.stderr
    on_port = json.loads(micropython.stdout)
    here = timing(minutes=0.5)
    for key in ("samples", "read", "blocks", "overruns", "gaps", "refills", "late_refills",
                "longest_transfer_us"):
        assert on_port[key] == here[key], key


def read_frames(port: serial.Serial, decoder: P.FrameDecoder, until, timeout: float = 10.0):
    frames = []
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        frames += decoder.feed(port.read(4096))
        if until(frames):
            return frames
    raise AssertionError(f"no such frame within {timeout} s; got "
                         f"{[P.TYPE_NAMES.get(f[0]) for f in frames][-10:]}")


def acked(ftype, seq):
    return lambda frames: any(f[0] == P.ACK and f[1] == seq and f[2][0] == ftype
                              for f in frames)


def test_capture_over_the_protocol_from_the_simulated_pen(tmp_path):
    with SimPen(rate_error=-0.021) as pen, serial.Serial(pen.port, 115200, timeout=0.05) as port:
        decoder = P.FrameDecoder()
        port.write(P.encode_frame(P.HELLO, 1, P.pack_hello(P.PROTOCOL_VERSION)))
        info = read_frames(port, decoder, lambda f: any(x[0] == P.INFO for x in f))
        fields = P.unpack_info(next(f[2] for f in info if f[0] == P.INFO))
        assert fields[6] & P.FEATURE_ACCEL
        port.write(P.encode_frame(P.CAPTURE_START, 2, P.pack_capture_start(3, 1344)))
        refused = read_frames(port, decoder, lambda f: any(x[0] == P.NACK for x in f))
        nack = next(f for f in refused if f[0] == P.NACK)
        assert P.unpack_nack(nack[2]) == (P.CAPTURE_START, P.E_BAD_CAPTURE)
        port.write(P.encode_frame(P.CAPTURE_START, 3, P.pack_capture_start(2, 1344)))
        frames = read_frames(port, decoder, acked(P.CAPTURE_START, 3))
        frames += read_frames(port, decoder, lambda f: sum(x[0] == P.SAMPLES for x in f) >= 60)
        port.write(P.encode_frame(P.CAPTURE_STOP, 4, P.pack_capture_stop()))
        frames += read_frames(port, decoder, acked(P.CAPTURE_STOP, 4))
    after_ack = frames[next(i for i, f in enumerate(frames)
                            if f[0] == P.ACK and f[2][0] == P.CAPTURE_STOP):]
    assert not any(f[0] == P.SAMPLES for f in after_ack)  # the ACK came after the last block
    blocks = [P.unpack_samples(f[2]) for f in frames if f[0] == P.SAMPLES]
    firsts = np.array([b[0] for b in blocks])
    counts = np.array([len(b[4]) // P.SAMPLE_BYTES for b in blocks])
    overran = np.array([bool(b[3] & P.SAMPLES_OVERRUN) for b in blocks])
    assert firsts[0] == 0 and all(b[2] == 2 for b in blocks)  # ±2 g
    # Every block follows the last, unless the pen says its FIFO overran in between (the
    # simulator runs in real time: a machine that stalls its process for 12 ms or more makes
    # the simulated FIFO overrun, as a stalled main loop would on the pen).
    follows = firsts[1:] == firsts[:-1] + counts[:-1]
    assert np.all(follows | overran[1:])
    assert overran.sum() <= 2
    # The rate from the pen's clock: the last sample of each block against the time its
    # FIFO level was read.
    last = firsts + counts - 1
    t_s = np.array([b[1] for b in blocks]) / 1e6
    rate = np.polyfit(t_s, last, 1)[0]
    assert rate == pytest.approx(pen.sensor_rate_hz, rel=0.005)
    assert abs(rate - 1344) > 20  # and it is not the nominal rate


def test_a_pen_without_a_sensor_and_a_slow_drain_say_so():
    with SimPen(sensor=False) as pen, serial.Serial(pen.port, 115200, timeout=0.05) as port:
        decoder = P.FrameDecoder()
        port.write(P.encode_frame(P.CAPTURE_START, 1, P.pack_capture_start(2, 1344)))
        frames = read_frames(port, decoder, lambda f: any(x[0] == P.NACK for x in f))
        nack = next(f for f in frames if f[0] == P.NACK)
        assert P.unpack_nack(nack[2]) == (P.CAPTURE_START, P.E_NO_SENSOR)
    with SimPen(capture_every_ms=60) as pen, serial.Serial(pen.port, 115200, timeout=0.05) as port:
        decoder = P.FrameDecoder()
        port.write(P.encode_frame(P.CAPTURE_START, 1, P.pack_capture_start(2, 1344)))
        frames = read_frames(port, decoder, lambda f: any(
            x[0] == P.EVENT and P.unpack_event(x[2])[0] == P.EV_OVERRUN for x in f))
        port.write(P.encode_frame(P.CAPTURE_STOP, 2, P.pack_capture_stop()))
        frames += read_frames(port, decoder, acked(P.CAPTURE_STOP, 2))
    blocks = [P.unpack_samples(f[2]) for f in frames if f[0] == P.SAMPLES]
    flagged = [b for b in blocks if b[3] & P.SAMPLES_OVERRUN]
    assert flagged and flagged[0][0] > 0
    # The index skips the samples the pen estimates it lost.
    firsts = [b[0] for b in blocks]
    counts = [len(b[4]) // P.SAMPLE_BYTES for b in blocks]
    jumps = [firsts[i + 1] - (firsts[i] + counts[i]) for i in range(len(blocks) - 1)]
    assert max(jumps) > 0 and min(jumps) >= 0
