"""The capture's timing on a virtual clock: the firmware's driver and capture against the
simulated LIS3DH and bus, beside the I2S refills the Pico's audio asks for (MicroPython Unix
port; also CPython).

Run: ``micropython sim_timing.py key=value …``; prints one JSON object. Arguments:
``minutes=10``, ``rate_error=0.013``, ``bus_hz=400000``, ``chunk=5`` (samples per transfer),
``watermark=16``, ``look_every_us=0`` (0: the capture decides when to look at the FIFO; more:
look only this often — a drain held back on purpose), ``encode_us=4000`` (CPU time to frame a
block: COBS and CRC in Python on the RP2040, a guess), ``loop_us=100`` (one main-loop pass),
``refill_us=500`` (the I2S refill callback's own run time, taken from the main loop; a guess),
``play=0`` (1: also render the pattern at every refill with the firmware's player — slower,
and the same timing, since the model charges ``refill_us`` either way). Main-loop passes
between two looks at the FIFO, which touch no bus, are skipped in one step.

The model of the Pico: the I2S DMA asks for a refill every 2 ms (one half of 32 frames at
16 kHz); the refill is a scheduled callback, which runs between bytecodes, so it waits only
while the main loop is inside a blocking C call — here an I2C transfer. A refill that cannot
finish within the half (wait + ``refill_us`` > 2 ms) is an underrun. The main loop passes every
``loop_us`` and sleeps 1 ms (``poller.poll(1)``) when idle. Charged exactly: the bus's bits at
``bus_hz``. Guessed, not measured on a Pico: the CPU times above.
"""

import json
import sys

from rp_capture import Capture
from rp_lis3dh import Lis3dh
from sim_lis3dh import SimI2C, SimLis3dh

HALF_US = 2000  # one DMA half at 16 kHz


class PicoClock:
    """A virtual µs clock that knows when the audio asks for refills and how long each waited.

    ``spend`` (a blocking transfer: refills wait until it ends), ``cpu`` and ``idle`` (Python
    code or sleep: refills run at once)."""

    def __init__(self, refill_us, on_refill=None):
        self.us = 0
        self.refill_us = refill_us
        self.on_refill = on_refill
        self.next_refill = HALF_US
        self.refills = 0
        self.late = 0
        self.longest_wait = 0

    def now(self):
        return self.us

    def _advance(self, us, blocking):
        end = self.us + us
        while self.next_refill <= end:
            wait = end - self.next_refill if blocking else 0
            if wait > self.longest_wait:
                self.longest_wait = wait
            if wait + self.refill_us > HALF_US:
                self.late += 1
            self.refills += 1
            if self.on_refill is not None:
                self.on_refill()
            # The callback runs on the main loop's core: the loop loses its run time.
            end += self.refill_us
            self.next_refill += HALF_US
        self.us = end

    def spend(self, us):
        self._advance(us, True)

    def cpu(self, us):
        self._advance(us, False)

    def idle(self, us):
        self._advance(us, False)


def options_from(argv):
    options = {"minutes": "10", "rate_error": "0.013", "bus_hz": "400000", "chunk": "5",
               "watermark": "16", "look_every_us": "0", "encode_us": "4000", "loop_us": "100",
               "refill_us": "500", "play": "0"}
    for word in argv:
        key, _sep, value = word.partition("=")
        if key not in options:
            raise ValueError("unknown argument: " + word)
        options[key] = value
    return options


def run(options):
    player = None
    block = None
    if options["play"] == "1":
        from array import array

        from rp_player import Player

        player = Player(8000, 32768, 32767)
        staging = player.staging()
        for i in range(8000):  # a 1 s pattern of a 175 Hz square-ish tone
            staging[i] = 12000 if (i * 175 // 4000) % 2 else -12000
        player.commit(8000, 1)
        player.set_state(1, 65535, 4096, 5)
        block = array("h", bytes(32))

    def refill():
        player.fill(block)

    clock = PicoClock(int(options["refill_us"]), refill if player is not None else None)
    model = SimLis3dh(clock, float(options["rate_error"]))
    bus = SimI2C(model, clock, int(options["bus_hz"]))
    driver = Lis3dh(bus, chunk=int(options["chunk"]))
    capture = Capture(driver, clock.now, clock.now, int(options["watermark"]))
    code = capture.start(2, 1344)
    if code:
        raise RuntimeError("capture did not start: " + str(code))
    end = int(float(options["minutes"]) * 60000000)
    look_every = int(options["look_every_us"])
    encode_us = int(options["encode_us"])
    loop_us = int(options["loop_us"])
    next_look = 0
    blocks = 0
    largest = 0
    burst_us = 0
    longest_burst = 0
    gaps = 0
    expected = 0
    while clock.now() < end:
        if look_every:
            if clock.now() >= next_look:
                capture._wait_us = 0
                next_look = clock.now() + look_every
            else:
                capture._wait_us = 1 << 40
        before_bus = bus.busy_us
        payload = capture.poll()
        if payload is not None:
            spent = bus.busy_us - before_bus
            burst_us += spent
            if spent > longest_burst:
                longest_burst = spent
            first = payload[0] | payload[1] << 8 | payload[2] << 16 | payload[3] << 24
            count = (len(payload) - 10) // 6
            if first != expected:
                gaps += 1
            expected = first + count
            if count > largest:
                largest = count
            blocks += 1
            clock.cpu(encode_us)
        clock.cpu(loop_us)
        if payload is None:
            # The passes between two looks at the FIFO do nothing on the bus: skip them.
            due = look_every and next_look - clock.now() or capture.due_in_us()
            clock.idle(max(1000, min(due, end - clock.now())))
    true_rate = model.true_rate
    produced = model.produced
    read = capture.index - capture.lost
    capture.drain()
    capture.stop()
    seconds = clock.now() / 1000000
    return {
        "simulated_s": seconds, "true_rate_hz": true_rate, "samples": produced,
        "read": read, "blocks": blocks, "largest_block": largest,
        "overruns": capture.overruns, "lost_estimated": capture.lost, "lost": model.lost,
        "gaps": gaps, "bus_busy_percent": 100.0 * bus.busy_us / clock.now(),
        "mean_burst_us": burst_us / blocks if blocks else 0, "longest_burst_us": longest_burst,
        "longest_transfer_us": bus.longest_us, "refills": clock.refills,
        "late_refills": clock.late, "longest_refill_wait_us": clock.longest_wait,
    }


def main():
    try:
        options = options_from(sys.argv[1:])
    except ValueError as error:
        sys.stderr.write("sim_timing: " + str(error) + "\n")
        sys.exit(2)
    print(json.dumps(run(options)))


if __name__ == "__main__":
    main()
