"""The page's own pen links in a real browser: the JS codec, Web Serial and Web Bluetooth.

Debian's Chromium driven by Playwright (as in test_live_browser.py), against the live app served
by uvicorn in this process:

- the JS codec (static/pen-protocol.js) against tests/data/protocol_vectors.json and against
  protocol.py on random frames;
- Web Serial: ``navigator.serial`` is replaced (before the page's scripts run) by a fake whose
  port streams are bridged with ``page.expose_function`` to a SimPen's pseudo-terminal, so the
  page talks to the real firmware under the MicroPython Unix port; the firmware's trace shows
  the page's SET_STATE and the uploaded pattern's swap;
- Web Bluetooth under Chromium's own emulation (CDP ``BluetoothEmulation``, which needs
  ``--enable-experimental-web-platform-features``): an emulated peripheral with the pen's GATT
  service whose characteristic operations are answered by the pen core (firmware/pico rp_pen
  and rp_player imported under CPython), and the device chooser answered through CDP
  ``DeviceAccess``.

What Chromium's emulation cannot do: CDP ``BluetoothEmulation`` (Chromium 156) has no command
that makes the emulated peripheral send a notification; an unsolicited
``simulateCharacteristicOperationResponse`` is accepted and dropped. The pen's replies reach the
page the only other way the emulation offers: the test asks the page to read TX
(``readValue()``), whose value the emulation answers with the pen core's output, and Chromium
fires the same ``characteristicvaluechanged`` event a notification fires (Web Bluetooth spec,
readValue), so the page's notification handler, decoder and upload run as with a real pen. TX
carries the read property in the emulation for that only; the firmware's TX is notify-only.
"""

from __future__ import annotations

import base64
import functools
import json
import os
import random
import sys
import time
import zlib
from array import array
from pathlib import Path

import pytest
from live_support import CHROMIUM, CHROMIUM_ARGS, CHROMIUM_MISSING

from realpen.device import protocol as P
from realpen.device.sim import read_trace as trace_events

ROOT = Path(__file__).resolve().parents[1]
ARTIFACTS = ROOT / "test-artifacts"
VECTORS = json.loads((ROOT / "tests" / "data" / "protocol_vectors.json").read_text())
BLE_ARGS = [*CHROMIUM_ARGS, "--enable-experimental-web-platform-features"]
CCCD = "00002902-0000-1000-8000-00805f9b34fb"  # Client Characteristic Configuration

if not CHROMIUM.exists():
    pytest.skip(CHROMIUM_MISSING, allow_module_level=True)
sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed")


class Server:
    """The live app in this process, uvicorn on a thread. It starts in the background (most of
    it is importing the app) while the browser launches; ``base`` waits for it. ``device``: the
    server's own pen (:func:`realpen.live.device.open_device`), closed when the app stops."""

    def __init__(self, folder: Path, device=None):
        import socket
        import threading

        self.folder = folder
        self.device = device
        self.socket = socket.socket()
        self.socket.bind(("127.0.0.1", 0))
        self.server = None
        self.problem: BaseException | None = None
        self.thread = threading.Thread(target=self.run, daemon=True)
        self.thread.start()

    def run(self):
        try:
            import uvicorn

            from realpen.live.app import LiveSettings, create_app

            app = create_app(LiveSettings.loopback(store=self.folder / "strokes.sqlite3",
                                                   device=self.device))
            self.server = uvicorn.Server(uvicorn.Config(app, log_level="warning"))
            self.server.run(sockets=[self.socket])
        except BaseException as error:  # reported by ``base``
            self.problem = error

    @property
    def base(self) -> str:
        deadline = time.monotonic() + 30
        while self.server is None or not self.server.started:
            if self.problem or not self.thread.is_alive() or time.monotonic() > deadline:
                raise RuntimeError(f"the live app did not start: {self.problem!r}")
            time.sleep(0.01)
        return f"http://127.0.0.1:{self.socket.getsockname()[1]}/"

    url = base

    def stop(self):
        if self.server is not None:
            self.server.should_exit = True
        self.thread.join(timeout=10)
        self.socket.close()


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    folder = tmp_path_factory.mktemp("web")
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("REALPEN_HOME", str(folder / "home"))  # no user profiles of this machine
        served = Server(folder)
        try:
            yield served
        finally:
            served.stop()


@pytest.fixture
def browser(chromium):
    return chromium(BLE_ARGS)


def open_page(browser, server, init_script: str | None = None):
    context = browser.new_context(viewport={"width": 1180, "height": 820})
    context.set_default_timeout(10_000)
    if init_script:
        context.add_init_script(init_script)
    page = context.new_page()
    problems: list[str] = []
    page.on("pageerror", lambda error: problems.append(str(error)))
    page.goto(server.url)
    page.wait_for_function("() => window.realpen && window.realpen.ready")
    return context, page, problems


# ---- the codec ------------------------------------------------------------------------------

CHECK_VECTORS = """async ([vectors, randoms, crc32s, captureTables]) => {
  const P = await import('/static/pen-protocol.js');
  const fails = [];
  const hex = P.toHex;
  const same = (what, got, want) => {
    const [g, w] = [JSON.stringify(got), JSON.stringify(want)];
    if (g !== w) fails.push(`${what}: ${g} != ${w}`);
  };
  const throws = (what, fn) => {
    try { fn(); fails.push(`${what}: no error`); } catch (e) {
      if (!(e instanceof P.ProtocolError)) fails.push(`${what}: ${e}`);
    }
  };
  for (const c of vectors.crc16) same(`crc16 ${c.data.slice(0, 20)}`, P.crc16(P.fromHex(c.data)), c.crc16);
  for (const c of vectors.cobs) {
    same(`cobs encode ${c.raw.slice(0, 20)}`, hex(P.cobsEncode(P.fromHex(c.raw))), c.encoded);
    same(`cobs decode ${c.encoded.slice(0, 20)}`, hex(P.cobsDecode(P.fromHex(c.encoded))), c.raw);
  }
  throws('cobs zero inside', () => P.cobsDecode(P.fromHex('030100')));
  throws('cobs past the end', () => P.cobsDecode(P.fromHex('05112233')));
  const whole = [];
  for (const f of vectors.frames) {
    const [pack, unpack] = P.MESSAGES[f.pack];
    // The last argument of these is bytes, written as hex in the vectors.
    const bytesArg = ['pack_pattern_chunk', 'pack_samples'].includes(f.pack);
    const args = bytesArg ? [...f.args.slice(0, -1), P.fromHex(f.args.at(-1))] : f.args;
    const payload = pack(...args);
    same(`${f.name} payload`, hex(payload), f.payload_hex);
    const frame = P.encodeFrame(f.type, f.seq, payload);
    same(`${f.name} frame`, hex(frame), f.frame_hex);
    whole.push(frame);
    let got = unpack(P.fromHex(f.payload_hex));
    if (bytesArg) got = [...got.slice(0, -1), hex(got.at(-1))];
    // protocol.py's None (CAPTURE_STOP) is null here: a message of no fields.
    same(`${f.name} unpack`, Array.isArray(got) ? got : got === null ? [] : [got], f.args);
    const decoder = new P.FrameDecoder();
    const frames = [];
    for (const byte of P.fromHex(f.frame_hex)) frames.push(...decoder.feed([byte]));
    same(`${f.name} decoded byte by byte`, frames.map(([t, s, p]) => [t, s, hex(p)]),
      [[f.type, f.seq, f.payload_hex]]);
    if (payload.length) throws(`${f.name} unpack of nothing`, () => unpack(new Uint8Array(0)));
    throws(`${f.name} unpack of 40 bytes more`, () => unpack(new Uint8Array(payload.length + 40)));
  }
  throws('a name longer than 32 bytes', () => P.packInfo(1, 1, 0, 0, 8000, 1, 0, 'x'.repeat(33)));
  throws('a chunk longer than MAX_CHUNK', () => P.packPatternChunk(0, new Uint8Array(P.MAX_CHUNK + 1)));
  throws('SAMPLES of no sample', () => P.packSamples(0, 0, 2, 0, new Uint8Array(0)));
  throws('SAMPLES of 33', () => P.packSamples(0, 0, 2, 0, new Uint8Array(6 * 33)));
  throws('SAMPLES of a part sample', () => P.unpackSamples(new Uint8Array(10 + 7)));
  same('capture ranges and rates', [P.CAPTURE_RANGES, P.CAPTURE_RATES], captureTables);
  for (const s of vectors.streams) {
    same(`stream "${s.why}"`, new P.FrameDecoder().feed(P.fromHex(s.stream_hex)).length, s.frames);
  }
  // All the frames in one stream cut at random places: every frame, in order.
  const stream = P.fromHex(whole.map(hex).join(''));
  const decoder = new P.FrameDecoder();
  const out = [];
  for (let at = 0; at < stream.length;) {
    const n = 1 + Math.floor(Math.random() * 40);
    out.push(...decoder.feed(stream.subarray(at, at + n)));
    at += n;
  }
  same('random cuts', out.map(([t, s]) => [t, s]), vectors.frames.map((f) => [f.type, f.seq]));
  same('random cuts: no errors', decoder.errors, 0);
  const encoded = randoms.map(([t, s, p]) => hex(P.encodeFrame(t, s, P.fromHex(p))));
  const crcs = crc32s.map(([data]) => P.crc32(P.fromHex(data)));
  same('crc32 of 123456789', P.crc32(new TextEncoder().encode('123456789')), 0xCBF43926);
  same('PROTOCOL_VERSION', P.PROTOCOL_VERSION, vectors.protocol_version);
  return { fails, encoded, crcs };
}"""


def test_codec_passes_the_vectors_in_the_browser(browser, server):
    """pen-protocol.js: every vector (CRC-16, COBS, frames, pack/unpack, streams, the capture
    messages among them), random frames encoded as protocol.py encodes them, CRC-32 as zlib
    computes it, and the capture ranges and rates as protocol.py lists them."""
    rng = random.Random(12)
    randoms = [(rng.randrange(256), rng.randrange(256),
                rng.randbytes(rng.choice([0, 1, 2, 250, 251, 252, rng.randrange(253)])).hex())
               for _ in range(300)]
    crc32s = [(rng.randbytes(n).hex(),) for n in (0, 1, 7, 1000, 24000)]
    context = browser.new_context()
    page = context.new_page()
    try:
        page.goto(f"{server.base}static/pen-protocol.js")  # any page of the origin will do
        captures = [list(P.CAPTURE_RANGES), list(P.CAPTURE_RATES)]
        result = page.evaluate(CHECK_VECTORS, [VECTORS, randoms, crc32s, captures])
    finally:
        context.close()
    assert result["fails"] == []
    assert result["encoded"] == [P.encode_frame(t, s, bytes.fromhex(p)).hex()
                                 for t, s, p in randoms]
    assert result["crcs"] == [zlib.crc32(bytes.fromhex(data)) for (data,) in crc32s]


# ---- Web Serial: a fake navigator.serial bridged to the real firmware -------------------------

# Replaces navigator.serial before the page's scripts run. The one port's streams call the
# functions the test exposes: __penOpen(baud) → bool, __penRead() → base64 of the bytes waiting
# ('' when none, null when the port is gone), __penWrite(base64), __penClose().
# window.__penGlitch() is a recoverable read error (a buffer overrun): the port's readable
# stream errors and, as Web Serial's does, the port hands out a new one; bytes already read go
# to the new stream.
FAKE_SERIAL = """(() => {
  const fromB64 = (text) => Uint8Array.from(atob(text), (c) => c.charCodeAt(0));
  const toB64 = (bytes) => btoa(Array.from(bytes, (b) => String.fromCharCode(b)).join(''));
  class FakePort extends EventTarget {
    constructor() { super(); this.readable = null; this.writable = null; }
    getInfo() { return { usbVendorId: 0x2e8a, usbProductId: 0x0005 }; }
    async open(options) {
      if (!(await window.__penOpen(options.baudRate))) {
        throw new DOMException('Failed to open serial port.', 'NetworkError');
      }
      const port = this;
      const carry = [];
      let source = null;
      const readable = () => {
        const mine = {
          live: true,
          start(controller) { mine.controller = controller; },
          async pull(controller) {
            if (carry.length) { controller.enqueue(carry.shift()); return; }
            while (mine.live) {
              const data = await window.__penRead();
              if (data === null) {
                if (!mine.live) return;
                port.readable = null;
                controller.error(new DOMException('The device has been lost.', 'NetworkError'));
                return;
              }
              if (data.length) {
                if (mine.live) controller.enqueue(fromB64(data)); else carry.push(fromB64(data));
                return;
              }
              await new Promise((resolve) => setTimeout(resolve, 3));
            }
          },
          cancel() { mine.live = false; },
        };
        source = mine;
        return new ReadableStream(mine);
      };
      this.readable = readable();
      window.__penGlitch = () => {
        const old = source;
        old.live = false;
        port.readable = readable();
        old.controller.error(new DOMException('Buffer overrun', 'BufferOverrunError'));
      };
      // A write resolves once queued, as a real port's does; the queue goes to the pty in
      // one call per task (one bridge call per chunk would make the upload crawl).
      let queued = [];
      const flush = () => {
        const bytes = queued.flatMap((chunk) => Array.from(chunk));
        queued = [];
        return window.__penWrite(toB64(bytes));
      };
      let flushing = Promise.resolve();
      this.writable = new WritableStream({
        write(chunk) {
          const task = () => new Promise((resolve) => setTimeout(resolve, 0));
          if (!queued.length) flushing = flushing.then(task).then(flush);
          queued.push(chunk);
        },
        close() { return flushing; },
      });
    }
    async close() {
      this.readable = null;
      this.writable = null;
      await window.__penClose();
    }
  }
  const port = new FakePort();
  const serial = new EventTarget();
  serial.requestPort = async () => port;
  serial.getPorts = async () => [port];
  Object.defineProperty(Navigator.prototype, 'serial', { get: () => serial, configurable: true });
})();"""


class SerialBridge:
    """The fake port's other end: the SimPen's pseudo-terminal through pyserial.

    ``frozen``: a hung pen (nothing read, nothing written) until the page closes the port.
    ``opened``: where in ``written`` each opening of the port began."""

    def __init__(self):
        self.sim = None
        self.port = None
        self.baud = None
        self.frozen = False
        self.early = b""  # what the pen said before the port's far end was opened again
        self.written = bytearray()
        self.opened: list[int] = []

    def expose(self, page):
        page.expose_function("__penOpen", self.open)
        page.expose_function("__penRead", self.read)
        page.expose_function("__penWrite", self.write)
        page.expose_function("__penClose", self.close)

    def open(self, baud):
        serial = pytest.importorskip("serial")
        self.baud = baud
        self.port = serial.Serial(self.sim.port, baud, timeout=0)
        self.opened.append(len(self.written))
        return True

    def reopen(self):
        """The pen restarted behind a port that stayed (a USB-serial adapter): the port's far
        end follows the SimPen to its new pseudo-terminal; the page sees no change. What the
        pen said at boot (its boot EVENT) is read first: pyserial's open flushes the input."""
        import select

        self.port.close()
        fd = os.open(self.sim.port, os.O_RDONLY | os.O_NOCTTY | os.O_NONBLOCK)
        try:
            if select.select([fd], [], [], 2.0)[0]:
                self.early = os.read(fd, 4096)
        finally:
            os.close(fd)
        self.port = pytest.importorskip("serial").Serial(self.sim.port, self.baud, timeout=0)

    def read(self):
        if self.port is None:
            return None
        if self.frozen:
            return ""
        try:
            data, self.early = self.early + self.port.read(4096), b""
        except OSError:  # SerialException too: the firmware is gone and the pty with it
            return None
        return base64.b64encode(data).decode()

    def write(self, text):
        if self.frozen:
            return
        data = base64.b64decode(text)
        self.written += data
        try:
            if self.port:
                self.port.write(data)
        except OSError:  # the firmware is gone: the read side tells the page
            pass

    def close(self):
        self.frozen = False  # letting go of a hung pen's port resets it (a watchdog would)
        if self.port:
            self.port.close()
            self.port = None


def pen_stroke(page, n=12, x0=300.0, y0=300.0, pressure=0.6):
    """A pen stroke on the writing surface through CDP (trusted pen events)."""
    cdp = page.context.new_cdp_session(page)
    box = page.locator("#ink").bounding_box()
    t0 = time.time()

    def event(kind, i, force):
        cdp.send("Input.dispatchMouseEvent", {
            "type": kind, "x": box["x"] + x0 + 6 * i, "y": box["y"] + y0, "button": "left",
            "buttons": 0 if kind == "mouseReleased" else 1, "clickCount": 1,
            "pointerType": "pen", "force": force, "timestamp": t0 + 0.008 * i})

    event("mousePressed", 0, pressure)
    for i in range(1, n):
        event("mouseMoved", i, pressure)
        page.wait_for_timeout(8)
    event("mouseReleased", n, 0.0)
    cdp.detach()


def until(page, check, timeout=8.0):
    """Wait until ``check()``; the page (and the bridge's calls) run while Playwright waits."""
    deadline = time.monotonic() + timeout
    while not check():
        assert time.monotonic() < deadline, f"timed out: {page.evaluate('window.realpen.penDevice')}"
        page.wait_for_timeout(10)


def longest_chunk_run(frames) -> int:
    """The most PATTERN_CHUNKs in a row: how far an upload ran ahead of the pen's PONG."""
    longest = run = 0
    for ftype, _, _ in frames:
        run = run + 1 if ftype == P.PATTERN_CHUNK else 0
        longest = max(longest, run)
    return longest




@pytest.mark.firmware
def test_web_serial_drives_the_firmware(browser, server, tmp_path):
    """Connect USB → HELLO/INFO, the pen's pattern uploaded at the pen's rate (a PING answered
    every 16 chunks) and swapped in at the firmware; a pen stroke → SET_STATE playing=1 with the
    Eq. 1 gain, then playing=0; a refused pattern request → the server's reason; a recoverable
    read error → the link reads on; the pen restarts behind the port (its boot EVENT) → pattern
    uploaded again; a hung pen (PINGs unanswered) → port closed and opened again, HELLO first;
    another pen picked → its pattern uploaded and swapped in; the firmware stops → the panel
    says so and the page writes and sounds on; an old firmware → one clear line."""
    from realpen.device.sim import SimPen

    httpx = pytest.importorskip("httpx")
    bridge = SerialBridge()
    context, page, problems = open_page(browser, server, FAKE_SERIAL)
    try:
        bridge.expose(page)
        pen = page.evaluate("window.realpen.pen")
        expected = httpx.get(f"{server.base}api/pens/{pen}/pen-pattern",
                             params={"rate": 8000}).content
        trace = tmp_path / "trace.jsonl"
        with SimPen(trace=trace) as sim:
            bridge.sim = sim
            page.click("#pen-device")
            assert page.is_visible("#pen-usb") and page.is_visible("#pen-ble")
            page.click("#pen-usb")
            page.wait_for_function("(pen) => window.realpen.penDevice.pattern === pen", arg=pen)
            status = page.evaluate("window.realpen.penDevice")
            assert status["info"]["sampleRate"] == 8000 and status["kind"] == "usb"
            page.wait_for_function(f"() => document.getElementById('pen-status').textContent"
                                   f" === {json.dumps(status['message'])}")
            assert status["message"].startswith("RealPen on USB 2e8a:0005 (firmware ")
            assert status["message"].endswith(f": {pen} pattern loaded (1.50 s).")
            assert page.is_hidden("#pen-usb") and page.is_visible("#pen-disconnect")
            assert page.text_content("#pen-panel-title") == "Pen: RealPen (this page, USB)"
            ARTIFACTS.mkdir(exist_ok=True)
            page.screenshot(path=str(ARTIFACTS / "pen-panel-usb.png"))
            pen_stroke(page)

            def lifted():  # the firmware has applied a playing state, then the pen-up state
                states = [e for e in trace_events(trace) if e["event"] == "set_state"]
                return any(e["playing"] for e in states) and not states[-1]["playing"]

            until(page, lifted)
            # A pattern the server refuses (a rate out of range, 422): its one-line reason.
            detail = httpx.get(f"{server.base}api/pens/{pen}/pen-pattern",
                               params={"rate": 5}).json()["detail"]
            assert page.evaluate("""async (pen) => {
              try { await window.realpen.penLink.fetchPattern(pen, 5); } catch (e) {
                return e.message; }
            }""", pen) == detail
            # A recoverable read error (a buffer overrun) ends one read stream, not the link.
            page.evaluate("window.__penGlitch()")
            assert page.evaluate("async () => (await window.realpen.penLink.ping()).deviceUs") >= 0
            assert page.evaluate("window.realpen.penDevice.state") == "connected"

            def swaps():
                return [e["id"] for e in trace_events(trace) if e["event"] == "swap"]

            # The pen restarts behind a port that stays: its boot EVENT → the page uploads again.
            sim.restart()
            bridge.reopen()
            until(page, lambda: len(swaps()) == 2)
            page.wait_for_function("(pen) => window.realpen.penDevice.pattern === pen", arg=pen)
            # A hung pen: two PINGs unanswered → the port is closed and opened again (as a pen
            # reset by a watchdog would need); HELLO goes first, then the pattern again.
            beat = "(ms) => { const link = window.realpen.penLink; link.heartbeatMs = ms; " \
                   "link.scheduleBeat(); }"
            page.evaluate(beat, 100)
            bridge.frozen = True
            lost = page.wait_for_function("""() => {
              const s = window.realpen.penDevice; return s.state === 'disconnected' && s; }""")
            page.evaluate(beat, 2000)
            lost = lost.json_value()
            assert "no answer to 2 PINGs in a row" in lost["message"]
            assert "reconnecting" in lost["message"] and lost["info"] is None
            page.wait_for_function("(pen) => window.realpen.penDevice.state === 'connected'"
                                   " && window.realpen.penDevice.pattern === pen", arg=pen)
            again = P.FrameDecoder().feed(bytes(bridge.written[bridge.opened[-1]:]))
            assert len(bridge.opened) == 2 and again[0][0] == P.HELLO
            until(page, lambda: len(swaps()) == 3)
            # Another pen picked on the page: its pattern goes to the pen, which swaps it in.
            other = next(p for p in ("ballpoint", "marker", "pencil") if p != pen)
            page.click(f'#pens [data-value="{other}"]')
            page.wait_for_function("(pen) => window.realpen.penDevice.pattern === pen", arg=other)
            until(page, lambda: len(swaps()) == 4)
            events = trace_events(trace)
        # The firmware's own record: what the page sent, the pattern it committed.
        states = [e for e in events if e["event"] == "set_state"]
        playing = [e for e in states if e["playing"] == 1]
        assert playing and all(e["rate"] == P.RATE_ONE for e in states)
        assert any(e["gain"] > 0 for e in playing)
        assert states[-1]["playing"] == 0
        second = httpx.get(f"{server.base}api/pens/{other}/pen-pattern", params={"rate": 8000})
        first_id = zlib.crc32(expected) & 0xFFFF
        assert [e["id"] for e in events if e["event"] == "swap"] == [
            first_id, first_id, first_id, zlib.crc32(second.content) & 0xFFFF]
        assert sum(e["event"] == "boot" for e in events) == 2
        frames = P.FrameDecoder().feed(bytes(bridge.written))
        chunks = b"".join(P.unpack_pattern_chunk(p)[1] for t, _, p in frames
                          if t == P.PATTERN_CHUNK)
        assert chunks == expected * 3 + second.content  # first, after the boot, after the hang
        assert longest_chunk_run(frames) == 16  # then a PING, answered before the next chunk
        begin = next(P.unpack_pattern_begin(p) for t, _, p in frames if t == P.PATTERN_BEGIN)
        assert begin[1:] == (len(expected) // 2, 8000, P.FORMAT_S16LE, zlib.crc32(expected))
        # The firmware is gone (SimPen stopped): the panel says so, the page writes and sounds on.
        page.wait_for_function("() => document.getElementById('pen-status').textContent"
                               ".startsWith('Pen disconnected')")
        assert page.evaluate("window.realpen.penDevice.info") is None
        assert page.evaluate("window.realpen.penDevice.state") == "disconnected"
        assert page.evaluate("() => window.realpen.audio.state") == "running"
        strokes = page.evaluate("window.realpen.strokes")
        pen_stroke(page)
        page.wait_for_function("(n) => window.realpen.strokes === n + 1 && !window.realpen.down",
                               arg=strokes)
        assert max(e["target"] for e in page.evaluate("window.realpen.trace")[-10:]) > 0
        # An old pen: HELLO refused with E_VERSION.
        with SimPen(protocol_version=2) as sim:
            bridge.sim = sim
            page.click("#pen-usb")
            page.wait_for_function("() => window.realpen.penDevice.state === 'error'")
            assert "does not speak protocol 1" in page.text_content("#pen-status")
        assert problems == []
    finally:
        bridge.close()
        context.close()


# ---- Web Bluetooth: Chromium's emulated peripheral answered by the pen core -----------------

BATTERY_SERVICE = "0000180f-0000-1000-8000-00805f9b34fb"
BATTERY_LEVEL = "00002a19-0000-1000-8000-00805f9b34fb"
NO_SERIAL = "delete Navigator.prototype.serial;"  # a browser with Web Bluetooth only
# Deliver what the pen core has sent: the page's link reads TX (see the module docstring).
READ_TX = """() => {
  const t = window.realpen.penLink.transport;
  if (t && t.tx) t.tx.readValue().catch(() => {});
}"""
# RX writes fail once as a busy GATT queue makes them, then go through; and a PING whose seq a
# stale request (an unanswered SET_STATE, 256 frames before) still holds. Each sets a result.
WRITE_FAILS_ONCE = """() => {
  const t = window.realpen.penLink.transport;
  const write = t.rx.writeValueWithoutResponse.bind(t.rx);
  let failed = false;
  t.rx.writeValueWithoutResponse = (piece) => {
    if (failed) return write(piece);
    failed = true;
    return Promise.reject(new DOMException('GATT operation already in progress.', 'NetworkError'));
  };
  window.__result = null;
  window.realpen.penLink.ping().then(() => { window.__result = 'pong'; },
    (e) => { window.__result = e.message; });
}"""
# The pen goes down while a SET_STATE write of this connection never settles.
STATE_WRITE_HANGS = """() => {
  const link = window.realpen.penLink;
  const t = link.transport;
  const write = t.write.bind(t);
  t.write = (bytes) => (bytes[1] === 0x20 ? new Promise(() => {}) : write(bytes));
  link.setState(true, 0.5, 5);
}"""
SEQ_WRAPS = """async () => {
  const P = await import('/static/pen-protocol.js');
  const link = window.realpen.penLink;
  const seq = link.seq;
  link.request(P.SET_STATE, P.packSetState(0, 0, P.RATE_ONE, 5), 30).catch(() => {});
  link.seq = seq;
  window.__result = null;
  link.ping().then(() => { window.__result = 'pong'; }, (e) => { window.__result = e.message; });
}"""


class EmulatedPen:
    """A peripheral in Chromium's Bluetooth emulation with the pen's GATT service (RX, TX +
    its CCCD, INFO) and the Battery service; its operations go to the pen core (rp_pen under
    CPython), which records the states it applies and the patterns it swaps in."""

    ADDRESS = "52:50:00:00:00:01"

    def __init__(self, browser, page):
        sys.path.insert(0, str(ROOT / "firmware" / "pico"))
        try:
            import rp_pen
        finally:
            sys.path.remove(str(ROOT / "firmware" / "pico"))
        self.page = page
        self.states: list[tuple] = []
        self.swaps: list[int] = []
        self.pen = rp_pen.Pen(
            name="RealPen", sample_rate=8000, features=P.FEATURE_BLE | P.FEATURE_RATE,
            on_state=lambda t_ns, sample, *state: self.states.append(state),
            on_swap=lambda sample, pattern_id: self.swaps.append(pattern_id))
        self.out = bytearray()
        self.link = self.pen.add_link(self.out.extend, "ble")
        self.block = array("h", bytes(64))
        self.received = bytearray()
        self.writes: list[int] = []  # bytes of each RX write
        self.lose_chunk = None  # the offset of a PATTERN_CHUNK to lose on the way, once
        self.reading = False
        self.connected = False
        self.queue: list[tuple[str, dict]] = []
        self.bt = browser.new_browser_cdp_session()  # BluetoothEmulation is a browser domain
        self.cdp = page.context.new_cdp_session(page)
        for name in ("gattOperationReceived", "characteristicOperationReceived",
                     "descriptorOperationReceived"):
            self.bt.on(f"BluetoothEmulation.{name}",
                       functools.partial(lambda n, e: self.queue.append((n, e)), name))
        self.cdp.on("DeviceAccess.deviceRequestPrompted",
                    lambda e: self.queue.append(("prompt", e)))
        self.cdp.send("DeviceAccess.enable")
        self.bt.send("BluetoothEmulation.enable", {"state": "powered-on", "leSupported": True})
        self.bt.send("BluetoothEmulation.simulatePreconnectedPeripheral", {
            "address": self.ADDRESS, "name": "RealPen", "manufacturerData": [],
            "knownServiceUuids": [P.BLE_SERVICE]})
        self.build_gatt()

    def build_gatt(self):
        """The pen's GATT database (again after a disconnection: Chromium forgets a device's
        services when its GATT connection drops, as it must rediscover them from a real one)."""
        service = self.add_service(P.BLE_SERVICE)
        self.rx = self.add_characteristic(service, P.BLE_RX, writeWithoutResponse=True)
        self.tx = self.add_characteristic(service, P.BLE_TX, notify=True, read=True)
        self.bt.send("BluetoothEmulation.addDescriptor",
                     {"characteristicId": self.tx, "descriptorUuid": CCCD})
        self.info = self.add_characteristic(service, P.BLE_INFO, read=True)
        self.battery = self.add_characteristic(self.add_service(BATTERY_SERVICE), BATTERY_LEVEL,
                                               read=True, notify=True)

    def add_service(self, uuid):
        return self.bt.send("BluetoothEmulation.addService",
                            {"address": self.ADDRESS, "serviceUuid": uuid})["serviceId"]

    def add_characteristic(self, service, uuid, **properties):
        return self.bt.send("BluetoothEmulation.addCharacteristic", {
            "serviceId": service, "characteristicUuid": uuid,
            "properties": properties})["characteristicId"]

    def respond(self, characteristic, kind, data: bytes | None = None):
        args = {"characteristicId": characteristic, "type": kind, "code": 0}
        if data is not None:
            args["data"] = base64.b64encode(data).decode()
        self.bt.send("BluetoothEmulation.simulateCharacteristicOperationResponse", args)

    def handle(self, name, event):
        if name == "prompt":  # the device chooser: pick the pen (it may be announced twice)
            try:
                self.cdp.send("DeviceAccess.selectPrompt",
                              {"id": event["id"], "deviceId": event["devices"][0]["id"]})
            except sync_api.Error:
                pass  # the second announcement of a prompt already answered
        elif name == "gattOperationReceived":  # connection, service discovery: both succeed
            self.connected = self.connected or event["type"] == "connection"
            self.bt.send("BluetoothEmulation.simulateGATTOperationResponse",
                         {"address": self.ADDRESS, "type": event["type"], "code": 0})
        elif name == "descriptorOperationReceived":
            args = {"descriptorId": event["descriptorId"], "type": event["type"], "code": 0}
            if event["type"] == "read":
                args["data"] = base64.b64encode(b"\x00\x00").decode()
            self.bt.send("BluetoothEmulation.simulateDescriptorOperationResponse", args)
        else:
            cid, kind = event["characteristicId"], event["type"]
            if kind == "write":
                if not self.connected:
                    return  # written before the link dropped, lost with it
                assert event["writeType"] == "write-without-response" and cid == self.rx
                data = base64.b64decode(event["data"])
                if self.lose_chunk is not None and data[-1:] == b"\x00":  # a frame a write
                    frame = P.FrameDecoder().feed(data)[0]
                    if (frame[0] == P.PATTERN_CHUNK
                            and P.unpack_pattern_chunk(frame[2])[0] == self.lose_chunk):
                        self.lose_chunk = None
                        return
                self.writes.append(len(data))
                self.received += data
                self.link.feed(data)
                self.pen.fill(self.block)  # the audio loop: states and swaps take effect
            elif kind == "read" and cid == self.info:
                self.respond(cid, kind, self.pen.info_payload())
            elif kind == "read" and cid == self.battery:
                self.respond(cid, kind, bytes([87]))
            elif kind == "read" and cid == self.tx:
                self.reading = False
                try:
                    self.respond(cid, kind, bytes(self.out[:512]))
                except sync_api.Error:  # the connection dropped meanwhile: the read is void
                    return
                del self.out[:512]
            else:  # (un)subscribe
                self.respond(cid, kind)

    def pump(self, until, timeout=8.0):
        """Answer the emulation until ``until()`` is true."""
        deadline = time.monotonic() + timeout
        while not until():
            if time.monotonic() > deadline:
                raise TimeoutError(f"the page and the emulated pen stalled: "
                                   f"{self.page.evaluate('window.realpen.penDevice')}")
            self.page.wait_for_timeout(4)  # CDP events are delivered while Playwright waits
            while self.queue:
                self.handle(*self.queue.pop(0))
            if self.out and not self.reading and self.connected:
                self.reading = True
                self.page.evaluate(READ_TX)

    def disconnect(self):
        """The link drops: what the pen had yet to notify is lost. No read of TX may be under
        way then (the emulation cannot answer it once the peripheral is gone)."""
        self.pump(lambda: not self.reading)
        self.connected = False
        self.out.clear()
        self.bt.send("BluetoothEmulation.simulateGATTDisconnection", {"address": self.ADDRESS})

    def close(self):
        self.bt.send("BluetoothEmulation.disable")
        self.bt.detach()


def test_web_bluetooth_under_chromium_emulation(browser, server):
    """Connect Bluetooth → the chooser (CDP DeviceAccess) picks the emulated pen, INFO is read,
    TX subscribed, the pattern uploaded through RX in writes ≤ 244 B (a PING answered every 4
    chunks) and the pen core swaps it in; a write that fails once goes again at the same size;
    a stale request's timer leaves a newer one of the same seq alone; a pen stroke → SET_STATE
    playing=1 then 0 at the pen core; a dropped connection → the panel says so, the link
    reconnects and uploads again (a chunk lost on the way: the pen's NACK stops the upload at
    the next PONG, and it is tried once more). Without Web Serial the USB button gives way to a
    plain note; the server's own pen shows in the panel, in one line."""
    httpx = pytest.importorskip("httpx")
    context = browser.new_context(viewport={"width": 1180, "height": 820})
    context.set_default_timeout(10_000)
    context.add_init_script(NO_SERIAL)
    context.route("**/api/device", lambda route: route.fulfill(json={
        "name": "sim", "kind": "sim", "connected": True,
        "message": "connected: RealPen, firmware 1.0.0, 8000 Hz", "info": None}))
    page = context.new_page()
    problems: list[str] = []
    page.on("pageerror", lambda error: problems.append(str(error)))
    page.goto(server.url)
    page.wait_for_function("() => window.realpen && window.realpen.ready")
    pen = None
    try:
        pen = EmulatedPen(browser, page)
        name = page.evaluate("window.realpen.pen")
        # The pattern's first 0.5 s (still many PING windows): each round trip through the
        # emulation takes tens of ms, and the USB test uploads the whole pattern.
        expected = httpx.get(f"{server.base}api/pens/{name}/pen-pattern",
                             params={"rate": 8000}).content[:8000]
        context.route("**/pen-pattern?*", lambda route: route.fulfill(
            body=expected, content_type="application/octet-stream"))
        page.click("#pen-device")
        assert not page.is_visible("#pen-usb") and page.is_visible("#pen-ble")
        assert "cannot reach a pen over USB serial" in page.text_content("#pen-note")
        page.wait_for_function("() => !document.getElementById('pen-bridge').hidden")
        assert page.text_content("#pen-bridge") == ("Server pen (sim): connected: RealPen, "
                                                    "firmware 1.0.0, 8000 Hz")
        page.click("#pen-ble", no_wait_after=True)
        done = f"() => window.realpen.penDevice.pattern === {json.dumps(name)}"
        pen.pump(lambda: page.evaluate(done))
        status = page.evaluate("window.realpen.penDevice")
        assert status["kind"] == "ble" and status["battery"] == 87
        assert status["message"].startswith("RealPen on Bluetooth (firmware ")
        page.wait_for_function("() => document.getElementById('pen-meta').textContent"
                               " === 'battery 87 %'")
        assert status["info"]["name"] == "RealPen" and status["info"]["sampleRate"] == 8000
        # Both sides' pens in the headline (the server's status here carries no INFO).
        assert page.text_content("#pen-panel-title") == (
            "Pen: RealPen (this page, Bluetooth) and a pen (server, simulated)")
        pen.pump(lambda: pen.swaps)
        assert pen.swaps == [zlib.crc32(expected) & 0xFFFF]
        page.screenshot(path=str(ARTIFACTS / "pen-panel-ble.png"))
        frames = P.FrameDecoder().feed(bytes(pen.received))
        assert b"".join(P.unpack_pattern_chunk(p)[1] for t, _, p in frames
                        if t == P.PATTERN_CHUNK) == expected
        # A frame a write, each within one write at ATT MTU 247 (244 bytes).
        assert len(pen.writes) == len(frames) and max(pen.writes) <= 244
        assert longest_chunk_run(frames) == 4  # then a PING, answered before the next chunk
        page.evaluate(WRITE_FAILS_ONCE)
        pen.pump(lambda: page.evaluate("window.__result"))
        assert page.evaluate("[window.__result, window.realpen.penLink.transport.piece]") \
            == ["pong", 0]
        page.evaluate(SEQ_WRAPS)
        page.wait_for_timeout(60)  # nothing answered meanwhile: the stale request times out
        pen.pump(lambda: page.evaluate("window.__result"))
        assert page.evaluate("window.__result") == "pong"
        pen_stroke(page)
        pen.pump(lambda: any(s[0] == 1 for s in pen.states) and pen.states[-1][0] == 0)
        assert any(s[0] == 1 and s[1] > 0 for s in pen.states)
        assert all(s[2] == P.RATE_ONE for s in pen.states)
        # The connection drops (a SET_STATE write hanging): the panel says so; the link connects
        # again, sends the state (the hung write holds up only its own connection's states) and
        # uploads again.
        begins = sum(t == P.PATTERN_BEGIN for t, _, _ in frames)
        page.evaluate(STATE_WRITE_HANGS)
        states = len(pen.states)
        pen.disconnect()
        pen.pump(lambda: "Pen disconnected" in page.text_content("#pen-status"))
        assert page.evaluate("window.realpen.penDevice.state") == "disconnected"
        pen.build_gatt()
        pen.lose_chunk = P.MAX_CHUNK
        pen.pump(lambda: page.evaluate(done + " && window.realpen.penDevice.state === 'connected'"))
        frames = P.FrameDecoder().feed(bytes(pen.received))
        assert sum(t == P.PATTERN_BEGIN for t, _, _ in frames) == begins + 2
        assert pen.lose_chunk is None
        first, again = [i for i, (t, _, _) in enumerate(frames) if t == P.PATTERN_BEGIN][-2:]
        assert [t for t, _, _ in frames[first:again]].count(P.PATTERN_CHUNK) == 3  # 4th: PING
        assert (1, 32768, P.RATE_ONE, 5) in pen.states[states:]
        page.evaluate("window.realpen.penLink.setState(false, 0)")

        def swapped():  # the pen, playing, swaps in the new pattern at its next wrap or idle
            pen.pen.fill(pen.block)  # its audio loop runs on
            return pen.states[-1][0] == 0 and len(pen.swaps) == 2

        pen.pump(swapped)
        assert problems == []
    finally:
        if pen is not None:
            pen.close()
        context.close()


# ---- what the page says about the pen -------------------------------------------------------

NOTHING_PLAYS = "Tactile: no pen connected and Tactile\u00a0\u2192\u00a0R is off \u2014 " \
                "nothing plays the vibration"


def test_tactile_with_nothing_to_play_it_on_says_so(browser, server):
    """Tactile chosen, no pen on either side (the server only logs), Tactile → R off: words
    where the gain meter was, and the headline says no pen is connected. Tactile → R on, or
    another modality: the meter is back."""
    context, page, problems = open_page(browser, server)
    try:
        assert page.text_content("#pen-panel-title") == "Pen: none connected"
        page.click('#modalities [data-value="tactile"]')
        page.wait_for_selector("#st-tactile", state="visible")
        assert page.text_content("#st-tactile") == NOTHING_PLAYS
        assert page.is_hidden("#st-gain")
        ARTIFACTS.mkdir(exist_ok=True)
        page.screenshot(path=str(ARTIFACTS / "pen-tactile-nothing-to-play.png"))
        page.click("#tactile-audio")
        page.wait_for_selector("#st-gain", state="visible")
        assert page.is_hidden("#st-tactile")
        page.click("#tactile-audio")
        page.wait_for_selector("#st-tactile", state="visible")
        page.click('#modalities [data-value="audio-tactile"]')
        page.wait_for_selector("#st-tactile", state="hidden")
        assert page.is_visible("#st-gain") and problems == []
    finally:
        context.close()


@pytest.mark.firmware
def test_the_pen_panel_names_the_servers_simulated_pen(browser, tmp_path, monkeypatch):
    """A server that drives the simulated pen (the serve command's ``--device sim``): the
    panel's headline names it by its INFO name and says it is the server's; Tactile then has
    a pen to play on, so the meter stays."""
    from realpen.live.device import open_device

    monkeypatch.setenv("REALPEN_HOME", str(tmp_path / "home"))
    device = open_device("sim")
    served = Server(tmp_path, device=device)
    try:
        context, page, problems = open_page(browser, served)
        try:
            page.click('#modalities [data-value="tactile"]')
            page.click("#pen-device")
            page.wait_for_function("() => document.getElementById('pen-panel-title')"
                                   ".textContent === 'Pen: RealPen (server, simulated)'",
                                   timeout=30_000)
            assert page.is_hidden("#st-tactile") and page.is_visible("#st-gain")
            ARTIFACTS.mkdir(exist_ok=True)
            page.screenshot(path=str(ARTIFACTS / "pen-panel-headline.png"))
            assert problems == []
        finally:
            context.close()
    finally:
        served.stop()
        device.close()  # the app's shutdown closed it already, unless the app never started
    assert not device.sim.alive
