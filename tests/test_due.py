"""The Arduino Due firmware's C core (firmware/arduino-due/realpen_due/realpen_{protocol,player}.c),
built on this machine with ``cc -std=c99 -Wall -Wextra -Werror`` (and AddressSanitizer and
UndefinedBehaviorSanitizer) into a small line-driven harness (firmware/arduino-due/test/
host_harness.c), and checked against the protocol's shared test vectors, the Python codec, an
independent numpy model of the player semantics (docs/protocol.md, "What the pen plays"), an
upload with a CRC mismatch, and 10⁵ random and corrupted frames.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import zlib
from pathlib import Path

import numpy as np
import pytest

from realpen.device import protocol as P

pytestmark = pytest.mark.firmware  # every test runs the C core, compiled here with cc

ROOT = Path(__file__).resolve().parents[1]
DUE = ROOT / "firmware" / "arduino-due"
SKETCH = DUE / "realpen_due"
VECTORS = ROOT / "tests" / "data" / "protocol_vectors.json"
WARNINGS = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-Wpedantic", "-Wshadow", "-Wconversion",
            "-Wsign-conversion"]
SANITIZE = ["-fsanitize=address,undefined", "-fno-sanitize-recover=all", "-fno-omit-frame-pointer"]
RATE = 8000
ENV = dict(os.environ, ASAN_OPTIONS="detect_leaks=0:abort_on_error=0",
           UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1")


def _build(out: Path) -> tuple[Path, bool]:
    """Compiles the harness; with the sanitizers when this machine's compiler has them."""
    cc = shutil.which("cc")
    if cc is None:
        # Not a skip: the Due firmware would go untested without a word. CI has cc.
        pytest.fail("no C compiler (cc) on PATH: tests/test_due.py builds the Due firmware's C "
                    "core with it; install gcc and libc6-dev (scripts/test.sh does)",
                    pytrace=False)
    sources = [str(SKETCH / "realpen_protocol.c"), str(SKETCH / "realpen_player.c"),
               str(DUE / "test" / "host_harness.c")]
    # REALPEN_DUE_CFLAGS adds flags, e.g. -m32 to run the core with the Due's 32-bit size_t
    # and long where a multilib compiler is installed.
    extra = os.environ.get("REALPEN_DUE_CFLAGS", "").split()
    base = [cc, *WARNINGS, *extra, "-O1", "-g", "-I", str(SKETCH), *sources, "-o", str(out)]
    sanitized = subprocess.run(base[:1] + SANITIZE + base[1:], capture_output=True, text=True)
    if sanitized.returncode == 0:
        probe = subprocess.run([str(out)], input="crc16 00\n", capture_output=True, text=True,
                               env=ENV)
        if probe.returncode == 0 and probe.stdout.strip() == "57840":
            return out, True
    # The warnings must hold either way: a plain build that fails is the code's fault.
    plain = subprocess.run(base, capture_output=True, text=True)
    assert plain.returncode == 0, plain.stderr
    return out, False


@pytest.fixture(scope="module")
def build(tmp_path_factory) -> tuple[Path, bool]:
    return _build(tmp_path_factory.mktemp("due") / "host_harness")


@pytest.fixture(scope="module")
def harness_exe(build) -> Path:
    return build[0]


class Harness:
    """One harness process: a line per command, a line per answer."""

    def __init__(self, exe: Path):
        self.proc = subprocess.Popen([str(exe)], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, text=True, env=ENV, bufsize=1)

    def __call__(self, *words) -> str:
        self.proc.stdin.write(" ".join(str(w) for w in words) + "\n")
        self.proc.stdin.flush()
        answer = self.proc.stdout.readline()
        assert answer, f"harness died: {self.proc.stderr.read()}"
        return answer.rstrip("\n")

    def ints(self, *words) -> np.ndarray:
        return np.array(self(*words).split(), dtype=np.int64)

    def close(self) -> str:
        self.proc.stdin.close()
        self.proc.wait(timeout=10)
        err = self.proc.stderr.read()
        self.proc.stdout.close()
        self.proc.stderr.close()
        assert self.proc.returncode == 0, err
        return err


@pytest.fixture
def harness(harness_exe):
    h = Harness(harness_exe)
    yield h
    assert "runtime error" not in h.close()


def hx(data: bytes) -> str:
    return data.hex() or "-"


def unhx(text: str) -> bytes:
    return b"" if text == "-" else bytes.fromhex(text)


# --- the shared vectors and the Python codec ---------------------------------------------

def test_build_is_clean_with_sanitizers(build):
    """The firmware compiles without a warning, and under ASan/UBSan where the compiler has them
    (the fallback to a plain build is for compilers without them, not for gcc or clang)."""
    _, sanitized = build
    if shutil.which("gcc") or shutil.which("clang"):
        assert sanitized


def test_sketch_pattern_is_the_bundled_pencil_export(tmp_path):
    """pattern.h is `realpen export pencil --format c-header --rate 8000` of today's pencil, and
    realpen_config.h names its identifiers."""
    from conftest import run_cli

    fresh = tmp_path / "pattern.h"
    result = run_cli("export", "pencil", "--format", "c-header", "--rate", str(RATE), "-o", fresh)
    assert result.returncode == 0, result.stderr
    shipped = (SKETCH / "pattern.h").read_text()
    body = shipped[shipped.index("#ifndef"):]       # the comment names RealPen's version
    assert body == fresh.read_text()[fresh.read_text().index("#ifndef"):], (
        "firmware/arduino-due/realpen_due/pattern.h is stale: regenerate it with "
        "realpen export pencil --format c-header --rate 8000 -o "
        "firmware/arduino-due/realpen_due/pattern.h")
    config = (SKETCH / "realpen_config.h").read_text()
    for name in ("realpen_pencil_tactile", "REALPEN_PENCIL_LENGTH", "REALPEN_PENCIL_RATE_HZ"):
        assert name in config and name in body
    assert "#define REALPEN_PENCIL_RATE_HZ 8000UL" in body


def test_shared_vectors(harness):
    vectors = json.loads(VECTORS.read_text())
    assert vectors["protocol_version"] == P.PROTOCOL_VERSION
    for case in vectors["crc16"]:
        assert int(harness("crc16", hx(bytes.fromhex(case["data"])))) == case["crc16"]
    for case in vectors["cobs"]:
        raw, encoded = bytes.fromhex(case["raw"]), bytes.fromhex(case["encoded"])
        assert unhx(harness("cobs_enc", hx(raw))) == encoded
        assert unhx(harness("cobs_dec", hx(encoded))) == raw
    for case in vectors["frames"]:
        args = list(case["args"])
        if case["pack"] == "pack_info":
            args[-1] = args[-1].encode().hex()
        if case["pack"] in ("pack_pattern_chunk", "pack_samples"):
            args[-1] = args[-1] or "-"
        assert unhx(harness("pack", case["pack"], *args)).hex() == case["payload_hex"], case["name"]
        frame = harness("frame", case["type"], case["seq"], case["payload_hex"] or "-")
        assert frame == case["frame_hex"], case["name"]
        count, errors, *frames = harness("decode", case["frame_hex"]).split(" ")
        assert (count, errors) == ("1", "0")
        assert frames == [f"{case['type']},{case['seq']},{case['payload_hex']}"]
    for case in vectors["streams"]:
        count = harness("decode", case["stream_hex"]).split(" ")[0]
        assert int(count) == case["frames"], case["why"]


def test_structs_round_trip_and_refuse_wrong_lengths(harness):
    assert harness("unpack", "begin", P.pack_pattern_begin(513, 12000, 8000, 1, 4152666804).hex()) \
        == "513 12000 8000 1 4152666804"
    assert harness("unpack", "state", P.pack_set_state(1, 65535, 16384, 7).hex()) \
        == "1 65535 16384 7"
    assert harness("unpack", "pong", P.pack_pong(7, 2**32 - 1).hex()) == f"7 {2**32 - 1}"
    assert harness("unpack", "event", P.pack_event(5, 99).hex()) == "5 99"
    assert harness("unpack", "capture_start", P.pack_capture_start(16, 1344).hex()) == "16 1344"
    assert harness("unpack", "capture_stop", "-") == "-"
    block = bytes(range(P.SAMPLE_BYTES * P.MAX_BLOCK_SAMPLES))
    samples = P.pack_samples(2**32 - 1, 77, 8, P.SAMPLES_OVERRUN, block)
    assert harness("unpack", "samples", samples.hex()) == f"{2**32 - 1} 77 8 1 {block.hex()}"
    info = P.pack_info(1, 0, 1, 0, 8000, 24576, 9, "Due pen é")
    assert harness("unpack", "info", info.hex()) == f"1 0 1 0 8000 24576 9 {'Due pen é'.encode().hex()}"
    chunk = P.pack_pattern_chunk(360, bytes(range(180)))
    assert harness("unpack", "chunk", chunk.hex()) == "360 " + bytes(range(180)).hex()
    for name, good in [("hello", 2), ("begin", 15), ("commit", 2), ("state", 7), ("ping", 4),
                       ("pong", 8), ("ack", 1), ("nack", 2), ("event", 5),
                       ("capture_start", 3)]:
        for n in (good - 1, good + 1):
            assert harness("unpack", name, hx(bytes(n))) == "err", (name, n)
    assert harness("unpack", "capture_stop", "00") == "err"
    for n in (0, 6, 10 + 5, 10 + 6 * 33):                   # 1 … 32 whole samples after 10 bytes
        assert harness("unpack", "samples", hx(bytes(n))) == "err", n
    for data in ("-", "00" * 7, "00" * 6 * 33):
        assert harness("pack", "pack_samples", 0, 0, 2, 0, data) == "err", data
    assert harness("unpack", "chunk", hx(bytes(4))) == "err"          # no data
    assert harness("unpack", "chunk", hx(bytes(4 + 181))) == "err"    # over MAX_CHUNK
    assert harness("unpack", "info", hx(bytes(16))) == "err"
    assert harness("unpack", "info", hx(bytes(17 + 33))) == "err"
    # A name longer than 32 bytes is cut at a character boundary, never inside one.
    long_name = ("é" * 20).encode().hex()
    payload = unhx(harness("pack", "pack_info", 1, 0, 1, 0, 8000, 1, 0, long_name))
    assert payload[17:] == ("é" * 16).encode()


def test_codec_matches_python_on_random_input(harness):
    rng = np.random.default_rng(12)
    for _ in range(300):
        raw = rng.integers(0, 256, int(rng.integers(0, 600)), dtype=np.uint8)
        raw[rng.random(raw.size) < rng.random()] = 0
        raw = raw.tobytes()
        assert int(harness("crc16", hx(raw))) == P.crc16(raw)
        assert int(harness("crc32", hx(raw))) == zlib.crc32(raw)
        assert unhx(harness("cobs_enc", hx(raw))) == P.cobs_encode(raw)
        # Malformed COBS (zero bytes inside, blocks past the end) is refused exactly as in Python.
        junk = rng.integers(0, 256, int(rng.integers(1, 40)), dtype=np.uint8)
        junk[rng.random(junk.size) < 0.1] = 0
        junk = junk.tobytes()
        try:
            expected = hx(P.cobs_decode(junk))
        except ValueError:
            expected = "err"
        assert harness("cobs_dec", hx(junk)) == expected
    assert harness("frame", 1, 0, hx(bytes(252))) == hx(P.encode_frame(1, 0, bytes(252)))
    assert harness("frame", 1, 0, hx(bytes(253))) == "err"            # over MAX_FRAME


def _python_decode(stream: bytes) -> tuple[list[str], int]:
    decoder = P.FrameDecoder()
    frames = [f"{t},{s},{p.hex()}" for t, s, p in decoder.feed(stream)]
    return frames, decoder.errors


def test_decoder_matches_python_frame_for_frame(harness):
    """Frames and dropped-frame counts equal protocol.py's FrameDecoder's on a mixed stream:
    good frames, corrupted ones, garbage, over-long runs without a delimiter."""
    stream = _fuzz_stream(np.random.default_rng(5), 1500, probe_every=0)[0]
    count, errors, *frames = harness("decode", stream.hex()).split(" ")
    py_frames, py_errors = _python_decode(stream)
    assert frames == py_frames
    assert (int(count), int(errors)) == (len(py_frames), py_errors)
    assert py_errors > 100 and len(py_frames) > 100


# --- the player against a numpy model of the contract -----------------------------------

class Model:
    """docs/protocol.md "What the pen plays", in numpy, written from the text, not the C."""

    def __init__(self, rate: int, cap: int):
        self.sr, self.cap = rate, cap
        self.samples = self.next = None
        self.id = self.next_id = 0
        self.playing = 0
        self.amp = self.amp0 = self.target = 0
        self.k = self.n = 0
        self.rate = self.rate0 = self.rate_target = P.RATE_ONE
        self.rk = self.rn = 0
        self.pos = 0

    def idle(self) -> bool:
        return not self.playing and self.amp == 0

    def set_state(self, playing, gain, rate=P.RATE_ONE, fade_ms=5):
        self.playing = playing
        self.amp0, self.target = self.amp, (gain * self.cap // P.GAIN_ONE if playing else 0)
        self.k, self.n = 0, max(max(fade_ms, 5) * self.sr // 1000, 1)
        if rate != self.rate_target:            # a repeated rate does not restart its ramp
            self.rate0, self.rate_target = self.rate, rate
            self.rk, self.rn = 0, max(5 * self.sr // 1000, 1)

    def load(self, samples, pid):
        self.next, self.next_id = np.asarray(samples, dtype=np.int64), pid
        if self.samples is None or self.idle():
            self._swap()

    def _swap(self):
        self.samples, self.id, self.next, self.pos = self.next, self.next_id, None, 0

    @staticmethod
    def _ramp(v0, target, k, n, count):
        if n == 0:                                # never set: the initial value holds
            return np.full(count, v0, dtype=np.int64)
        ks = np.minimum(k + np.arange(1, count + 1), n)
        return v0 + (target - v0) * ks // n

    def render(self, count: int) -> np.ndarray:
        amp = self._ramp(self.amp0, self.target, self.k, self.n, count)
        rate = self._ramp(self.rate0, self.rate_target, self.rk, self.rn, count)
        self.k, self.rk = min(self.k + count, self.n), min(self.rk + count, self.rn)
        out = np.zeros(count, dtype=np.int64)
        j = 0
        while j < count and self.samples is not None:
            s = self.samples
            end = s.size << 16
            steps = rate[j:] << 4
            pos = self.pos + np.concatenate([[0], np.cumsum(steps)[:-1]])  # before each sample
            stopped = np.flatnonzero((amp[j:] == 0) & (not self.playing))
            wraps = np.flatnonzero(pos + steps >= end) if self.next is not None else []
            z = stopped[0] if len(stopped) else None
            w = wraps[0] if len(wraps) else None
            last = count - j - 1
            if z is not None and (w is None or z <= w):
                last = z
            elif w is not None:
                last = w
            p = pos[:last + 1] % end
            i, frac = p >> 16, p & 0xFFFF
            a, b = s[i], s[(i + 1) % s.size]
            value = np.where(frac == 0, a, a + ((b - a) * (frac >> 2) >> 14))
            out[j:j + last + 1] = value * amp[j:j + last + 1] >> 15
            if z is not None and last == z:        # stopped and silent: back to the start
                self.pos = 0
                if self.next is not None:
                    self._swap()
                break                              # amp stays 0 until the next SET_STATE
            if w is not None and last == w:        # the new pattern starts at the wrap
                self._swap()
                j += last + 1
                continue
            self.pos = int((pos[last] + steps[last]) % end)
            break
        self.amp, self.rate = int(amp[-1]), int(rate[-1])
        return out


def _pattern(rng, n):
    return rng.integers(-32768, 32768, n).astype(np.int16)


class Both:
    """The C player (through the harness) and the model, driven by the same script in blocks."""

    def __init__(self, harness, rate=RATE, cap=32767):
        self.h, self.m = harness, Model(rate, cap)
        assert harness("pen", rate, 65536, cap, "-") == "ok"

    def load(self, samples, pid):
        assert self.h("load", pid, samples.astype("<i2").tobytes().hex()) == "0"
        self.m.load(samples, pid)

    def state(self, *args):
        assert self.h("state", *args) == "0"
        self.m.set_state(*args)

    def render(self, count, block=32):
        got, want = [], []
        for start in range(0, count, block):
            n = min(block, count - start)
            got.append(self.h.ints("render", n))
            want.append(self.m.render(n))
        got, want = np.concatenate(got), np.concatenate(want)
        bad = np.flatnonzero(got != want)
        assert bad.size == 0, f"first difference at sample {bad[0]}: {got[bad[0]]} != {want[bad[0]]}"
        return got


def test_player_silent_before_any_pattern(harness):
    both = Both(harness)
    both.state(1, 65535, 4096, 5)
    assert not both.render(200).any()


def test_player_ramps_cap_loop_and_reset(harness):
    rng = np.random.default_rng(1)
    a = _pattern(rng, 500)
    both = Both(harness, cap=20000)
    both.load(a, 1)
    both.state(1, 40000, 4096, 20)            # 20 ms ramp up to 40000/65535 of the cap
    out = both.render(1300)                   # through two wraps
    np.testing.assert_array_equal(out[160:500], a[160:500].astype(np.int64) * 12207 >> 15)
    both.state(1, 65535, 4096, 0)             # 0 → the 5 ms minimum, up to the cap
    both.render(700, block=50)
    assert harness("info").split()[4] == "20000"
    both.state(0, 65535, 4096, 12)            # stop: 96-sample fade, then the position resets
    both.render(300)
    assert harness("info").split()[3] == "0"
    both.state(1, 65535, 4096, 5)             # the next stroke starts at the pattern's start
    out = both.render(100)
    assert out[0] == int(a[0]) * (20000 // 40) >> 15
    both.state(1, 10000, 4096, 30)            # a ramp interrupted by another
    both.render(64)
    both.state(0, 0, 4096, 7)
    both.render(200, block=17)


def test_player_rate_interpolates_and_ramps(harness):
    rng = np.random.default_rng(2)
    both = Both(harness)
    both.load(_pattern(rng, 777), 3)
    both.state(1, 50000, 6000, 5)
    both.render(2000)
    both.state(1, 50000, 1024, 9)
    both.render(900, block=40)
    both.state(1, 50000, 16384, 5)
    both.render(900)
    both.state(1, 50000, 4096, 5)             # back to RATE_ONE at a fractional position
    both.render(20)
    both.state(1, 30000, 4096, 5)             # the same rate again: its ramp goes on
    both.render(500)


def test_player_swaps_at_the_wrap_or_at_once_when_idle(harness):
    rng = np.random.default_rng(3)
    a, b, c = _pattern(rng, 400), _pattern(rng, 250), _pattern(rng, 300)
    both = Both(harness)
    both.load(a, 10)                          # idle: at once
    assert harness("info").split()[:3] == ["10", "1", "0"]
    both.state(1, 65535, 4096, 5)
    both.render(160)
    both.load(b, 11)                          # playing: waits for a's wrap at sample 400
    assert harness("info").split()[:3] == ["10", "1", "1"]
    out = both.render(400)
    assert harness("info").split()[:2] == ["11", "2"]
    np.testing.assert_array_equal(out[240:250], b[:10].astype(np.int64) * 32767 >> 15)
    both.load(c, 12)                          # replaced before its wrap by d: d plays next
    d = _pattern(rng, 90)
    both.load(d, 13)
    both.render(300)
    assert harness("info").split()[:2] == ["13", "3"]
    both.state(1, 65535, 5000, 5)             # wrap at a fractional position, then a swap
    both.load(a, 14)
    both.render(400)
    both.load(b, 15)                          # stopping with a pattern waiting: swap when silent
    both.state(0, 0, 4096, 5)
    both.render(100)
    assert harness("info").split()[:3] == ["15", "5", "0"]


def test_player_matches_the_pico_player_sample_for_sample(harness):
    """The Due's C player and the Pico's MicroPython player (firmware/pico/rp_player.py, run
    here under CPython) render the same samples for the same script, block by block."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(
        "rp_player_pico", ROOT / "firmware" / "pico" / "rp_player.py")
    pico = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(pico)
    from array import array

    rng = np.random.default_rng(6)
    a, b = _pattern(rng, 700), _pattern(rng, 333)
    py = pico.Player(RATE, 4096, 24000)
    assert harness("pen", RATE, 4096, 24000, "-") == "ok"

    def load(samples, pid):
        py.staging()[:samples.size] = array("h", samples.tobytes())
        py.commit(samples.size, pid)
        assert harness("load", pid, samples.astype("<i2").tobytes().hex()) == "0"

    def state(*args):
        py.set_state(*args)
        assert harness("state", *args) == "0"

    def render(count, block=32):
        buf = array("h", bytes(2 * block))
        for _ in range(count // block):
            py.fill(buf)
            np.testing.assert_array_equal(harness.ints("render", block), np.array(buf))

    load(a, 1)
    state(1, 65535, 4096, 5)
    render(1024)
    state(1, 20000, 7000, 30)
    render(640)
    load(b, 2)                                # waits for the wrap
    render(1600)
    state(1, 65535, 2000, 5)
    render(320)
    state(1, 65535, 2000, 9)                  # same rate: no new rate ramp
    render(640)
    state(0, 65535, 4096, 12)                 # stop: position back to 0
    render(320)
    state(1, 40000, 4096, 5)
    render(960, block=40)


def test_dac_codes_and_header_codes_round_trip(harness):
    both = Both(harness)
    codes = np.arange(4096)
    samples = np.array([int(harness("code", c)) for c in range(0, 4096, 273)] + [0])
    np.testing.assert_array_equal(samples[:-1], 16 * (codes[::273] - 2048) + 8)
    table = (16 * (codes - 2048) + 8).astype(np.int16)
    both.load(table, 1)
    both.state(1, 65535, 4096, 5)             # full drive: the header's codes come back
    harness("render", 40)
    dac = harness.ints("dac", 4056)
    np.testing.assert_array_equal(dac, codes[40:])
    assert dac.min() >= 0 and dac.max() <= 4095
    both.state(1, 32768, 4096, 5)             # half drive: 2048 + (((s * amp) >> 15) >> 4)
    harness("render", 40)
    dac = harness.ints("dac", 2000)
    amp = 32768 * 32767 // 65535
    expected = 2048 + ((table[40:2040].astype(np.int64) * amp >> 15) >> 4)
    np.testing.assert_array_equal(dac, expected)


# --- the pen: upload, commit, refusals ----------------------------------------------------

class Host:
    """Talks to the C pen through the harness with the Python codec."""

    def __init__(self, harness, rate=RATE, buffer_bytes=8192, cap=32767, name="Due test"):
        self.h, self.seq = harness, 0
        assert harness("pen", rate, buffer_bytes, cap, name.encode().hex()) == "ok"

    def send(self, ftype, payload=b"") -> list[tuple[int, int, bytes]]:
        self.seq = (self.seq + 1) & 0xFF
        out = unhx(self.h("feed", P.encode_frame(ftype, self.seq, payload).hex()))
        return P.FrameDecoder().feed(out)

    def nack(self, ftype, payload, code):
        assert self.send(ftype, payload) == [(P.NACK, self.seq, P.pack_nack(ftype, code))]

    def upload(self, samples, pid, *, crc=None, rate=RATE) -> list:
        data = samples.astype("<i2").tobytes()
        begin = P.pack_pattern_begin(pid, samples.size, rate, P.FORMAT_S16LE,
                                     zlib.crc32(data) if crc is None else crc)
        assert self.send(P.PATTERN_BEGIN, begin) == [(P.ACK, self.seq, bytes([P.PATTERN_BEGIN]))]
        for at in range(0, len(data), P.MAX_CHUNK):
            assert self.send(P.PATTERN_CHUNK, P.pack_pattern_chunk(at, data[at:at + P.MAX_CHUNK])) \
                == []
        return self.send(P.PATTERN_COMMIT, P.pack_pattern_commit(pid))


def test_pen_hello_info_ping_and_refusals(harness):
    host = Host(harness, buffer_bytes=8192)
    [(ftype, seq, payload)] = host.send(P.HELLO, P.pack_hello(1))
    assert (ftype, seq) == (P.INFO, host.seq)
    assert P.unpack_info(payload) == (1, 0, 1, 0, RATE, 8192, P.FEATURE_USB | P.FEATURE_RATE,
                                      "Due test")
    refused = host.send(P.HELLO, P.pack_hello(2))
    assert refused[0] == (P.NACK, host.seq, P.pack_nack(P.HELLO, P.E_VERSION))
    assert [(kind, seq, P.unpack_info(payload)[0]) for kind, seq, payload in refused[1:]] == [
        (P.INFO, host.seq, P.PROTOCOL_VERSION)]  # the host learns which version the pen speaks
    host.nack(P.HELLO, b"\x01", P.E_BAD_LENGTH)
    [(ftype, seq, payload)] = host.send(P.PING, P.pack_ping(0xDEADBEEF))
    assert ftype == P.PONG and seq == host.seq and P.unpack_pong(payload)[0] == 0xDEADBEEF
    host.nack(0x77, b"", P.E_UNKNOWN_TYPE)
    host.nack(P.INFO, b"", P.E_UNKNOWN_TYPE)
    host.nack(P.SET_STATE, P.pack_set_state(2, 0, 4096, 5), P.E_BAD_STATE)
    host.nack(P.SET_STATE, P.pack_set_state(1, 0, 1023, 5), P.E_BAD_STATE)
    host.nack(P.SET_STATE, P.pack_set_state(1, 0, 16385, 5), P.E_BAD_STATE)
    host.nack(P.SET_STATE, b"\x01\x00", P.E_BAD_LENGTH)
    assert host.send(P.SET_STATE, P.pack_set_state(1, 100, 16384, 0)) == []
    host.nack(P.PATTERN_BEGIN, P.pack_pattern_begin(1, 4097, RATE, 1, 0), P.E_TOO_LARGE)
    host.nack(P.PATTERN_BEGIN, P.pack_pattern_begin(1, 100, RATE, 2, 0), P.E_BAD_FORMAT)
    host.nack(P.PATTERN_BEGIN, P.pack_pattern_begin(1, 100, 44100, 1, 0), P.E_BAD_RATE)
    host.nack(P.PATTERN_BEGIN, P.pack_pattern_begin(1, 0, RATE, 1, 0), P.E_BAD_FORMAT)
    host.nack(P.PATTERN_CHUNK, P.pack_pattern_chunk(0, b"\x01\x02"), P.E_NO_UPLOAD)
    host.nack(P.PATTERN_COMMIT, P.pack_pattern_commit(1), P.E_NO_UPLOAD)
    host.nack(P.PATTERN_CHUNK, P.pack_pattern_chunk(0, b"") + b"", P.E_BAD_LENGTH)


def test_the_due_has_no_sensor_to_capture_from(harness):
    """No FEATURE_ACCEL in INFO; CAPTURE_START is refused with E_NO_SENSOR whatever it asks for
    (E_BAD_LENGTH when malformed); CAPTURE_STOP is acknowledged, as any pen with no capture
    under way acknowledges it, and no SAMPLES ever come."""
    host = Host(harness)
    [(_, _, info)] = host.send(P.HELLO, P.pack_hello(1))
    assert not P.unpack_info(info)[6] & P.FEATURE_ACCEL
    host.nack(P.CAPTURE_START, P.pack_capture_start(2, P.CAPTURE_RATE), P.E_NO_SENSOR)
    host.nack(P.CAPTURE_START, P.pack_capture_start(3, 999), P.E_NO_SENSOR)
    host.nack(P.CAPTURE_START, b"\x02", P.E_BAD_LENGTH)
    assert host.send(P.CAPTURE_STOP) == [(P.ACK, host.seq, bytes([P.CAPTURE_STOP]))]
    assert host.send(P.CAPTURE_STOP) == [(P.ACK, host.seq, bytes([P.CAPTURE_STOP]))]
    host.nack(P.CAPTURE_STOP, b"\x00", P.E_BAD_LENGTH)
    host.nack(P.SAMPLES, P.pack_samples(0, 0, 2, 0, bytes(6)), P.E_UNKNOWN_TYPE)  # pen → host
    assert P.FrameDecoder().feed(unhx(harness("poll", 0))) == []


def test_upload_commit_and_crc_mismatch_keeps_the_old_pattern(harness):
    rng = np.random.default_rng(4)
    a, b, c = _pattern(rng, 1200), _pattern(rng, 900), _pattern(rng, 1000)
    host = Host(harness, buffer_bytes=4096)
    model = Model(RATE, 32767)
    assert host.upload(a, 0x0201) == [(P.ACK, host.seq, bytes([P.PATTERN_COMMIT]))]
    model.load(a, 0x0201)
    events = P.FrameDecoder().feed(unhx(harness("poll", 0)))
    assert events == [(P.EVENT, 0, P.pack_event(P.EV_PATTERN, 0x0201))]
    host.send(P.SET_STATE, P.pack_set_state(1, 65535, 4096, 5))
    model.set_state(1, 65535, 4096, 5)

    def play(n):
        got = np.concatenate([harness.ints("render", 50) for _ in range(n // 50)])
        want = np.concatenate([model.render(50) for _ in range(n // 50)])
        np.testing.assert_array_equal(got, want)

    play(500)
    # A corrupted upload: every chunk arrives, the CRC differs; the pen keeps a.
    data_b = b.astype("<i2").tobytes()
    assert host.upload(b, 7, crc=zlib.crc32(data_b) ^ 1) == \
        [(P.NACK, host.seq, P.pack_nack(P.PATTERN_COMMIT, P.E_CRC))]
    play(2500)
    assert harness("info").split()[:3] == ["513", "1", "0"]
    # Incomplete, out of order, too many bytes, a commit for another id: refused, a kept.
    begin = P.pack_pattern_begin(8, c.size, RATE, 1, zlib.crc32(c.astype("<i2").tobytes()))
    assert host.send(P.PATTERN_BEGIN, begin)[0][0] == P.ACK
    host.send(P.PATTERN_CHUNK, P.pack_pattern_chunk(0, bytes(180)))
    host.nack(P.PATTERN_COMMIT, P.pack_pattern_commit(8), P.E_INCOMPLETE)
    assert host.send(P.PATTERN_BEGIN, begin)[0][0] == P.ACK
    host.nack(P.PATTERN_COMMIT, P.pack_pattern_commit(9), P.E_NO_UPLOAD)   # another id
    host.nack(P.PATTERN_COMMIT, P.pack_pattern_commit(8), P.E_NO_UPLOAD)   # ended by it
    assert host.send(P.PATTERN_BEGIN, begin)[0][0] == P.ACK
    host.nack(P.PATTERN_CHUNK, P.pack_pattern_chunk(180, bytes(180)), P.E_BAD_OFFSET)
    host.nack(P.PATTERN_CHUNK, P.pack_pattern_chunk(0, bytes(180)), P.E_NO_UPLOAD)  # abandoned
    short = P.pack_pattern_begin(8, 10, RATE, 1, 0)
    assert host.send(P.PATTERN_BEGIN, short)[0][0] == P.ACK
    host.nack(P.PATTERN_CHUNK, P.pack_pattern_chunk(0, bytes(21)), P.E_TOO_LARGE)
    play(1000)
    assert P.FrameDecoder().feed(unhx(harness("poll", 0))) == []
    # A good upload while playing: ACK, a plays to its wrap, then b.
    assert host.upload(b, 0x0102)[0] == (P.ACK, host.seq, bytes([P.PATTERN_COMMIT]))
    model.load(b, 0x0102)
    play(2000)
    assert harness("info").split()[:2] == [str(0x0102), "2"]
    assert P.FrameDecoder().feed(unhx(harness("poll", 3))) == [
        (P.EVENT, 1, P.pack_event(P.EV_PATTERN, 0x0102)),
        (P.EVENT, 2, P.pack_event(P.EV_UNDERRUN, 3))]
    # Odd-sized chunks split samples across frames and still land byte for byte.
    data_c = c.astype("<i2").tobytes()
    begin = P.pack_pattern_begin(5, c.size, RATE, 1, zlib.crc32(data_c))
    host.send(P.PATTERN_BEGIN, begin)
    for at in range(0, len(data_c), 177):
        assert host.send(P.PATTERN_CHUNK, P.pack_pattern_chunk(at, data_c[at:at + 177])) == []
    assert host.send(P.PATTERN_COMMIT, P.pack_pattern_commit(5))[0][0] == P.ACK
    model.load(c, 5)
    host.send(P.SET_STATE, P.pack_set_state(0, 0, 4096, 5))
    model.set_state(0, 0, 4096, 5)
    play(1500)
    host.send(P.SET_STATE, P.pack_set_state(1, 65535, 4096, 5))
    model.set_state(1, 65535, 4096, 5)
    play(1500)
    assert harness("info").split()[0] == "5"


def test_a_malformed_chunk_or_commit_ends_the_upload(harness):
    """As on the Pico (docs/protocol.md): a chunk with a malformed payload abandons the upload,
    and a COMMIT ends it even when its payload is malformed."""
    host = Host(harness, buffer_bytes=4096)
    data = bytes(range(40))
    begin = P.pack_pattern_begin(3, 20, RATE, P.FORMAT_S16LE, zlib.crc32(data))
    assert host.send(P.PATTERN_BEGIN, begin)[0][0] == P.ACK
    host.nack(P.PATTERN_CHUNK, P.pack_pattern_chunk(0, b""), P.E_BAD_LENGTH)  # no data
    host.nack(P.PATTERN_CHUNK, P.pack_pattern_chunk(0, data), P.E_NO_UPLOAD)  # abandoned
    assert host.send(P.PATTERN_BEGIN, begin)[0][0] == P.ACK
    assert host.send(P.PATTERN_CHUNK, P.pack_pattern_chunk(0, data)) == []
    host.nack(P.PATTERN_COMMIT, P.pack_pattern_commit(3) + b"\x00", P.E_BAD_LENGTH)
    host.nack(P.PATTERN_COMMIT, P.pack_pattern_commit(3), P.E_NO_UPLOAD)  # ended by it
    pattern_id, _, waiting = harness("info").split()[:3]
    assert pattern_id != "3" and waiting == "0"  # nothing of it was committed


# --- 10⁵ random and corrupted frames ------------------------------------------------------

def _frame_pool(rng, size=600) -> list[bytes]:
    """Valid frames of every kind, many of them things the pen acts on."""
    pool = []
    for _ in range(size):
        kind = int(rng.integers(0, 9))
        seq = int(rng.integers(0, 256))
        if kind == 0:
            pool.append(P.encode_frame(P.SET_STATE, seq, P.pack_set_state(
                int(rng.integers(0, 3)), int(rng.integers(0, 65536)),
                int(rng.integers(512, 20000)), int(rng.integers(0, 50)))))
        elif kind == 1:
            pool.append(P.encode_frame(P.PATTERN_BEGIN, seq, P.pack_pattern_begin(
                int(rng.integers(0, 4)), int(rng.integers(0, 3000)),
                int(rng.choice([8000, 8000, 44100])), int(rng.integers(0, 3)),
                int(rng.integers(0, 2**32)))))
        elif kind == 2:
            data = rng.integers(0, 256, int(rng.integers(1, P.MAX_CHUNK + 1)), dtype=np.uint8)
            offset = int(rng.choice([0, 180, 360, int(rng.integers(0, 6000))]))
            pool.append(P.encode_frame(P.PATTERN_CHUNK, seq,
                                       P.pack_pattern_chunk(offset, data.tobytes())))
        elif kind == 3:
            pool.append(P.encode_frame(P.PATTERN_COMMIT, seq,
                                       P.pack_pattern_commit(int(rng.integers(0, 4)))))
        elif kind == 4:
            pool.append(P.encode_frame(P.HELLO, seq, P.pack_hello(int(rng.integers(0, 3)))))
        elif kind == 5:
            pool.append(P.encode_frame(int(rng.choice([P.CAPTURE_START, P.CAPTURE_STOP])), seq,
                                       P.pack_capture_start(int(rng.integers(0, 17)), 1344)
                                       if rng.random() < 0.5 else b""))
        else:
            payload = rng.integers(0, 256, int(rng.integers(0, 252)), dtype=np.uint8).tobytes()
            pool.append(P.encode_frame(int(rng.integers(0, 256)), seq, payload))
    return pool


def _fuzz_stream(rng, items: int, *, probe_every: int) -> tuple[bytes, list[int]]:
    """items random or corrupted frames (and a few good ones); after every probe_every-th, a
    delimiter and a good PING whose token is its number. Every random draw is made up front, in
    arrays, so that building 10⁵ items takes a fraction of a second."""
    pool = _frame_pool(rng)
    kinds = rng.integers(0, 8, items).tolist()
    picks = rng.integers(0, len(pool), items).tolist()
    short = rng.integers(1, 80, items).tolist()
    long_ = np.where(rng.random(items) < 0.2, rng.integers(260, 600, items),
                     rng.integers(1, 260, items)).tolist()
    where = rng.random(items).tolist()
    bits = (1 << rng.integers(0, 8, items)).tolist()
    extra = rng.integers(0, 256, items).tolist()
    size = 1 << 20
    any_bytes = rng.integers(0, 256, size, dtype=np.uint8).tobytes()
    no_zero = rng.integers(1, 256, size, dtype=np.uint8).tobytes()
    starts = rng.integers(0, size - 600, items).tolist()
    parts, probes = [], []
    for n in range(items):
        frame = pool[picks[n]]
        kind = kinds[n]
        at = int(where[n] * (len(frame) - 1))
        if kind == 0:       # random bytes, zeros included
            part = any_bytes[starts[n]:starts[n] + short[n]]
        elif kind == 1:     # random bytes without a delimiter, sometimes too long for a frame
            part = no_zero[starts[n]:starts[n] + long_[n]]
        elif kind == 2:     # one flipped bit
            part = frame[:at] + bytes([frame[at] ^ bits[n]]) + frame[at + 1:]
        elif kind == 3:     # truncated
            part = frame[:at]
        elif kind == 4:     # a byte lost
            part = frame[:at] + frame[at + 1:]
        elif kind == 5:     # a byte inserted
            part = frame[:at] + bytes([extra[n]]) + frame[at:]
        elif kind == 6:     # two frames run together without their delimiter
            part = frame[:-1] + pool[(picks[n] + 1) % len(pool)]
        else:               # intact: the pen acts on it
            part = frame
        parts.append(part)
        if probe_every and n % probe_every == 0:
            probes.append(n)
            parts.append(b"\x00" + P.encode_frame(P.PING, n & 0xFF, P.pack_ping(n)))
    return b"".join(parts), probes


def test_fuzz_1e5_frames_never_crash_and_resync(harness_exe, tmp_path):
    rng = np.random.default_rng(2026)
    stream, probes = _fuzz_stream(rng, 100_000, probe_every=20)
    (tmp_path / "in.bin").write_bytes(stream)
    run = subprocess.run([str(harness_exe), "fuzz", str(tmp_path / "in.bin"),
                          str(tmp_path / "out.bin"), "77"], capture_output=True, text=True,
                         env=ENV, timeout=60)
    assert run.returncode == 0 and "runtime error" not in run.stderr, run.stderr
    errors, written = map(int, run.stdout.split())
    out = (tmp_path / "out.bin").read_bytes()
    assert len(out) == written
    replies = P.FrameDecoder().feed(out)
    pongs = {P.unpack_pong(p)[0]: s for t, s, p in replies if t == P.PONG}
    # Every PING after garbage and a delimiter is answered, with its own seq.
    missing = [n for n in probes if pongs.get(n) != n & 0xFF]
    assert not missing, f"{len(missing)} of {len(probes)} pings unanswered, e.g. {missing[:5]}"
    assert errors > 50_000
    kinds = {t for t, _, _ in replies}
    assert {P.PONG, P.ACK, P.NACK, P.INFO, P.EVENT} <= kinds
