// @ts-check
// The pen over Web Bluetooth: its GATT service as a byte pipe for pen-link.js, and the
// browser's device chooser.
//
// RX is written without response, a frame per write (a frame is at most ~192 bytes: one write
// at the ATT MTU of 247 the firmware asks for). The page cannot see the MTU Chrome negotiated:
// when a write fails twice the link goes on in smaller pieces (BLE_PIECES), which the pen's
// decoder joins again, as pen-protocol.js's decoder joins TX notifications: pieces of the same
// byte stream as USB. Writes without response have no flow control: an upload waits for a PONG
// every BLE_UPLOAD_WINDOW chunks so that it never runs further ahead of the pen than the pen's
// buffer holds.

import { BLE_INFO, BLE_RX, BLE_SERVICE, BLE_TX } from './pen-protocol.js';
import { PenError, cancelled, sleep } from './pen-transport.js';

/** Bytes per RX write: 244 is one write at ATT MTU 247; 182 at the MTU of 185 some hosts
 *  (macOS, iOS) settle on; 20 at the minimum MTU of 23. */
export const BLE_PIECES = [244, 182, 20];
/** Pattern chunks an upload sends before it waits for the pen (≈ 760 B): the Pico W's receive
 *  buffer holds 4 KB and drains slowly. As realpen.device.transport BLE_UPLOAD_WINDOW
 *  (tests/test_js_constants.py checks both). */
export const BLE_UPLOAD_WINDOW = 4;
const WRITE_RETRY_MS = 20; // a failed write goes again after this

/** @returns {boolean} whether this browser has Web Bluetooth */
export const hasBluetooth = () => typeof navigator !== 'undefined' && 'bluetooth' in navigator;

/**
 * @param {DataView} value
 * @returns {Uint8Array}
 */
const bytesOf = (value) => new Uint8Array(value.buffer, value.byteOffset, value.byteLength);

/** The pen's GATT service: RX written without response, TX notifications into `onData`,
 *  INFO read; `onClose(reason)` when the device disconnects. */
export class BleTransport {
  /** @param {BluetoothDevice} device */
  constructor(device) {
    this.device = device;
    /** @readonly */
    this.kind = /** @type {const} */ ('ble');
    /** Chunks an upload may run ahead of the pen's answer. @readonly */
    this.uploadWindow = BLE_UPLOAD_WINDOW;
    this.closed = false;
    this.piece = 0; // index into BLE_PIECES
    /** @type {Promise<unknown>} the write under way: one GATT operation at a time */
    this.queue = Promise.resolve();
    /** @type {number | null} Battery Level (%), or null when the pen has no battery service */
    this.battery = null;
    /** @type {(bytes: Uint8Array) => void} */
    this.onData = () => {};
    /** @type {(reason: string) => void} */
    this.onClose = () => {};
    /** @type {BluetoothRemoteGATTCharacteristic | null} */
    this.rx = null;
    /** @type {BluetoothRemoteGATTCharacteristic | null} */
    this.tx = null;
    /** @type {BluetoothRemoteGATTCharacteristic | null} */
    this.info = null;
    this.disconnected = () => this.lost('Bluetooth connection lost');
    /** @param {Event} event */
    this.notified = (event) => {
      const { value } = /** @type {BluetoothRemoteGATTCharacteristic} */ (event.target);
      if (value) this.onData(bytesOf(value));
    };
  }

  /**
   * Connect to the device's GATT server and subscribe to TX.
   * @param {(bytes: Uint8Array) => void} onData every notification, in order
   * @param {(reason: string) => void} onClose once, when the device disconnects by itself
   */
  async open(onData, onClose) {
    this.onData = onData;
    this.onClose = onClose;
    this.closed = false;
    this.device.addEventListener('gattserverdisconnected', this.disconnected);
    const gatt = this.device.gatt;
    if (!gatt) throw new PenError('this Bluetooth device has no GATT server');
    const server = await gatt.connect();
    const service = await server.getPrimaryService(BLE_SERVICE);
    this.rx = await service.getCharacteristic(BLE_RX);
    this.tx = await service.getCharacteristic(BLE_TX);
    this.info = await service.getCharacteristic(BLE_INFO);
    this.tx.addEventListener('characteristicvaluechanged', this.notified);
    await this.tx.startNotifications();
    this.battery = await this.readBattery(server);
  }

  /**
   * The standard Battery Level (%), or null when the pen has no battery service.
   * @param {BluetoothRemoteGATTServer} server
   * @returns {Promise<number | null>}
   */
  async readBattery(server) {
    try {
      const service = await server.getPrimaryService('battery_service');
      const level = await (await service.getCharacteristic('battery_level')).readValue();
      return level.getUint8(0);
    } catch { return null; }
  }

  /** The INFO characteristic: the INFO payload that HELLO answers over USB. */
  async readInfo() {
    if (!this.info) throw new PenError('the pen is not connected');
    return bytesOf(await this.info.readValue());
  }

  /** @param {string} reason */
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

  /**
   * Writes go one after another (a GATT operation at a time), each in pieces.
   * @param {Uint8Array<ArrayBuffer>} bytes
   * @returns {Promise<void>}
   */
  write(bytes) {
    const run = this.queue.then(() => this.writePieces(bytes));
    this.queue = run.catch(() => {});
    return run;
  }

  /** @param {Uint8Array<ArrayBuffer>} bytes */
  async writePieces(bytes) {
    let at = 0;
    let failed = 0; // failures of this piece at this size
    while (at < bytes.length) {
      if (this.closed || !this.rx) throw new PenError('the pen disconnected');
      const piece = bytes.subarray(at, at + BLE_PIECES[this.piece]);
      try {
        await this.rx.writeValueWithoutResponse(piece);
      } catch (error) {
        if (this.closed || !this.device.gatt || !this.device.gatt.connected) throw error;
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
    try {
      if (this.device.gatt && this.device.gatt.connected) this.device.gatt.disconnect();
    } catch { /* gone */ }
  }

  /** A new transport to the same device, to connect again after this one was lost. */
  again() {
    return new BleTransport(this.device);
  }

  /** How the status line names it. */
  get label() {
    return 'Bluetooth';
  }
}

/**
 * Ask the user for a pen over Bluetooth (the browser's chooser; call from a click).
 * @returns {Promise<BleTransport | null>} the pen's transport (not yet open), or null when the
 *   user closed the chooser
 */
export async function chooseBluetoothPen() {
  if (!hasBluetooth()) throw new PenError('This browser has no Web Bluetooth.');
  try {
    return new BleTransport(await navigator.bluetooth.requestDevice({
      filters: [{ services: [BLE_SERVICE] }],
      optionalServices: ['battery_service', 'device_information'],
    }));
  } catch (error) {
    if (cancelled(error)) return null;
    throw error;
  }
}
