// A pen driven straight from the page, over Web Serial (USB) or Web Bluetooth, with the codec of
// pen-protocol.js: for a lab where the pen is next to the tablet and the server is not.
//
//   connect → HELLO / INFO (over Bluetooth the INFO characteristic is read instead): a pen that
//   speaks another protocol version is refused with one clear line
//   → upload the current pen's pattern (GET /api/pens/{name}/pen-pattern?rate=<INFO rate>, int16
//   LE): PATTERN_BEGIN → ACK, PATTERN_CHUNKs, PATTERN_COMMIT → ACK; the pen keeps its old
//   pattern until the new one is complete and checked
//   → SET_STATE on every pen down, gain change and pen up (the whole state each time, latest
//   wins, sent again every REFRESH_MS so a lost frame is mended)
//   → a PING every HEARTBEAT_MS while nothing else is asked: a pen that misses two PONGs in a
//   row has hung, and is let go of and connected again.
//
// Nothing here can stop the page: the page's own sound and ink never wait for the pen, every
// error becomes the status line, and a pen that disconnects is reconnected (Bluetooth: the same
// device, with backoff; USB: when the port comes back, or at once when the pen only stopped
// answering) and gets its pattern and state again, as after the pen's boot EVENT (a pen that
// restarted behind a port that stayed).
//
// Bluetooth: RX is written without response, a frame per write (a frame is at most ~192 bytes:
// one write at the ATT MTU of 247 the firmware asks for). The page cannot see the MTU Chrome
// negotiated: when a write fails twice the link goes on in smaller pieces (BLE_PIECES), which
// the pen's decoder joins again, as it joins TX notifications, pieces of the same byte stream as
// USB, here. Writes without response have no flow control: an upload waits for a PONG every
// few chunks so that it never runs further ahead of the pen than the pen's buffer holds.

import {
  ACK, BLE_INFO, BLE_RX, BLE_SERVICE, BLE_TX, E_BAD_FORMAT, E_BAD_RATE, E_TOO_LARGE, E_VERSION,
  EV_BATTERY, EV_BOOT, EV_UNDERRUN, EVENT,
  FORMAT_S16LE, FrameDecoder, GAIN_ONE, HELLO, INFO, MAX_CHUNK, NACK, NACK_TEXT, PATTERN_BEGIN,
  PATTERN_CHUNK, PATTERN_COMMIT, PING, PONG, PROTOCOL_VERSION, RATE_ONE, SET_STATE, crc32,
  encodeFrame, packHello, packPatternBegin, packPatternChunk, packPatternCommit, packPing,
  packSetState, unpackAck, unpackEvent, unpackInfo, unpackNack, unpackPong,
} from './pen-protocol.js';

export const BAUD_RATE = 115200;
// Bytes per RX write: 244 is one write at ATT MTU 247; 182 at the MTU of 185 some hosts
// (macOS, iOS) settle on; 20 at the minimum MTU of 23.
export const BLE_PIECES = [244, 182, 20];
const REPLY_MS = 1000; // a request's reply (INFO, ACK, PONG) must come within this
const COMMIT_MS = 3000; // the pen checks the CRC-32 of the whole pattern before it answers
const HELLO_TRIES = 3; // a pen that has just booted may miss the first HELLO
const REFRESH_MS = 1000; // the current state goes again this often (SET_STATE is unanswered)…
const REFRESH_FOR_MS = 3000; // …while the pen plays and for this long after the last change
const RETRY_MAX_MS = 1000; // reconnect backoff ceiling
// Pattern chunks an upload sends before it waits for the pen (a PING answered), as the Python
// host does (realpen.device.transport UPLOAD_WINDOW, BLE_UPLOAD_WINDOW): ≈ 2.9 KB over USB;
// over Bluetooth 4 (≈ 760 B): the Pico W's receive buffer holds 4 KB and drains slowly.
const UPLOAD_WINDOW = 16;
const BLE_UPLOAD_WINDOW = 4;
const UPLOAD_TRIES = 2; // a failed upload is tried once more (not when the pen refused the pattern)
const HEARTBEAT_MS = 2000; // an idle link PINGs this often…
const HEARTBEAT_MISSES = 2; // …and a pen that misses this many PONGs in a row has hung
const WRITE_RETRY_MS = 20; // a failed Bluetooth write goes again after this
const CLOSE_WAIT_MS = 1000; // a hung pen's port may take long to close: reopen after this at most

const hasSerial = () => typeof navigator !== 'undefined' && 'serial' in navigator;
const hasBluetooth = () => typeof navigator !== 'undefined' && 'bluetooth' in navigator;

/** What this browser can do: { serial, bluetooth } (Chrome and Edge on a computer have both;
 *  Safari and Firefox have neither). */
export function support() {
  return { serial: hasSerial(), bluetooth: hasBluetooth() };
}

function describe(error) {
  if (!error) return 'unknown error';
  return error.message ? String(error.message) : String(error);
}

/** The user closed the browser's chooser (NotFoundError is also "no adapter", which is said). */
const cancelled = (error) => Boolean(error && error.name === 'NotFoundError'
  && /cancel|no port selected/i.test(error.message || ''));

const hex4 = (n) => n.toString(16).padStart(4, '0');
const sleep = (ms) => new Promise((resolve) => { setTimeout(resolve, ms); });

/** A failure the user should read as it is (no "Error:" prefix, no stack). */
class PenError extends Error {}

// ---- transports: a byte pipe each --------------------------------------------------------

/** A serial port opened at 115200 8N1: `write(bytes)`, `close()`; the reader loop hands
 *  every chunk to `onData` and calls `onClose(reason)` once when the port goes away. */
class SerialTransport {
  constructor(port) {
    this.port = port;
    this.kind = 'usb';
    this.closed = false;
  }

  async open(onData, onClose) {
    this.onData = onData;
    this.onClose = onClose;
    await this.port.open({ baudRate: BAUD_RATE, dataBits: 8, stopBits: 1, parity: 'none',
      flowControl: 'none' });
    this.writer = this.port.writable.getWriter();
    this.reading = this.readLoop();
  }

  async readLoop() {
    let reason = 'the port closed';
    let stream = this.port.readable;
    while (!this.closed && stream) {
      reason = 'the port closed';
      this.reader = stream.getReader();
      try {
        for (;;) {
          const { value, done } = await this.reader.read();
          if (done) break;
          if (value && value.length) this.onData(value);
        }
      } catch (error) {
        // A recoverable read error (framing, parity, break, buffer overrun) ends this stream
        // only: the port hands out a new one and reading goes on. A lost device leaves none.
        reason = describe(error);
      } finally {
        this.reader.releaseLock();
      }
      const next = this.port.readable;
      stream = next === stream ? null : next; // the same stream again has ended for good
    }
    this.lost(reason);
  }

  lost(reason) {
    if (this.closed) return;
    this.closed = true;
    this.onClose(reason);
  }

  async write(bytes) {
    if (this.closed) throw new PenError('the port is closed');
    await this.writer.write(bytes);
  }

  async close() {
    this.closed = true;
    try { if (this.reader) await this.reader.cancel(); } catch { /* already gone */ }
    try { await this.reading; } catch { /* already reported */ }
    try { this.writer.releaseLock(); } catch { /* already released */ }
    try { await this.port.close(); } catch { /* already closed */ }
  }

  get label() {
    const info = this.port.getInfo ? this.port.getInfo() : {};
    return info.usbVendorId !== undefined
      ? `USB ${hex4(info.usbVendorId)}:${hex4(info.usbProductId || 0)}`
      : 'USB serial';
  }
}

/** The pen's GATT service: RX written without response, TX notifications into `onData`,
 *  INFO read; `onClose(reason)` when the device disconnects. */
class BleTransport {
  constructor(device) {
    this.device = device;
    this.kind = 'ble';
    this.closed = false;
    this.piece = 0; // index into BLE_PIECES
    this.queue = Promise.resolve();
    this.disconnected = () => this.lost('Bluetooth connection lost');
    this.notified = (event) => {
      const v = event.target.value;
      this.onData(new Uint8Array(v.buffer, v.byteOffset, v.byteLength));
    };
  }

  async open(onData, onClose) {
    this.onData = onData;
    this.onClose = onClose;
    this.closed = false;
    this.device.addEventListener('gattserverdisconnected', this.disconnected);
    const server = await this.device.gatt.connect();
    const service = await server.getPrimaryService(BLE_SERVICE);
    this.rx = await service.getCharacteristic(BLE_RX);
    this.tx = await service.getCharacteristic(BLE_TX);
    this.info = await service.getCharacteristic(BLE_INFO);
    this.tx.addEventListener('characteristicvaluechanged', this.notified);
    await this.tx.startNotifications();
    this.battery = await this.readBattery(server);
  }

  /** The standard Battery Level (%), or null when the pen has no battery service. */
  async readBattery(server) {
    try {
      const service = await server.getPrimaryService('battery_service');
      const level = await (await service.getCharacteristic('battery_level')).readValue();
      return level.getUint8(0);
    } catch { return null; }
  }

  async readInfo() {
    const value = await this.info.readValue();
    return new Uint8Array(value.buffer, value.byteOffset, value.byteLength);
  }

  lost(reason) {
    if (this.closed) return;
    this.closed = true;
    this.detach();
    this.onClose(reason);
  }

  detach() {
    this.device.removeEventListener('gattserverdisconnected', this.disconnected);
    if (this.tx) this.tx.removeEventListener('characteristicvaluechanged', this.notified);
  }

  /** Writes go one after another (a GATT operation at a time), each in pieces. */
  write(bytes) {
    const run = this.queue.then(() => this.writePieces(bytes));
    this.queue = run.catch(() => {});
    return run;
  }

  async writePieces(bytes) {
    let at = 0;
    let failed = 0; // failures of this piece at this size
    while (at < bytes.length) {
      if (this.closed) throw new PenError('the pen disconnected');
      const piece = bytes.subarray(at, at + BLE_PIECES[this.piece]);
      try {
        await this.rx.writeValueWithoutResponse(piece);
      } catch (error) {
        if (this.closed || !this.device.gatt.connected) throw error;
        failed += 1;
        // A write fails for passing reasons too ("GATT operation already in progress", a busy
        // controller): the same piece goes once more before the size is blamed.
        if (failed === 1) {
          await sleep(WRITE_RETRY_MS);
          continue;
        }
        // Failed twice: longer than the ATT MTU allows, if a smaller piece would be shorter;
        // the link goes on in smaller pieces for good.
        const smaller = BLE_PIECES[this.piece + 1];
        if (smaller !== undefined && piece.length > smaller) {
          this.piece += 1;
          failed = 0;
          continue;
        }
        throw error;
      }
      failed = 0;
      at += piece.length;
    }
  }

  async close() {
    this.closed = true;
    this.detach();
    try { if (this.tx) await this.tx.stopNotifications(); } catch { /* already gone */ }
    try { if (this.device.gatt.connected) this.device.gatt.disconnect(); } catch { /* gone */ }
  }

  get label() {
    return 'Bluetooth';
  }
}

// ---- the link ---------------------------------------------------------------------------------

/**
 * The page's direct link to a pen.
 *
 * options.fetchPattern(name, rate) → ArrayBuffer of int16 LE samples at `rate` Hz (the page's
 * GET /api/pens/{name}/pen-pattern); options.onChange(status) whenever the status changes.
 *
 * status: { state: 'idle' | 'connecting' | 'connected' | 'uploading' | 'disconnected' |
 * 'error', kind: 'usb' | 'ble' | null, message (one line for the panel), info (the pen's INFO
 * as an object, or null), pattern (the pen name whose pattern the pen holds), progress (0-1 of
 * an upload), battery (% from the Bluetooth Battery service, or null), batteryMv (mV from the
 * pen's battery EVENT, or null), sent (SET_STATE frames written), errors (frames the decoder
 * dropped), underruns (the pen's underrun count, from its EVENTs) }.
 *
 * heartbeatMs (default HEARTBEAT_MS) is how often an idle link PINGs; a change takes effect
 * from the next beat, or at once after scheduleBeat().
 */
export class PenLink {
  constructor({ fetchPattern, onChange = () => {} } = {}) {
    this.fetchPattern = fetchPattern;
    this.onChange = onChange;
    this.transport = null;
    this.decoder = new FrameDecoder();
    this.seq = 0;
    this.pending = new Map(); // seq → { resolve, reject, timer }
    this.wanted = { playing: false, gain: 0, fadeMs: 5 };
    this.changedAt = 0;
    this.sentState = null;
    this.stateBusy = null; // the generation whose SET_STATE write is under way
    this.stateDirty = false;
    this.chunkRefused = null; // the NACK code of a refused PATTERN_CHUNK of this upload
    this.reconnecting = null; // the token of the reconnect loop under way
    this.heartbeatMs = HEARTBEAT_MS;
    this.missed = 0; // PONGs missed in a row
    this.pen = null; // the page's pen (profile name)
    this.holds = null; // `${pen}@${rate}#${crc32}` of the pattern the pen holds
    this.uploading = null;
    this.userClosed = true;
    this.generation = 0; // bumps with each connection: stale async work gives up
    this.status = { state: 'idle', kind: null, message: 'No pen connected.', info: null,
      pattern: null, progress: null, battery: null, batteryMv: null, sent: 0, errors: 0,
      underruns: 0 };
    this.refresh = setInterval(() => {
      const recent = performance.now() - this.changedAt < REFRESH_FOR_MS;
      if (this.wanted.playing || recent) this.sendState(true);
    }, REFRESH_MS);
    this.scheduleBeat();
    if (hasSerial()) {
      navigator.serial.addEventListener('connect', (event) => this.portBack(event.target));
    }
  }

  update(fields) {
    Object.assign(this.status, fields);
    this.onChange(this.status);
  }

  get connected() {
    return this.status.state === 'connected' || this.status.state === 'uploading';
  }

  // ---- connecting ----

  /** Ask for a serial port (the browser's chooser; call from a click) and connect to it. */
  async connectSerial() {
    if (!hasSerial()) throw new PenError('This browser has no Web Serial.');
    let port;
    try {
      port = await navigator.serial.requestPort();
    } catch (error) {
      if (cancelled(error)) return false;
      throw error;
    }
    await this.start(new SerialTransport(port));
    return true;
  }

  /** Ask for a pen over Bluetooth (the browser's chooser; call from a click) and connect. */
  async connectBluetooth() {
    if (!hasBluetooth()) throw new PenError('This browser has no Web Bluetooth.');
    let device;
    try {
      device = await navigator.bluetooth.requestDevice({
        filters: [{ services: [BLE_SERVICE] }],
        optionalServices: ['battery_service', 'device_information'],
      });
    } catch (error) {
      if (cancelled(error)) return false;
      throw error;
    }
    await this.start(new BleTransport(device));
    return true;
  }

  /** Let go of the pen (it is told to stop first). */
  async disconnect() {
    this.userClosed = true;
    this.reconnecting = null;
    const transport = this.transport;
    this.generation += 1;
    if (transport && this.connected) {
      try {
        await transport.write(encodeFrame(SET_STATE, this.nextSeq(),
          packSetState(0, 0, RATE_ONE, this.wanted.fadeMs)));
      } catch { /* gone already */ }
    }
    this.transport = null;
    this.failPending('disconnected');
    if (transport) await transport.close();
    this.update({ state: 'idle', kind: null, message: 'No pen connected.', info: null,
      pattern: null, progress: null, battery: null, batteryMv: null });
  }

  async start(transport) {
    if (this.transport) await this.disconnect();
    this.reconnecting = null;
    this.userClosed = false;
    this.lastTransport = transport;
    this.update({ state: 'connecting', kind: transport.kind, info: null, pattern: null,
      progress: null, message: `Connecting to ${transport.label}…` });
    await this.open(transport);
  }

  /** Open `transport`, say hello, send the state, upload. Failures become the status (while
   *  `retrying` — the reason the pen was lost — it stays "disconnected, reconnecting").
   *  Resolves to whether the pen is connected. */
  async open(transport, retrying = null) {
    const generation = ++this.generation;
    this.decoder = new FrameDecoder();
    this.holds = null;
    this.sentState = null;
    this.stateDirty = false;
    this.missed = 0;
    this.status.info = null; // until this pen's HELLO: no state nor upload goes out
    try {
      await transport.open((bytes) => this.received(bytes, transport),
        (reason) => this.lost(transport, reason));
      if (generation !== this.generation) { // another connection overtook this one
        await transport.close();
        return false;
      }
      this.transport = transport;
      const info = await this.hello(transport);
      if (generation !== this.generation) return false;
      this.update({ state: 'connected', info, pattern: null, battery: transport.battery ?? null,
        message: `${this.describePen(info, transport)}: connected.` });
      this.sendState();
      await this.syncPattern();
      return true;
    } catch (error) {
      if (generation !== this.generation) return false;
      const versionProblem = error instanceof PenError && error.version;
      if (versionProblem) this.userClosed = true; // reconnecting cannot mend it
      this.transport = null;
      this.failPending(describe(error));
      await transport.close();
      if (retrying && !versionProblem) {
        this.update({ state: 'disconnected', info: null, message: this.lostMessage(retrying,
          `last try: ${describe(error)}`) });
      } else {
        this.update({ state: 'error', info: null, message: describe(error) });
      }
      return false;
    }
  }

  describePen(info, transport) {
    const khz = (info.sampleRate / 1000).toFixed(info.sampleRate % 1000 ? 1 : 0);
    return `${info.name || 'Pen'} on ${transport.label} `
      + `(firmware ${info.firmware}, ${khz}\u00a0kHz)`;
  }

  lostMessage(reason, detail = '') {
    let next = '';
    if (!this.userClosed) {
      next = this.reconnecting || this.status.kind !== 'usb' ? '; reconnecting…'
        : '; it reconnects when the port is back';
    }
    const text = `Pen disconnected (${reason})${next}${detail ? ` (${detail})` : ''}`;
    return `${text}${text.endsWith('…') ? '' : '.'} The page's own sound goes on.`;
  }

  /** HELLO → INFO (USB), or the INFO characteristic (Bluetooth); checks the version. */
  async hello(transport) {
    let raw;
    if (transport.kind === 'ble') {
      raw = await transport.readInfo();
    } else {
      // A lone delimiter ends whatever partial frame the pen holds (a half-written frame
      // from before, a terminal's keystrokes) so that HELLO is decoded on its own.
      await transport.write(Uint8Array.of(0));
      let reply = null;
      for (let attempt = 1; reply === null; attempt += 1) {
        try {
          reply = await this.request(HELLO, packHello(PROTOCOL_VERSION));
        } catch (error) {
          if (!(error instanceof PenError && error.timeout)) throw error;
          if (attempt >= HELLO_TRIES) {
            throw new PenError(`No answer to HELLO on ${transport.label}: is it a RealPen pen `
              + 'with its firmware running?');
          }
        }
      }
      const [ftype, , payload] = reply;
      if (ftype === NACK) {
        const [, code] = unpackNack(payload);
        const problem = new PenError(code === E_VERSION
          ? `This pen does not speak protocol ${PROTOCOL_VERSION}, which this page speaks: `
            + 'update the pen\'s firmware (or the page) so both match.'
          : `The pen refused HELLO: ${NACK_TEXT[code] || `error ${code}`}.`);
        problem.version = code === E_VERSION;
        throw problem;
      }
      if (ftype !== INFO) throw new PenError(`The pen answered HELLO with frame type ${ftype}.`);
      raw = payload;
    }
    const [protocol, major, minor, patch, sampleRate, maxPatternBytes, features, name] =
      unpackInfo(raw);
    if (protocol !== PROTOCOL_VERSION) {
      const problem = new PenError(`This pen speaks protocol ${protocol}; this page speaks `
        + `${PROTOCOL_VERSION}: update the `
        + `${protocol < PROTOCOL_VERSION ? 'pen\'s firmware' : 'page'} so both match.`);
      problem.version = true;
      throw problem;
    }
    return { protocol, firmware: `${major}.${minor}.${patch}`, sampleRate, maxPatternBytes,
      features, name };
  }

  /** `transport` is gone. Bluetooth (or `reopen`) connects again to the same device or port
   *  once `closing` (the old link's close) is done; USB waits for the port to come back. */
  lost(transport, reason, reopen = transport.kind === 'ble', closing = null) {
    if (transport !== this.transport) return;
    this.transport = null;
    this.generation += 1;
    this.failPending(reason);
    const token = reopen && !this.userClosed ? {} : null;
    this.reconnecting = token;
    // What the pen is, holds and plays is unknown until it says HELLO again: nothing may go
    // out with the INFO of before (the state refresh, a change of pen).
    this.update({ state: 'disconnected', info: null, progress: null, pattern: null,
      message: this.lostMessage(reason) });
    if (token) this.reconnect(transport, reason, token, closing);
  }

  /** The pen stopped answering (hung, or its end of the link did): let go of the link and
   *  connect to the same device or port again. */
  hangUp(transport, reason) {
    if (transport !== this.transport) return;
    const closing = transport.close().catch(() => {});
    this.lost(transport, reason, true, closing);
  }

  /** Connect to the same Bluetooth device or serial port again, backing off to RETRY_MAX_MS,
   *  until it works, the user disconnects or connects another pen (or the port comes back). */
  async reconnect(old, reason, token, closing = null) {
    const going = () => !this.userClosed && this.reconnecting === token && !this.transport;
    try {
      if (closing) await Promise.race([closing, sleep(CLOSE_WAIT_MS)]);
      let wait = 200;
      while (going()) {
        await sleep(wait);
        if (!going()) return;
        const again = old.kind === 'ble' ? new BleTransport(old.device)
          : new SerialTransport(old.port);
        if (await this.open(again, reason)) return;
        wait = Math.min(wait * 2, RETRY_MAX_MS);
      }
    } finally {
      if (this.reconnecting === token) this.reconnecting = null;
    }
  }

  /** USB: a port the user gave before is back (the pen was plugged in again or rebooted). */
  portBack(port) {
    const last = this.lastTransport;
    if (this.userClosed || this.transport || !last || last.kind !== 'usb') return;
    const a = last.port.getInfo ? last.port.getInfo() : {};
    const b = port.getInfo ? port.getInfo() : {};
    const same = a.usbVendorId === b.usbVendorId && a.usbProductId === b.usbProductId;
    if (port !== last.port && !same) return;
    this.start(new SerialTransport(port)).catch(() => {});
  }

  // ---- frames ----

  nextSeq() {
    const seq = this.seq;
    this.seq = (this.seq + 1) & 0xff;
    return seq;
  }

  received(bytes, transport) {
    if (transport !== this.transport) return;
    for (const [ftype, seq, payload] of this.decoder.feed(bytes)) {
      if (ftype === EVENT) {
        this.event(payload);
        continue;
      }
      const waiting = this.pending.get(seq);
      if (!waiting) { // a late reply, or a NACK of an unanswered frame
        if (ftype === NACK) this.refused(payload);
        continue;
      }
      this.pending.delete(seq);
      clearTimeout(waiting.timer);
      waiting.resolve([ftype, seq, payload]);
    }
    if (this.decoder.errors !== this.status.errors) this.update({ errors: this.decoder.errors });
  }

  /** A NACK nobody waits for: a refused PATTERN_CHUNK fails the upload at its next PONG. */
  refused(payload) {
    try {
      const [ftype, code] = unpackNack(payload);
      if (ftype === PATTERN_CHUNK && this.uploading && this.chunkRefused === null) {
        this.chunkRefused = code;
      }
    } catch { /* a malformed NACK says nothing */ }
  }

  event(payload) {
    let kind;
    let value;
    try {
      [kind, value] = unpackEvent(payload);
    } catch { return; } // a malformed event is only an event
    if (kind === EV_BATTERY) this.update({ batteryMv: value });
    else if (kind === EV_UNDERRUN) this.update({ underruns: value }); // the pen's count
    else if (kind === EV_BOOT) this.rebooted();
  }

  /** The pen started again behind a link that stayed (a USB-serial adapter, a watchdog
   *  reset): it holds no pattern and plays nothing, so both go again. */
  rebooted() {
    this.holds = null;
    this.sentState = null;
    if (!this.transport || !this.status.info) return; // still saying HELLO: open() sends both
    this.update({ pattern: null });
    this.sendState();
    this.syncPattern().catch(() => {}); // reported in the status
  }

  /** Send a frame and wait for the reply with its seq: [ftype, seq, payload]. */
  request(ftype, payload, timeoutMs = REPLY_MS, transport = this.transport) {
    if (!transport) return Promise.reject(new PenError('no pen connected'));
    const seq = this.nextSeq();
    return new Promise((resolve, reject) => {
      const entry = { resolve, reject, timer: null };
      // Seqs wrap at 256: a stale timer or write error must not take a newer request's entry.
      const drop = () => {
        if (this.pending.get(seq) !== entry) return false;
        this.pending.delete(seq);
        clearTimeout(entry.timer);
        return true;
      };
      entry.timer = setTimeout(() => {
        drop();
        const error = new PenError(`the pen did not answer within ${timeoutMs} ms`);
        error.timeout = true;
        reject(error);
      }, timeoutMs);
      this.pending.set(seq, entry);
      transport.write(encodeFrame(ftype, seq, payload)).catch((error) => {
        if (drop()) reject(error);
      });
    });
  }

  failPending(reason) {
    for (const { reject, timer } of this.pending.values()) {
      clearTimeout(timer);
      reject(new PenError(reason));
    }
    this.pending.clear();
  }

  /** PING → PONG: { roundTripMs, deviceUs }. */
  async ping(timeoutMs = REPLY_MS, transport = this.transport) {
    const token = (Math.random() * 0x100000000) >>> 0;
    const started = performance.now();
    const [ftype, , payload] = await this.request(PING, packPing(token), timeoutMs, transport);
    if (ftype !== PONG) throw new PenError(`the pen answered PING with frame type ${ftype}`);
    const [echo, deviceUs] = unpackPong(payload);
    if (echo !== token) throw new PenError('the pen answered another PING');
    return { roundTripMs: performance.now() - started, deviceUs };
  }

  /** The next heartbeat in heartbeatMs (one chain of them: a call replaces the next beat). */
  scheduleBeat() {
    clearTimeout(this.heartbeat);
    this.heartbeat = setTimeout(() => {
      this.beat().finally(() => this.scheduleBeat());
    }, this.heartbeatMs);
  }

  /** PING an idle pen (nothing asked, nothing uploading): without it a hung pen would look
   *  connected for good. HEARTBEAT_MISSES PONGs missed in a row → hang up and reconnect. */
  async beat() {
    const transport = this.transport;
    if (!transport || this.status.state !== 'connected' || this.uploading || this.pending.size) {
      return;
    }
    try {
      await this.ping(Math.min(REPLY_MS, this.heartbeatMs), transport);
      if (transport === this.transport) this.missed = 0;
    } catch (error) {
      if (transport !== this.transport || !(error instanceof PenError && error.timeout)) return;
      this.missed += 1;
      if (this.missed >= HEARTBEAT_MISSES) {
        this.hangUp(transport, `no answer to ${this.missed} PINGs in a row`);
      }
    }
  }

  // ---- the pattern ----

  /** The page's pen changed: its pattern goes to the pen (when one is connected). */
  setPen(name) {
    this.pen = name;
    this.syncPattern().catch(() => {}); // reported in the status
  }

  async syncPattern() {
    if (!this.transport || !this.status.info || !this.pen || !this.fetchPattern) return;
    if (this.uploading) {
      // The pen changed (or restarted, or was connected again) mid-upload: the latest pen
      // goes next, with the latest INFO.
      this.uploadAgain = true;
      return;
    }
    this.uploading = this.pen;
    try {
      do {
        this.uploadAgain = false;
        const info = this.status.info;
        if (!this.transport || !info) break;
        await this.upload(this.pen, info);
      } while (this.uploadAgain);
    } finally {
      this.uploading = null;
    }
  }

  async upload(name, info) {
    const transport = this.transport;
    const generation = this.generation;
    let bytes;
    try {
      bytes = new Uint8Array(await this.fetchPattern(name, info.sampleRate));
    } catch (error) {
      this.update({ message: `Could not get the ${name} pattern for the pen: ${describe(error)}` });
      return;
    }
    if (generation !== this.generation) return;
    const crc = crc32(bytes);
    const key = `${name}@${info.sampleRate}#${crc}`;
    if (this.holds === key) return;
    if (bytes.length % 2) {
      this.update({ message: `The ${name} pattern has an odd number of bytes (${bytes.length}).` });
      return;
    }
    if (bytes.length > info.maxPatternBytes) {
      this.update({ message: `The ${name} pattern (${bytes.length} bytes) does not fit the pen `
        + `(at most ${info.maxPatternBytes} bytes); the pen keeps its last pattern.` });
      return;
    }
    this.update({ state: 'uploading', progress: 0, message: `Uploading the ${name} pattern…` });
    for (let attempt = 1; ; attempt += 1) {
      try {
        if (!await this.sendPattern(name, bytes, crc, info, transport, generation)) return;
        this.holds = key;
        this.update({ state: 'connected', pattern: name, progress: null,
          message: `${this.describePen(info, transport)}: ${name} pattern loaded `
            + `(${(bytes.length / 2 / info.sampleRate).toFixed(2)} s).` });
        return;
      } catch (error) {
        if (generation !== this.generation) return;
        // Once more (a lost frame, a late reply, a damaged chunk), unless the pen refused the
        // pattern itself: that would only be refused again.
        if (attempt < UPLOAD_TRIES && !error.refused) {
          this.update({ progress: 0,
            message: `Uploading the ${name} pattern again (${describe(error)})…` });
          continue;
        }
        this.update({ state: 'connected', progress: null,
          message: `Upload of the ${name} pattern failed: ${describe(error)}` });
        return;
      }
    }
  }

  /** PATTERN_BEGIN → ACK, the chunks, PATTERN_COMMIT → ACK (the pen keeps its old pattern
   *  until then). Resolves false when another connection overtook this one; throws PenError
   *  (`refused` set when the pen refused the pattern as such: too large, format, rate). */
  async sendPattern(name, bytes, crc, info, transport, generation) {
    const pid = crc & 0xffff;
    const refusal = (what, code) => {
      const error = new PenError(`The pen refused the ${name} pattern (${what}): `
        + `${NACK_TEXT[code] || `error ${code}`}; it keeps its last pattern.`);
      error.refused = [E_TOO_LARGE, E_BAD_FORMAT, E_BAD_RATE].includes(code);
      return error;
    };
    const fail = (what, reply) => {
      const [ftype, , payload] = reply;
      if (ftype === NACK) return refusal(what, unpackNack(payload)[1]);
      return new PenError(`The pen answered ${what} with frame type ${ftype}.`);
    };
    const acked = (reply, ftype) => reply[0] === ACK && unpackAck(reply[2]) === ftype;
    this.chunkRefused = null;
    const begin = await this.request(PATTERN_BEGIN,
      packPatternBegin(pid, bytes.length / 2, info.sampleRate, FORMAT_S16LE, crc),
      REPLY_MS, transport);
    if (!acked(begin, PATTERN_BEGIN)) throw fail('PATTERN_BEGIN', begin);
    const window = transport.kind === 'ble' ? BLE_UPLOAD_WINDOW : UPLOAD_WINDOW;
    let count = 0;
    for (let offset = 0; offset < bytes.length; offset += MAX_CHUNK) {
      if (generation !== this.generation) return false;
      const chunk = bytes.subarray(offset, offset + MAX_CHUNK);
      // Chunks go unanswered (a wrong one is NACKed): awaiting each write only paces them,
      // and lets a SET_STATE in between.
      await transport.write(encodeFrame(PATTERN_CHUNK, this.nextSeq(),
        packPatternChunk(offset, chunk)));
      count += 1;
      // Every `window` chunks the pen must have handled all so far (its PONG comes after
      // them): a link without flow control (Bluetooth writes without response) never runs
      // further ahead of the pen than its receive buffer holds, and a refused chunk stops the
      // upload early.
      if (count % window === 0) {
        await this.ping(REPLY_MS, transport);
        if (this.chunkRefused !== null) throw refusal('PATTERN_CHUNK', this.chunkRefused);
      }
      this.update({ progress: (offset + chunk.length) / bytes.length });
    }
    const commit = await this.request(PATTERN_COMMIT, packPatternCommit(pid), COMMIT_MS,
      transport);
    if (this.chunkRefused !== null) throw refusal('PATTERN_CHUNK', this.chunkRefused);
    if (!acked(commit, PATTERN_COMMIT)) throw fail('PATTERN_COMMIT', commit);
    return true;
  }

  // ---- the state ----

  /**
   * The page's pen state: playing (the pen is down and the modality is tactile), gain 0-1 (the
   * Eq. 1 gain over a_max), fadeMs (the ramp to it). Sent at once, latest wins.
   */
  setState(playing, gain, fadeMs = 5) {
    const g = Number.isFinite(gain) ? Math.min(Math.max(gain, 0), 1) : 0;
    this.wanted = { playing: Boolean(playing), gain: playing ? g : 0,
      fadeMs: Math.max(0, Math.min(65535, Math.round(fadeMs))) };
    this.changedAt = performance.now();
    this.sendState();
  }

  /** Send the wanted state if it differs from the last sent (or `again`); one write at a
   *  time, and a state that changed meanwhile goes right after. */
  sendState(again = false) {
    const transport = this.transport;
    if (!transport || !this.status.info) return;
    const { playing, gain, fadeMs } = this.wanted;
    const frame = [playing ? 1 : 0, Math.round(gain * GAIN_ONE), RATE_ONE, fadeMs];
    const same = this.sentState && frame.every((v, i) => v === this.sentState[i]);
    if (same && !again) return;
    const generation = this.generation;
    if (this.stateBusy === generation) {
      this.stateDirty = true;
      return;
    }
    this.stateBusy = generation;
    this.sentState = frame;
    transport.write(encodeFrame(SET_STATE, this.nextSeq(), packSetState(...frame)))
      .then(() => { this.status.sent += 1; })
      .catch(() => { // the disconnect is reported by the transport
        if (generation === this.generation) this.sentState = null;
      })
      .finally(() => {
        // Busy is per connection: a write of an older one that settles late (or never) holds
        // up no state of a later one.
        if (this.stateBusy !== generation) return;
        this.stateBusy = null;
        if (this.stateDirty) {
          this.stateDirty = false;
          this.sendState();
        }
      });
  }
}
