"""The page's pen link (static/pen-link.js) leaves no timer behind.

Chromium loads the link's modules as they are (served from the package's static folder by a
Playwright route, no server), with the page's timer functions counted and a fake pen that
answers HELLO, PING and the pattern upload in the pen protocol. The link holds timers only
while a pen is connected (the state refresh, the heartbeat, a request's reply deadline, the
reconnect loop's waits): none before a pen is connected, none after disconnect(), after a USB
pen is lost, after a disconnect during Bluetooth reconnecting, and none (nor a serial
``connect`` listener) after close() ends a link that was hanging up on a pen that stopped
answering.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from live_support import CHROMIUM, CHROMIUM_ARGS, CHROMIUM_MISSING

STATIC = Path(__file__).resolve().parents[1] / "src" / "realpen" / "live" / "static"
ORIGIN = "http://realpen.test"

if not CHROMIUM.exists():
    pytest.skip(CHROMIUM_MISSING, allow_module_level=True)
sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed")

# Before any module runs: every live timer by id, and a navigator.serial that counts listeners.
COUNT_TIMERS = """(() => {
  const live = new Map();
  const real = {
    setTimeout: setTimeout.bind(window), clearTimeout: clearTimeout.bind(window),
    setInterval: setInterval.bind(window), clearInterval: clearInterval.bind(window),
  };
  window.__live = live;
  window.__sleep = (ms) => new Promise((resolve) => { real.setTimeout(resolve, ms); });
  window.setTimeout = (fn, ms, ...args) => {
    const id = real.setTimeout(() => { live.delete(id); fn(...args); }, ms);
    live.set(id, 'timeout');
    return id;
  };
  window.setInterval = (fn, ms, ...args) => {
    const id = real.setInterval(fn, ms, ...args);
    live.set(id, 'interval');
    return id;
  };
  window.clearTimeout = (id) => { live.delete(id); real.clearTimeout(id); };
  window.clearInterval = (id) => { live.delete(id); real.clearInterval(id); };
  const serial = new EventTarget();
  serial.listeners = 0;
  const add = serial.addEventListener.bind(serial);
  const remove = serial.removeEventListener.bind(serial);
  serial.addEventListener = (...a) => { serial.listeners += 1; add(...a); };
  serial.removeEventListener = (...a) => { serial.listeners -= 1; remove(...a); };
  Object.defineProperty(Navigator.prototype, 'serial', { value: serial, configurable: true });
})();"""

SCENARIOS = """async () => {
  const P = await import('/static/pen-protocol.js');
  const { PenLink } = await import('/static/pen-link.js');
  const live = window.__live;
  const timers = () => [...live.values()].sort();
  const until = async (check, what) => {
    for (let i = 0; i < 500; i += 1) {
      if (check()) return;
      await window.__sleep(10);
    }
    throw new Error(`timed out waiting for ${what}`);
  };
  const INFO = P.packInfo(P.PROTOCOL_VERSION, 1, 0, 0, 8000, 65536, P.FEATURE_USB, 'Fake');

  // A pen that answers in the pen protocol; `answering = false` makes it hang.
  class FakePen {
    constructor(kind, failOpen = false) {
      this.kind = kind;
      this.label = 'a fake pen';
      this.uploadWindow = 4;
      this.battery = null;
      this.failOpen = failOpen;
      this.answering = true;
      this.decoder = new P.FrameDecoder();
    }
    async open(onData, onClose) {
      if (this.failOpen) throw new Error('the pen is out of range');
      this.onData = onData;
      this.onClose = onClose;
    }
    async write(bytes) {
      for (const [ftype, seq, payload] of this.decoder.feed(bytes)) {
        let reply = null;
        if (ftype === P.HELLO) reply = [P.INFO, INFO];
        else if (ftype === P.PING) reply = [P.PONG, P.packPong(P.unpackPing(payload), 0)];
        else if (ftype === P.PATTERN_BEGIN || ftype === P.PATTERN_COMMIT) {
          reply = [P.ACK, P.packAck(ftype)];
        }
        if (reply && this.answering) {
          queueMicrotask(() => this.onData(P.encodeFrame(reply[0], seq, reply[1])));
        }
      }
    }
    async readInfo() { return INFO; }
    async close() {}
    again() { return new FakePen(this.kind, true); } // it stays away: the loop keeps trying
  }

  const seen = {};
  const link = new PenLink({ fetchPattern: async () => new Uint8Array(2000).buffer });
  link.setPen('ballpoint');
  seen.idle = timers();
  seen.listening = navigator.serial.listeners;

  await link.start(new FakePen('usb'));
  await until(() => link.status.pattern === 'ballpoint', 'the upload');
  seen.connected = timers();
  await link.disconnect();
  seen.disconnected = timers();
  seen.disconnectedState = link.status.state;

  const usb = new FakePen('usb');
  await link.start(usb);
  usb.onClose('the port closed');
  seen.usbLost = timers();
  seen.usbLostState = link.status.state;

  const ble = new FakePen('ble');
  await link.start(ble);
  ble.onClose('Bluetooth connection lost');
  await window.__sleep(300); // the first retry has failed; the loop waits for the next
  seen.reconnecting = timers();
  seen.reconnectingMessage = link.status.message;
  await link.disconnect();
  seen.reconnectDisconnected = timers();

  const hung = new FakePen('usb');
  await link.start(hung);
  await until(() => link.status.pattern === 'ballpoint', 'the second upload');
  link.heartbeatMs = 50;
  link.scheduleBeat();
  hung.answering = false;
  await until(() => link.status.state === 'disconnected', 'the hang-up');
  seen.hungMessage = link.status.message;
  await link.close();
  seen.closed = timers();
  seen.listeningAfterClose = navigator.serial.listeners;
  return seen;
}"""


@pytest.fixture(scope="module")
def page(chromium):
    context = chromium(CHROMIUM_ARGS).new_context()
    try:
        context.add_init_script(COUNT_TIMERS)

        def serve(route):
            path = route.request.url.removeprefix(ORIGIN)
            if path.startswith("/static/"):
                file = STATIC / path.removeprefix("/static/")
                route.fulfill(path=str(file), content_type="text/javascript")
            else:
                route.fulfill(body="<!doctype html><title>pen link</title>",
                              content_type="text/html")

        context.route(f"{ORIGIN}/**", serve)
        tab = context.new_page()
        problems: list[str] = []
        tab.on("pageerror", lambda error: problems.append(str(error)))
        tab.goto(f"{ORIGIN}/")
        yield tab
        assert problems == []
    finally:
        context.close()


def test_the_pen_link_holds_timers_only_while_a_pen_is_connected(page):
    seen = page.evaluate(SCENARIOS)
    assert seen["idle"] == []  # a link with no pen: no refresh, no heartbeat
    assert seen["listening"] == 1  # for a USB port that comes back
    assert "interval" in seen["connected"] and "timeout" in seen["connected"]
    assert seen["disconnected"] == [] and seen["disconnectedState"] == "idle"
    assert seen["usbLost"] == [] and seen["usbLostState"] == "disconnected"
    assert seen["reconnecting"] == ["timeout"]  # the reconnect loop's wait, and only it
    assert "reconnecting" in seen["reconnectingMessage"]
    assert seen["reconnectDisconnected"] == []  # disconnect() ends the wait at once
    assert "no answer to 2 PINGs in a row" in seen["hungMessage"]
    assert seen["closed"] == [] and seen["listeningAfterClose"] == 0
