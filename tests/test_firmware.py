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


class CorePen:
    """``rp_pen.Pen`` in this process with one link; :meth:`ask` returns the decoded frames it
    sent back."""

    def __init__(self, **settings):
        from rp_pen import Pen

        self.sent: list[bytes] = []
        self.pen = Pen(**settings)
        self.link = self.pen.add_link(self.sent.append, "test")

    def ask(self, ftype, payload=b"", seq=9):
        self.sent.clear()
        self.link.feed(P.encode_frame(ftype, seq, payload))
        return self.frames()

    def frames(self):
        return [(t, s, p) for frame in self.sent for t, s, p in P.FrameDecoder().feed(frame)]

    def upload(self, pattern_id, samples):
        data = np.asarray(samples, dtype="<i2").tobytes()
        begin = P.pack_pattern_begin(pattern_id, len(samples), RATE, P.FORMAT_S16LE,
                                     zlib.crc32(data))
        assert self.ask(P.PATTERN_BEGIN, begin)[0][0] == P.ACK
        assert self.ask(P.PATTERN_CHUNK, P.pack_pattern_chunk(0, data)) == []
        return self.ask(P.PATTERN_COMMIT, P.pack_pattern_commit(pattern_id))


def test_a_malformed_chunk_or_commit_ends_the_upload():
    """docs/protocol.md: a chunk with a malformed payload abandons the upload, and a COMMIT
    ends it even when its payload is malformed (the Due does the same, tests/test_due.py)."""
    core = CorePen(max_pattern_bytes=400)
    data = bytes(range(40))
    begin = P.pack_pattern_begin(3, 20, RATE, P.FORMAT_S16LE, zlib.crc32(data))

    def nack(ftype, code):
        return [(P.NACK, 9, P.pack_nack(ftype, code))]

    assert core.ask(P.PATTERN_BEGIN, begin)[0][0] == P.ACK
    assert core.ask(P.PATTERN_CHUNK, P.pack_pattern_chunk(0, b"")) == nack(P.PATTERN_CHUNK,
                                                                           P.E_BAD_LENGTH)
    assert core.ask(P.PATTERN_CHUNK, P.pack_pattern_chunk(0, data)) == nack(P.PATTERN_CHUNK,
                                                                            P.E_NO_UPLOAD)
    assert core.ask(P.PATTERN_BEGIN, begin)[0][0] == P.ACK
    assert core.ask(P.PATTERN_CHUNK, P.pack_pattern_chunk(0, data)) == []
    commit = P.pack_pattern_commit(3)
    assert core.ask(P.PATTERN_COMMIT, commit + b"\x00") == nack(P.PATTERN_COMMIT, P.E_BAD_LENGTH)
    assert core.ask(P.PATTERN_COMMIT, commit) == nack(P.PATTERN_COMMIT, P.E_NO_UPLOAD)
    assert not core.pen.player.pending and core.pen.player.pattern_id == -1


def test_the_pong_clock_runs_on_across_ticks_us_wraps(monkeypatch):
    """ticks_us wraps at 2**30 µs on the rp2 port and ticks_diff is right only for gaps under
    2**29 µs (about 9 minutes): the pen's tick (every main-loop pass) keeps the PONG clock, so
    a first PING after 20 minutes still reads 20 minutes."""
    import rp_pen

    period = 1 << 30
    now = [period - 3_000_000]  # 3 s before a wrap
    monkeypatch.setattr(rp_pen, "ticks_us", lambda: now[0] % period)
    monkeypatch.setattr(rp_pen, "ticks_diff",
                        lambda a, b: (a - b + period // 2) % period - period // 2)
    core = CorePen()
    for _ in range(20 * 6):  # the main loop ticks; here every 10 s of the fake clock
        now[0] += 10_000_000
        core.pen.tick()
    [(ftype, _, payload)] = core.ask(P.PING, P.pack_ping(1))
    assert ftype == P.PONG and P.unpack_pong(payload) == (1, 20 * 60 * 1_000_000)
    for _ in range(4000):  # 11 hours on: PONG wraps at 2**32 µs, as documented
        now[0] += 10_000_000
        core.pen.tick()
    assert P.unpack_pong(core.ask(P.PING, P.pack_ping(2))[0][2])[1] == (
        (20 * 60 + 40000) * 1_000_000) % 2**32


def test_every_swap_is_announced_so_a_host_knows_what_plays():
    """EVENT pattern after each swap, with the id now playing; a BEGIN while a committed
    pattern still waits for the wrap cancels that one (docs/protocol.md), and no EVENT ever
    names it."""
    from array import array

    core = CorePen(max_pattern_bytes=400)
    block = array("h", bytes(32))

    def run(blocks):
        core.sent.clear()
        for _ in range(blocks):
            core.pen.fill(block)
            core.pen.tick()
        return [P.unpack_event(p) for t, _, p in core.frames() if t == P.EVENT]

    assert core.upload(1, [1000] * 50)[0][0] == P.ACK
    assert run(1) == [(P.EV_PATTERN, 1)]  # idle: at once
    core.ask(P.SET_STATE, P.pack_set_state(1, P.GAIN_ONE, P.RATE_ONE, 5))
    run(1)
    assert core.upload(2, [2000] * 60)[0][0] == P.ACK  # waits for pattern 1's wrap
    assert core.pen.player.pending
    assert core.ask(P.PATTERN_BEGIN, P.pack_pattern_begin(3, 70, RATE, P.FORMAT_S16LE, 0)) == [
        (P.ACK, 9, P.pack_ack(P.PATTERN_BEGIN))]
    assert not core.pen.player.pending  # pattern 2 is gone, pattern 1 plays on
    assert run(4) == [] and core.pen.player.pattern_id == 1
    assert core.upload(3, [3000] * 70)[0][0] == P.ACK
    assert run(4) == [(P.EV_PATTERN, 3)] and core.pen.player.pattern_id == 3


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


@pytest.mark.firmware
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


@pytest.mark.firmware
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
    "fake_micropython.py": """
import micropython as _real

const = _real.const
schedule = _real.schedule
LOG = []  # what the firmware did first: each kind of step once, in order

def log(step):
    if step not in LOG:
        LOG.append(step)

def kbd_intr(char):
    log("kbd_intr %d" % char)
    _real.kbd_intr(char)
""",
    "fake_gc.py": """
import gc as _real
from fake_micropython import log

mem_alloc = _real.mem_alloc
collections = 0

def collect():
    global collections
    collections += 1
    _real.collect()
""",
    "fake_machine.py": """
import micropython
import bluetooth
from fake_micropython import log

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
    # The rp2 driver's non-blocking TX path as its source has it (micropython
    # ports/rp2/machine_i2s.c, extmod/machine_i2s.c): a DMA buffer of two 128-byte halves
    # (machine_i2s.c:51-52); at each half's interrupt, write()'s buffer is copied into the ring
    # (ibuf bytes holding ibuf - 1) only if all of it fits, at most 512 bytes (extmod
    # machine_i2s.c:181-183, 322-339), and the callback is scheduled once it is all in; then
    # the half that just went out is refilled from the ring if the ring holds a half's worth,
    # else with silence (machine_i2s.c:210-239). A mono sample fills both channels, so a half
    # takes 64 ring bytes in MONO and 128 in STEREO.
    TX = 0
    MONO = 0
    STEREO = 1
    writes = 0
    irqs = 0
    peak = 0
    held = True  # every pattern sample went out twice in a row (the zero-order hold)
    same = True  # STEREO writes: left == right
    silent = 0  # halves the DMA played as silence after the first sound (underflows)
    lag = 0  # most DMA halves from a write() to its first frame entering the PIO FIFO
    last = None
    settings = None
    def __init__(self, ident, **settings):
        log("i2s")
        I2S.settings = settings
        self.ibuf = settings["ibuf"]
        self.mono = settings["format"] == I2S.MONO
        self.ring = b""
        self.pushed = 0  # bytes ever pushed into the ring
        self.popped = 0
        self.starts = []  # (ring offset of a block's first byte, irqs when it was written)
        self.app = None
        self.index = 0
        self.written_at = 0
        self.callback = None
        self.sounding = False
        I2S.last = self
    def irq(self, callback):
        self.callback = callback
    def write(self, buf):
        I2S.writes += 1
        self.app = bytes(buf)
        self.index = 0
        self.written_at = I2S.irqs
        if I2S.writes == 600:
            bluetooth.central_writes()
        if I2S.writes == 900:
            bluetooth.central_drops_mid_frame()
        return len(buf)
    def interrupt(self):
        I2S.irqs += 1
        if self.app is not None:
            n = min(512, len(self.app) - self.index)
            if self.ibuf - len(self.ring) - 1 >= n:
                if self.index == 0:
                    self.starts.append((self.pushed, self.written_at))
                self.ring += self.app[self.index:self.index + n]
                self.pushed += n
                self.index += n
                if self.index >= len(self.app):
                    self.app = None
                    micropython.schedule(self.callback, self)
        need = 64 if self.mono else 128
        if len(self.ring) < need:
            if self.sounding:
                I2S.silent += 1
            return
        half = self.ring[:need]
        self.ring = self.ring[need:]
        while self.starts and self.starts[0][0] < self.popped + need:
            # This half goes out after the one the DMA started at this interrupt.
            I2S.lag = max(I2S.lag, I2S.irqs + 1 - self.starts.pop(0)[1])
        self.popped += need
        self.sounding = True
        for i in range(0, need, 4):
            a = half[i] | half[i + 1] << 8
            b = half[i + 2] | half[i + 3] << 8
            if self.mono and a != b:
                I2S.held = False
            if not self.mono and a != b:
                I2S.same = False
            a = a - 65536 if a & 0x8000 else a
            if abs(a) > I2S.peak:
                I2S.peak = abs(a)

    @staticmethod
    def tick():
        # A DMA half has gone out: here every other main-loop poll, a pace that leaves the loop
        # time to read the host's bytes.
        I2S.ticks = getattr(I2S, "ticks", 0) + 1
        if I2S.ticks % 2 == 0 and I2S.last is not None and I2S.last.callback is not None:
            I2S.last.interrupt()
""",
    "rp2.py": """
from fake_micropython import log

def bootsel_button():
    log("bootsel")
    return 0
""",
    "fake_select.py": """
import select as real
import fake_machine
from fake_micropython import log
POLLIN = real.POLLIN

class poll:
    # The real poll, until the fake I2S has taken 1500 blocks (or played 8000 halves, should
    # the driver never take a block): then the main loop ends (an exception in a scheduled
    # callback would only be printed).
    def __init__(self):
        self.poller = real.poll()
    def register(self, stream, flags):
        self.poller.register(stream, flags)
    def poll(self, timeout):
        log("usb")
        if fake_machine.I2S.writes >= 1500 or fake_machine.I2S.irqs >= 8000:
            raise SystemExit
        fake_machine.I2S.tick()
        return self.poller.poll(0)  # the loop's 1 ms naps would only slow the test
""",
    "bluetooth.py": """
import rp_protocol as P
from fake_micropython import log

_ble = []

def UUID(value):
    return bytearray(16)  # the real one has the buffer protocol: its 16 bytes

class BLE:
    def __init__(self):
        log("ble")
        self.values = {}
        self.notified = []
        self.adverts = 0
        self.handler = None
        self.connected = set()
        self.drop = None  # a connection to drop after its first notification
        self.after_drop = 0  # notifications tried on a connection after it was gone
        _ble.append(self)
    def active(self, on):
        pass
    def config(self, **settings):
        self.settings = settings
    def gatts_register_services(self, services):
        return ((1, 2, 3), (4, 5, 6), (7,))
    def gatts_set_buffer(self, handle, size, append):
        self.rx_buffer = size
    def gatts_write(self, handle, value):
        self.values[handle] = bytes(value)
    def gatts_read(self, handle):
        value = self.values.get(handle, b"")
        self.values[handle] = b""
        return value
    def gatts_notify(self, connection, handle, data=None):
        if connection not in self.connected:
            self.after_drop += 1
            raise OSError(107)  # ENOTCONN
        self.notified.append((connection, handle, bytes(data)))
        if connection == self.drop:
            # The host walks away mid-frame: the stack's event runs before the next piece.
            self.connected.discard(connection)
            self.handler(2, (connection, 0, b""))
    def gap_advertise(self, interval, adv_data=None, resp_data=None, connectable=True):
        self.adverts += 1
    def irq(self, handler):
        self.handler = handler

def central_writes():
    ble = _ble[0]
    ble.connected.add(9)
    ble.handler(1, (9, 0, b""))  # a host connects
    ble.handler(21, (9, 40))  # and negotiates ATT MTU 40: notifications of 37 bytes
    ble.values[1] = P.encode_frame(P.PING, 5, P.pack_ping(0xB1E)) + P.encode_frame(
        P.HELLO, 6, P.pack_hello(1))
    ble.handler(3, (9, 1))  # it writes RX

def central_drops_mid_frame():
    ble = _ble[0]
    ble.connected.discard(9)
    ble.handler(2, (9, 0, b""))  # the first host leaves
    ble.connected.add(12)
    ble.handler(1, (12, 0, b""))  # another comes, at ATT MTU 23: the INFO reply in 2 pieces
    ble.drop = 12  # and leaves after the first
    ble.values[1] = P.encode_frame(P.HELLO, 7, P.pack_hello(1)) + P.encode_frame(
        P.SET_STATE, 8, P.pack_set_state(0, 0, P.RATE_ONE, 5))  # and stops the pen
    ble.handler(3, (12, 1))
""",
}

BOARD_SCRIPT = """
import sys
sys.path.insert(0, {fakes!r})
sys.path.insert(1, {firmware!r})
import fake_micropython
sys.modules["micropython"] = fake_micropython
import fake_gc
sys.modules["gc"] = fake_gc
import fake_machine
import fake_select
sys.modules["machine"] = fake_machine
sys.modules["select"] = fake_select
import config
config.STARTUP_WINDOW_MS = 20  # a short BOOTSEL window, polled twice
config.GC_IDLE_BYTES = 1  # collect at every silent idle pass
try:
    import main
except SystemExit:
    pass
import bluetooth
ble = bluetooth._ble[0]
I2S = fake_machine.I2S
stream = b"".join(data for conn, handle, data in ble.notified if handle == 2 and conn == 9)
second = [len(data) for conn, handle, data in ble.notified if handle == 2 and conn == 12]
sys.stderr.write("log %s %d\\n" % (",".join(fake_micropython.LOG).replace(" ", "_"),
                                    fake_gc.collections))
sys.stderr.write("i2s %d %d %d %d %d %d %d %d %d %d\\n" % (
    I2S.writes, I2S.peak, I2S.held, I2S.same, I2S.silent, I2S.lag, I2S.settings["rate"],
    I2S.settings["format"] == I2S.MONO, I2S.settings["ibuf"], I2S.settings["bits"]))
sys.stderr.write("ble %d %d %s %s %d %d %d\\n" % (
    ble.adverts, max(len(d) for c, h, d in ble.notified), stream.hex(), ble.values[3].hex(),
    ble.rx_buffer, len(second), ble.after_drop))
"""

DMA_HALF_FRAMES = 32  # 128-byte halves of 16-bit stereo frames (ports/rp2/machine_i2s.c:51-52)


@pytest.mark.firmware
def test_the_pico_entry_point_runs_over_fake_hardware(tmp_path):
    """main.py and ble_pico.py cannot meet a real Pico here; this runs them under the Unix port
    with fake ``micropython`` (kbd_intr), ``machine``, ``rp2`` and ``bluetooth`` modules: Ctrl-C
    off before anything else, the I2S queue as the rp2 driver's source would hold it, USB in,
    GATT handles, BLE pieces, and a host leaving in the middle of a notified frame."""
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
    assert 0x03 in frames[0]  # the HELLO holds the byte Ctrl-C is (its COBS code after 0x00)
    process = subprocess.run([find_micropython(), str(script)], input=b"".join(frames),
                             capture_output=True, timeout=60, cwd=tmp_path)
    report = process.stderr.decode()
    assert process.returncode == 0, report + process.stdout.decode(errors="replace")
    lines = {line.split()[0]: line.split()[1:] for line in report.splitlines() if line.strip()}
    steps = lines["log"][0].split(",")
    assert int(lines["log"][1]) >= 2  # once at start, then while silent and idle (the stop)
    # Ctrl-C off first of all: before the BOOTSEL window, the I2S and BLE set-up, any USB read.
    assert steps[0] == "kbd_intr_-1" and {"bootsel", "i2s", "ble", "usb"} <= set(steps[1:])
    writes, peak, held, same, silent, lag, rate, mono, ibuf, bits = map(int, lines["i2s"])
    assert writes >= 1500 and peak > 15000 and silent == 0  # it played, never ran dry
    assert (rate, mono, held, same, bits) == (2 * RATE, 1, 1, 1, 16)  # each sample twice
    # Queued ahead of the PIO: a block waits at most `lag` halves for the bus once written,
    # and a SET_STATE at most one half more for the block it goes into.
    half_ms = DMA_HALF_FRAMES * 1000 / rate
    assert lag == 2 and (lag + 1) * half_ms <= 8, (lag, half_ms, ibuf)
    usb = {(t, s): p for t, s, p in P.FrameDecoder().feed(process.stdout)}
    info = P.unpack_info(usb[(P.INFO, 1)])
    assert info[4] == RATE and info[6] == P.FEATURE_USB | P.FEATURE_BLE | P.FEATURE_RATE
    assert usb[(P.ACK, 4)] == P.pack_ack(P.PATTERN_COMMIT)
    assert P.unpack_pong(usb[(P.PONG, 6)])[0] == 42
    adverts, longest, stream, characteristic, rx_buffer, pieces, after_drop = lines["ble"]
    assert int(adverts) >= 3 and int(longest) <= 37  # advertised again after each host; pieces fit
    over_ble = {(t, s): p for t, s, p in P.FrameDecoder().feed(bytes.fromhex(stream))}
    assert P.unpack_pong(over_ble[(P.PONG, 5)])[0] == 0xB1E
    assert over_ble[(P.INFO, 6)] == bytes.fromhex(characteristic) == usb[(P.INFO, 1)]
    assert int(rx_buffer) >= 4096  # 16 chunk frames (~3 KB) written before the pen reads them
    # The host that left mid-frame got the first piece and was not notified again.
    assert int(pieces) == 1 and int(after_drop) == 0


# -- end to end: host → pseudo-terminal → firmware ----------------------------------------------

class Host:
    """The host side over the raw pseudo-terminal, with only realpen.device.protocol."""

    def __init__(self, port: str):
        self.fd = os.open(port, os.O_RDWR | os.O_NOCTTY)
        self.decoder = P.FrameDecoder()
        self.seq = 0
        self.events = []
        self.replies: dict[int, list[tuple[int, bytes]]] = {}  # seq → replies not yet taken

    def send(self, ftype: int, payload: bytes = b"") -> int:
        self.seq = (self.seq + 1) & 0xFF
        os.write(self.fd, P.encode_frame(ftype, self.seq, payload))
        return self.seq

    def read(self, timeout: float) -> None:
        """Take every frame of one read: EVENTs to ``events``, replies stashed by seq."""
        if select.select([self.fd], [], [], timeout)[0]:
            for ftype, rseq, payload in self.decoder.feed(os.read(self.fd, 4096)):
                if ftype == P.EVENT:
                    self.events.append(P.unpack_event(payload))
                else:
                    self.replies.setdefault(rseq, []).append((ftype, payload))

    def reply(self, seq: int, timeout: float = 3.0):
        """The first reply to ``seq`` not taken yet: (type, payload)."""
        deadline = time.monotonic() + timeout
        while not self.replies.get(seq):
            if time.monotonic() > deadline:
                raise AssertionError(f"no reply to seq {seq}")
            self.read(0.05)
        return self.replies[seq].pop(0)

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


@pytest.mark.firmware
def test_end_to_end_upload_play_gain_stop_and_a_corrupted_upload_keeps_the_old_pattern(tmp_path):
    rng = np.random.default_rng(3)
    pattern = rng.integers(-30000, 30000, 1200).astype(np.int16)  # 150 ms: many loops
    other = rng.integers(-30000, 30000, 600).astype(np.int16)
    wav, trace = tmp_path / "played.wav", tmp_path / "trace.jsonl"
    # A stalled process is a stalled pen here (no steady clock): the stall must run it dry.
    with SimPen(record=wav, trace=trace, steady_clock=False) as pen:
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
            deadline = time.monotonic() + 2  # the underrun EVENT, if it is not in yet
            while (not any(kind == P.EV_UNDERRUN for kind, _ in host.events)
                   and time.monotonic() < deadline):
                host.read(0.05)
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
    assert np.array_equal(played.astype(np.int64), want), "the recording is not the specification"
    # The old pattern kept playing through the refused upload (at gain 20000).
    after = states[1]["sample"] + 240
    assert np.abs(played[after:states[2]["sample"]]).max() > 5000
    # Stopped: silence once the 10 ms ramp is over (later if the sink ran dry meanwhile).
    stop = states[2]["sample"]
    quiet = stop + 80 + sum(e["missing"] for e in events
                            if e["event"] == "underrun" and e["sample"] >= stop)
    assert quiet < len(played) and not played[quiet:].any()


@pytest.mark.firmware
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


@pytest.mark.firmware
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
