"""The pen protocol: COBS frames with a CRC-16, little-endian fixed structs (docs/protocol.md).

One implementation for both ends: the host imports it as ``realpen.device.protocol`` and the
pen's MicroPython firmware as ``rp_protocol`` (a link in ``firmware/pico``). So this module uses
only what MicroPython has (``struct``, plain classes, no type annotations, no ``__future__``)
and imports nothing from the rest of RealPen.

A frame on the wire is ``COBS([type u8][seq u8][payload][crc16 u16 LE]) 0x00``; the CRC is
CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no final XOR) over type, seq and
payload. The 0x00 delimiter never occurs inside a COBS-encoded frame, so a receiver that lost
bytes resynchronises at the next delimiter.

>>> frame = encode_frame(PING, 7, pack_ping(0x01020304))
>>> FrameDecoder().feed(b"\\x13\\x37garbage\\x00" + frame)
[(48, 7, b'\\x04\\x03\\x02\\x01')]
"""

import struct

PROTOCOL_VERSION = 1
MAX_FRAME = 256  # bytes of the largest decoded frame: type + seq + payload + CRC
MAX_CHUNK = 180  # pattern bytes per PATTERN_CHUNK: a whole frame fits one BLE write at MTU 247
MAX_NAME = 32  # bytes of the pen's UTF-8 name in INFO

# Frame types (host → pen: HELLO, PATTERN_*, SET_STATE, PING; pen → host: the others).
HELLO = 0x01
INFO = 0x02
PATTERN_BEGIN = 0x10
PATTERN_CHUNK = 0x11
PATTERN_COMMIT = 0x12
SET_STATE = 0x20
PING = 0x30
PONG = 0x31
ACK = 0x40
NACK = 0x41
EVENT = 0x50
CAPTURE_START = 0x60
CAPTURE_STOP = 0x61
SAMPLES = 0x62

TYPE_NAMES = {
    HELLO: "HELLO", INFO: "INFO", PATTERN_BEGIN: "PATTERN_BEGIN", PATTERN_CHUNK: "PATTERN_CHUNK",
    PATTERN_COMMIT: "PATTERN_COMMIT", SET_STATE: "SET_STATE", PING: "PING", PONG: "PONG",
    ACK: "ACK", NACK: "NACK", EVENT: "EVENT", CAPTURE_START: "CAPTURE_START",
    CAPTURE_STOP: "CAPTURE_STOP", SAMPLES: "SAMPLES",
}

# NACK codes.
E_UNKNOWN_TYPE = 1
E_BAD_LENGTH = 2
E_VERSION = 3
E_TOO_LARGE = 4
E_BAD_FORMAT = 5
E_BAD_OFFSET = 6
E_CRC = 7
E_INCOMPLETE = 8
E_NO_UPLOAD = 9
E_BAD_RATE = 10
E_BAD_STATE = 11
E_NO_SENSOR = 12
E_BAD_CAPTURE = 13

NACK_TEXT = {
    E_UNKNOWN_TYPE: "unknown frame type",
    E_BAD_LENGTH: "payload of the wrong length",
    E_VERSION: "protocol version not supported",
    E_TOO_LARGE: "pattern larger than the pen holds",
    E_BAD_FORMAT: "sample format not supported",
    E_BAD_OFFSET: "pattern chunk out of order",
    E_CRC: "pattern CRC-32 mismatch",
    E_INCOMPLETE: "pattern upload incomplete",
    E_NO_UPLOAD: "no pattern upload under way",
    E_BAD_RATE: "sample rate not supported",
    E_BAD_STATE: "state value out of range",
    E_NO_SENSOR: "the pen has no accelerometer",
    E_BAD_CAPTURE: "capture range or rate not supported",
}

# EVENT kinds and what their value means.
EV_BOOT = 1  # value: firmware boot count or 0
EV_UNDERRUN = 2  # value: underruns so far
EV_BATTERY = 3  # value: battery voltage in mV
EV_PATTERN = 4  # value: id of the pattern now playing
EV_DECODE_ERRORS = 5  # value: frames dropped so far (bad COBS, CRC, length)
EV_OVERRUN = 6  # value: sensor FIFO overruns in this capture so far (samples were lost)
EV_CAPTURE_DROPPED = 7  # value: SAMPLES blocks of this capture the pen could not send so far

EVENT_NAMES = {EV_BOOT: "boot", EV_UNDERRUN: "underrun", EV_BATTERY: "battery",
               EV_PATTERN: "pattern", EV_DECODE_ERRORS: "decode_errors",
               EV_OVERRUN: "overrun", EV_CAPTURE_DROPPED: "capture_dropped"}

FORMAT_S16LE = 1  # pattern samples: signed 16-bit little-endian

FEATURE_USB = 1
FEATURE_BLE = 2
FEATURE_BATTERY = 4
FEATURE_RATE = 8
FEATURE_ACCEL = 16  # an accelerometer (LIS3DH) the host can capture from

# Capture: full-scale ranges in g and output rates in Hz the LIS3DH offers (normal and
# high-resolution modes); 1344 Hz is the method's rate. SAMPLES blocks hold at most a FIFO's worth.
CAPTURE_RANGES = (2, 4, 8, 16)
CAPTURE_RATES = (1, 10, 25, 50, 100, 200, 400, 1344)
CAPTURE_RATE = 1344
MAX_BLOCK_SAMPLES = 32  # the LIS3DH FIFO depth
SAMPLE_BYTES = 6  # x, y, z as int16 little-endian, left-justified as the sensor gives them
SAMPLES_OVERRUN = 1  # SAMPLES flags bit: the sensor's FIFO overran before this block

GAIN_ONE = 65535  # SET_STATE gain: 65535 is the firmware's capped full drive
RATE_ONE = 4096  # SET_STATE rate: Q12 playback-rate factor, 4096 plays the pattern as stored
RATE_MIN = 1024
RATE_MAX = 16384

BLE_SERVICE = "7e570001-2f5c-4b0a-9c1e-8d3f5a6b7c10"
BLE_RX = "7e570002-2f5c-4b0a-9c1e-8d3f5a6b7c10"  # host → pen, write without response
BLE_TX = "7e570003-2f5c-4b0a-9c1e-8d3f5a6b7c10"  # pen → host, notify
BLE_INFO = "7e570004-2f5c-4b0a-9c1e-8d3f5a6b7c10"  # read: the INFO payload

_HELLO = "<H"
_INFO = "<HBBBIII"
_BEGIN = "<HIIBI"
_CHUNK = "<I"
_COMMIT = "<H"
_STATE = "<BHHH"
_PING = "<I"
_PONG = "<II"
_ACK = "<B"
_NACK = "<BB"
_EVENT = "<BI"
_CAPTURE_START = "<BH"
_SAMPLES = "<IIBB"


def _crc16_table():
    table = []
    for byte in range(256):
        crc = byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) if crc & 0x8000 else (crc << 1)
        table.append(crc & 0xFFFF)
    return table


_CRC16_TABLE = _crc16_table()


def crc16(data, crc=0xFFFF):
    """CRC-16/CCITT-FALSE of ``data`` (bytes-like), continuing from ``crc``.

    >>> hex(crc16(b"123456789"))
    '0x29b1'
    """
    table = _CRC16_TABLE
    for byte in data:
        crc = ((crc << 8) & 0xFFFF) ^ table[((crc >> 8) ^ byte) & 0xFF]
    return crc


def cobs_encode(data):
    """Consistent Overhead Byte Stuffing of ``data``: the same bytes with no 0x00 in them.

    Cheshire & Baker 1999 (doi:10.1109/90.769765); at most one byte longer per 254.

    >>> cobs_encode(b"\\x11\\x00\\x00\\x22")
    b'\\x02\\x11\\x01\\x02"'
    """
    out = bytearray()
    code_at = 0
    out.append(0)
    code = 1
    after_full_block = False  # a block of 254 data bytes ended just before the current one
    for byte in data:
        after_full_block = False
        if byte == 0:
            out[code_at] = code
            code_at = len(out)
            out.append(0)
            code = 1
        else:
            out.append(byte)
            code += 1
            if code == 0xFF:
                out[code_at] = code
                code_at = len(out)
                out.append(0)
                code = 1
                after_full_block = True
    if after_full_block:
        # Data ending exactly at a full block needs no empty block after it.
        return bytes(out[:code_at])
    out[code_at] = code
    return bytes(out)


def cobs_decode(data):
    """The bytes :func:`cobs_encode` made ``data`` from (no delimiter); ValueError if malformed."""
    out = bytearray()
    index = 0
    end = len(data)
    while index < end:
        code = data[index]
        if code == 0:
            raise ValueError("COBS: zero byte inside a frame")
        index += 1
        stop = index + code - 1
        if stop > end:
            raise ValueError("COBS: block runs past the frame")
        for at in range(index, stop):
            if data[at] == 0:
                raise ValueError("COBS: zero byte inside a frame")
        out.extend(data[index:stop])
        index = stop
        if code != 0xFF and index < end:
            out.append(0)
    return bytes(out)


def encode_frame(ftype, seq, payload=b""):
    """One frame ready for the wire: ``COBS(type, seq, payload, CRC-16 LE) + 0x00``."""
    body = bytearray(2 + len(payload) + 2)
    body[0] = ftype & 0xFF
    body[1] = seq & 0xFF
    body[2:2 + len(payload)] = payload
    crc = crc16(memoryview(body)[:2 + len(payload)])
    body[-2] = crc & 0xFF
    body[-1] = crc >> 8
    if len(body) > MAX_FRAME:
        raise ValueError(f"frame of {len(body)} bytes is larger than {MAX_FRAME}")
    return cobs_encode(body) + b"\x00"


class FrameDecoder:
    """Frames out of a byte stream split anywhere; bad frames are dropped and counted.

    ``feed`` returns a list of ``(type, seq, payload)``. A frame whose COBS, CRC or length is
    wrong is dropped (``errors`` counts them) and decoding resumes after the next 0x00, so no
    input can make it raise or grow beyond a fixed buffer.
    """

    def __init__(self, max_frame=MAX_FRAME):
        self.max_frame = max_frame
        self.max_encoded = max_frame + max_frame // 254 + 2
        self.buffer = bytearray()
        self.overflow = False
        self.errors = 0

    def feed(self, data):
        """Frames completed by ``data`` (bytes-like), in order."""
        frames = []
        buffer = self.buffer
        for byte in data:
            if byte == 0:
                if self.overflow:
                    self.errors += 1
                elif buffer:
                    frame = self._decode(buffer, self.max_frame)
                    if frame is None:
                        self.errors += 1
                    else:
                        frames.append(frame)
                self.overflow = False
                buffer[:] = b""
            elif not self.overflow:
                if len(buffer) >= self.max_encoded:
                    self.overflow = True
                    buffer[:] = b""
                else:
                    buffer.append(byte)
        return frames

    @staticmethod
    def _decode(encoded, max_frame):
        try:
            body = cobs_decode(encoded)
        except ValueError:
            return None
        if len(body) < 4 or len(body) > max_frame:
            return None
        crc = body[-2] | (body[-1] << 8)
        if crc16(memoryview(body)[:-2]) != crc:
            return None
        return body[0], body[1], bytes(body[2:-2])


def _unpack(fmt, payload):
    if len(payload) != struct.calcsize(fmt):
        raise ValueError(f"payload of {len(payload)} bytes, expected {struct.calcsize(fmt)}")
    return struct.unpack(fmt, payload)


def pack_hello(version):
    """HELLO: the host's protocol version."""
    return struct.pack(_HELLO, version)


def unpack_hello(payload):
    return _unpack(_HELLO, payload)[0]


def pack_info(protocol, fw_major, fw_minor, fw_patch, sample_rate, max_pattern_bytes, features,
              name):
    """INFO: protocol version, firmware version, sample rate (Hz), largest pattern (bytes),
    feature bits and the pen's name (UTF-8, at most :data:`MAX_NAME` bytes)."""
    encoded = name.encode("utf-8") if isinstance(name, str) else bytes(name)
    if len(encoded) > MAX_NAME:
        raise ValueError(f"name longer than {MAX_NAME} bytes")
    return struct.pack(_INFO, protocol, fw_major, fw_minor, fw_patch, sample_rate,
                       max_pattern_bytes, features) + encoded


def unpack_info(payload):
    size = struct.calcsize(_INFO)
    if len(payload) < size or len(payload) > size + MAX_NAME:
        raise ValueError(f"INFO payload of {len(payload)} bytes")
    fields = struct.unpack(_INFO, payload[:size])
    name = bytes(payload[size:]).decode("utf-8")
    return fields + (name,)


def pack_pattern_begin(pattern_id, length, rate, sample_format, crc32):
    """PATTERN_BEGIN: id, length in samples, rate in Hz, sample format, CRC-32 of the bytes."""
    return struct.pack(_BEGIN, pattern_id, length, rate, sample_format, crc32)


def unpack_pattern_begin(payload):
    return _unpack(_BEGIN, payload)


def pack_pattern_chunk(offset, data):
    """PATTERN_CHUNK: byte offset in the pattern, then at most :data:`MAX_CHUNK` bytes."""
    if len(data) > MAX_CHUNK:
        raise ValueError(f"chunk of {len(data)} bytes is larger than {MAX_CHUNK}")
    return struct.pack(_CHUNK, offset) + bytes(data)


def unpack_pattern_chunk(payload):
    if len(payload) < 5 or len(payload) > 4 + MAX_CHUNK:
        raise ValueError(f"PATTERN_CHUNK payload of {len(payload)} bytes")
    return struct.unpack(_CHUNK, payload[:4])[0], bytes(payload[4:])


def pack_pattern_commit(pattern_id):
    """PATTERN_COMMIT: the id given in PATTERN_BEGIN."""
    return struct.pack(_COMMIT, pattern_id)


def unpack_pattern_commit(payload):
    return _unpack(_COMMIT, payload)[0]


def pack_set_state(playing, gain, rate, fade_ms):
    """SET_STATE: playing (0/1), gain (0 … :data:`GAIN_ONE`), rate (Q12), ramp time in ms."""
    return struct.pack(_STATE, playing, gain, rate, fade_ms)


def unpack_set_state(payload):
    return _unpack(_STATE, payload)


def pack_ping(token):
    """PING: a token the PONG echoes."""
    return struct.pack(_PING, token)


def unpack_ping(payload):
    return _unpack(_PING, payload)[0]


def pack_pong(token, device_us):
    """PONG: the PING's token and the pen's clock in µs (wraps at 2**32)."""
    return struct.pack(_PONG, token, device_us & 0xFFFFFFFF)


def unpack_pong(payload):
    return _unpack(_PONG, payload)


def pack_ack(ftype):
    """ACK: the type of the frame acknowledged (the seq is the request's)."""
    return struct.pack(_ACK, ftype)


def unpack_ack(payload):
    return _unpack(_ACK, payload)[0]


def pack_nack(ftype, code):
    """NACK: the type of the frame refused and why (``E_*``)."""
    return struct.pack(_NACK, ftype, code)


def unpack_nack(payload):
    return _unpack(_NACK, payload)


def pack_event(kind, value):
    """EVENT: kind (``EV_*``) and its value."""
    return struct.pack(_EVENT, kind, value)


def unpack_event(payload):
    return _unpack(_EVENT, payload)


def pack_capture_start(range_g, rate_hz):
    """CAPTURE_START: full-scale range in g (:data:`CAPTURE_RANGES`) and output rate in Hz
    (:data:`CAPTURE_RATES`)."""
    return struct.pack(_CAPTURE_START, range_g, rate_hz)


def unpack_capture_start(payload):
    return _unpack(_CAPTURE_START, payload)


def pack_capture_stop():
    """CAPTURE_STOP: no payload; the ACK follows the capture's last SAMPLES block."""
    return b""


def unpack_capture_stop(payload):
    if len(payload):
        raise ValueError(f"CAPTURE_STOP payload of {len(payload)} bytes, expected 0")
    return None


def pack_samples(first, t_us, range_g, flags, data):
    """SAMPLES: index of the block's first sample since CAPTURE_START (lost samples counted),
    the pen's clock in µs when the sensor's FIFO level was read (the block's last sample had
    been taken by then; wraps at 2**32), the range in g, flags (:data:`SAMPLES_OVERRUN`), then
    1 … :data:`MAX_BLOCK_SAMPLES` samples of x, y, z as the sensor gives them (int16 LE,
    left-justified)."""
    count = len(data)
    if count == 0 or count % SAMPLE_BYTES or count > MAX_BLOCK_SAMPLES * SAMPLE_BYTES:
        raise ValueError(f"SAMPLES data of {count} bytes")
    return struct.pack(_SAMPLES, first & 0xFFFFFFFF, t_us & 0xFFFFFFFF, range_g, flags) + bytes(data)


def unpack_samples(payload):
    size = struct.calcsize(_SAMPLES)
    count = len(payload) - size
    if count <= 0 or count % SAMPLE_BYTES or count > MAX_BLOCK_SAMPLES * SAMPLE_BYTES:
        raise ValueError(f"SAMPLES payload of {len(payload)} bytes")
    return struct.unpack(_SAMPLES, payload[:size]) + (bytes(payload[size:]),)
