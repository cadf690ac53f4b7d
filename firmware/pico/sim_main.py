"""The pen firmware under the MicroPython Unix port: a pseudo-terminal for USB, a paced sink.

Run by ``realpen.device.sim.SimPen`` (``realpen device sim``) with a pseudo-terminal's master as
stdin and stdout, so a host on the slave (``/dev/pts/N``) talks to it as to the Pico's USB
port. The same ``rp_pen`` and ``rp_player`` as on the Pico answer the frames; instead of I2S a
sink paced by ``time.ticks_us`` plays the samples: it renders blocks of ``BLOCK_SAMPLES`` while
at most 8 ms are queued ahead of a virtual DAC that consumes ``rate`` samples a second, and
records every sample the DAC plays (silence where the queue ran dry: an underrun) to a raw
int16 file.

Arguments are ``key=value`` words:

- ``record=PATH``: append the played samples to PATH (raw int16, native byte order).
- ``trace=PATH``: append JSON lines to PATH: ``boot``, ``set_state`` (``t_ns`` wall clock in ns
  when its frame was decoded, ``sample`` the first sample it affects, and its fields),
  ``swap`` (``sample``, ``id``), ``underrun`` (``sample``, ``missing``: silent samples played),
  ``stop``. Sample indices count the record file's samples, including earlier runs in it.
- ``rate=8000``, ``max_pattern_bytes=32768``, ``gain_cap=32767``, ``protocol=1``,
  ``name=RealPen``: the pen's settings (defaults from config.py).
- ``nonblocking=1``: stdin is in non-blocking mode (SimPen sets it), so reads take what is there;
  otherwise bytes are read one at a time while poll says there are more.
- ``steady=1``: the simulated pen's clock (its DAC, its sensor, the PONG and SAMPLES times)
  stands still while the host's scheduler holds the process back: a step of more than
  ``STEADY_STEP_US`` between two readings counts as that long (a ``stall`` trace line says how
  much was left out). Without it a stalled process is a stalled pen: its sink runs dry.
- ``sensor=1``: a simulated LIS3DH on a simulated 400 kHz I2C bus (``sim_lis3dh.py``), driven by
  the firmware's own driver (``rp_lis3dh.py``, ``rp_capture.py``); INFO then says
  accelerometer. With it: ``accel=PATH`` what the pen feels while writing, float32 x, y, z in g
  at the sensor's true rate, looped; ``rate_error=0`` the sensor's rate error (true rate =
  1344 × (1 + rate_error)); ``actuator=b0,b1,b2,a1,a2`` the actuator as a biquad at the pen's
  rate, through which what the pen plays reaches the sensor, ``mount_g=1`` its acceleration in
  g at full scale and |H| = 1; ``bus_hz=400000``; ``chunk=5`` samples per I2C transfer;
  ``capture_every_ms=0`` how often the main loop looks at the FIFO (0: every pass; a long one
  drains too slowly and overruns, on purpose).

SIGINT (KeyboardInterrupt) ends it cleanly: the files are closed and a ``stop`` line written.
"""

import json
import os
import select
import sys
import time
from array import array

import config
import rp_pen
import rp_protocol as P
from rp_pen import Pen
from sim_lis3dh import RealClock

QUEUE_MS = 8  # the most audio rendered ahead of the virtual DAC
# With steady=1, the longest step of the pen's clock between two readings: the main loop reads
# it at least every 1.2 ms (it polls the host for at most 1 ms; a bus transfer takes 0.8 ms), so
# a longer step is a stall.
STEADY_STEP_US = 2000
FEED_PIECE = 64  # bytes handed to the pen between two looks at the sink


def parse_args(argv):
    """``key=value`` words → dict of str (ValueError naming a word that is not one)."""
    options = {}
    for word in argv:
        key, sep, value = word.partition("=")
        if not sep or not key:
            raise ValueError("argument not of the form key=value: " + word)
        options[key] = value
    return options


class Trace:
    """JSON lines to a file (flushed per line, so a reader sees them at once), or nothing."""

    def __init__(self, path):
        self.file = open(path, "a") if path else None

    def write(self, record):
        if self.file is not None:
            self.file.write(json.dumps(record) + "\n")
            self.file.flush()

    def close(self):
        if self.file is not None:
            self.file.close()
            self.file = None


def file_samples(path):
    """Samples already in a raw int16 file (0 if it does not exist)."""
    try:
        return os.stat(path)[6] // 2
    except OSError:
        return 0


def make_sender(out, blocking, idle=None):
    """A send(data) for the pen: writes all of ``data`` to ``out``; when the host does not read
    (a non-blocking pty whose buffer is full) it waits up to 200 ms, then drops the rest (the
    host's decoder resynchronises at the next frame) and returns False. ``idle``: a list whose
    first item, when set, is called while it waits (the sink: on the Pico the audio runs from
    its interrupt whatever the USB does)."""
    poller = select.poll()
    poller.register(out, select.POLLOUT)

    def send(data):
        if blocking:
            out.write(data)
            return
        view = memoryview(data)
        done = 0
        waited = 0
        while done < len(data):
            count = out.write(view[done:])
            if count:
                done += count
            elif waited >= 200:
                return False
            else:
                if idle is not None and idle[0] is not None:
                    idle[0]()
                poller.poll(1)
                waited += 1
        return True

    return send


class Sink:
    """The virtual DAC: plays ``rate`` samples a second by the clock; :meth:`pump` renders the
    pen's blocks while at most ``QUEUE_MS`` are queued, records what is played, and counts as
    an underrun (silence played, the player standing still) every time the queue ran dry."""

    def __init__(self, pen, rate, block, record, trace, clock, actuator=None):
        self.pen = pen
        self.clock = clock
        self.actuator = actuator
        self.rate = rate
        self.block = block
        self.ahead = max(rate * QUEUE_MS // 1000, block)
        self.record = record
        self.trace = trace
        self.buf = array("h", bytes(2 * block))
        self.silence = array("h", bytes(2 * block))
        self.start = pen.samples  # the DAC's sample count at elapsed 0
        self.t0 = clock.now()

    def dac_position(self, t_us):
        """The DAC's position (samples, fractional) at clock time ``t_us``."""
        return self.start + (t_us - self.t0) * self.rate / 1000000

    def pump(self):
        """Render what is due; returns ms until the next block is due (for poll)."""
        pen = self.pen
        elapsed_us = self.clock.now() - self.t0
        due = self.start + elapsed_us * self.rate // 1000000  # played by now
        if due > pen.samples:
            missing = due - pen.samples
            self.trace.write({"event": "underrun", "t_ns": time.time_ns(),
                              "sample": pen.samples, "missing": missing})
            if self.record is not None:
                left = missing
                while left > 0:
                    count = min(left, self.block)
                    self.record.write(memoryview(self.silence)[:count])
                    left -= count
            pen.samples += missing
            pen.underrun()
        while pen.samples + self.block <= due + self.ahead:
            first = pen.samples
            pen.fill(self.buf)
            if self.record is not None:
                self.record.write(self.buf)
            if self.actuator is not None:
                self.actuator.play(first, self.buf)
        room = pen.samples - (due + self.ahead - self.block)
        return (room * 1000 + self.rate - 1) // self.rate if room > 0 else 0


def make_sensor(options, clock):
    """The simulated LIS3DH on its bus, its driver and the actuator from ``options``."""
    from array import array

    from rp_lis3dh import Lis3dh
    from sim_lis3dh import SimActuator, SimI2C, SimLis3dh

    source = None
    path = options.get("accel")
    if path:
        size = os.stat(path)[6]
        source = array("f", bytes(size - size % 12))
        with open(path, "rb") as file:
            file.readinto(source)
    actuator = None
    if options.get("actuator"):
        coefficients = [float(word) for word in options["actuator"].split(",")]
        actuator = SimActuator(coefficients, float(options.get("mount_g", "1")))
    model = SimLis3dh(clock, float(options.get("rate_error", "0")), source, actuator)
    bus = SimI2C(model, clock, int(options.get("bus_hz", "400000")))
    driver = Lis3dh(bus, chunk=int(options.get("chunk", "5")))
    return driver, actuator, model


def run(options):
    rate = int(options.get("rate", config.SAMPLE_RATE))
    max_bytes = int(options.get("max_pattern_bytes", config.MAX_PATTERN_BYTES))
    gain_cap = int(options.get("gain_cap", config.GAIN_CAP))
    protocol = int(options.get("protocol", P.PROTOCOL_VERSION))
    name = options.get("name", config.NAME)
    nonblocking = options.get("nonblocking", "0") == "1"
    record_path = options.get("record")
    trace = Trace(options.get("trace"))
    first = file_samples(record_path) if record_path else 0
    record = open(record_path, "ab") if record_path else None

    def on_state(t_ns, sample, playing, gain, rate_q12, fade_ms):
        trace.write({"event": "set_state", "t_ns": t_ns, "sample": sample, "playing": playing,
                     "gain": gain, "rate": rate_q12, "fade_ms": fade_ms})

    def on_swap(sample, pattern_id):
        trace.write({"event": "swap", "t_ns": time.time_ns(), "sample": sample,
                     "id": pattern_id})

    steady = options.get("steady", "0") == "1"
    if steady:
        def on_stall(us):
            trace.write({"event": "stall", "t_ns": time.time_ns(), "us": us})

        clock = RealClock(STEADY_STEP_US)  # stalls are traced from the boot line on
        # The pen's own clock (PONG, SAMPLES, when the FIFO is looked at) is the same clock.
        rp_pen.ticks_us = clock.now
    else:
        clock = RealClock()
    sensor = None
    actuator = None
    features = P.FEATURE_USB | P.FEATURE_RATE
    if options.get("sensor", "0") == "1":
        sensor, actuator, model = make_sensor(options, clock)
        features |= P.FEATURE_ACCEL
    pen = Pen(name=name, sample_rate=rate, max_pattern_bytes=max_bytes, gain_cap=gain_cap,
              features=features, protocol_version=protocol,
              on_state=on_state, on_swap=on_swap, sensor=sensor)
    pen.samples = first
    stdin = sys.stdin.buffer
    pump = [None]  # the sink, once there is one: the sender pumps it while the host lags
    link = pen.add_link(make_sender(sys.stdout.buffer, not nonblocking, pump), "pty")
    inbuf = bytearray(512)
    one = bytearray(1)
    poller = select.poll()
    poller.register(stdin, select.POLLIN)

    trace.write({"event": "boot", "t_ns": time.time_ns(), "sample": first, "rate": rate,
                 "block": config.BLOCK_SAMPLES})
    pen.boot()
    if steady:
        clock.on_stall = on_stall
    sink = Sink(pen, rate, config.BLOCK_SAMPLES, record, trace, clock, actuator)
    pump[0] = sink.pump
    capture_every_us = int(options.get("capture_every_ms", "0")) * 1000
    capture_at = clock.now()
    if sensor is not None:
        model.dac_position = sink.dac_position
        sensor.bus.before = sink.pump  # on the Pico the I2S refill runs between transfers
        trace.write({"event": "sensor", "t_ns": time.time_ns(), "rate": model.rate_error})
    try:
        while True:
            wait_ms = sink.pump()
            # Sleep until one more block fits in the queue, or until the host writes.
            if steady and wait_ms > 1:
                wait_ms = 1  # short steps: a longer one is then surely a stall
            for _obj, flags in poller.poll(wait_ms):
                if flags & (select.POLLHUP | select.POLLERR) and not flags & select.POLLIN:
                    raise EOFError  # the pseudo-terminal is gone: the host side closed
                if nonblocking:
                    count = stdin.readinto(inbuf) or 0
                else:
                    count = 0
                    while count < len(inbuf) and poller.poll(0):
                        if not stdin.readinto(one):
                            break
                        inbuf[count] = one[0]
                        count += 1
                # A piece at a time, the sink between: on the Pico the I2S interrupt would
                # break in, here a long upload must not starve the sink.
                for at in range(0, count, FEED_PIECE):
                    link.feed(memoryview(inbuf)[at:min(at + FEED_PIECE, count)])
                    sink.pump()
            if capture_every_us and pen.capture is not None and pen.capture.active:
                # A drain held back on purpose: only every capture_every_ms.
                now = clock.now()
                if now - capture_at >= capture_every_us:
                    capture_at = now
                    pen.capture._wait_us = 0
                else:
                    pen.capture._wait_us = 1 << 29
            pen.tick()
    except (KeyboardInterrupt, EOFError):
        pass
    finally:
        if record is not None:
            record.close()
        trace.write({"event": "stop", "t_ns": time.time_ns(), "sample": pen.samples})
        trace.close()


def main():
    try:
        options = parse_args(sys.argv[1:])
    except ValueError as exc:
        sys.stderr.write("sim_main: " + str(exc) + "\n")
        sys.exit(2)
    run(options)


main()
