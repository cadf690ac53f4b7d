"""The pen firmware on a Raspberry Pi Pico W / Pico 2 W: USB CDC and BLE in, I2S out.

A thin layer over ``rp_pen`` (protocol) and ``rp_player`` (the loop): it wires the player to a
MAX98357A I2S amplifier through ``machine.I2S`` (interrupt-driven, non-blocking writes of
``config.BLOCK_SAMPLES``), the USB serial port (``sys.stdin`` / ``sys.stdout``) and the BLE
service (``ble_pico``) to the pen, and reads the battery. Settings are in ``config.py``.

The USB port is the one MicroPython's REPL uses: the firmware switches Ctrl-C off so that a
0x03 in a frame is data. To reach the REPL (to update the files with mpremote), press and hold
BOOTSEL during the first 1.5 s after a reset (``config.STARTUP_WINDOW_MS``): the firmware then does not start.
"""

import select
import sys
import time
from array import array

import config
import micropython
import rp2
import rp_protocol as P
from machine import ADC, I2S, Pin
from rp_pen import Pen


class Audio:
    """The player's samples to the I2S amplifier, refilled from the I2S interrupt.

    The mono block is sent as 16-bit stereo (the same sample on both channels, so the
    MAX98357A plays it whichever channel its SD_MODE selects): the rp2 driver moves 128-byte
    halves of its DMA buffer, 4 ms of stereo at 8 kHz, through a ring of ``config.I2S_IBUF``
    bytes. A refill more than two blocks after the last counts as an underrun: the driver then
    found no block to move and played silence, and says nothing of it itself.
    """

    def __init__(self, player):
        count = config.BLOCK_SAMPLES
        self.player = player
        self.mono = array("h", bytes(2 * count))
        self.stereo = array("h", bytes(4 * count))
        self.late_us = 2 * count * 1000000 // config.SAMPLE_RATE
        self.underruns = 0
        self.last = time.ticks_us()
        self.i2s = I2S(config.I2S_ID, sck=Pin(config.I2S_SCK_PIN), ws=Pin(config.I2S_WS_PIN),
                       sd=Pin(config.I2S_SD_PIN), mode=I2S.TX, bits=16, format=I2S.STEREO,
                       rate=config.SAMPLE_RATE, ibuf=config.I2S_IBUF)
        self._refill_cb = self.refill  # one bound method for the interrupt, made once
        self.i2s.irq(self._refill_cb)  # with a callback, write() no longer blocks
        self.refill(self.i2s)

    def refill(self, _i2s):
        """Render the next block and queue it (allocates nothing)."""
        now = time.ticks_us()
        if time.ticks_diff(now, self.last) > self.late_us:
            self.underruns += 1
        self.last = now
        mono = self.mono
        stereo = self.stereo
        self.player.fill(mono)
        for i in range(len(mono)):
            value = mono[i]
            stereo[2 * i] = value
            stereo[2 * i + 1] = value
        self.i2s.write(stereo)


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


def startup_escape():
    """True when BOOTSEL is held during the startup window: leave the REPL to mpremote."""
    start = time.ticks_ms()
    while time.ticks_diff(time.ticks_ms(), start) < config.STARTUP_WINDOW_MS:
        if rp2.bootsel_button():
            return True
        time.sleep_ms(10)
    return False


def main():
    if startup_escape():
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
    pen = Pen(name=config.NAME, sample_rate=config.SAMPLE_RATE,
              max_pattern_bytes=config.MAX_PATTERN_BYTES, gain_cap=config.GAIN_CAP,
              features=features, battery=battery.millivolts if battery is not None else None)
    usb = pen.add_link(sys.stdout.buffer.write, "usb")
    ble = None
    if ble_module is not None:
        try:
            ble = ble_module.BlePen(pen, config.NAME, config.MANUFACTURER, config.MODEL, battery)
        except OSError:  # the radio did not come up: USB only, and INFO says so
            pen.features &= ~P.FEATURE_BLE
    audio = Audio(pen.player)

    micropython.kbd_intr(-1)  # 0x03 is data from now on
    stdin = sys.stdin.buffer
    poller = select.poll()
    poller.register(sys.stdin, select.POLLIN)
    inbuf = bytearray(64)
    one = bytearray(1)
    pen.boot()
    if battery is not None:
        pen.event(P.EV_BATTERY, battery.millivolts())
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
        pen.tick()
        if not count:
            poller.poll(1)  # nothing came: sleep up to 1 ms (interrupts still run)


main()
