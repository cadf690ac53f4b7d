"""The pen's protocol core: frames in, replies and events out, the player behind it.

Plain MicroPython (it runs unchanged under CPython: the BLE virtual pen of the tests imports it
with ``sys.path.insert(0, "firmware/pico")``). Hardware stays outside: each link (USB, BLE, a
pseudo-terminal) is a :class:`Link` made by :meth:`Pen.add_link` with a function that sends
bytes; whoever reads bytes from the link hands them to :meth:`Link.feed`. The audio side calls
``pen.player.fill(buf)`` (or :meth:`Pen.fill`, which also reports what the block did), and the
main loop calls :meth:`Pen.tick` now and then for the periodic EVENTs.

Messages, replies and NACK codes are those of docs/protocol.md. A pattern is uploaded into the
player's staging buffer and checked (length, CRC-32) at COMMIT; any refusal abandons the upload
and the pen keeps its last good pattern.
"""

import time

try:
    from binascii import crc32
except ImportError:  # a MicroPython build without binascii.crc32
    from zlib import crc32

try:
    import rp_protocol as P
except ImportError:  # a checkout without the link: the host package has the same module
    from realpen.device import protocol as P

from rp_capture import Capture
from rp_player import Player

try:
    from time import ticks_diff, ticks_ms, ticks_us
except ImportError:  # CPython

    def ticks_us():
        return time.perf_counter_ns() // 1000

    def ticks_ms():
        return time.perf_counter_ns() // 1000000

    def ticks_diff(a, b):
        return a - b


def time_ns():
    """Wall-clock time in ns (for traces; MicroPython's Unix and rp2 ports have time.time_ns)."""
    try:
        return time.time_ns()
    except AttributeError:
        return int(time.time() * 1000000000)


FIRMWARE_VERSION = (1, 0, 0)
DECODE_ERRORS_EVERY_MS = 1000  # at most one decode_errors EVENT a second, and only on growth
UNDERRUN_EVERY_MS = 250  # at most four underrun EVENTs a second (and as many overrun, dropped)
BATTERY_EVERY_MS = 60000  # battery EVENT once a minute


# What the pen accepts from a host, and how each payload is read.
_UNPACK = {
    P.SET_STATE: P.unpack_set_state,
    P.PATTERN_CHUNK: P.unpack_pattern_chunk,
    P.PING: P.unpack_ping,
    P.HELLO: P.unpack_hello,
    P.PATTERN_BEGIN: P.unpack_pattern_begin,
    P.PATTERN_COMMIT: P.unpack_pattern_commit,
    P.CAPTURE_START: P.unpack_capture_start,
    P.CAPTURE_STOP: P.unpack_capture_stop,
}


class Link:
    """One byte stream to a host (USB, BLE, a pseudo-terminal): its own frame decoder and a
    ``send(data)`` function the pen writes replies and events with."""

    def __init__(self, pen, send, name):
        self.pen = pen
        self.send = send
        self.name = name
        self.decoder = P.FrameDecoder()

    def feed(self, data):
        """Hand the pen bytes read from this link (any split of the stream)."""
        self.pen.feed(self, data)


class Pen:
    """The protocol core of one pen.

    ``name``: the pen's name in INFO (UTF-8, ≤ 32 bytes). ``sample_rate``: Hz the player runs at.
    ``max_pattern_bytes``: the largest pattern (2 bytes a sample). ``gain_cap``: Q15 amplitude of
    full gain. ``features``: INFO feature bits. ``protocol_version``: the version this pen
    speaks (a test may make it speak another). ``battery``: a function returning the battery
    voltage in mV, or None. ``on_state(t_ns, sample, playing, gain, rate, fade_ms)`` and
    ``on_swap(sample, pattern_id)``: optional hooks :meth:`fill` calls when a SET_STATE takes
    effect (``t_ns``: wall clock when its frame was decoded; ``sample``: the first sample it
    affects, counted by :meth:`fill`) and when a new pattern starts playing. ``sensor``: an
    accelerometer driver (``rp_lis3dh.Lis3dh``) for CAPTURE_START, or None (NACK
    ``E_NO_SENSOR``); :meth:`tick` sends its SAMPLES blocks to the link that started the capture.
    """

    def __init__(self, name="RealPen", sample_rate=8000, max_pattern_bytes=32768,
                 gain_cap=32767, features=P.FEATURE_USB | P.FEATURE_RATE,
                 protocol_version=P.PROTOCOL_VERSION, firmware=FIRMWARE_VERSION, battery=None,
                 on_state=None, on_swap=None, sensor=None):
        self.name = name
        self.sample_rate = sample_rate
        self.max_pattern_bytes = max_pattern_bytes
        self.features = features
        self.protocol_version = protocol_version
        self.firmware = firmware
        self.battery = battery
        self.on_state = on_state
        self.on_swap = on_swap
        self.player = Player(sample_rate, max_pattern_bytes, gain_cap)
        self.links = []
        self.samples = 0  # samples rendered through fill()
        self.underruns = 0
        self._event_seq = 0
        # Upload under way: id, length (samples), crc32, bytes received, the staging buffer and
        # the low byte of a sample split between two chunks.
        self._upload = None
        self._received = 0
        self._staging = None
        self._low = 0
        self._state = None  # (t_ns, playing, gain, rate, fade_ms) of the latest SET_STATE
        self._swaps_seen = 0
        self._errors_sent = 0
        self._underruns_sent = 0
        now = ticks_ms()
        self._errors_at = now
        self._underrun_at = now
        self._battery_at = now
        # The PONG clock: whole seconds and the µs within the second, advanced by ticks_diff at
        # every tick() (ticks_us wraps at 2**30 µs on the rp2 port, and ticks_diff is only
        # right for gaps under half that, 537 s), kept in two small ints so that advancing it
        # allocates nothing on a 32-bit port.
        self._us_last = ticks_us()
        self._clock_s = 0
        self._clock_us = 0
        self.capture = Capture(sensor, self.clock_us, ticks_us) if sensor is not None else None
        self._capture_link = None
        self._overruns_sent = 0
        self._dropped_sent = 0
        self._capture_event_at = now

    # -- links ------------------------------------------------------------------------------

    def add_link(self, send, name="link"):
        """A new link whose replies go out through ``send(data)``; returns the :class:`Link`."""
        link = Link(self, send, name)
        self.links.append(link)
        return link

    def info_payload(self):
        """The INFO payload (also the BLE INFO characteristic's value)."""
        major, minor, patch = self.firmware
        return P.pack_info(self.protocol_version, major, minor, patch, self.sample_rate,
                           self.max_pattern_bytes, self.features, self.name)

    def boot(self):
        """Announce the start on every link (EVENT boot, value 0)."""
        self.event(P.EV_BOOT, 0)

    def event(self, kind, value):
        """Send EVENT(kind, value) on every link, numbered with the pen's own counter."""
        frame = P.encode_frame(P.EVENT, self._event_seq, P.pack_event(kind, value & 0xFFFFFFFF))
        self._event_seq = (self._event_seq + 1) & 0xFF
        for link in self.links:
            self._send(link, frame)

    def _advance_clock(self):
        # Called from tick() (every main-loop pass) and at each PING, so consecutive readings
        # of ticks_us are never half a ticks period (2**29 µs, about 9 minutes) apart.
        now = ticks_us()
        us = self._clock_us + ticks_diff(now, self._us_last)
        self._us_last = now
        while us >= 1000000:
            us -= 1000000
            self._clock_s += 1
        self._clock_us = us

    def clock_us(self):
        """The pen's clock since start, in µs, modulo 2**32 (what PONG carries)."""
        self._advance_clock()
        return (self._clock_s * 1000000 + self._clock_us) & 0xFFFFFFFF

    @staticmethod
    def _send(link, frame):
        try:
            link.send(frame)
        except OSError:  # a link that went away; its owner notices on reading
            pass

    def _reply(self, link, ftype, seq, payload):
        self._send(link, P.encode_frame(ftype, seq, payload))

    def _nack(self, link, ftype, seq, code):
        self._reply(link, P.NACK, seq, P.pack_nack(ftype, code))

    # -- frames -----------------------------------------------------------------------------

    def feed(self, link, data):
        """Decode ``data`` from ``link`` and answer every complete frame."""
        for ftype, seq, payload in link.decoder.feed(data):
            self.handle(link, ftype, seq, payload)

    def handle(self, link, ftype, seq, payload):
        """Act on one decoded frame from ``link`` and send its reply, if it has one."""
        unpack = _UNPACK.get(ftype)
        if unpack is None:
            self._nack(link, ftype, seq, P.E_UNKNOWN_TYPE)
            return
        try:
            fields = unpack(payload)
        except ValueError:
            self._nack(link, ftype, seq, P.E_BAD_LENGTH)
            if ftype == P.PATTERN_CHUNK or ftype == P.PATTERN_COMMIT:
                # A chunk lost is an upload lost, and a COMMIT always ends the upload.
                self._upload = None
            return
        if ftype == P.SET_STATE:
            self._set_state(link, seq, fields)
        elif ftype == P.PATTERN_CHUNK:
            self._chunk(link, seq, fields[0], fields[1])
        elif ftype == P.PING:
            self._reply(link, P.PONG, seq, P.pack_pong(fields, self.clock_us()))
        elif ftype == P.HELLO:
            if fields != self.protocol_version:
                # INFO after the NACK: its first field tells the host which version to ask for.
                self._nack(link, ftype, seq, P.E_VERSION)
                self._reply(link, P.INFO, seq, self.info_payload())
            else:
                self._reply(link, P.INFO, seq, self.info_payload())
        elif ftype == P.PATTERN_BEGIN:
            self._begin(link, seq, fields)
        elif ftype == P.PATTERN_COMMIT:
            self._commit(link, seq, fields)
        elif ftype == P.CAPTURE_START:
            self._capture_start(link, seq, fields)
        else:
            self._capture_stop(link, seq)

    def _capture_start(self, link, seq, fields):
        capture = self.capture
        if capture is None:
            self._nack(link, P.CAPTURE_START, seq, P.E_NO_SENSOR)
            return
        if capture.active:
            self._finish_capture()
        code = capture.start(fields[0], fields[1])
        if code:
            self._nack(link, P.CAPTURE_START, seq, code)
            return
        self._capture_link = link
        self._overruns_sent = 0
        self._dropped_sent = 0
        self._reply(link, P.ACK, seq, P.pack_ack(P.CAPTURE_START))

    def _capture_stop(self, link, seq):
        # The ACK follows the last block, so a host has every sample once it has the ACK.
        if self.capture is not None and self.capture.active:
            self._finish_capture()
        self._reply(link, P.ACK, seq, P.pack_ack(P.CAPTURE_STOP))

    def _finish_capture(self):
        capture = self.capture
        payload = capture.drain()
        if payload is not None:
            self._send_samples(payload)
        capture.stop()
        self._capture_events(True)
        self._capture_link = None

    def _send_samples(self, payload):
        frame = P.encode_frame(P.SAMPLES, self._event_seq, payload)
        self._event_seq = (self._event_seq + 1) & 0xFF
        try:
            sent = self._capture_link.send(frame)
        except OSError:
            sent = False
        if sent is False:  # the link could not take it (a send function may say so)
            self.capture.dropped += 1

    def _capture_events(self, force):
        capture = self.capture
        now = ticks_ms()
        if not force and ticks_diff(now, self._capture_event_at) < UNDERRUN_EVERY_MS:
            return
        if capture.overruns != self._overruns_sent:
            self._overruns_sent = capture.overruns
            self._capture_event_at = now
            self.event(P.EV_OVERRUN, capture.overruns)
        if capture.dropped != self._dropped_sent:
            self._dropped_sent = capture.dropped
            self._capture_event_at = now
            self.event(P.EV_CAPTURE_DROPPED, capture.dropped)

    def poll_capture(self):
        """Drain the sensor's FIFO when it reached the watermark and send the block (called
        by :meth:`tick`; a main loop may call it more often)."""
        capture = self.capture
        if capture is None or not capture.active:
            return
        payload = capture.poll()
        if payload is not None:
            self._send_samples(payload)
        self._capture_events(False)

    def _set_state(self, link, seq, fields):
        playing, gain, rate, fade_ms = fields
        if playing > 1 or not P.RATE_MIN <= rate <= P.RATE_MAX:
            self._nack(link, P.SET_STATE, seq, P.E_BAD_STATE)
            return
        if self.on_state is not None:
            self._state = (time_ns(), playing, gain, rate, fade_ms)
        self.player.set_state(playing, gain, rate, fade_ms)

    def _begin(self, link, seq, fields):
        pattern_id, length, rate, sample_format, crc = fields
        self._upload = None
        if sample_format != P.FORMAT_S16LE or length == 0:  # an empty pattern is no format
            code = P.E_BAD_FORMAT
        elif rate != self.sample_rate:
            code = P.E_BAD_RATE
        elif 2 * length > self.max_pattern_bytes:
            code = P.E_TOO_LARGE
        else:
            code = 0
        if code:
            self._nack(link, P.PATTERN_BEGIN, seq, code)
            return
        self._staging = self.player.staging()
        self._upload = (pattern_id, length, crc)
        self._received = 0
        self._reply(link, P.ACK, seq, P.pack_ack(P.PATTERN_BEGIN))

    def _chunk(self, link, seq, offset, data):
        upload = self._upload
        if upload is None:
            self._nack(link, P.PATTERN_CHUNK, seq, P.E_NO_UPLOAD)
            return
        if offset != self._received:
            self._upload = None
            self._nack(link, P.PATTERN_CHUNK, seq, P.E_BAD_OFFSET)
            return
        if offset + len(data) > 2 * upload[1]:
            self._upload = None
            self._nack(link, P.PATTERN_CHUNK, seq, P.E_TOO_LARGE)
            return
        self._store(data)

    def _store(self, data):
        # Little-endian byte pairs into the int16 staging buffer, a sample at a time: the same
        # on every port and byte order; a sample may be split between two chunks.
        buf = self._staging
        pos = self._received
        count = len(data)
        i = 0
        if pos & 1:
            value = self._low | (data[0] << 8)
            buf[pos >> 1] = value - 0x10000 if value & 0x8000 else value
            i = 1
        k = (pos + i) >> 1
        while i + 1 < count:
            value = data[i] | (data[i + 1] << 8)
            buf[k] = value - 0x10000 if value & 0x8000 else value
            i += 2
            k += 1
        if i < count:
            self._low = data[i]
        self._received = pos + count

    def _commit(self, link, seq, pattern_id):
        upload = self._upload
        self._upload = None
        if upload is None or upload[0] != pattern_id:
            self._nack(link, P.PATTERN_COMMIT, seq, P.E_NO_UPLOAD)
            return
        length = upload[1]
        if self._received != 2 * length:
            self._nack(link, P.PATTERN_COMMIT, seq, P.E_INCOMPLETE)
            return
        if crc32(memoryview(self._staging)[:length]) & 0xFFFFFFFF != upload[2]:
            self._nack(link, P.PATTERN_COMMIT, seq, P.E_CRC)
            return
        self.player.commit(length, pattern_id)
        self._reply(link, P.ACK, seq, P.pack_ack(P.PATTERN_COMMIT))

    # -- audio side and housekeeping --------------------------------------------------------

    def fill(self, buf):
        """Render the next ``len(buf)`` samples and call the hooks for what they did.

        For the simulator and the virtual pen; the Pico's audio interrupt calls
        ``player.fill`` directly (this method counts samples in an ever-growing int).
        """
        player = self.player
        player.fill(buf)
        if player.applied and self.on_state is not None and self._state is not None:
            t_ns, playing, gain, rate, fade_ms = self._state
            self.on_state(t_ns, self.samples, playing, gain, rate, fade_ms)
        if player.swap_at >= 0 and self.on_swap is not None:
            self.on_swap(self.samples + player.swap_at, player.pattern_id)
        self.samples += len(buf)

    def underrun(self):
        """Count an underrun (the audio output ran dry); :meth:`tick` reports it."""
        self.underruns += 1

    def tick(self):
        """Send the EVENTs that are due: pattern swapped in, underruns, decode errors (when
        their count grew, at most once a second), battery (once a minute). Call often (at
        least every few minutes: it also keeps the PONG clock across ``ticks_us`` wraps)."""
        self._advance_clock()
        self.poll_capture()
        player = self.player
        if player.swaps != self._swaps_seen:
            self._swaps_seen = player.swaps
            self.event(P.EV_PATTERN, player.pattern_id)
        now = ticks_ms()
        if (self.underruns != self._underruns_sent
                and ticks_diff(now, self._underrun_at) >= UNDERRUN_EVERY_MS):
            self._underruns_sent = self.underruns
            self._underrun_at = now
            self.event(P.EV_UNDERRUN, self.underruns)
        if ticks_diff(now, self._errors_at) >= DECODE_ERRORS_EVERY_MS:
            self._errors_at = now
            errors = 0
            for link in self.links:
                errors += link.decoder.errors
            if errors != self._errors_sent:
                self._errors_sent = errors
                self.event(P.EV_DECODE_ERRORS, errors)
        if self.battery is not None and ticks_diff(now, self._battery_at) >= BATTERY_EVERY_MS:
            self._battery_at = now
            self.event(P.EV_BATTERY, self.battery())
