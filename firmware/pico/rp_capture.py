"""Accelerometer capture: the sensor's FIFO drained once per watermark into SAMPLES payloads.

Plain MicroPython (also CPython). :class:`Capture` wraps a sensor driver (``rp_lis3dh.Lis3dh``
or anything with its ``start``/``stop``/``fifo_status``/``read_fifo``) and a µs clock (the
pen's PONG clock, so that a host can relate the blocks' times to its own pings). The pen's main
loop calls :meth:`Capture.poll` often; it looks at the FIFO only when the watermark can have
been reached, and returns the next SAMPLES payload, or None.

Samples are numbered from 0 at CAPTURE_START. When the FIFO overran (it held 32 unread samples
and the sensor went on writing), samples were lost inside the sensor: how many is estimated from
the time since the last look at the FIFO at the nominal rate, added to the running index (so
the host sees the gap where it is) and flagged in the block (``SAMPLES_OVERRUN``).
"""

try:
    import rp_protocol as P
except ImportError:  # a checkout without the link: the host package has the same module
    from realpen.device import protocol as P

try:
    from time import ticks_diff
except ImportError:  # CPython

    def ticks_diff(a, b):
        return a - b


WATERMARK = 16  # samples: the drain starts at 16 of the FIFO's 32 (11.9 ms at 1344 Hz)


class Capture:
    """One sensor's capture. ``sensor``: the driver; ``clock_us()``: the pen's µs clock
    (wrapping at 2**32, as PONG); ``ticks_us()``: a monotonic µs tick for the polling interval
    (``time.ticks_us`` on the board); ``watermark``: samples that start a drain."""

    def __init__(self, sensor, clock_us, ticks_us, watermark=WATERMARK):
        self.sensor = sensor
        self.clock_us = clock_us
        self.ticks_us = ticks_us
        self.watermark = watermark
        self.active = False
        self.range_g = 0
        self.rate_hz = 0
        self.index = 0  # the next sample's index since CAPTURE_START (lost samples counted)
        self.overruns = 0  # FIFO overruns seen in this capture
        self.lost = 0  # samples estimated lost in them
        self.dropped = 0  # blocks the pen could not send (counted by the caller)
        self.blocks = 0
        self._buffer = bytearray(P.MAX_BLOCK_SAMPLES * P.SAMPLE_BYTES)
        self._view = memoryview(self._buffer)
        self._last_look = 0  # ticks_us of the last FIFO_SRC read
        self._left = 0  # samples estimated in the FIFO after the last drain
        self._wait_us = 0
        self._period_us = 0

    def start(self, range_g, rate_hz):
        """Start capturing; returns 0, or the NACK code (``E_BAD_CAPTURE``, ``E_NO_SENSOR``)."""
        if range_g not in P.CAPTURE_RANGES or rate_hz not in P.CAPTURE_RATES:
            return P.E_BAD_CAPTURE
        try:
            self.sensor.start(range_g, rate_hz, self.watermark)
        except ValueError:
            return P.E_BAD_CAPTURE
        except OSError:  # the sensor stopped answering
            return P.E_NO_SENSOR
        self.active = True
        self.range_g = range_g
        self.rate_hz = rate_hz
        self.index = 0
        self.overruns = self.lost = self.dropped = self.blocks = 0
        self._last_look = self.ticks_us()
        self._left = 0
        # Look again when the watermark can have been reached: a look costs a bus transfer.
        self._period_us = self.watermark * 1000000 // rate_hz * 3 // 4
        self._wait_us = self._period_us
        return 0

    def stop(self):
        """Stop capturing (idempotent); the caller sends the last block from :meth:`drain`
        first."""
        if self.active:
            self.active = False
            try:
                self.sensor.stop()
            except OSError:
                pass

    def poll(self, force=False):
        """The next SAMPLES payload when the FIFO reached the watermark (or held anything, with
        ``force``), else None."""
        if not self.active:
            return None
        now = self.ticks_us()
        elapsed = ticks_diff(now, self._last_look)
        if not force and elapsed < self._wait_us:
            return None
        t_us = self.clock_us()
        count, overrun, _wtm = self.sensor.fifo_status()
        self._last_look = now
        flags = 0
        if overrun:
            # The FIFO is full: those produced beyond its 32 since the last look are gone.
            expected = self._left + elapsed * self.rate_hz // 1000000
            lost = expected - P.MAX_BLOCK_SAMPLES
            if lost < 1:
                lost = 1  # full, and the sensor writes over the oldest at its next sample
            self.overruns += 1
            self.lost += lost
            self.index += lost
            flags = P.SAMPLES_OVERRUN
        if count == 0 or (count < self.watermark and not force and not overrun):
            # Look again when the watermark should be there.
            self._left = count
            self._wait_us = (self.watermark - count) * 1000000 // self.rate_hz
            return None
        self._wait_us = self._period_us
        self.sensor.read_fifo(self._view, count)
        self._left = 0
        first = self.index
        self.index += count
        self.blocks += 1
        return P.pack_samples(first, t_us, self.range_g, flags,
                              self._view[:count * P.SAMPLE_BYTES])

    def due_in_us(self):
        """µs until :meth:`poll` will look at the FIFO again (0: now)."""
        if not self.active:
            return 1 << 29
        left = self._wait_us - ticks_diff(self.ticks_us(), self._last_look)
        return left if left > 0 else 0

    def drain(self):
        """What is left in the FIFO as one last payload (or None), before :meth:`stop`."""
        return self.poll(force=True)
