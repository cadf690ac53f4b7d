// @ts-check
// The pen over Web Serial (USB): a byte pipe for pen-link.js, and the browser's port chooser.
// It knows nothing of frames: pen-protocol.js's decoder joins whatever pieces the reads give.

import { PenError, cancelled, describe } from './pen-transport.js';

/** 8N1 at this rate: USB CDC ignores it; a UART bridge (or the Due's programming port) needs
 *  it. As realpen.device.transport BAUD_RATE. */
export const BAUD_RATE = 115200;
/** Pattern chunks an upload sends before it waits for the pen (a PING answered): ≈ 2.9 KB.
 *  As realpen.device.transport UPLOAD_WINDOW (tests/test_js_constants.py checks both). */
export const UPLOAD_WINDOW = 16;

/** @returns {boolean} whether this browser has Web Serial */
export const hasSerial = () => typeof navigator !== 'undefined' && 'serial' in navigator;

/** @param {number} n */
const hex4 = (n) => n.toString(16).padStart(4, '0');

/** A serial port opened at 115200 8N1: `write(bytes)`, `close()`; the reader loop hands
 *  every chunk to `onData` and calls `onClose(reason)` once when the port goes away. */
export class SerialTransport {
  /** @param {SerialPort} port */
  constructor(port) {
    this.port = port;
    /** @readonly */
    this.kind = /** @type {const} */ ('usb');
    /** Chunks an upload may run ahead of the pen's answer. @readonly */
    this.uploadWindow = UPLOAD_WINDOW;
    this.closed = false;
    /** @type {number | null} Battery Level (%): a serial pen has no battery service */
    this.battery = null;
    /** @type {(bytes: Uint8Array) => void} */
    this.onData = () => {};
    /** @type {(reason: string) => void} */
    this.onClose = () => {};
    /** @type {WritableStreamDefaultWriter<Uint8Array> | null} */
    this.writer = null;
    /** @type {ReadableStreamDefaultReader<Uint8Array> | null} */
    this.reader = null;
    /** @type {Promise<void> | null} the reader loop */
    this.reading = null;
  }

  /**
   * Open the port and start reading.
   * @param {(bytes: Uint8Array) => void} onData every chunk read, in order
   * @param {(reason: string) => void} onClose once, when the port goes away by itself
   */
  async open(onData, onClose) {
    this.onData = onData;
    this.onClose = onClose;
    await this.port.open({ baudRate: BAUD_RATE, dataBits: 8, stopBits: 1, parity: 'none',
      flowControl: 'none' });
    if (!this.port.writable) throw new PenError('the port cannot be written');
    this.writer = this.port.writable.getWriter();
    this.reading = this.readLoop();
  }

  async readLoop() {
    let reason = 'the port closed';
    let stream = this.port.readable;
    while (!this.closed && stream) {
      reason = 'the port closed';
      const reader = stream.getReader();
      this.reader = reader;
      try {
        for (;;) {
          const { value, done } = await reader.read();
          if (done) break;
          if (value && value.length) this.onData(value);
        }
      } catch (error) {
        // A recoverable read error (framing, parity, break, buffer overrun) ends this stream
        // only: the port hands out a new one and reading goes on. A lost device leaves none.
        reason = describe(error);
      } finally {
        reader.releaseLock();
      }
      const next = this.port.readable;
      stream = next === stream ? null : next; // the same stream again has ended for good
    }
    this.lost(reason);
  }

  /** @param {string} reason */
  lost(reason) {
    if (this.closed) return;
    this.closed = true;
    this.onClose(reason);
  }

  /** @param {Uint8Array<ArrayBuffer>} bytes */
  async write(bytes) {
    if (this.closed || !this.writer) throw new PenError('the port is closed');
    await this.writer.write(bytes);
  }

  async close() {
    this.closed = true;
    try { if (this.reader) await this.reader.cancel(); } catch { /* already gone */ }
    try { await this.reading; } catch { /* already reported */ }
    try { if (this.writer) this.writer.releaseLock(); } catch { /* already released */ }
    try { await this.port.close(); } catch { /* already closed */ }
  }

  /** A new transport on the same port, to connect again after this one was lost. */
  again() {
    return new SerialTransport(this.port);
  }

  /**
   * Whether `port` is this transport's port back again: the same object, or a port of the
   * same USB vendor and product (the pen was plugged in again or rebooted).
   * @param {SerialPort} port
   */
  isPort(port) {
    if (port === this.port) return true;
    const a = info(this.port);
    const b = info(port);
    return a.usbVendorId === b.usbVendorId && a.usbProductId === b.usbProductId;
  }

  /** How the status line names it: "USB 2e8a:0005", or "USB serial". */
  get label() {
    const { usbVendorId, usbProductId } = info(this.port);
    return usbVendorId !== undefined
      ? `USB ${hex4(usbVendorId)}:${hex4(usbProductId || 0)}`
      : 'USB serial';
  }
}

/**
 * @param {SerialPort} port
 * @returns {SerialPortInfo}
 */
function info(port) {
  return port.getInfo ? port.getInfo() : {};
}

/**
 * Ask the user for a serial port (the browser's chooser; call from a click).
 * @returns {Promise<SerialTransport | null>} the port's transport (not yet open), or null
 *   when the user closed the chooser
 */
export async function chooseSerialPort() {
  if (!hasSerial()) throw new PenError('This browser has no Web Serial.');
  try {
    return new SerialTransport(await navigator.serial.requestPort());
  } catch (error) {
    if (cancelled(error)) return null;
    throw error;
  }
}

/**
 * Call `listener(port)` whenever a port the user gave this page before comes back (plugged
 * in again, the pen rebooted).
 * @param {(port: SerialPort) => void} listener
 * @returns {() => void} what stops listening
 */
export function watchPorts(listener) {
  if (!hasSerial()) return () => {};
  /** @param {Event} event */
  const connected = (event) => listener(/** @type {SerialPort} */ (event.target));
  navigator.serial.addEventListener('connect', connected);
  return () => navigator.serial.removeEventListener('connect', connected);
}
