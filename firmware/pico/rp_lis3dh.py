"""The LIS3DH accelerometer over I2C: FIFO stream mode, drained in short transfers.

Plain MicroPython (also CPython): the bus is anything with ``machine.I2C``'s
``readfrom_mem_into(addr, reg, buf)`` and ``writeto_mem(addr, reg, buf)`` — the Pico's
``machine.I2C`` at 400 kHz, or the simulator's register-level model (``sim_lis3dh.py``).

Register facts (ST LIS3DH datasheet, DocID17530): WHO_AM_I (0x0F) reads 0x33; CTRL_REG1 (0x20)
holds the output rate in bits 7–4 (0b1001: 1.344 kHz in normal and high-resolution mode) and
the axis enables; CTRL_REG4 (0x23) the block data update, the full scale (bits 5–4) and the
high-resolution bit; CTRL_REG5 (0x24) bit 6 enables the FIFO; FIFO_CTRL_REG (0x2E) the mode
(bits 7–6, 0b10 stream) and the watermark (bits 4–0); FIFO_SRC_REG (0x2F) the watermark flag
(bit 7), the overrun flag (bit 6: the FIFO holds 32 unread samples, and the next one replaces
the oldest), empty (bit 5) and the unread count (bits 4–0). Reading from OUT_X_L (0x28) with
the sub-address's top bit set auto-increments and, with the FIFO on, wraps from OUT_Z_H (0x2D)
back to 0x28, so one transfer of 6 × n bytes reads n samples. The samples are left-justified
16-bit two's complement (12 significant bits in high-resolution mode).
"""

ADDRESS = 0x18  # SDO/SA0 to GND; 0x19 with SDO to VDD
WHO_AM_I = 0x0F
WHO_AM_I_VALUE = 0x33
CTRL_REG1 = 0x20
CTRL_REG3 = 0x22
CTRL_REG4 = 0x23
CTRL_REG5 = 0x24
OUT_X_L = 0x28
FIFO_CTRL_REG = 0x2E
FIFO_SRC_REG = 0x2F
AUTO_INCREMENT = 0x80  # the I2C sub-address's top bit

FIFO_DEPTH = 32
FIFO_WTM = 0x80
FIFO_OVRN = 0x40
FIFO_EMPTY = 0x20
FIFO_COUNT = 0x1F
MODE_BYPASS = 0x00
MODE_STREAM = 0x80

# Output rate (Hz) → CTRL_REG1 ODR code (normal and high-resolution modes).
ODR_CODES = {1: 1, 10: 2, 25: 3, 50: 4, 100: 5, 200: 6, 400: 7, 1344: 9}
# Full scale (g) → CTRL_REG4 FS code.
RANGE_CODES = {2: 0, 4: 1, 8: 2, 16: 3}
BDU = 0x80
HIGH_RESOLUTION = 0x08
XYZ_ENABLE = 0x07
FIFO_ENABLE = 0x40


class Lis3dh:
    """One LIS3DH on an I2C bus.

    ``bus``: a ``machine.I2C``-like object. ``address``: 0x18 or 0x19. ``chunk``: the most
    samples read in one I2C transfer. On the Pico the I2S refill is a scheduled callback, which
    cannot run inside a blocking transfer: 5 samples (33 bytes, about 0.75 ms at 400 kHz) keep
    it waiting well under one DMA half (2 ms). ``between``: called between two transfers of a
    drain (the simulator pumps its audio there), or None.
    """

    def __init__(self, bus, address=ADDRESS, chunk=5, between=None):
        self.bus = bus
        self.address = address
        self.chunk = max(1, min(chunk, FIFO_DEPTH))
        self.between = between
        self._one = bytearray(1)
        self._status = bytearray(1)
        self.range_g = 0
        self.rate_hz = 0

    def _write(self, register, value):
        self._one[0] = value
        self.bus.writeto_mem(self.address, register, self._one)

    def _read(self, register):
        self.bus.readfrom_mem_into(self.address, register, self._one)
        return self._one[0]

    def present(self):
        """True when a LIS3DH answers at the address (WHO_AM_I reads 0x33)."""
        try:
            return self._read(WHO_AM_I) == WHO_AM_I_VALUE
        except OSError:
            return False

    def start(self, range_g, rate_hz, watermark=16):
        """Power up at ``rate_hz`` and ±``range_g`` g, FIFO in stream mode; the watermark flag
        rises when more than ``watermark - 1`` samples wait. Raises ValueError for a range or
        rate the sensor does not have."""
        if range_g not in RANGE_CODES or rate_hz not in ODR_CODES:
            raise ValueError("range or rate not supported")
        self._write(CTRL_REG1, 0)  # power down while reconfiguring
        self._write(FIFO_CTRL_REG, MODE_BYPASS)  # bypass empties the FIFO
        self._write(CTRL_REG4, BDU | (RANGE_CODES[range_g] << 4) | HIGH_RESOLUTION)
        self._write(CTRL_REG5, FIFO_ENABLE)
        self._write(FIFO_CTRL_REG, MODE_STREAM | ((watermark - 1) & FIFO_COUNT))
        self._write(CTRL_REG1, (ODR_CODES[rate_hz] << 4) | XYZ_ENABLE)
        self.range_g = range_g
        self.rate_hz = rate_hz

    def stop(self):
        """Power down (the FIFO is emptied by bypass mode)."""
        self._write(CTRL_REG1, 0)
        self._write(FIFO_CTRL_REG, MODE_BYPASS)

    def fifo_status(self):
        """``(count, overrun, watermark)``: unread samples (32 when the overrun flag says the
        FIFO is full), the overrun flag, the watermark flag."""
        self.bus.readfrom_mem_into(self.address, FIFO_SRC_REG, self._status)
        value = self._status[0]
        overrun = 1 if value & FIFO_OVRN else 0
        count = FIFO_DEPTH if overrun else value & FIFO_COUNT
        if value & FIFO_EMPTY:
            count = 0
        return count, overrun, 1 if value & FIFO_WTM else 0

    def read_fifo(self, view, count):
        """Read ``count`` samples (x, y, z int16 LE each) into the memoryview ``view`` (at
        least 6 × count bytes), in transfers of at most ``chunk`` samples."""
        done = 0
        while done < count:
            if done and self.between is not None:
                self.between()
            n = min(self.chunk, count - done)
            self.bus.readfrom_mem_into(self.address, OUT_X_L | AUTO_INCREMENT,
                                       view[6 * done:6 * (done + n)])
            done += n
