"""Simulated parts for the firmware under the MicroPython Unix port: a LIS3DH at register level,
an I2C bus that charges every transfer its time on the wire, and the pen's actuator.

Not used on the Pico. ``sim_main.py`` wires them to the real firmware (``rp_lis3dh``,
``rp_capture``, ``rp_pen``), so the driver's every register access goes through
:class:`SimLis3dh` as it would through the Pico's ``machine.I2C`` to a real part.

What the model does (ST LIS3DH datasheet, DocID17530): WHO_AM_I 0x33; the output rate from
CTRL_REG1 (off when 0), off from the nominal rate by ``rate_error`` (the real part's internal
oscillator is off by up to a few per cent); the full scale and the high-resolution bit from
CTRL_REG4 (12-bit data in high resolution, 10-bit otherwise, left-justified in 16 bits,
clipped at full scale); the FIFO from CTRL_REG5 and FIFO_CTRL_REG: bypass (empty) or stream
(32 samples, the oldest replaced by each new one when full: samples lost, counted in
:attr:`SimLis3dh.lost`); FIFO_SRC_REG with the watermark flag (more than FTH samples), the
overrun flag (full), empty and the count; OUT_X_L … OUT_Z_H read with the sub-address's top bit
set auto-increment and, with the FIFO on, wrap from 0x2D to 0x28, and a sample leaves the FIFO
once its OUT_Z_H is read. What the sensor feels is ``source`` (what the pen feels while
writing, in g, at the sensor's true rate, looped) plus what the actuator does.

Not modelled: the sensor's own noise beyond what the source carries (the host adds it), its
internal filters, self-test, interrupts, the reading of OUT registers in bypass mode beyond the
latest sample, SPI.
"""

import time

SENSITIVITY_MG = ((1, 2, 4, 12), (4, 8, 16, 48))  # mg/digit by FS code: high resolution, normal


class RealClock:
    """The sim's µs clock: ``time.ticks_us`` accumulated so that it never wraps; a transfer's
    time is spent for real (the CPU waits on the bus, as on the Pico).

    ``max_step_us``: a longer step between two readings counts as only this long, and the
    rest is added to :attr:`stalled_us` (and passed to ``on_stall(us)``). The simulated pen
    then stands still while the host's scheduler holds its process back — a pen has its
    processor to itself, and a desktop scheduler stalls a process for 10–20 ms now and then
    even on an idle machine. None: every step counts (the process's stalls are the pen's).
    """

    def __init__(self, max_step_us=None, on_stall=None):
        self.last = time.ticks_us()
        self.us = 0
        self.max_step_us = max_step_us
        self.on_stall = on_stall
        self.stalled_us = 0

    def now(self):
        t = time.ticks_us()
        step = time.ticks_diff(t, self.last)
        self.last = t
        if self.max_step_us is not None and step > self.max_step_us:
            self.stalled_us += step - self.max_step_us
            if self.on_stall is not None:
                self.on_stall(step - self.max_step_us)
            step = self.max_step_us
        self.us += step
        return self.us

    def spend(self, us):
        time.sleep_us(us)


class VirtualClock:
    """A µs clock that only moves when told: a transfer's time is added to it."""

    def __init__(self):
        self.us = 0

    def now(self):
        return self.us

    def spend(self, us):
        self.us += us


class SimI2C:
    """``machine.I2C``'s ``readfrom_mem_into`` / ``writeto_mem`` against one device model,
    charging each transfer ``(bytes × 9 + 2) / freq`` plus ``overhead_us`` of the clock
    (START, address, sub-address, repeated START and address, data, STOP). ``busy_us`` adds up
    what the bus took; ``longest_us`` is the longest single transfer. ``before``: called before
    each transfer (the simulator's audio sink, which on the Pico runs from an interrupt)."""

    def __init__(self, device, clock, freq=400000, overhead_us=10):
        self.before = None
        self.device = device
        self.clock = clock
        self.freq = freq
        self.overhead_us = overhead_us
        self.busy_us = 0
        self.longest_us = 0
        self.transfers = 0

    def _charge(self, nbytes):
        us = (nbytes * 9 + 2) * 1000000 // self.freq + self.overhead_us
        self.busy_us += us
        self.transfers += 1
        if us > self.longest_us:
            self.longest_us = us
        self.clock.spend(us)

    def readfrom_mem_into(self, addr, reg, buf):
        if self.before is not None:
            self.before()
        if addr != self.device.address:
            raise OSError(19)  # ENODEV: nobody acknowledged the address
        self.device.read(reg, buf)
        self._charge(3 + len(buf))

    def writeto_mem(self, addr, reg, buf):
        if self.before is not None:
            self.before()
        if addr != self.device.address:
            raise OSError(19)
        self.device.write(reg, buf)
        self._charge(2 + len(buf))


class SimActuator:
    """The pen's actuator as a biquad at the player's rate (coefficients from the host: the
    actuator spec is unknown to the firmware, as a real part's is), driving the sensor's axes
    with ``mount_g`` g per full-scale sample at |H| = 1 and the weights ``axes``.

    :meth:`play` takes the samples the DAC plays, with the index of the first; the sensor asks
    :meth:`value_at` for the acceleration at a DAC position (samples, fractional)."""

    RING = 2048  # samples kept: 256 ms at 8 kHz, more than the sensor's lag behind the DAC

    def __init__(self, coefficients, mount_g=1.0, axes=(1.0, 0.25, 0.1)):
        self.b0, self.b1, self.b2, self.a1, self.a2 = coefficients
        self.scale = mount_g / 32768.0
        self.axes = axes
        self.ring = [0.0] * self.RING
        self.written = 0  # DAC samples filtered so far
        self.quiet_from = 0  # the output is 0 from this DAC index on (None: it moves)
        self.x1 = self.x2 = self.y1 = self.y2 = 0.0

    def play(self, first, samples):
        """Filter the DAC's samples from index ``first`` (earlier ones not given are 0)."""
        if self.quiet_from is not None and not any(samples):
            self.written = first + len(samples)  # still at rest: nothing to compute
            return
        if self.quiet_from is not None:
            self._zero_ring(self.quiet_from, first)
            self.written = first
            self.quiet_from = None
        ring = self.ring
        mask = self.RING
        b0, b1, b2, a1, a2 = self.b0, self.b1, self.b2, self.a1, self.a2
        x1, x2, y1, y2 = self.x1, self.x2, self.y1, self.y2
        scale = self.scale
        index = self.written
        while index < first:  # a stretch the DAC played as silence
            y = b1 * x1 + b2 * x2 - a1 * y1 - a2 * y2
            x2, x1, y2, y1 = x1, 0.0, y1, y
            ring[index % mask] = y
            index += 1
        for value in samples:
            x = value * scale
            y = b0 * x + b1 * x1 + b2 * x2 - a1 * y1 - a2 * y2
            x2, x1, y2, y1 = x1, x, y1, y
            ring[index % mask] = y
            index += 1
        self.x1, self.x2, self.y1, self.y2 = x1, x2, y1, y2
        self.written = index
        if (not any(samples) and -1e-9 < y1 < 1e-9 and -1e-9 < y2 < 1e-9
                and x1 == 0 and x2 == 0):
            # At rest: from here on the output is 0 until the DAC plays something again.
            self.x1 = self.x2 = self.y1 = self.y2 = 0.0
            self.quiet_from = index

    def _zero_ring(self, start, end):
        ring = self.ring
        for index in range(max(start, end - self.RING), end):
            ring[index % self.RING] = 0.0

    def value_at(self, position):
        """Acceleration (g, along the actuator's axis) at a DAC position (samples)."""
        i = int(position)
        if i < 0 or i + 1 >= self.written or self.written - i >= self.RING:
            return 0.0
        if self.quiet_from is not None and i >= self.quiet_from:
            return 0.0
        frac = position - i
        a = self.ring[i % self.RING]
        return a + (self.ring[(i + 1) % self.RING] - a) * frac


class SimLis3dh:
    """The LIS3DH's registers, its FIFO and its data.

    ``clock``: a :class:`RealClock` or :class:`VirtualClock`. ``rate_error``: the true output
    rate is the nominal one × (1 + rate_error). ``source``: an ``array('f')`` of x, y, z in g
    at the true rate, looped (None: the sensor feels nothing but the actuator). ``actuator``: a
    :class:`SimActuator`, with ``dac_position(t_us)`` giving the DAC's position at a clock time,
    or None. ``address``: where it answers.
    """

    def __init__(self, clock, rate_error=0.0, source=None, actuator=None, dac_position=None,
                 address=0x18):
        self.clock = clock
        self.rate_error = rate_error
        self.source = source
        self.source_frames = len(source) // 3 if source is not None else 0
        self.actuator = actuator
        self.dac_position = dac_position
        self.address = address
        self.regs = bytearray(0x40)
        self.regs[0x0F] = 0x33
        self.true_rate = 0.0
        self.t_on = 0  # clock µs of sample 0
        self.produced = 0  # samples taken since power-up
        self.oldest = 0  # index of the oldest sample in the FIFO
        self.count = 0  # samples in the FIFO
        self.lost = 0  # samples replaced in a full FIFO (the real part says nothing of them)
        self.current = 0  # index of the sample OUT_* show in bypass
        self.byte_in_sample = 0
        self.sample_bytes = bytearray(6)
        self.sample_loaded = -1
        self._zeros = memoryview(bytearray(6 * 32))

    # -- time ------------------------------------------------------------------------------

    def _odr(self):
        code = self.regs[0x20] >> 4
        return (0, 1, 10, 25, 50, 100, 200, 400, 0, 1344)[code] if code < 10 else 0

    def _stream(self):
        return self.regs[0x24] & 0x40 and (self.regs[0x2E] >> 6) == 2

    def update(self):
        """Take the samples due by now."""
        if not self.true_rate:
            return
        # Sample k is taken one period after the previous, the first one period after power-up.
        due = int((self.clock.now() - self.t_on) * self.true_rate / 1000000)
        new = due - self.produced
        if new <= 0:
            return
        if self._stream():
            total = self.count + new
            if total > 32:
                self.lost += total - 32
                self.oldest += total - 32
                self.count = 32
            else:
                self.count = total
        self.produced = due

    # -- data ------------------------------------------------------------------------------

    def acceleration(self, index):
        """(x, y, z) in g that sample ``index`` measures."""
        x = y = z = 0.0
        if self.source_frames:
            at = 3 * (index % self.source_frames)
            source = self.source
            x, y, z = source[at], source[at + 1], source[at + 2]
        actuator = self.actuator
        if actuator is not None and self.dac_position is not None:
            t_us = self.t_on + (index + 1) * 1000000 / self.true_rate
            a = actuator.value_at(self.dac_position(t_us))
            if a:
                wx, wy, wz = actuator.axes
                x += a * wx
                y += a * wy
                z += a * wz
        return x, y, z

    def _load(self, index):
        self.sample_loaded = index
        if not self.source_frames and self.actuator is None:
            out = self.sample_bytes
            for i in range(6):
                out[i] = 0
            return
        ctrl4 = self.regs[0x23]
        high = 1 if ctrl4 & 0x08 else 0
        mg = SENSITIVITY_MG[0 if high else 1][(ctrl4 >> 4) & 3]
        bits = 12 if high else 10
        top = (1 << (bits - 1)) - 1
        shift = 16 - bits
        out = self.sample_bytes
        at = 0
        for g in self.acceleration(index):
            counts = int(g * 1000 / mg + (0.5 if g >= 0 else -0.5))
            if counts > top:
                counts = top
            elif counts < -top - 1:
                counts = -top - 1
            raw = (counts << shift) & 0xFFFF
            out[at] = raw & 0xFF
            out[at + 1] = raw >> 8
            at += 2

    # -- registers -------------------------------------------------------------------------

    def read(self, reg, buf):
        """Bytes from ``reg`` on (auto-increment when its top bit is set) into ``buf``."""
        self.update()
        increment = reg & 0x80
        reg &= 0x7F
        size = len(buf)
        if (reg == 0x28 and increment and size % 6 == 0 and self._stream()
                and size // 6 <= self.count):
            # Whole samples from a FIFO that holds them: what the byte loop below does, faster.
            if not self.source_frames and self.actuator is None:  # it feels nothing: zeros
                buf[0:size] = self._zeros[0:size]
                self.oldest += size // 6
                self.count -= size // 6
                return
            at = 0
            while at < size:
                if self.sample_loaded != self.oldest:
                    self._load(self.oldest)
                buf[at:at + 6] = self.sample_bytes
                self.oldest += 1
                self.count -= 1
                at += 6
            return
        for i in range(size):
            buf[i] = self._read_one(reg)
            if increment:
                reg += 1
                if reg == 0x2E and self.regs[0x24] & 0x40:
                    reg = 0x28  # the FIFO's wrap: X_L follows Z_H
                reg &= 0x7F

    def _read_one(self, reg):
        if 0x28 <= reg <= 0x2D:
            if self._stream():
                index = self.oldest if self.count else self.oldest - 1
            else:
                index = self.produced - 1
            if index < 0:
                return 0
            if self.sample_loaded != index:
                self._load(index)
            value = self.sample_bytes[reg - 0x28]
            if reg == 0x2D and self._stream() and self.count:
                self.oldest += 1  # OUT_Z_H read: the sample leaves the FIFO
                self.count -= 1
            return value
        if reg == 0x2F:
            count = self.count
            fth = self.regs[0x2E] & 0x1F
            value = count & 0x1F
            if count > fth:
                value |= 0x80
            if count >= 32:
                value |= 0x40
            if count == 0:
                value |= 0x20
            return value
        return self.regs[reg]

    def write(self, reg, buf):
        """Bytes written from ``reg`` on (auto-increment when its top bit is set)."""
        self.update()
        increment = reg & 0x80
        reg &= 0x7F
        for value in buf:
            self._write_one(reg, value)
            if increment:
                reg = (reg + 1) & 0x7F

    def _write_one(self, reg, value):
        if reg == 0x0F or reg == 0x2F or 0x28 <= reg <= 0x2D:
            return  # read-only
        old = self.regs[reg]
        self.regs[reg] = value
        if reg == 0x20 and (old >> 4) != (value >> 4):
            odr = self._odr()
            self.true_rate = odr * (1 + self.rate_error) if odr else 0.0
            self.t_on = self.clock.now()
            self.produced = 0
            self.oldest = 0
            self.count = 0
            self.sample_loaded = -1
        elif reg == 0x2E or reg == 0x24:
            if not self._stream():
                self.count = 0
            self.oldest = self.produced
