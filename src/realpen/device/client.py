"""Talk to a pen: HELLO, pattern upload, SET_STATE, PING, the pen's events and its captures.

:class:`PenClient` speaks the protocol (:mod:`realpen.device.protocol`, ``docs/protocol.md``)
over any :class:`~realpen.device.transport.Transport`. A reader thread feeds the bytes that
arrive to a :class:`~realpen.device.protocol.FrameDecoder`: a reply (INFO, ACK, NACK, PONG)
wakes the request that carries the same sequence number, an EVENT is queued for
:meth:`PenClient.read_event`, a SAMPLES block of an accelerometer capture for
:meth:`PenClient.read_samples`. Frames the pen does not answer (PATTERN_CHUNK, SET_STATE) are only
answered when refused; such a NACK is kept until :meth:`PenClient.sync` (or the upload) reports
it.

Every failure is one line naming the port (:class:`~realpen.device.transport.DeviceError`): no
reply within the timeout, a pen that speaks another protocol version, a pattern too large for
the pen, a CRC mismatch in an upload (the pen keeps its last good pattern), any other refusal
with the pen's reason.

Example (a simulated pen, the real firmware under the MicroPython Unix port)::

    from realpen.device.sim import SimPen
    from realpen.device.transport import open_transport

    with SimPen() as pen, PenClient(open_transport(pen.port)) as client:
        info = client.hello()
        client.upload(samples, info.sample_rate)
        client.set_state(True, 0.5)
"""

from __future__ import annotations

import itertools
import queue
import threading
import time
import zlib
from collections import deque
from dataclasses import dataclass

import numpy as np

from realpen.checks import require_number
from realpen.defaults import DEVICE_TIMEOUT_S
from realpen.device import protocol as p
from realpen.device.pattern import check_fits, pattern_bytes
from realpen.device.transport import UPLOAD_WINDOW, DeviceDisconnected, DeviceError, Transport
from realpen.errors import ParameterError

__all__ = ["PenClient", "PenInfo", "PenEvent", "SampleBlock", "state_payload", "DEFAULT_TIMEOUT_S",
           "SYNC_EVERY_CHUNKS", "FEATURE_NAMES", "EVENT_NAMES", "MAX_QUEUED_BLOCKS"]

DEFAULT_TIMEOUT_S = DEVICE_TIMEOUT_S  # a reply takes ms over USB, tens of ms over Bluetooth
# An upload waits for the pen (a PING) after this many chunks (≈ 2.9 KB), unless its transport
# lets fewer run ahead (Transport.upload_window: 4 over Bluetooth).
SYNC_EVERY_CHUNKS = UPLOAD_WINDOW
STRAY_INFO_S = 0.2  # after a refused HELLO, how long to wait for an INFO that says the version
_READ_S = 0.1  # how long one read of the reader thread waits: how fast close() is noticed
_REPLIES = (p.INFO, p.ACK, p.NACK, p.PONG)
# SAMPLES blocks held for read_samples: about 6.5 minutes of a 1344 Hz capture in blocks of 32
# (more at the firmware's smaller blocks), some 8 MB. A host that falls further behind loses
# the blocks that arrive while the queue is full; they are counted (PenClient.blocks_dropped)
# and show as gaps.
MAX_QUEUED_BLOCKS = 16384

FEATURE_NAMES = {p.FEATURE_USB: "USB", p.FEATURE_BLE: "Bluetooth LE",
                 p.FEATURE_BATTERY: "battery", p.FEATURE_RATE: "playback rate",
                 p.FEATURE_ACCEL: "accelerometer"}
EVENT_NAMES = p.EVENT_NAMES
FRAME_NAMES = p.TYPE_NAMES


@dataclass(frozen=True)
class PenInfo:
    """What a pen says of itself in INFO.

    Attributes:
        protocol: the protocol version it speaks.
        firmware: its firmware version (major, minor, patch).
        sample_rate: the rate it plays patterns at, in Hz.
        max_pattern_bytes: the largest pattern it holds, in bytes (2 per sample).
        features: bit set of ``FEATURE_*`` (USB, Bluetooth LE, battery, playback rate).
        name: its name (also what it advertises over Bluetooth).
    """

    protocol: int
    firmware: tuple[int, int, int]
    sample_rate: int
    max_pattern_bytes: int
    features: int
    name: str

    @classmethod
    def from_payload(cls, payload: bytes) -> PenInfo:
        """Parse an INFO payload (ValueError when it is malformed)."""
        protocol, major, minor, patch, rate, largest, features, name = p.unpack_info(payload)
        return cls(protocol, (major, minor, patch), rate, largest, features, name)

    @property
    def firmware_version(self) -> str:
        """``"major.minor.patch"``."""
        return ".".join(map(str, self.firmware))

    @property
    def feature_names(self) -> list[str]:
        """The features in words (unknown bits as ``bit N``)."""
        names = [text for bit, text in FEATURE_NAMES.items() if self.features & bit]
        known = sum(FEATURE_NAMES)
        names += [f"bit {n}" for n in range(32) if self.features & ~known & (1 << n)]
        return names

    @property
    def max_pattern_s(self) -> float:
        """The longest pattern the pen holds, in seconds at its rate."""
        return self.max_pattern_bytes / 2 / self.sample_rate if self.sample_rate else 0.0


@dataclass(frozen=True)
class PenEvent:
    """Something the pen reported on its own (an EVENT frame).

    Attributes:
        kind: ``EV_*`` code.
        value: its value (boot: 0; underruns: the count so far; battery: the voltage in mV;
            pattern: the id now playing; decode errors: frames dropped so far; overrun: the
            sensor FIFO's overruns so far in this capture; capture_dropped: SAMPLES blocks the
            pen could not send so far in this capture).
        seq: the pen's own frame counter.
        at: ``time.monotonic()`` when the host received it, in seconds.
    """

    kind: int
    value: int
    seq: int
    at: float

    @property
    def name(self) -> str:
        """The kind in words (``"underrun"``), or ``"event N"`` for a kind this host does not
        know."""
        return EVENT_NAMES.get(self.kind, f"event {self.kind}")

    def __str__(self) -> str:
        unit = " mV" if self.kind == p.EV_BATTERY else ""
        return f"{self.name} {self.value}{unit}"


@dataclass(frozen=True, eq=False)
class SampleBlock:
    """One SAMPLES block of an accelerometer capture, as the pen sent it.

    Attributes:
        first: index of its first sample since CAPTURE_START, lost samples counted (u32: wraps
            at 2³² samples, 37 days at 1344 Hz; :class:`realpen.device.capture.CaptureAssembler`
            unwraps it).
        t_us: the pen's clock in µs (the PONG clock, wrapping at 2³²) when it read the sensor's
            FIFO level: its last sample had been taken by then.
        range_g: the sensor's full-scale range in g.
        flags: bit set of ``SAMPLES_*`` (``SAMPLES_OVERRUN``: the FIFO overran before this
            block; samples were lost inside the sensor).
        raw: the samples as the LIS3DH gives them, int16 of shape (n, 3) (x, y, z;
            left-justified: see :func:`realpen.device.capture.accel_ms2`).
        at: ``time.monotonic()`` when the host received it, in seconds.
    """

    first: int
    t_us: int
    range_g: int
    flags: int
    raw: np.ndarray
    at: float

    @classmethod
    def from_payload(cls, payload: bytes, at: float) -> SampleBlock:
        """Parse a SAMPLES payload received at ``at`` (ValueError when it is malformed)."""
        first, t_us, range_g, flags, data = p.unpack_samples(payload)
        raw = np.frombuffer(data, dtype="<i2").astype(np.int16).reshape(-1, 3)
        raw.flags.writeable = False
        return cls(first, t_us, range_g, flags, raw, at)

    @property
    def count(self) -> int:
        """How many samples it holds."""
        return int(self.raw.shape[0])

    @property
    def overrun(self) -> bool:
        """Whether the sensor's FIFO overran before this block (samples lost)."""
        return bool(self.flags & p.SAMPLES_OVERRUN)


def state_payload(playing: bool, gain: float, rate: float = 1.0, fade_ms: int = 5) -> bytes:
    """The SET_STATE payload of a play state, its values checked (see
    :meth:`PenClient.set_state`).

    Raises:
        ParameterError: ``gain`` outside 0 … 1, ``rate`` outside 0.25 … 4, ``fade_ms`` not a
            whole number of ms from 0 to 65535.

    >>> state_payload(True, 0.5).hex()
    '01008000100500'
    """
    require_number("gain", gain, 0, 1)
    require_number("rate", rate, p.RATE_MIN / p.RATE_ONE, p.RATE_MAX / p.RATE_ONE)
    require_number("fade_ms", fade_ms, 0, 0xFFFF)
    if int(fade_ms) != fade_ms:
        raise ParameterError("fade_ms", f"must be a whole number of ms, got {fade_ms:g}")
    scaled_rate = min(p.RATE_MAX, max(p.RATE_MIN, round(rate * p.RATE_ONE)))
    return p.pack_set_state(1 if playing else 0, round(gain * p.GAIN_ONE), scaled_rate,
                            int(fade_ms))


class _Waiter:
    """One request waiting for its reply."""

    __slots__ = ("done", "reply", "error")

    def __init__(self):
        self.done = threading.Event()
        self.reply: tuple[int, bytes] | None = None
        self.error: DeviceError | None = None


class PenClient:
    """The protocol over a transport, with one reader thread.

    Args:
        transport: an open :class:`~realpen.device.transport.Transport`; the client owns it
            and closes it.
        timeout: seconds to wait for each reply.

    Methods may be called from several threads: frames are written whole, one at a time.
    """

    def __init__(self, transport: Transport, *, timeout: float = DEFAULT_TIMEOUT_S):
        require_number("timeout", timeout, 0, 3600, inclusive=False)
        self.transport = transport
        self.timeout = float(timeout)
        self.info: PenInfo | None = None
        self._decoder = p.FrameDecoder()
        self._lock = threading.Lock()  # the sequence counter and the waiters
        self._write_lock = threading.Lock()  # one whole frame at a time, in sequence order
        self._seq = 0
        self._pending: dict[int, _Waiter] = {}
        self._refusals: deque[tuple[int, int, int]] = deque(maxlen=64)  # (ftype, code, seq)
        self._events: queue.Queue[PenEvent] = queue.Queue()
        # (capture, block): the capture a block belongs to is counted by the reader, from
        # the ACK of each CAPTURE_START, so that the blocks of an earlier capture still on the
        # way never pass for the new one's.
        self._blocks: queue.Queue[tuple[int, SampleBlock]] = queue.Queue(MAX_QUEUED_BLOCKS)
        self._blocks_dropped = 0
        self._capture = 0
        self._tokens = itertools.count(1)
        # INFO frames nobody waited for, by seq: how a pen that refused HELLO says its version
        self._stray_info: dict[int, bytes] = {}
        self._stray_arrived = threading.Condition(self._lock)
        self._error: DeviceError | None = None
        self._closing = threading.Event()
        self._reader = threading.Thread(target=self._read_loop, daemon=True,
                                        name=f"realpen pen reader {transport.name}")
        self._reader.start()

    # -- the link ----------------------------------------------------------------------------

    @property
    def name(self) -> str:
        """The pen's port as the user gave it."""
        return self.transport.name

    @property
    def connected(self) -> bool:
        """Whether the link is still up (False once it went away or the client closed)."""
        return self._error is None and not self._closing.is_set()

    @property
    def decode_errors(self) -> int:
        """Frames from the pen the decoder dropped (garbled on the way)."""
        return self._decoder.errors

    @property
    def blocks_dropped(self) -> int:
        """SAMPLES blocks of the current capture this host dropped because nobody read them
        (more than :data:`MAX_QUEUED_BLOCKS` waiting); they show as gaps in the capture."""
        return self._blocks_dropped

    def close(self) -> None:
        """Stop the reader and close the transport (again: nothing happens)."""
        if self._closing.is_set():
            return
        self._closing.set()
        try:
            self.transport.close()
        finally:
            if self._reader is not threading.current_thread():
                self._reader.join(2.0)
            self._fail_all(DeviceDisconnected(f"{self.name}: the connection is closed"))

    def __enter__(self) -> PenClient:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _read_loop(self) -> None:
        while not self._closing.is_set():
            try:
                data = self.transport.read(_READ_S)
            except DeviceError as error:
                if not self._closing.is_set():
                    self._fail_all(error)
                return
            except Exception as error:  # a transport bug must not leave callers waiting
                self._fail_all(DeviceError(f"{self.name}: reading failed ({error!r})"))
                return
            if data:
                for frame in self._decoder.feed(data):
                    self._dispatch(*frame)

    def _dispatch(self, ftype: int, seq: int, payload: bytes) -> None:
        if ftype == p.EVENT:
            try:
                kind, value = p.unpack_event(payload)
            except ValueError:
                return  # a malformed event says nothing; the frame's CRC was fine, so skip it
            self._events.put(PenEvent(kind, value, seq, time.monotonic()))
            return
        if ftype == p.SAMPLES:
            try:
                block = SampleBlock.from_payload(payload, time.monotonic())
            except ValueError:
                return  # a malformed block: its samples show as a gap (its index is skipped)
            try:
                self._blocks.put_nowait((self._capture, block))
            except queue.Full:
                self._blocks_dropped += 1
            return
        if ftype == p.ACK and payload == p.pack_ack(p.CAPTURE_START):
            self._capture += 1  # blocks from here on are the new capture's
        if ftype not in _REPLIES:
            return  # the pen sends nothing else; ignore what a newer firmware might add
        with self._lock:
            waiter = self._pending.pop(seq, None)
        if waiter is not None:
            waiter.reply = (ftype, payload)
            waiter.done.set()
        elif ftype == p.INFO:  # unasked: a pen that refused HELLO saying what it speaks
            with self._lock:
                if len(self._stray_info) >= 8:  # a pen that chatters: keep the newest few
                    self._stray_info.pop(next(iter(self._stray_info)))
                self._stray_info[seq] = payload
                self._stray_arrived.notify_all()
        elif ftype == p.NACK:  # a refused frame that expects no reply (a chunk, SET_STATE)
            try:
                refused, code = p.unpack_nack(payload)
            except ValueError:
                return
            self._refusals.append((refused, code, seq))

    def _fail_all(self, error: DeviceError) -> None:
        with self._lock:
            if self._error is None:
                self._error = error
            waiters, self._pending = list(self._pending.values()), {}
        for waiter in waiters:
            waiter.error = self._error
            waiter.done.set()

    # -- frames ------------------------------------------------------------------------------

    def _check_link(self) -> None:
        if self._error is not None:
            raise type(self._error)(str(self._error))
        if self._closing.is_set():
            raise DeviceDisconnected(f"{self.name}: the connection is closed")

    def _send(self, ftype: int, payload: bytes = b"", waiter: _Waiter | None = None,
              resync: bool = False) -> int:
        """Write one frame (and register its waiter first, so no reply can come before);
        ``resync``: a lone 0x00 first, which ends whatever frame the pen has half received."""
        self._check_link()
        # The reader takes only _lock: a write that blocks (the pen reading slowly) never
        # keeps it from handing replies over.
        with self._write_lock:
            with self._lock:
                seq = self._seq
                self._seq = (self._seq + 1) & 0xFF
                if waiter is not None:
                    self._pending[seq] = waiter
            try:
                frame = p.encode_frame(ftype, seq, payload)
                self.transport.write(b"\x00" + frame if resync else frame)
            except DeviceError as error:
                with self._lock:
                    self._pending.pop(seq, None)
                if isinstance(error, DeviceDisconnected):
                    self._fail_all(error)  # the reader may not have noticed yet
                raise
        return seq

    def _request(self, ftype: int, payload: bytes = b"", timeout: float | None = None
                 ) -> tuple[int, bytes]:
        """Send a frame and wait for the reply that carries its sequence number."""
        waiter = _Waiter()
        seq = self._send(ftype, payload, waiter)
        return self._wait_reply(ftype, seq, waiter, timeout)

    def _wait_reply(self, ftype: int, seq: int, waiter: _Waiter, timeout: float | None = None
                    ) -> tuple[int, bytes]:
        """Wait for the reply to the frame ``_send`` wrote as ``seq`` with ``waiter``."""
        wait = self.timeout if timeout is None else timeout
        if not waiter.done.wait(wait):
            with self._lock:
                self._pending.pop(seq, None)
            raise DeviceError(f"{self.name}: no reply to {FRAME_NAMES.get(ftype, ftype)} within "
                              f"{wait:g} s (is a RealPen pen on this port, running its "
                              f"firmware?)")
        if waiter.error is not None:
            raise type(waiter.error)(str(waiter.error))
        return waiter.reply

    def _unexpected(self, what: str, ftype: int) -> DeviceError:
        return DeviceError(f"{self.name}: the pen answered {what} with "
                           f"{FRAME_NAMES.get(ftype, f'frame type 0x{ftype:02x}')}")

    def _garbled(self, what: str) -> DeviceError:
        return DeviceError(f"{self.name}: the pen's {what} is malformed (another protocol?)")

    # -- messages ----------------------------------------------------------------------------

    def hello(self) -> PenInfo:
        """Say HELLO with this host's protocol version; the pen answers with its INFO.

        Returns:
            The pen's :class:`PenInfo` (also kept as :attr:`info`).

        Raises:
            DeviceError: no reply, or the pen speaks another protocol version ("the pen
                speaks protocol N, this host speaks 1").
        """
        # An INFO that came late for an earlier HELLO (one that timed out) says nothing of
        # this one's refusal: forget it.
        with self._lock:
            self._stray_info.clear()
        waiter = _Waiter()
        # A host that was interrupted mid-write (Ctrl-C in an upload) leaves a half frame in
        # the pen's decoder, which would swallow this HELLO into one garbled frame: a 0x00
        # first ends it (the pen drops it and ignores the empty frame).
        seq = self._send(p.HELLO, p.pack_hello(p.PROTOCOL_VERSION), waiter, resync=True)
        ftype, payload = self._wait_reply(p.HELLO, seq, waiter)
        if ftype == p.NACK:
            refused, code = self._nack(payload, "HELLO")
            if code == p.E_VERSION:
                version = self._refusing_pen_version(seq)
                if version is not None and version != p.PROTOCOL_VERSION:
                    raise self._version_error(version)
                raise DeviceError(f"{self.name}: the pen refused HELLO: it speaks another "
                                  f"protocol version, this host speaks {p.PROTOCOL_VERSION}; "
                                  f"update the pen's firmware or RealPen so both speak the same")
            raise self._refused("HELLO", code)
        if ftype != p.INFO:
            raise self._unexpected("HELLO", ftype)
        try:
            info = PenInfo.from_payload(payload)
        except (ValueError, UnicodeError):
            # An INFO of another length may still start with the version: say which.
            version = int.from_bytes(payload[:2], "little") if len(payload) >= 2 else None
            if version is not None and version != p.PROTOCOL_VERSION:
                raise self._version_error(version) from None
            raise self._garbled("INFO") from None
        if info.protocol != p.PROTOCOL_VERSION:
            raise self._version_error(info.protocol)
        self.info = info
        return info

    def _refusing_pen_version(self, seq: int) -> int | None:
        """The protocol version of a pen that refused the HELLO of sequence number ``seq``,
        when it can be learnt: the INFO the pen sends after its NACK (with the same seq), or
        (over Bluetooth) its INFO characteristic."""
        with self._lock:
            self._stray_arrived.wait_for(lambda: seq in self._stray_info, STRAY_INFO_S)
            payload = self._stray_info.pop(seq, None)
        if payload is None:
            if not hasattr(self.transport, "read_characteristic"):
                return None
            try:
                payload = self.transport.read_characteristic(p.BLE_INFO)
            except DeviceError:
                return None
        return int.from_bytes(payload[:2], "little") if len(payload) >= 2 else None

    def _version_error(self, version: int) -> DeviceError:
        which = "the pen's firmware" if version < p.PROTOCOL_VERSION else "RealPen on this host"
        return DeviceError(f"{self.name}: the pen speaks protocol {version}, this host speaks "
                           f"{p.PROTOCOL_VERSION}; update {which} so both speak the same")

    def _nack(self, payload: bytes, what: str) -> tuple[int, int]:
        try:
            return p.unpack_nack(payload)
        except ValueError:
            raise self._garbled(f"refusal of {what}") from None

    def _refused(self, what: str, code: int, keeps_pattern: bool = False) -> DeviceError:
        reason = p.NACK_TEXT.get(code, f"code {code}")
        tail = "; it keeps its last good pattern" if keeps_pattern else ""
        return DeviceError(f"{self.name}: the pen refused {what} ({reason}){tail}")

    def upload(self, samples: np.ndarray, rate: int, *, pattern_id: int | None = None,
               progress=None) -> int:
        """Send a pattern; the pen checks it (length, CRC-32) and swaps to it at its next wrap.

        Until the commit succeeds the pen keeps playing its last good pattern.

        Args:
            samples: int16 samples, shape (frames,), looped by the pen.
            rate: their rate in Hz (the pen refuses a rate it does not play).
            pattern_id: 0 … 65535, the id the pen reports for it (default: from the content,
                the CRC-32's low 16 bits, never 0).
            progress: called as ``progress(bytes_sent, total_bytes)`` after each chunk.

        Returns:
            The pattern's id.

        Raises:
            ParameterError: ``samples`` not a 1-D int16 array of at least one sample, ``rate``
                or ``pattern_id`` out of range.
            DeviceError: the pattern is too large for the pen (both sizes said), the pen found
                a CRC mismatch or refused the upload (it keeps its last good pattern), or no
                reply.
        """
        samples = np.asarray(samples)
        if samples.ndim != 1 or samples.dtype != np.int16 or samples.size == 0:
            raise ParameterError("samples", f"must be int16 samples of shape (frames,), got "
                                            f"{samples.dtype} of shape {samples.shape}")
        require_number("rate", rate, 1, 2**32 - 1)
        if int(rate) != rate:
            raise ParameterError("rate", f"must be a whole number of Hz, got {rate:g}")
        data = pattern_bytes(samples)
        crc = zlib.crc32(data) & 0xFFFFFFFF
        if pattern_id is None:
            pattern_id = (crc & 0xFFFF) or 1
        require_number("pattern_id", pattern_id, 0, 0xFFFF)
        info = self.info or self.hello()
        check_fits(len(data), info, port=self.name)
        self._refusals.clear()
        ftype, payload = self._request(p.PATTERN_BEGIN, p.pack_pattern_begin(
            int(pattern_id), samples.size, int(rate), p.FORMAT_S16LE, crc))
        if ftype == p.NACK:
            _, code = self._nack(payload, "PATTERN_BEGIN")
            raise self._upload_error(code, len(data), int(rate), info)
        if ftype != p.ACK:
            raise self._unexpected("PATTERN_BEGIN", ftype)
        window = max(1, int(getattr(self.transport, "upload_window", SYNC_EVERY_CHUNKS)))
        for count, offset in enumerate(range(0, len(data), p.MAX_CHUNK), 1):
            chunk = data[offset:offset + p.MAX_CHUNK]
            self._send(p.PATTERN_CHUNK, p.pack_pattern_chunk(offset, chunk))
            if progress is not None:
                progress(offset + len(chunk), len(data))
            # Every `window` chunks wait until the pen has handled every chunk so far: a link
            # without flow control (Bluetooth writes without response) never runs further
            # ahead of it than its receive buffer holds, and a refused chunk stops the upload
            # early.
            if count % window == 0:
                self._sync_upload(len(data), int(rate), info)
        self._sync_upload(len(data), int(rate), info)
        ftype, payload = self._request(p.PATTERN_COMMIT, p.pack_pattern_commit(int(pattern_id)))
        if ftype == p.NACK:
            _, code = self._nack(payload, "PATTERN_COMMIT")
            raise self._upload_error(code, len(data), int(rate), info)
        if ftype != p.ACK:
            raise self._unexpected("PATTERN_COMMIT", ftype)
        return int(pattern_id)

    def _sync_upload(self, n_bytes: int, rate: int, info: PenInfo) -> None:
        self.ping()
        for refused, code, _ in list(self._refusals):
            if refused == p.PATTERN_CHUNK:
                self._refusals.clear()  # the later chunks' refusals follow from the first
                raise self._upload_error(code, n_bytes, rate, info)

    def _upload_error(self, code: int, n_bytes: int, rate: int, info: PenInfo) -> DeviceError:
        if code == p.E_TOO_LARGE:
            return DeviceError(f"{self.name}: the pattern ({n_bytes} bytes) is too large for "
                               f"the pen {info.name!r}, which holds at most "
                               f"{info.max_pattern_bytes} bytes; it keeps its last good pattern")
        if code == p.E_CRC:
            return DeviceError(f"{self.name}: the pen found a CRC-32 mismatch in the uploaded "
                               f"pattern (damaged on the way) and keeps its last good pattern; "
                               f"upload it again")
        if code == p.E_BAD_RATE:
            return DeviceError(f"{self.name}: the pen does not play patterns at {rate} Hz (it "
                               f"plays at {info.sample_rate} Hz); it keeps its last good pattern")
        return self._refused("the pattern", code, keeps_pattern=True)

    def set_state(self, playing: bool, gain: float, rate: float = 1.0, fade_ms: int = 5) -> None:
        """Send the whole play state (never answered: a lost frame is mended by the next).

        Args:
            playing: loop the pattern (True) or fade to silence (False).
            gain: 0 … 1 of the pen's capped full drive.
            rate: playback-rate factor, 0.25 … 4 (1: the pattern's own rate).
            fade_ms: ramp to the new gain over this many ms (the pen uses at least 5 ms),
                0 … 65535.

        Raises:
            ParameterError: a value out of range.
            DeviceError: the link is gone.
        """
        self._send(p.SET_STATE, state_payload(playing, gain, rate, fade_ms))

    def ping(self) -> tuple[float, int]:
        """PING the pen.

        Returns:
            (round trip in seconds, the pen's clock in µs, wrapping at 2³²).

        Raises:
            DeviceError: no reply, or a reply to another PING.
        """
        token = next(self._tokens) & 0xFFFFFFFF
        start = time.perf_counter()
        ftype, payload = self._request(p.PING, p.pack_ping(token))
        elapsed = time.perf_counter() - start
        if ftype != p.PONG:
            if ftype == p.NACK:
                raise self._refused("PING", self._nack(payload, "PING")[1])
            raise self._unexpected("PING", ftype)
        try:
            echoed, device_us = p.unpack_pong(payload)
        except ValueError:
            raise self._garbled("PONG") from None
        if echoed != token:
            raise DeviceError(f"{self.name}: the pen answered PING {token} with PONG {echoed}")
        return elapsed, device_us

    def sync(self) -> float:
        """Wait until the pen has handled every frame sent so far (a PING round trip), and
        report a frame it refused meanwhile (a SET_STATE out of range, a stray chunk).

        Returns:
            The round trip in seconds.

        Raises:
            DeviceError: no reply, or the pen refused a frame since the last sync.
        """
        elapsed, _ = self.ping()
        if self._refusals:
            refused, code, _ = self._refusals.popleft()
            self._refusals.clear()
            raise self._refused(FRAME_NAMES.get(refused, f"frame type 0x{refused:02x}"), code)
        return elapsed

    def read_event(self, timeout: float | None = None) -> PenEvent | None:
        """The next event from the pen, waiting up to ``timeout`` seconds (None: forever).

        Returns:
            A :class:`PenEvent`, or None when none came within ``timeout``.

        Raises:
            DeviceDisconnected: the link went away and no event is left.
        """
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            try:
                return self._events.get(timeout=_READ_S if deadline is None else
                                        max(0.0, min(_READ_S, deadline - time.monotonic())))
            except queue.Empty:
                pass
            self._check_link()
            if deadline is not None and time.monotonic() >= deadline:
                return None

    def events(self) -> list[PenEvent]:
        """The events received and not yet read, without waiting."""
        found = []
        while True:
            try:
                found.append(self._events.get_nowait())
            except queue.Empty:
                return found

    # -- accelerometer capture ---------------------------------------------------------------

    def start_capture(self, range_g: int = 2, rate_hz: int = p.CAPTURE_RATE) -> None:
        """Start the pen's accelerometer capture; its SAMPLES blocks then come to
        :meth:`read_samples` (on this link only).

        Blocks of an earlier capture not yet read are dropped, and :attr:`blocks_dropped`
        starts again from 0.

        Args:
            range_g: full-scale range in g: 2, 4, 8 or 16.
            rate_hz: the sensor's output rate in Hz (:data:`~realpen.device.protocol.CAPTURE_RATES`;
                1344 is the method's).

        Raises:
            ParameterError: a range or rate the protocol does not offer.
            DeviceError: the pen has no accelerometer, refused the range or rate, or did not
                answer.
        """
        if range_g not in p.CAPTURE_RANGES:
            raise ParameterError("range_g", f"must be one of "
                                            f"{', '.join(map(str, p.CAPTURE_RANGES))} g, got "
                                            f"{range_g!r}")
        if rate_hz not in p.CAPTURE_RATES:
            raise ParameterError("rate_hz", f"must be one of "
                                            f"{', '.join(map(str, p.CAPTURE_RATES))} Hz, got "
                                            f"{rate_hz!r}")
        while True:  # what an earlier capture left behind is not this one's
            try:
                self._blocks.get_nowait()
            except queue.Empty:
                break
        self._blocks_dropped = 0
        ftype, payload = self._request(p.CAPTURE_START,
                                       p.pack_capture_start(int(range_g), int(rate_hz)))
        if ftype == p.NACK:
            _, code = self._nack(payload, "CAPTURE_START")
            raise self._capture_error(code)
        if ftype != p.ACK:
            raise self._unexpected("CAPTURE_START", ftype)

    def _capture_error(self, code: int) -> DeviceError:
        if code in (p.E_NO_SENSOR, p.E_UNKNOWN_TYPE):  # unknown type: firmware before capture
            return DeviceError(f"{self.name}: the pen has no accelerometer")
        if code == p.E_BAD_CAPTURE:
            return DeviceError(f"{self.name}: the pen refused the capture: range or rate not "
                               f"supported (ranges {'/'.join(map(str, p.CAPTURE_RANGES))} g, rates "
                               f"{', '.join(map(str, p.CAPTURE_RATES))} Hz)")
        return self._refused("the capture", code)

    def read_samples(self, timeout: float | None = None) -> SampleBlock | None:
        """The next SAMPLES block of the capture, waiting up to ``timeout`` seconds (None:
        forever).

        Returns:
            A :class:`SampleBlock`, or None when none came within ``timeout``.

        Raises:
            DeviceDisconnected: the link went away and no block is left.
        """
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            try:
                capture, block = self._blocks.get(
                    timeout=_READ_S if deadline is None else
                    max(0.0, min(_READ_S, deadline - time.monotonic())))
                if capture == self._capture:
                    return block
                continue  # an earlier capture's block, sent before the pen took the new start
            except queue.Empty:
                pass
            self._check_link()
            if deadline is not None and time.monotonic() >= deadline:
                return None

    def stop_capture(self, timeout: float | None = None) -> None:
        """Stop the capture. The pen answers after its last block, so when this returns every
        block of the capture is waiting for :meth:`read_samples`.

        Args:
            timeout: seconds to wait for the pen's answer (None: the client's timeout).

        Raises:
            DeviceError: the pen refused or did not answer.
        """
        ftype, payload = self._request(p.CAPTURE_STOP, p.pack_capture_stop(), timeout)
        if ftype == p.NACK:
            _, code = self._nack(payload, "CAPTURE_STOP")
            raise self._capture_error(code)
        if ftype != p.ACK:
            raise self._unexpected("CAPTURE_STOP", ftype)
