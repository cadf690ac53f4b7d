// @ts-check
// A pen driven straight from the page, over Web Serial (USB, pen-transport-serial.js) or Web
// Bluetooth (pen-transport-ble.js), with the codec of pen-protocol.js: for a lab where the pen
// is next to the tablet and the server is not.
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
// Timers run only while a pen is connected: the state refresh and the heartbeat start when a
// transport opens and stop when it is lost or let go of; the reconnect loop's waits end at
// disconnect() and close(). A link nobody connected, or one disconnected, holds no timer.

import {
  ACK, E_BAD_FORMAT, E_BAD_RATE, E_TOO_LARGE, E_VERSION, EV_BATTERY, EV_BOOT, EV_UNDERRUN, EVENT,
  FORMAT_S16LE, FrameDecoder, GAIN_ONE, HELLO, INFO, MAX_CHUNK, NACK, NACK_TEXT, PATTERN_BEGIN,
  PATTERN_CHUNK, PATTERN_COMMIT, PING, PONG, PROTOCOL_VERSION, RATE_ONE, SET_STATE, crc32,
  encodeFrame, packHello, packPatternBegin, packPatternChunk, packPatternCommit, packPing,
  packSetState, unpackAck, unpackEvent, unpackInfo, unpackNack, unpackPong,
} from './pen-protocol.js';
import { PenError, describe } from './pen-transport.js';
import { chooseBluetoothPen, hasBluetooth } from './pen-transport-ble.js';
import { SerialTransport, chooseSerialPort, hasSerial, watchPorts } from './pen-transport-serial.js';

const REPLY_MS = 1000; // a request's reply (INFO, ACK, PONG) must come within this
const COMMIT_MS = 3000; // the pen checks the CRC-32 of the whole pattern before it answers
const HELLO_TRIES = 3; // a pen that has just booted may miss the first HELLO
const REFRESH_MS = 1000; // the current state goes again this often (SET_STATE is unanswered)…
const REFRESH_FOR_MS = 3000; // …while the pen plays and for this long after the last change
const RETRY_MAX_MS = 1000; // reconnect backoff ceiling
const UPLOAD_TRIES = 2; // a failed upload is tried once more (not when the pen refused the pattern)
const HEARTBEAT_MS = 2000; // an idle link PINGs this often…
const HEARTBEAT_MISSES = 2; // …and a pen that misses this many PONGs in a row has hung
const CLOSE_WAIT_MS = 1000; // a hung pen's port may take long to close: reopen after this at most

/** @typedef {import('./pen-transport-serial.js').SerialTransport} SerialLink */
/** @typedef {import('./pen-transport-ble.js').BleTransport} BleLink */
/** @typedef {SerialLink | BleLink} Transport a byte pipe to the pen; `kind` tells which */
/** @typedef {import('./pen-protocol.js').Frame} Frame */

/**
 * The pen's INFO, as the link reports it.
 * @typedef {object} PenInfo
 * @property {number} protocol the protocol version the pen speaks
 * @property {string} firmware "major.minor.patch"
 * @property {number} sampleRate Hz of the pen's player: patterns are uploaded at this rate
 * @property {number} maxPatternBytes the largest pattern the pen holds, bytes
 * @property {number} features FEATURE_* bits
 * @property {string} name the pen's name (UTF-8, at most MAX_NAME bytes)
 */

/**
 * What the link shows: one object, replaced field by field.
 * @typedef {object} PenStatus
 * @property {'idle' | 'connecting' | 'connected' | 'uploading' | 'disconnected' | 'error'} state
 * @property {'usb' | 'ble' | null} kind
 * @property {string} message one line for the panel
 * @property {PenInfo | null} info the pen's INFO, or null until it said HELLO
 * @property {string | null} pattern the pen name whose pattern the pen holds
 * @property {number | null} progress 0-1 of an upload under way
 * @property {number | null} battery % from the Bluetooth Battery service
 * @property {number | null} batteryMv mV from the pen's battery EVENT
 * @property {number} sent SET_STATE frames written
 * @property {number} errors frames the decoder dropped
 * @property {number} underruns the pen's underrun count, from its EVENTs
 */

/**
 * A request waiting for its reply.
 * @typedef {object} Pending
 * @property {(frame: Frame) => void} resolve
 * @property {(error: Error) => void} reject
 * @property {number | undefined} timer
 */

/** @typedef {[playing: number, gain: number, rate: number, fadeMs: number]} StateFrame */

/**
 * What this browser can do (Chrome and Edge on a computer have both; Safari and Firefox have
 * neither).
 * @returns {{ serial: boolean, bluetooth: boolean }}
 */
export function support() {
  return { serial: hasSerial(), bluetooth: hasBluetooth() };
}

/**
 * The page's direct link to a pen.
 *
 * options.fetchPattern(name, rate) → ArrayBuffer of int16 LE samples at `rate` Hz (the page's
 * GET /api/pens/{name}/pen-pattern); options.onChange(status) whenever the status changes
 * (see PenStatus).
 *
 * heartbeatMs (default HEARTBEAT_MS) is how often an idle link PINGs; a change takes effect
 * from the next beat, or at once after scheduleBeat().
 */
export class PenLink {
  /**
   * @param {{ fetchPattern?: (name: string, rate: number) => Promise<ArrayBuffer>,
   *   onChange?: (status: PenStatus) => void }} [options]
   */
  constructor({ fetchPattern, onChange = () => {} } = {}) {
    this.fetchPattern = fetchPattern;
    this.onChange = onChange;
    /** @type {Transport | null} the open link, once it opened */
    this.transport = null;
    /** @type {Transport | null} the last transport started (the port that may come back) */
    this.lastTransport = null;
    this.decoder = new FrameDecoder();
    this.seq = 0;
    /** @type {Map<number, Pending>} seq → the request waiting for its reply */
    this.pending = new Map();
    this.wanted = { playing: false, gain: 0, fadeMs: 5 };
    this.changedAt = 0;
    /** @type {StateFrame | null} */
    this.sentState = null;
    /** @type {number | null} the generation whose SET_STATE write is under way */
    this.stateBusy = null;
    this.stateDirty = false;
    /** @type {number | null} the NACK code of a refused PATTERN_CHUNK of this upload */
    this.chunkRefused = null;
    /** @type {object | null} the token of the reconnect loop under way */
    this.reconnecting = null;
    this.heartbeatMs = HEARTBEAT_MS;
    this.missed = 0; // PONGs missed in a row
    /** @type {string | null} the page's pen (profile name) */
    this.pen = null;
    /** @type {string | null} `${pen}@${rate}#${crc32}` of the pattern the pen holds */
    this.holds = null;
    /** @type {string | null} the pen whose pattern is being uploaded */
    this.uploading = null;
    this.uploadAgain = false;
    this.userClosed = true;
    this.generation = 0; // bumps with each connection: stale async work gives up
    /** @type {PenStatus} */
    this.status = { state: 'idle', kind: null, message: 'No pen connected.', info: null,
      pattern: null, progress: null, battery: null, batteryMv: null, sent: 0, errors: 0,
      underruns: 0 };
    /** @type {number | null} the state refresh (setInterval), while a pen is connected */
    this.refresh = null;
    /** @type {number | null} the next heartbeat (setTimeout), while a pen is connected */
    this.heartbeat = null;
    /** @type {Set<() => void>} what ends each wait of the reconnect loop */
    this.pauses = new Set();
    this.unwatch = watchPorts((port) => this.portBack(port));
  }

  /** @param {Partial<PenStatus>} fields */
  update(fields) {
    Object.assign(this.status, fields);
    this.onChange(this.status);
  }

  get connected() {
    return this.status.state === 'connected' || this.status.state === 'uploading';
  }

  // ---- timers ----

  /** The state refresh and the heartbeat: they run while a transport is open. */
  startTimers() {
    if (this.refresh === null) {
      this.refresh = setInterval(() => {
        const recent = performance.now() - this.changedAt < REFRESH_FOR_MS;
        if (this.wanted.playing || recent) this.sendState(true);
      }, REFRESH_MS);
    }
    this.scheduleBeat();
  }

  stopTimers() {
    if (this.refresh !== null) clearInterval(this.refresh);
    if (this.heartbeat !== null) clearTimeout(this.heartbeat);
    this.refresh = null;
    this.heartbeat = null;
  }

  /**
   * A wait that disconnect() and close() cut short, so that no timer outlives the link.
   * @param {number} ms
   * @returns {Promise<void>}
   */
  pause(ms) {
    return new Promise((resolve) => {
      const end = () => {
        clearTimeout(timer);
        this.pauses.delete(end);
        resolve();
      };
      const timer = setTimeout(end, ms);
      this.pauses.add(end);
    });
  }

  /** End every wait of the reconnect loop now (it then finds it has nothing to do). */
  endPauses() {
    for (const end of [...this.pauses]) end();
  }

  // ---- connecting ----

  /** Ask for a serial port (the browser's chooser; call from a click) and connect to it.
   *  @returns {Promise<boolean>} false when the user closed the chooser */
  async connectSerial() {
    const transport = await chooseSerialPort();
    if (!transport) return false;
    await this.start(transport);
    return true;
  }

  /** Ask for a pen over Bluetooth (the browser's chooser; call from a click) and connect.
   *  @returns {Promise<boolean>} false when the user closed the chooser */
  async connectBluetooth() {
    const transport = await chooseBluetoothPen();
    if (!transport) return false;
    await this.start(transport);
    return true;
  }

  /** Let go of the pen (it is told to stop first). */
  async disconnect() {
    this.userClosed = true;
    this.reconnecting = null;
    this.endPauses();
    const transport = this.transport;
    this.generation += 1;
    if (transport && this.connected) {
      try {
        await transport.write(encodeFrame(SET_STATE, this.nextSeq(),
          packSetState(0, 0, RATE_ONE, this.wanted.fadeMs)));
      } catch { /* gone already */ }
    }
    this.transport = null;
    this.stopTimers();
    this.failPending('disconnected');
    if (transport) await transport.close();
    this.update({ state: 'idle', kind: null, message: 'No pen connected.', info: null,
      pattern: null, progress: null, battery: null, batteryMv: null });
  }

  /** Done with the link for good (the page goes away, a test): let go of the pen and stop
   *  listening for serial ports; no timer nor listener stays behind. */
  async close() {
    this.unwatch();
    this.unwatch = () => {};
    await this.disconnect();
  }

  /** @param {Transport} transport a transport not yet open */
  async start(transport) {
    if (this.transport) await this.disconnect();
    this.reconnecting = null;
    this.endPauses();
    this.userClosed = false;
    this.lastTransport = transport;
    this.update({ state: 'connecting', kind: transport.kind, info: null, pattern: null,
      progress: null, message: `Connecting to ${transport.label}…` });
    await this.open(transport);
  }

  /**
   * Open `transport`, say hello, send the state, upload. Failures become the status (while
   * `retrying` — the reason the pen was lost — it stays "disconnected, reconnecting").
   * @param {Transport} transport
   * @param {string | null} [retrying]
   * @returns {Promise<boolean>} whether the pen is connected
   */
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
      this.startTimers();
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
      this.stopTimers();
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

  /**
   * @param {PenInfo} info
   * @param {Transport} transport
   */
  describePen(info, transport) {
    const khz = (info.sampleRate / 1000).toFixed(info.sampleRate % 1000 ? 1 : 0);
    return `${info.name || 'Pen'} on ${transport.label} `
      + `(firmware ${info.firmware}, ${khz}\u00a0kHz)`;
  }

  /**
   * @param {string} reason
   * @param {string} [detail]
   */
  lostMessage(reason, detail = '') {
    let next = '';
    if (!this.userClosed) {
      next = this.reconnecting || this.status.kind !== 'usb' ? '; reconnecting…'
        : '; it reconnects when the port is back';
    }
    const text = `Pen disconnected (${reason})${next}${detail ? ` (${detail})` : ''}`;
    return `${text}${text.endsWith('…') ? '' : '.'} The page's own sound goes on.`;
  }

  /**
   * HELLO → INFO (USB), or the INFO characteristic (Bluetooth); checks the version.
   * @param {Transport} transport
   * @returns {Promise<PenInfo>}
   */
  async hello(transport) {
    let raw;
    if (transport.kind === 'ble') {
      raw = await transport.readInfo();
    } else {
      // A lone delimiter ends whatever partial frame the pen holds (a half-written frame
      // from before, a terminal's keystrokes) so that HELLO is decoded on its own.
      await transport.write(Uint8Array.of(0));
      /** @type {Frame | null} */
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
        throw new PenError(code === E_VERSION
          ? `This pen does not speak protocol ${PROTOCOL_VERSION}, which this page speaks: `
            + 'update the pen\'s firmware (or the page) so both match.'
          : `The pen refused HELLO: ${NACK_TEXT[code] || `error ${code}`}.`,
        { version: code === E_VERSION });
      }
      if (ftype !== INFO) throw new PenError(`The pen answered HELLO with frame type ${ftype}.`);
      raw = payload;
    }
    const [protocol, major, minor, patch, sampleRate, maxPatternBytes, features, name] =
      unpackInfo(raw);
    if (protocol !== PROTOCOL_VERSION) {
      throw new PenError(`This pen speaks protocol ${protocol}; this page speaks `
        + `${PROTOCOL_VERSION}: update the `
        + `${protocol < PROTOCOL_VERSION ? 'pen\'s firmware' : 'page'} so both match.`,
      { version: true });
    }
    return { protocol, firmware: `${major}.${minor}.${patch}`, sampleRate, maxPatternBytes,
      features, name };
  }

  /**
   * `transport` is gone. Bluetooth (or `reopen`) connects again to the same device or port
   * once `closing` (the old link's close) is done; USB waits for the port to come back.
   * @param {Transport} transport
   * @param {string} reason
   * @param {boolean} [reopen]
   * @param {Promise<void> | null} [closing]
   */
  lost(transport, reason, reopen = transport.kind === 'ble', closing = null) {
    if (transport !== this.transport) return;
    this.transport = null;
    this.stopTimers();
    this.generation += 1;
    this.failPending(reason);
    const token = reopen && !this.userClosed ? {} : null;
    this.reconnecting = token;
    this.endPauses(); // an older reconnect loop ends now
    // What the pen is, holds and plays is unknown until it says HELLO again: nothing may go
    // out with the INFO of before (the state refresh, a change of pen).
    this.update({ state: 'disconnected', info: null, progress: null, pattern: null,
      message: this.lostMessage(reason) });
    if (token) this.reconnect(transport, reason, token, closing);
  }

  /**
   * The pen stopped answering (hung, or its end of the link did): let go of the link and
   * connect to the same device or port again.
   * @param {Transport} transport
   * @param {string} reason
   */
  hangUp(transport, reason) {
    if (transport !== this.transport) return;
    const closing = transport.close().catch(() => {});
    this.lost(transport, reason, true, closing);
  }

  /**
   * Connect to the same Bluetooth device or serial port again, backing off to RETRY_MAX_MS,
   * until it works, the user disconnects or connects another pen (or the port comes back).
   * @param {Transport} old the transport that was lost
   * @param {string} reason
   * @param {object} token this loop's; it stops when the link's `reconnecting` is another
   * @param {Promise<void> | null} [closing]
   */
  async reconnect(old, reason, token, closing = null) {
    const going = () => !this.userClosed && this.reconnecting === token && !this.transport;
    try {
      if (closing) await Promise.race([closing, this.pause(CLOSE_WAIT_MS)]);
      let wait = 200;
      while (going()) {
        await this.pause(wait);
        if (!going()) return;
        if (await this.open(old.again(), reason)) return;
        wait = Math.min(wait * 2, RETRY_MAX_MS);
      }
    } finally {
      if (this.reconnecting === token) this.reconnecting = null;
    }
  }

  /**
   * USB: a port the user gave before is back (the pen was plugged in again or rebooted).
   * @param {SerialPort} port
   */
  portBack(port) {
    const last = this.lastTransport;
    if (this.userClosed || this.transport || !last || last.kind !== 'usb') return;
    if (!last.isPort(port)) return;
    this.start(new SerialTransport(port)).catch(() => {});
  }

  // ---- frames ----

  nextSeq() {
    const seq = this.seq;
    this.seq = (this.seq + 1) & 0xff;
    return seq;
  }

  /**
   * @param {Uint8Array} bytes what the transport read
   * @param {Transport} transport
   */
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

  /**
   * A NACK nobody waits for: a refused PATTERN_CHUNK fails the upload at its next PONG.
   * @param {Uint8Array} payload
   */
  refused(payload) {
    try {
      const [ftype, code] = unpackNack(payload);
      if (ftype === PATTERN_CHUNK && this.uploading && this.chunkRefused === null) {
        this.chunkRefused = code;
      }
    } catch { /* a malformed NACK says nothing */ }
  }

  /** @param {Uint8Array} payload */
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

  /**
   * Send a frame and wait for the reply with its seq.
   * @param {number} ftype
   * @param {Uint8Array} payload
   * @param {number} [timeoutMs]
   * @param {Transport | null} [transport]
   * @returns {Promise<Frame>} [ftype, seq, payload] of the reply
   */
  request(ftype, payload, timeoutMs = REPLY_MS, transport = this.transport) {
    if (!transport) return Promise.reject(new PenError('no pen connected'));
    const seq = this.nextSeq();
    return new Promise((resolve, reject) => {
      /** @type {Pending} */
      const entry = { resolve, reject, timer: undefined };
      // Seqs wrap at 256: a stale timer or write error must not take a newer request's entry.
      const drop = () => {
        if (this.pending.get(seq) !== entry) return false;
        this.pending.delete(seq);
        clearTimeout(entry.timer);
        return true;
      };
      entry.timer = setTimeout(() => {
        drop();
        reject(new PenError(`the pen did not answer within ${timeoutMs} ms`, { timeout: true }));
      }, timeoutMs);
      this.pending.set(seq, entry);
      transport.write(encodeFrame(ftype, seq, payload)).catch((error) => {
        if (drop()) reject(error);
      });
    });
  }

  /** @param {string} reason */
  failPending(reason) {
    for (const { reject, timer } of this.pending.values()) {
      clearTimeout(timer);
      reject(new PenError(reason));
    }
    this.pending.clear();
  }

  /**
   * PING → PONG.
   * @param {number} [timeoutMs]
   * @param {Transport | null} [transport]
   * @returns {Promise<{ roundTripMs: number, deviceUs: number }>} the round trip (ms) and the
   *   pen's clock (µs, wraps at 2**32)
   */
  async ping(timeoutMs = REPLY_MS, transport = this.transport) {
    const token = (Math.random() * 0x100000000) >>> 0;
    const started = performance.now();
    const [ftype, , payload] = await this.request(PING, packPing(token), timeoutMs, transport);
    if (ftype !== PONG) throw new PenError(`the pen answered PING with frame type ${ftype}`);
    const [echo, deviceUs] = unpackPong(payload);
    if (echo !== token) throw new PenError('the pen answered another PING');
    return { roundTripMs: performance.now() - started, deviceUs };
  }

  /** The next heartbeat in heartbeatMs (one chain of them: a call replaces the next beat);
   *  none while no transport is open (opening one starts the chain). */
  scheduleBeat() {
    if (this.heartbeat !== null) clearTimeout(this.heartbeat);
    this.heartbeat = null;
    if (!this.transport) return;
    const next = setTimeout(() => {
      this.beat().finally(() => {
        if (this.heartbeat === next) this.scheduleBeat(); // not replaced nor stopped meanwhile
      });
    }, this.heartbeatMs);
    this.heartbeat = next;
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

  /**
   * The page's pen changed: its pattern goes to the pen (when one is connected).
   * @param {string} name the pen's profile name
   */
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

  /**
   * Fetch `name`'s pattern at the pen's rate and upload it, unless the pen holds it already.
   * Every outcome becomes the status.
   * @param {string} name
   * @param {PenInfo} info
   */
  async upload(name, info) {
    const transport = this.transport;
    const generation = this.generation;
    if (!transport || !this.fetchPattern) return;
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
        if (attempt < UPLOAD_TRIES && !(error instanceof PenError && error.refused)) {
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

  /**
   * PATTERN_BEGIN → ACK, the chunks, PATTERN_COMMIT → ACK (the pen keeps its old pattern
   * until then). Throws PenError (`refused` set when the pen refused the pattern as such: too
   * large, format, rate).
   * @param {string} name
   * @param {Uint8Array} bytes the pattern, int16 LE
   * @param {number} crc its CRC-32
   * @param {PenInfo} info
   * @param {Transport} transport
   * @param {number} generation the connection this upload belongs to
   * @returns {Promise<boolean>} false when another connection overtook this one
   */
  async sendPattern(name, bytes, crc, info, transport, generation) {
    const pid = crc & 0xffff;
    /**
     * @param {string} what
     * @param {number} code
     */
    const refusal = (what, code) => new PenError(`The pen refused the ${name} pattern (${what}): `
      + `${NACK_TEXT[code] || `error ${code}`}; it keeps its last pattern.`,
    { refused: [E_TOO_LARGE, E_BAD_FORMAT, E_BAD_RATE].includes(code) });
    /**
     * @param {string} what
     * @param {Frame} reply
     */
    const fail = (what, reply) => {
      const [ftype, , payload] = reply;
      if (ftype === NACK) return refusal(what, unpackNack(payload)[1]);
      return new PenError(`The pen answered ${what} with frame type ${ftype}.`);
    };
    /**
     * @param {Frame} reply
     * @param {number} ftype
     */
    const acked = (reply, ftype) => reply[0] === ACK && unpackAck(reply[2]) === ftype;
    this.chunkRefused = null;
    const begin = await this.request(PATTERN_BEGIN,
      packPatternBegin(pid, bytes.length / 2, info.sampleRate, FORMAT_S16LE, crc),
      REPLY_MS, transport);
    if (!acked(begin, PATTERN_BEGIN)) throw fail('PATTERN_BEGIN', begin);
    let count = 0;
    for (let offset = 0; offset < bytes.length; offset += MAX_CHUNK) {
      if (generation !== this.generation) return false;
      const chunk = bytes.subarray(offset, offset + MAX_CHUNK);
      // Chunks go unanswered (a wrong one is NACKed): awaiting each write only paces them,
      // and lets a SET_STATE in between.
      await transport.write(encodeFrame(PATTERN_CHUNK, this.nextSeq(),
        packPatternChunk(offset, chunk)));
      count += 1;
      // Every uploadWindow chunks the pen must have handled all so far (its PONG comes after
      // them): a link without flow control (Bluetooth writes without response) never runs
      // further ahead of the pen than its receive buffer holds, and a refused chunk stops the
      // upload early.
      if (count % transport.uploadWindow === 0) {
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
   * @param {boolean} playing
   * @param {number} gain
   * @param {number} [fadeMs]
   */
  setState(playing, gain, fadeMs = 5) {
    const g = Number.isFinite(gain) ? Math.min(Math.max(gain, 0), 1) : 0;
    this.wanted = { playing: Boolean(playing), gain: playing ? g : 0,
      fadeMs: Math.max(0, Math.min(65535, Math.round(fadeMs))) };
    this.changedAt = performance.now();
    this.sendState();
  }

  /**
   * Send the wanted state if it differs from the last sent (or `again`); one write at a time,
   * and a state that changed meanwhile goes right after.
   * @param {boolean} [again]
   */
  sendState(again = false) {
    const transport = this.transport;
    if (!transport || !this.status.info) return;
    const { playing, gain, fadeMs } = this.wanted;
    /** @type {StateFrame} */
    const frame = [playing ? 1 : 0, Math.round(gain * GAIN_ONE), RATE_ONE, fadeMs];
    const sent = this.sentState;
    const same = sent !== null && frame.every((v, i) => v === sent[i]);
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
