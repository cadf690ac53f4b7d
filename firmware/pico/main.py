"""The pen firmware on a Raspberry Pi Pico W / Pico 2 W: USB CDC and BLE in, I2S out.

A thin layer over ``rp_pen`` (protocol) and ``rp_player`` (the loop): it wires the player to a
MAX98357A I2S amplifier through ``machine.I2S`` (interrupt-driven, non-blocking writes of one
DMA half at a time), the USB serial port (``sys.stdin`` / ``sys.stdout``) and the BLE service
(``ble_pico``) to the pen, and reads the battery. Settings are in ``config.py``.

The USB port is the one MicroPython's REPL uses: the firmware switches Ctrl-C off first thing in
:func:`main`, so that a 0x03 in a frame is data (a HELLO's COBS code byte is 0x03 for 255 of the
256 sequence numbers: a host saying HELLO while the pen boots would otherwise stop the firmware).
To reach the REPL (to update the files with mpremote), press and hold BOOTSEL during the first
1.5 s after a reset (``config.STARTUP_WINDOW_MS``): the firmware then gives Ctrl-C back and does
not start.
"""

import gc
import select
import sys
import time
from array import array

import config
import micropython
import rp2
from machine import ADC, I2S, Pin

# The rp2 driver's DMA buffer is 256 bytes played as two halves of 128
# (micropython ports/rp2/machine_i2s.c:51-52), that is 32 frames of 16-bit stereo whatever the
# rate and the mono/stereo format. One block fills exactly one half.
DMA_HALF_FRAMES = 32
# I2S runs at this multiple of the pattern rate, each pattern sample going out this many times
# (a zero-order hold): a half then lasts 2 ms at 8 kHz instead of 4, which is what keeps the
# audio queued ahead of the amplifier within 6.25 ms (README.md, "Audio buffering on the Pico").
I2S_RATE_FACTOR = 2


class Audio:
    """The player's samples to the I2S amplifier, refilled from the I2S interrupt.

    Each block is ``DMA_HALF_FRAMES // I2S_RATE_FACTOR`` pattern samples (16 at the default
    8 kHz: 2 ms), written as ``DMA_HALF_FRAMES`` mono samples at ``I2S_RATE_FACTOR`` times the
    pattern rate; the driver copies each mono sample to both channels (so the MAX98357A plays it
    whichever channel its SD_MODE selects). The driver calls :meth:`refill` when it has taken
    the last block into its ring buffer, once per DMA half, and plays silence for a half it
    finds no block for, saying nothing of it itself: a refill more than two blocks after the
    last counts as an underrun here, unless the output was silent anyway.
    """

    def __init__(self, player):
        frames = DMA_HALF_FRAMES
        count = frames // I2S_RATE_FACTOR
        rate = config.SAMPLE_RATE * I2S_RATE_FACTOR
        self.player = player
        self.block = array("h", bytes(2 * count))  # pattern samples
        self.out = array("h", bytes(2 * frames))  # each pattern sample twice, for the I2S rate
        self.slot_us = frames * 1000000 // rate  # one DMA half: 2000 µs at the default rate
        self.late_us = 2 * self.slot_us
        self.underruns = 0
        self.last = time.ticks_us()
        self.i2s = I2S(config.I2S_ID, sck=Pin(config.I2S_SCK_PIN), ws=Pin(config.I2S_WS_PIN),
                       sd=Pin(config.I2S_SD_PIN), mode=I2S.TX, bits=16, format=I2S.MONO,
                       rate=rate, ibuf=config.I2S_IBUF)
        self._refill_cb = self.refill  # one bound method for the interrupt, made once
        self.i2s.irq(self._refill_cb)  # with a callback, write() no longer blocks
        self.refill(self.i2s)

    def refill(self, _i2s):
        """Render the next block and queue it (allocates nothing)."""
        now = time.ticks_us()
        player = self.player
        if time.ticks_diff(now, self.last) > self.late_us and (player.amp or player.playing):
            self.underruns += 1
        self.last = now
        block = self.block
        out = self.out
        player.fill(block)
        k = 0
        for i in range(len(block)):  # I2S_RATE_FACTOR == 2
            value = block[i]
            out[k] = value
            out[k + 1] = value
            k += 2
        self.i2s.write(out)


class Battery:
    """VSYS through a divider on an ADC pin (config.BATTERY_*), in mV and percent."""

    def __init__(self, pin):
        self.adc = ADC(Pin(pin))

    def millivolts(self):
        total = 0
        for _ in range(8):
            total += self.adc.read_u16()
        return total // 8 * 3300 * config.BATTERY_DIVIDER // 65535

    def percent(self):
        span = config.BATTERY_FULL_MV - config.BATTERY_EMPTY_MV
        level = (self.millivolts() - config.BATTERY_EMPTY_MV) * 100 // span
        return min(100, max(0, level))


def find_accelerometer():
    """The LIS3DH driver when one answers on the configured bus, else None."""
    if not config.ACCEL:
        return None
    try:
        from machine import I2C
        from rp_lis3dh import Lis3dh

        bus = I2C(config.ACCEL_I2C_ID, sda=Pin(config.ACCEL_SDA_PIN),
                  scl=Pin(config.ACCEL_SCL_PIN), freq=config.ACCEL_I2C_HZ)
        sensor = Lis3dh(bus, config.ACCEL_ADDRESS, config.ACCEL_CHUNK_SAMPLES)
    except (ImportError, OSError, ValueError):  # no I2C on this port, or a pin in use
        return None
    return sensor if sensor.present() else None


def startup_escape():
    """True when BOOTSEL is held during the startup window: leave the REPL to mpremote."""
    start = time.ticks_ms()
    while time.ticks_diff(time.ticks_ms(), start) < config.STARTUP_WINDOW_MS:
        if rp2.bootsel_button():
            return True
        time.sleep_ms(10)
    return False


def main():
    """Start the pen: USB and BLE in, I2S out, until the board resets."""
    micropython.kbd_intr(-1)  # first of all: 0x03 on the USB port is data from now on
    # Imported here, after the line above: compiling them takes a moment on the board, and a
    # host may already be talking.
    import rp_protocol as P
    from rp_pen import Pen

    if startup_escape():
        micropython.kbd_intr(3)  # the REPL gets Ctrl-C back
        print("RealPen: BOOTSEL held, firmware not started")
        return
    if config.AMP_SD_PIN is not None:
        Pin(config.AMP_SD_PIN, Pin.OUT, value=1)  # keep the amplifier enabled
    battery = Battery(config.BATTERY_ADC_PIN) if config.BATTERY_ADC_PIN is not None else None
    features = P.FEATURE_USB | P.FEATURE_RATE
    if battery is not None:
        features |= P.FEATURE_BATTERY
    ble_module = None
    if config.BLE:
        try:
            import ble_pico as ble_module
        except ImportError:  # a Pico without radio: USB only
            ble_module = None
    if ble_module is not None:
        features |= P.FEATURE_BLE
    sensor = find_accelerometer()
    if sensor is not None:
        features |= P.FEATURE_ACCEL
    pen = Pen(name=config.NAME, sample_rate=config.SAMPLE_RATE,
              max_pattern_bytes=config.MAX_PATTERN_BYTES, gain_cap=config.GAIN_CAP,
              features=features, battery=battery.millivolts if battery is not None else None,
              sensor=sensor)
    usb = pen.add_link(sys.stdout.buffer.write, "usb")
    ble = None
    if ble_module is not None:
        try:
            ble = ble_module.BlePen(pen, config.NAME, config.MANUFACTURER, config.MODEL, battery)
        except OSError:  # the radio did not come up: USB only, and INFO says so
            pen.features &= ~P.FEATURE_BLE
    player = pen.player
    gc.collect()  # the large allocations are done: the audio starts on a clean heap
    audio = Audio(player)

    stdin = sys.stdin.buffer
    poller = select.poll()
    poller.register(sys.stdin, select.POLLIN)
    inbuf = bytearray(64)
    one = bytearray(1)
    pen.boot()
    if battery is not None:
        pen.event(P.EV_BATTERY, battery.millivolts())
    collected = gc.mem_alloc()
    while True:
        count = 0
        while count < len(inbuf) and poller.poll(0):
            if not stdin.readinto(one):  # the CDC stream gives a byte at a time
                break
            inbuf[count] = one[0]
            count += 1
        if count:
            usb.feed(memoryview(inbuf)[:count])
        if ble is not None:
            ble.poll()
        pen.underruns = audio.underruns
        pen.tick()  # also drains the accelerometer's FIFO when a capture runs
        if not count:
            # Collect the garbage while the pen is silent and nothing came, once enough has
            # piled up: a collection holds the refill back, and one that outlasted a DMA half
            # (2 ms) during a stroke would be a gap in the vibration. The automatic collection
            # (when the heap runs out) stays, for the rare stroke that allocates the heap full.
            if (not player.playing and not player.amp
                    and gc.mem_alloc() - collected >= config.GC_IDLE_BYTES):
                gc.collect()
                collected = gc.mem_alloc()
            poller.poll(1)  # nothing came: sleep up to 1 ms (interrupts still run)


main()
