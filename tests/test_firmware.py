"""The pen firmware (firmware/pico): the player against the specification, no allocation in the
audio loop, 10⁵ fuzzed frames, and host → pseudo-terminal → firmware end to end.

The player's specification (docs/protocol.md, "What the pen plays") is written out literally in
:class:`Reference` (one Q16 position, the ramp formula ``amp0 + (target - amp0) * k // N``), and
the firmware's incremental integer version must agree with it sample for sample.
"""

from __future__ import annotations

import os
import random
import select
import signal
import subprocess
import sys
import time
import zlib
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf

from realpen.device import protocol as P
from realpen.device.sim import SimPen, find_micropython
from realpen.errors import RealPenError

FIRMWARE = Path(__file__).resolve().parents[1] / "firmware" / "pico"
sys.path.insert(0, str(FIRMWARE))

from rp_player import Player  # noqa: E402  (firmware module, found through the path above)

RATE = 8000


class Reference:
    """The player exactly as docs/protocol.md words it, written for clarity, not speed."""

    def __init__(self, rate=RATE, gain_cap=32767):
        self.rate, self.cap = rate, gain_cap
        self.amp = self.playing = 0
        self.a0 = self.a_target = self.a_n = self.a_k = 0
        self.r = self.r0 = self.r_target = P.RATE_ONE
        self.r_n = self.r_k = 0
        self.pos = 0  # Q16
        self.pattern = None
        self.next = None
        self.request = None
        self.swaps = []  # output index where each new pattern started
        self.count = 0

    def set_state(self, playing, gain, rate=P.RATE_ONE, fade_ms=5):
        self.request = (playing, gain, rate, fade_ms)

    def commit(self, samples):
        self.next = list(samples)

    def swap_now(self, samples):
        self.pattern, self.pos = list(samples), 0

    def render(self, n):
        if self.request is not None:
            playing, gain, rate, fade_ms = self.request
            self.request = None
            self.playing = playing
            self.a0, self.a_k = self.amp, 0
            self.a_target = gain * self.cap // P.GAIN_ONE if playing else 0
            self.a_n = max(fade_ms, 5) * self.rate // 1000
            if rate != self.r_target:
                self.r0, self.r_target, self.r_k = self.r, rate, 0
                self.r_n = 5 * self.rate // 1000
        out = []
        for _ in range(n):
            if self.a_k < self.a_n:
                self.a_k += 1
                self.amp = self.a0 + (self.a_target - self.a0) * self.a_k // self.a_n
            if self.r_k < self.r_n:
                self.r_k += 1
                self.r = self.r0 + (self.r_target - self.r0) * self.r_k // self.r_n
            if self.pattern is None or (self.amp == 0 and not self.playing):
                self.pos = 0
                if self.next is not None:
                    self.pattern, self.next = self.next, None
                    self.swaps.append(self.count)
                if self.pattern is None or (self.amp == 0 and not self.playing):
                    out.append(0)
                    self.count += 1
                    continue
            length = len(self.pattern)
            i, frac = self.pos >> 16, self.pos & 0xFFFF
            p = self.pattern[i]
            if frac:
                p += ((self.pattern[(i + 1) % length] - p) * (frac >> 2)) >> 14
            out.append((p * self.amp) >> 15)
            self.count += 1
            self.pos += self.r << 4
            if self.pos >= length << 16:
                if self.next is not None:
                    self.pattern, self.next, self.pos = self.next, None, 0
                    self.swaps.append(self.count)
                else:
                    self.pos %= length << 16
        return out


def load(player: Player, samples) -> None:
    staging = player.staging()
    staging[:len(samples)] = type(staging)("h", samples)
    player.commit(len(samples), 1)


def render(player: Player, n: int, block: int = 32) -> list[int]:
    from array import array

    out = []
    buf = array("h", bytes(2 * block))
    for _ in range(n // block):
        player.fill(buf)
        out.extend(buf)
    return out


def random_pattern(rng: np.random.Generator, n: int) -> list[int]:
    return rng.integers(-32768, 32768, n).tolist()


# -- the player, in CPython ----------------------------------------------------------------

def test_gain_ramps_follow_the_formula_and_the_cap():
    player = Player(RATE, 1024, gain_cap=20000)
    load(player, [32767] * 100)
    player.set_state(1, 65535, P.RATE_ONE, 10)  # N = 80 samples
    up = render(player, 128)
    amps = [0 + (20000 - 0) * k // 80 for k in range(1, 81)] + [20000] * 48
    assert up == [(32767 * a) >> 15 for a in amps]
    player.set_state(1, 30000, P.RATE_ONE, 0)  # at least 5 ms: N = 40
    down = render(player, 64)
    target = 30000 * 20000 // 65535
    amps = [20000 + (target - 20000) * k // 40 for k in range(1, 41)] + [target] * 24
    assert down == [(32767 * a) >> 15 for a in amps]
    assert max(up) <= 20000  # full gain never exceeds the cap


def test_rate_one_plays_the_pattern_exactly_and_loops():
    rng = np.random.default_rng(1)
    pattern = random_pattern(rng, 100)
    player = Player(RATE, 1024)
    load(player, pattern)
    player.set_state(1, 65535, P.RATE_ONE, 5)
    out = render(player, 320)
    looped = [pattern[i % 100] for i in range(320)]
    assert out[40:] == [(p * 32767) >> 15 for p in looped[40:]]


def test_stop_resets_the_position_so_the_next_stroke_starts_at_the_pattern_start():
    pattern = list(range(1000, 1100))
    player = Player(RATE, 1024, gain_cap=32767)
    load(player, pattern)
    player.set_state(1, 65535, P.RATE_ONE, 5)
    render(player, 96)
    player.set_state(0, 65535, P.RATE_ONE, 5)
    render(player, 64)
    assert player.amp == 0 and player.index == 0 and player.frac == 0
    player.set_state(1, 65535, P.RATE_ONE, 5)
    again = render(player, 32)
    assert again[0] == (pattern[0] * (32767 // 40)) >> 15  # the first ramp step, at position 0
    assert again[1] == (pattern[1] * (32767 * 2 // 40)) >> 15


def test_a_commit_swaps_at_the_wrap_while_playing_and_at_once_when_idle():
    a, b = [100] * 50, [-200] * 30
    player = Player(RATE, 1024)
    load(player, a)
    player.set_state(1, 65535)
    out = render(player, 64)  # position 14 of the 50-sample pattern after 64 samples
    load(player, b)
    assert player.pending
    out += render(player, 64)
    assert player.swaps == 2 and player.pattern_id == 1
    swap = next(i for i, v in enumerate(out) if v < 0)
    assert swap == 100  # the second wrap of pattern a: 2 × 50 samples (a began at sample 0)
    assert all(v == (-200 * 32767) >> 15 for v in out[swap:])
    # Idle: a commit takes effect at the next block's first sample.
    idle = Player(RATE, 1024)
    load(idle, a)
    render(idle, 32)
    assert idle.length == 50 and idle.swap_at == 0


def test_no_pattern_is_silence_even_when_playing():
    player = Player(RATE, 1024)
    player.set_state(1, 65535)
    assert render(player, 128) == [0] * 128
    assert player.amp == 32767  # the ramp ran; there was nothing to play


def test_the_player_matches_the_literal_specification_under_random_states():
    rng = np.random.default_rng(7)
    player, reference = Player(RATE, 4096, gain_cap=23000), Reference(gain_cap=23000)
    patterns = [random_pattern(rng, int(n)) for n in (37, 200, 1, 999)]
    load(player, patterns[0])
    reference.commit(patterns[0])
    got, want = [], []
    for step in range(300):
        if rng.random() < 0.3:
            state = (int(rng.random() < 0.7), int(rng.integers(0, 65536)),
                     int(rng.choice([P.RATE_ONE, rng.integers(P.RATE_MIN, P.RATE_MAX + 1)])),
                     int(rng.choice([0, 5, 7, 30, 200])))
            player.set_state(*state)
            reference.set_state(*state)
        if step % 60 == 59:
            pattern = patterns[(step // 60) % len(patterns)]
            load(player, pattern)
            reference.commit(pattern)
        got += render(player, 32)
        want += reference.render(32)
    assert got == want
    assert player.swaps == len(reference.swaps) >= 3


def test_states_out_of_range_are_refused():
    player = Player(RATE, 1024)
    for state in [(2, 0, P.RATE_ONE, 5), (1, 65536, P.RATE_ONE, 5), (1, 0, 1023, 5),
                  (1, 0, 16385, 5)]:
        with pytest.raises(ValueError):
            player.set_state(*state)


# -- the protocol core, in CPython ------------------------------------------------------------

def test_the_pen_answers_every_refusal_with_its_code_and_keeps_the_last_good_pattern():
    from rp_pen import Pen

    sent = []
    pen = Pen(max_pattern_bytes=400)
    link = pen.add_link(sent.append, "test")

    def ask(ftype, payload=b"", seq=9):
        sent.clear()
        link.feed(P.encode_frame(ftype, seq, payload))
        return [(t, s, p) for frame in sent for t, s, p in P.FrameDecoder().feed(frame)]

    def nack(ftype, code):
        return [(P.NACK, 9, P.pack_nack(ftype, code))]

    def begin(n, crc, rate=RATE, fmt=P.FORMAT_S16LE, pid=1):
        return ask(P.PATTERN_BEGIN, P.pack_pattern_begin(pid, n, rate, fmt, crc))

    good = np.arange(-50, 50, dtype="<i2") * 300
    data = good.tobytes()
    assert begin(100, zlib.crc32(data)) == [(P.ACK, 9, P.pack_ack(P.PATTERN_BEGIN))]
    for at in (0, 7, 100, 190):  # splits that cut samples in two
        assert ask(P.PATTERN_CHUNK, P.pack_pattern_chunk(at, data[at:at + {0: 7, 7: 93, 100: 90,
                                                                          190: 10}[at]])) == []
    assert ask(P.PATTERN_COMMIT, P.pack_pattern_commit(1)) == [
        (P.ACK, 9, P.pack_ack(P.PATTERN_COMMIT))]
    render(pen.player, 32)
    assert list(pen.player.samples()) == good.tolist()

    refused = ask(P.HELLO, P.pack_hello(2))
    assert refused[:1] == nack(P.HELLO, P.E_VERSION)
    assert [(kind, seq, P.unpack_info(payload)[0]) for kind, seq, payload in refused[1:]] == [
        (P.INFO, 9, P.PROTOCOL_VERSION)]  # the host learns which version the pen speaks
    assert ask(0x77) == nack(0x77, P.E_UNKNOWN_TYPE)
    assert ask(P.PING, b"abc") == nack(P.PING, P.E_BAD_LENGTH)
    assert ask(P.SET_STATE, P.pack_set_state(2, 0, P.RATE_ONE, 5)) == nack(P.SET_STATE,
                                                                           P.E_BAD_STATE)
    assert ask(P.SET_STATE, P.pack_set_state(1, 0, 999, 5)) == nack(P.SET_STATE, P.E_BAD_STATE)
    assert begin(201, 0) == nack(P.PATTERN_BEGIN, P.E_TOO_LARGE)
    assert begin(10, 0, fmt=2) == nack(P.PATTERN_BEGIN, P.E_BAD_FORMAT)
    assert begin(0, 0) == nack(P.PATTERN_BEGIN, P.E_BAD_FORMAT)
    assert begin(10, 0, rate=44100) == nack(P.PATTERN_BEGIN, P.E_BAD_RATE)
    chunk = P.pack_pattern_chunk(0, bytes(20))
    assert ask(P.PATTERN_CHUNK, chunk) == nack(P.PATTERN_CHUNK, P.E_NO_UPLOAD)
    assert ask(P.PATTERN_COMMIT, P.pack_pattern_commit(1)) == nack(P.PATTERN_COMMIT,
                                                                   P.E_NO_UPLOAD)
    begin(10, zlib.crc32(bytes(20)))
    assert ask(P.PATTERN_CHUNK, P.pack_pattern_chunk(2, bytes(18))) == nack(P.PATTERN_CHUNK,
                                                                            P.E_BAD_OFFSET)
    assert ask(P.PATTERN_CHUNK, chunk) == nack(P.PATTERN_CHUNK, P.E_NO_UPLOAD)  # abandoned
    begin(10, zlib.crc32(bytes(20)))
    assert ask(P.PATTERN_CHUNK, P.pack_pattern_chunk(0, bytes(22))) == nack(P.PATTERN_CHUNK,
                                                                            P.E_TOO_LARGE)
    begin(10, zlib.crc32(bytes(20)))
    ask(P.PATTERN_CHUNK, P.pack_pattern_chunk(0, bytes(18)))
    assert ask(P.PATTERN_COMMIT, P.pack_pattern_commit(1)) == nack(P.PATTERN_COMMIT,
                                                                   P.E_INCOMPLETE)
    begin(10, zlib.crc32(bytes(20)) ^ 4)
    ask(P.PATTERN_CHUNK, chunk)
    assert ask(P.PATTERN_COMMIT, P.pack_pattern_commit(1)) == nack(P.PATTERN_COMMIT, P.E_CRC)
    render(pen.player, 64)
    assert list(pen.player.samples()) == good.tolist()  # every refusal left it in place
    assert pen.player.swaps == 1
    token, _ = P.unpack_pong(ask(P.PING, P.pack_ping(0xFFFFFFFF))[0][2])
    assert token == 0xFFFFFFFF


# -- the Unix port: no allocation, fuzzed frames ----------------------------------------------

def run_micropython(script: Path, *args: str, timeout: float = 60) -> subprocess.CompletedProcess:
    return subprocess.run([find_micropython(), str(script), *args], capture_output=True,
                          timeout=timeout, cwd=FIRMWARE)


HEAP_SCRIPT = """
import sys
sys.path.insert(0, {firmware!r})
import micropython
from array import array
from rp_player import Player

class Allocating(Player):
    def fill(self, buf):
        Player.fill(self, buf)
        self.last = [buf[0]]  # a list a block: what the check must catch

def exercise(player):
    buf = array("h", bytes(64))
    staging = player.staging()
    for i in range(300):
        staging[i] = (i * 97) % 60000 - 30000
    player.commit(300, 1)
    states = [(1, 65535, 4096, 5), (1, 30000, 5000, 20), (1, 65535, 1024, 5), (0, 0, 4096, 5),
              (1, 100, 16384, 9), (0, 65535, 4096, 0)]
    for step in range(120):
        if step % 20 == 0:
            player.set_state(*states[(step // 20) % len(states)])
        if step == 50:
            player.staging()
            player.commit(77, 2)
        micropython.heap_lock()
        try:
            player.fill(buf)
        except MemoryError:
            micropython.heap_unlock()
            return "allocates"
        micropython.heap_unlock()
    return "allocation-free %d swaps" % player.swaps

print(exercise(Player(8000, 1024)))
print(exercise(Allocating(8000, 1024)))
"""


def test_fill_allocates_nothing_under_heap_lock_and_the_check_can_fail(tmp_path):
    script = tmp_path / "heap.py"
    script.write_text(HEAP_SCRIPT.format(firmware=str(FIRMWARE)))
    result = run_micropython(script)
    assert result.returncode == 0, result.stderr.decode()
    assert result.stdout.decode().splitlines() == ["allocation-free 2 swaps", "allocates"]


FUZZ_SCRIPT = """
import sys
sys.path.insert(0, {firmware!r})
from array import array
from rp_pen import Pen

out = sys.stdout.buffer
pen = Pen(max_pattern_bytes=4096)
link = pen.add_link(out.write, "fuzz")
buf = array("h", bytes(64))
source = open(sys.argv[1], "rb")
chunk = bytearray(1000)
step = 0
sizes = (1, 7, 64, 300, 3, 1000, 19)  # the stream split anywhere
while True:
    size = sizes[step % len(sizes)]
    count = source.readinto(memoryview(chunk)[:size])
    if not count:
        break
    link.feed(memoryview(chunk)[:count])
    step += 1
    if step % 16 == 0:
        pen.player.fill(buf)
sys.stderr.write("done %d %d\\n" % (step, link.decoder.errors))
"""

SENTINEL = 0x5EED0000


def fuzz_stream(count: int, seed: int) -> tuple[bytes, list[int]]:
    """``count`` frames: valid ones of every type with random payloads, corrupted ones, garbage
    and overlong runs; after every 50th a 0x00 and a PING whose PONG proves the resync.

    Valid frames are drawn from a pool of 3000 random ones (encoding is the slow part in
    CPython); every corruption, cut and garbage run is fresh."""
    rng = random.Random(seed)
    types = [P.HELLO, P.PATTERN_BEGIN, P.PATTERN_CHUNK, P.PATTERN_COMMIT, P.SET_STATE, P.PING,
             P.ACK, 0x77]
    sizes = [0, 1, 2, 2, 4, 5, 7, 7, 9, 15, 40]  # the message payloads, and others
    pool = []
    for i in range(3000):
        ftype = rng.choice(types)
        if ftype == P.SET_STATE and rng.random() < 0.5:
            payload = P.pack_set_state(rng.randrange(3), rng.randrange(65536),
                                       rng.randrange(65536), rng.randrange(65536))
        else:
            payload = rng.randbytes(184 if rng.random() < 0.04 else rng.choice(sizes))
        pool.append(P.encode_frame(ftype, i & 0xFF, payload))
    pieces, tokens = [], []
    for i in range(count):
        kind = rng.random()
        frame = rng.choice(pool)
        if kind < 0.35:
            pieces.append(frame)  # valid, often refused
        elif kind < 0.6:
            corrupt = bytearray(frame)
            corrupt[rng.randrange(len(corrupt))] ^= 1 << rng.randrange(8)
            pieces.append(bytes(corrupt))  # a bit flipped (the delimiter too, sometimes)
        elif kind < 0.8:
            pieces.append(frame[:rng.randrange(1, len(frame))])  # cut short: merges with the next
        elif kind < 0.99:
            pieces.append(rng.randbytes(rng.randrange(1, 25)))  # garbage, zeros included
        else:
            pieces.append(rng.randbytes(300).replace(b"\x00", b"\x01"))  # overlong, no 0x00
        if i % 50 == 49:
            token = SENTINEL | len(tokens)
            tokens.append(token)
            pieces.append(b"\x00" + P.encode_frame(P.PING, 0xEE, P.pack_ping(token)))
    return b"".join(pieces), tokens


def test_ten_to_the_fifth_fuzzed_frames_never_crash_the_firmware_and_it_resyncs(tmp_path):
    stream, tokens = fuzz_stream(100_000, seed=12)
    data = tmp_path / "fuzz.bin"
    data.write_bytes(stream)
    script = tmp_path / "fuzz.py"
    script.write_text(FUZZ_SCRIPT.format(firmware=str(FIRMWARE)))
    result = run_micropython(script, str(data))
    assert result.returncode == 0, result.stderr.decode()[-2000:]
    assert result.stderr.decode().startswith("done")
    replies = P.FrameDecoder().feed(result.stdout)
    assert replies, "the firmware answered nothing"
    pongs = {P.unpack_pong(p)[0] for t, s, p in replies if t == P.PONG and s == 0xEE}
    missing = [t for t in tokens if t not in pongs]
    assert not missing, f"{len(missing)} of {len(tokens)} PINGs after garbage went unanswered"
    kinds = {P.unpack_nack(p)[1] for t, _, p in replies if t == P.NACK}
    assert {P.E_UNKNOWN_TYPE, P.E_BAD_LENGTH, P.E_BAD_STATE} <= kinds


# -- main.py and ble_pico.py under the Unix port, with fake hardware modules -------------------

FAKES = {
    "fake_machine.py": """
import micropython
import bluetooth

class Pin:
    OUT = 1
    IN = 0
    def __init__(self, number, mode=None, value=None):
        self.number = number

class ADC:
    def __init__(self, pin):
        pass
    def read_u16(self):
        return 26000  # 1.31 V at the pin: 3.93 V on VSYS through the 3:1 divider

class I2S:
    TX = 0
    MONO = 0
    STEREO = 1
    writes = 0
    peak = 0
    stereo_ok = True
    last = None
    def __init__(self, ident, **settings):
        self.settings = settings
        self.callback = None
    def irq(self, callback):
        self.callback = callback
    def write(self, buf):
        I2S.writes += 1
        for i in range(0, len(buf), 2):
            if buf[i] != buf[i + 1]:
                I2S.stereo_ok = False
            if abs(buf[i]) > I2S.peak:
                I2S.peak = abs(buf[i])
        if I2S.writes == 600:
            bluetooth.central_writes()
        I2S.last = self

    @staticmethod
    def tick():
        # The driver asks for the next block: here every other main-loop poll, a pace that
        # leaves the loop time to read the host's bytes, as the real 4 ms period does.
        I2S.ticks = getattr(I2S, "ticks", 0) + 1
        if I2S.ticks % 2 == 0 and I2S.last is not None and I2S.last.callback is not None:
            micropython.schedule(I2S.last.callback, I2S.last)
""",
    "rp2.py": "def bootsel_button():\n    return 0\n",
    "fake_select.py": """
import select as real
import fake_machine
POLLIN = real.POLLIN

class poll:
    # The real poll, until the fake I2S has taken 1500 blocks: then the main loop ends (an
    # exception in a scheduled callback would only be printed).
    def __init__(self):
        self.poller = real.poll()
    def register(self, stream, flags):
        self.poller.register(stream, flags)
    def poll(self, timeout):
        if fake_machine.I2S.writes >= 1500:
            raise SystemExit
        fake_machine.I2S.tick()
        return self.poller.poll(0)  # the loop's 1 ms naps would only slow the test
""",
    "bluetooth.py": """
import rp_protocol as P

_ble = []

def UUID(value):
    return bytearray(16)  # the real one has the buffer protocol: its 16 bytes

class BLE:
    def __init__(self):
        self.values = {}
        self.notified = []
        self.adverts = 0
        self.handler = None
        _ble.append(self)
    def active(self, on):
        pass
    def config(self, **settings):
        self.settings = settings
    def gatts_register_services(self, services):
        return ((1, 2, 3), (4, 5, 6), (7,))
    def gatts_set_buffer(self, handle, size, append):
        pass
    def gatts_write(self, handle, value):
        self.values[handle] = bytes(value)
    def gatts_read(self, handle):
        value = self.values.get(handle, b"")
        self.values[handle] = b""
        return value
    def gatts_notify(self, connection, handle, data=None):
        self.notified.append((connection, handle, bytes(data)))
    def gap_advertise(self, interval, adv_data=None, resp_data=None, connectable=True):
        self.adverts += 1
    def irq(self, handler):
        self.handler = handler

def central_writes():
    ble = _ble[0]
    ble.handler(1, (9, 0, b""))  # a host connects
    ble.handler(21, (9, 40))  # and negotiates ATT MTU 40: notifications of 37 bytes
    ble.values[1] = P.encode_frame(P.PING, 5, P.pack_ping(0xB1E)) + P.encode_frame(
        P.HELLO, 6, P.pack_hello(1))
    ble.handler(3, (9, 1))  # it writes RX
""",
}

BOARD_SCRIPT = """
import sys
sys.path.insert(0, {fakes!r})
sys.path.insert(1, {firmware!r})
import fake_machine
import fake_select
sys.modules["machine"] = fake_machine
sys.modules["select"] = fake_select
import config
config.STARTUP_WINDOW_MS = 0  # no BOOTSEL wait
try:
    import main
except SystemExit:
    pass
import bluetooth
ble = bluetooth._ble[0]
stream = b"".join(data for conn, handle, data in ble.notified if handle == 2)
sys.stderr.write("i2s %d %d %d\\n" % (fake_machine.I2S.writes, fake_machine.I2S.peak,
                                       fake_machine.I2S.stereo_ok))
sys.stderr.write("ble %d %d %s %s\\n" % (ble.adverts, max(len(d) for c, h, d in ble.notified),
                                         stream.hex(), ble.values[3].hex()))
"""


def test_the_pico_entry_point_runs_over_fake_hardware(tmp_path):
    """main.py and ble_pico.py cannot meet a real Pico here; this runs them under the Unix port
    with fake ``machine``, ``rp2`` and ``bluetooth`` modules, so at least their wiring (USB in,
    I2S refills, GATT handles, BLE pieces) runs."""
    for name, text in FAKES.items():
        (tmp_path / name).write_text(text)
    script = tmp_path / "board.py"
    script.write_text(BOARD_SCRIPT.format(fakes=str(tmp_path), firmware=str(FIRMWARE)))
    rng = np.random.default_rng(5)
    pattern = rng.integers(-20000, 20000, 400).astype("<i2")
    data = pattern.tobytes()
    frames = [P.encode_frame(P.HELLO, 1, P.pack_hello(1)),
              P.encode_frame(P.PATTERN_BEGIN, 2, P.pack_pattern_begin(
                  3, len(pattern), RATE, P.FORMAT_S16LE, zlib.crc32(data)))]
    frames += [P.encode_frame(P.PATTERN_CHUNK, 3, P.pack_pattern_chunk(at, data[at:at + 180]))
               for at in range(0, len(data), 180)]
    frames += [P.encode_frame(P.PATTERN_COMMIT, 4, P.pack_pattern_commit(3)),
               P.encode_frame(P.SET_STATE, 5, P.pack_set_state(1, P.GAIN_ONE, P.RATE_ONE, 5)),
               P.encode_frame(P.PING, 6, P.pack_ping(42))]
    process = subprocess.run([find_micropython(), str(script)], input=b"".join(frames),
                             capture_output=True, timeout=60, cwd=tmp_path)
    report = process.stderr.decode()
    assert process.returncode == 0, report + process.stdout.decode(errors="replace")
    i2s = next(line for line in report.splitlines() if line.startswith("i2s")).split()
    assert int(i2s[1]) >= 1500 and int(i2s[2]) > 15000 and i2s[3] == "1"  # played, L == R
    usb = {(t, s): p for t, s, p in P.FrameDecoder().feed(process.stdout)}
    info = P.unpack_info(usb[(P.INFO, 1)])
    assert info[6] == P.FEATURE_USB | P.FEATURE_BLE | P.FEATURE_RATE
    assert usb[(P.ACK, 4)] == P.pack_ack(P.PATTERN_COMMIT)
    assert P.unpack_pong(usb[(P.PONG, 6)])[0] == 42
    ble = next(line for line in report.splitlines() if line.startswith("ble")).split()
    assert int(ble[1]) >= 1 and int(ble[2]) <= 37  # advertised; pieces fit the MTU
    over_ble = {(t, s): p for t, s, p in P.FrameDecoder().feed(bytes.fromhex(ble[3]))}
    assert P.unpack_pong(over_ble[(P.PONG, 5)])[0] == 0xB1E
    assert over_ble[(P.INFO, 6)] == bytes.fromhex(ble[4]) == usb[(P.INFO, 1)]


# -- end to end: host → pseudo-terminal → firmware ----------------------------------------------

class Host:
    """The host side over the raw pseudo-terminal, with only realpen.device.protocol."""

    def __init__(self, port: str):
        self.fd = os.open(port, os.O_RDWR | os.O_NOCTTY)
        self.decoder = P.FrameDecoder()
        self.seq = 0
        self.events = []

    def send(self, ftype: int, payload: bytes = b"") -> int:
        self.seq = (self.seq + 1) & 0xFF
        os.write(self.fd, P.encode_frame(ftype, self.seq, payload))
        return self.seq

    def reply(self, seq: int, timeout: float = 3.0):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if select.select([self.fd], [], [], 0.05)[0]:
                for ftype, rseq, payload in self.decoder.feed(os.read(self.fd, 4096)):
                    if ftype == P.EVENT:
                        self.events.append(P.unpack_event(payload))
                    elif rseq == seq:
                        return ftype, payload
        raise AssertionError(f"no reply to seq {seq}")

    def upload(self, samples: np.ndarray, pattern_id: int, crc: int | None = None):
        data = samples.astype("<i2").tobytes()
        crc = zlib.crc32(data) if crc is None else crc
        seq = self.send(P.PATTERN_BEGIN, P.pack_pattern_begin(pattern_id, len(samples), RATE,
                                                               P.FORMAT_S16LE, crc))
        assert self.reply(seq) == (P.ACK, P.pack_ack(P.PATTERN_BEGIN))
        for offset in range(0, len(data), P.MAX_CHUNK):
            self.send(P.PATTERN_CHUNK, P.pack_pattern_chunk(offset, data[offset:offset + 180]))
        return self.reply(self.send(P.PATTERN_COMMIT, P.pack_pattern_commit(pattern_id)))

    def close(self):
        os.close(self.fd)


def reconstruct(events: list[dict], total: int, patterns: dict[int, list[int]]) -> np.ndarray:
    """What the pen should have played, from the trace alone and the specification."""
    reference = Reference()
    out: list[int] = []
    for event in sorted(events, key=lambda e: e.get("sample", 0)):
        if event["event"] not in ("set_state", "swap", "underrun"):
            continue
        out += reference.render(event["sample"] - len(out))
        if event["event"] == "set_state":
            reference.set_state(event["playing"], event["gain"], event["rate"], event["fade_ms"])
        elif event["event"] == "swap":
            reference.swap_now(patterns[event["id"]])
        else:
            out += [0] * event["missing"]  # the sink ran dry: silence, the player stood still
    out += reference.render(total - len(out))
    return np.array(out[:total], dtype=np.int64)


def test_end_to_end_upload_play_gain_stop_and_a_corrupted_upload_keeps_the_old_pattern(tmp_path):
    rng = np.random.default_rng(3)
    pattern = rng.integers(-30000, 30000, 1200).astype(np.int16)  # 150 ms: many loops
    other = rng.integers(-30000, 30000, 600).astype(np.int16)
    wav, trace = tmp_path / "played.wav", tmp_path / "trace.jsonl"
    with SimPen(record=wav, trace=trace) as pen:
        host = Host(pen.port)
        try:
            kind, payload = host.reply(host.send(P.HELLO, P.pack_hello(P.PROTOCOL_VERSION)))
            assert kind == P.INFO
            info = P.unpack_info(payload)
            assert info[0] == P.PROTOCOL_VERSION and info[4] == RATE and info[5] == 32768
            assert host.upload(pattern, 7) == (P.ACK, P.pack_ack(P.PATTERN_COMMIT))
            host.send(P.SET_STATE, P.pack_set_state(1, P.GAIN_ONE, P.RATE_ONE, 5))
            time.sleep(0.3)
            host.send(P.SET_STATE, P.pack_set_state(1, 20000, P.RATE_ONE, 30))
            time.sleep(0.2)
            os.kill(pen.pid, signal.SIGSTOP)  # the pen stalls 60 ms: its sink must run dry
            time.sleep(0.06)
            os.kill(pen.pid, signal.SIGCONT)
            refused = host.upload(other, 8, crc=zlib.crc32(other.tobytes()) ^ 1)
            assert refused == (P.NACK, P.pack_nack(P.PATTERN_COMMIT, P.E_CRC))
            time.sleep(0.2)
            host.send(P.SET_STATE, P.pack_set_state(0, 20000, P.RATE_ONE, 10))
            time.sleep(0.1)
            kind, payload = host.reply(host.send(P.PING, P.pack_ping(99)))
            assert kind == P.PONG and P.unpack_pong(payload)[0] == 99
        finally:
            host.close()
        events = pen.events()
    played, rate = sf.read(wav, dtype="int16")
    assert rate == RATE and len(played) > RATE * 0.7
    assert (P.EV_BOOT, 0) in host.events and (P.EV_PATTERN, 7) in host.events
    assert any(kind == P.EV_UNDERRUN for kind, _ in host.events)
    gaps = [e["missing"] for e in events if e["event"] == "underrun"]
    assert gaps and max(gaps) >= 0.04 * RATE  # the stall is in the recording, as silence
    swaps = [e for e in events if e["event"] == "swap"]
    assert [e["id"] for e in swaps] == [7]  # the refused upload never played
    states = [e for e in events if e["event"] == "set_state"]
    assert [(e["playing"], e["gain"]) for e in states] == [(1, 65535), (1, 20000), (0, 20000)]
    want = reconstruct(events, len(played), {7: pattern.tolist()})
    assert np.abs(played.astype(np.int64) - want).max() <= 1
    # The old pattern kept playing through the refused upload (at gain 20000).
    after = states[1]["sample"] + 240
    assert np.abs(played[after:states[2]["sample"]]).max() > 5000
    # Stopped: silence once the 10 ms ramp is over (later if the sink ran dry meanwhile).
    stop = states[2]["sample"]
    quiet = stop + 80 + sum(e["missing"] for e in events
                            if e["event"] == "underrun" and e["sample"] >= stop)
    assert quiet < len(played) and not played[quiet:].any()


def test_restart_reboots_the_pen_on_a_new_pty_behind_the_same_link(tmp_path):
    link = tmp_path / "pen-port"
    with SimPen(link=link, protocol_version=2) as pen:
        first = os.readlink(link)
        host = Host(str(link))
        kind, payload = host.reply(host.send(P.HELLO, P.pack_hello(1)))
        assert (kind, P.unpack_nack(payload)) == (P.NACK, (P.HELLO, P.E_VERSION))
        old_fd = host.fd
        pen.restart()
        assert pen.alive and os.readlink(link) != first
        with pytest.raises(OSError):  # the old port hung up with the old firmware
            for _ in range(50):
                if not os.read(old_fd, 4096):
                    raise OSError("end of file")
        host.close()
        host = Host(str(link))
        kind, payload = host.reply(host.send(P.PING, P.pack_ping(5)))
        assert kind == P.PONG
        host.close()
    assert not link.exists() and not pen.alive


def test_sim_pen_errors_are_one_clear_line(tmp_path):
    with pytest.raises(RealPenError, match="no such MicroPython executable"):
        SimPen(micropython=str(tmp_path / "nothing")).start()
    with pytest.raises(RealPenError, match="sample rate"):
        SimPen(rate=12.5)
    (tmp_path / "file").write_text("")
    with pytest.raises(RealPenError, match="x.jsonl: cannot write"):
        SimPen(trace=tmp_path / "file" / "x.jsonl").start()
    with pytest.raises(RealPenError, match="file: exists and is not a link"):
        SimPen(link=tmp_path / "file").start()
    assert (tmp_path / "file").read_text() == ""
    broken = tmp_path / "micropython"
    broken.write_text("#!/bin/sh\necho 'ImportError: no module named rp_pen' >&2\nexit 1\n")
    broken.chmod(0o755)
    pen = SimPen(micropython=str(broken))
    with pytest.raises(RealPenError, match=r"exited at start \(code 1\): ImportError: no module"):
        pen.start()
    assert not pen.alive and pen.pty is None


def test_a_pattern_committed_while_idle_plays_from_the_first_stroke_after_it():
    """A COMMIT and a SET_STATE(playing) decoded before the same block: the new pattern starts
    the stroke (it must not wait a whole loop of the old one)."""
    player = Player(sample_rate=RATE, max_pattern_bytes=4096)
    for samples, pid in (([1000] * 200, 1), ([-2000] * 300, 2)):
        staging = player.staging()
        staging[:len(samples)] = type(staging)("h", samples)
        player.commit(len(samples), pid)
        if pid == 1:
            render(player, 32)
    player.set_state(1, P.GAIN_ONE, P.RATE_ONE, 5)
    out = np.array(render(player, 64))
    assert player.pattern_id == 2
    assert np.count_nonzero(out) > 50 and np.all(out[out != 0] < 0)  # the new one, from the start
