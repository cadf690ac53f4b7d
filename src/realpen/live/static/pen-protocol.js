// @ts-check
// The pen protocol for the page: the same codec as realpen/device/protocol.py (docs/protocol.md),
// byte for byte, so the page can speak to a pen over Web Serial or Web Bluetooth itself.
//
// A frame on the wire is COBS([type u8][seq u8][payload][CRC-16/CCITT-FALSE of the rest, LE])
// followed by one 0x00 delimiter. Payloads are little-endian fixed structs. The same test vectors
// (tests/data/protocol_vectors.json) run through this module in Chromium and through
// protocol.py in Python.
//
// Bytes are Uint8Arrays throughout. The unpack functions return arrays in the order of
// protocol.py's tuples (unpackInfo returns the eight INFO fields) and throw ProtocolError on a
// payload of the wrong length, where protocol.py raises ValueError.

/**
 * Bytes as the codec returns them.
 * @typedef {Uint8Array<ArrayBuffer>} Bytes
 */
/**
 * Bytes as the codec takes them: a Uint8Array, an ArrayBuffer, any view of one, or an array of
 * byte values.
 * @typedef {Uint8Array | ArrayBuffer | ArrayBufferView | number[]} BytesLike
 */
/**
 * A decoded frame: its type, sequence number and payload.
 * @typedef {[ftype: number, seq: number, payload: Bytes]} Frame
 */

export const PROTOCOL_VERSION = 1;
export const MAX_FRAME = 256; // largest decoded frame (type + seq + payload + CRC), bytes
export const MAX_CHUNK = 180; // pattern bytes per PATTERN_CHUNK: a frame fits one BLE write

export const HELLO = 0x01;
export const INFO = 0x02;
export const PATTERN_BEGIN = 0x10;
export const PATTERN_CHUNK = 0x11;
export const PATTERN_COMMIT = 0x12;
export const SET_STATE = 0x20;
export const PING = 0x30;
export const PONG = 0x31;
export const ACK = 0x40;
export const NACK = 0x41;
export const EVENT = 0x50;
export const CAPTURE_START = 0x60;
export const CAPTURE_STOP = 0x61;
export const SAMPLES = 0x62;

export const E_UNKNOWN_TYPE = 1;
export const E_BAD_LENGTH = 2;
export const E_VERSION = 3;
export const E_TOO_LARGE = 4;
export const E_BAD_FORMAT = 5;
export const E_BAD_OFFSET = 6;
export const E_CRC = 7;
export const E_INCOMPLETE = 8;
export const E_NO_UPLOAD = 9;
export const E_BAD_RATE = 10;
export const E_BAD_STATE = 11;
export const E_NO_SENSOR = 12;
export const E_BAD_CAPTURE = 13;

/** @type {Readonly<Record<number, string>>} */
export const NACK_TEXT = {
  [E_UNKNOWN_TYPE]: 'unknown frame type',
  [E_BAD_LENGTH]: 'payload of the wrong length',
  [E_VERSION]: 'protocol version not supported',
  [E_TOO_LARGE]: 'pattern larger than the pen holds',
  [E_BAD_FORMAT]: 'sample format not supported',
  [E_BAD_OFFSET]: 'pattern chunk out of order',
  [E_CRC]: 'pattern CRC-32 mismatch',
  [E_INCOMPLETE]: 'pattern upload incomplete',
  [E_NO_UPLOAD]: 'no pattern upload under way',
  [E_BAD_RATE]: 'sample rate not supported',
  [E_BAD_STATE]: 'state value out of range',
  [E_NO_SENSOR]: 'the pen has no accelerometer',
  [E_BAD_CAPTURE]: 'capture range or rate not supported',
};

/** @type {Readonly<Record<number, string>>} */
export const TYPE_NAMES = {
  [HELLO]: 'HELLO', [INFO]: 'INFO', [PATTERN_BEGIN]: 'PATTERN_BEGIN',
  [PATTERN_CHUNK]: 'PATTERN_CHUNK', [PATTERN_COMMIT]: 'PATTERN_COMMIT', [SET_STATE]: 'SET_STATE',
  [PING]: 'PING', [PONG]: 'PONG', [ACK]: 'ACK', [NACK]: 'NACK', [EVENT]: 'EVENT',
  [CAPTURE_START]: 'CAPTURE_START', [CAPTURE_STOP]: 'CAPTURE_STOP', [SAMPLES]: 'SAMPLES',
};

export const EV_BOOT = 1; // value: firmware boot count or 0
export const EV_UNDERRUN = 2; // value: underruns so far
export const EV_BATTERY = 3; // value: battery voltage in mV
export const EV_PATTERN = 4; // value: id of the pattern now playing
export const EV_DECODE_ERRORS = 5; // value: frames dropped so far
export const EV_OVERRUN = 6; // value: sensor FIFO overruns in this capture so far
export const EV_CAPTURE_DROPPED = 7; // value: SAMPLES blocks of this capture not sent so far

/** @type {Readonly<Record<number, string>>} */
export const EVENT_NAMES = {
  [EV_BOOT]: 'boot', [EV_UNDERRUN]: 'underrun', [EV_BATTERY]: 'battery', [EV_PATTERN]: 'pattern',
  [EV_DECODE_ERRORS]: 'decode_errors', [EV_OVERRUN]: 'overrun',
  [EV_CAPTURE_DROPPED]: 'capture_dropped',
};

export const FORMAT_S16LE = 1;
export const FEATURE_USB = 1;
export const FEATURE_BLE = 2;
export const FEATURE_BATTERY = 4;
export const FEATURE_RATE = 8;
export const FEATURE_ACCEL = 16; // an accelerometer (LIS3DH) the host can capture from

// Capture: the LIS3DH's full-scale ranges (g) and output rates (Hz); 1344 Hz is the method's.
/** @type {readonly number[]} */
export const CAPTURE_RANGES = Object.freeze([2, 4, 8, 16]);
/** @type {readonly number[]} */
export const CAPTURE_RATES = Object.freeze([1, 10, 25, 50, 100, 200, 400, 1344]);
export const CAPTURE_RATE = 1344;
export const MAX_BLOCK_SAMPLES = 32; // the LIS3DH FIFO depth
export const SAMPLE_BYTES = 6; // x, y, z int16 LE, left-justified as the sensor gives them
export const SAMPLES_OVERRUN = 1; // SAMPLES flags bit: the FIFO overran before this block

export const GAIN_ONE = 65535; // SET_STATE gain: 65535 = the firmware's capped full drive
export const RATE_ONE = 4096; // SET_STATE rate, Q12 playback-rate factor
export const RATE_MIN = 1024;
export const RATE_MAX = 16384;

export const BLE_SERVICE = '7e570001-2f5c-4b0a-9c1e-8d3f5a6b7c10';
export const BLE_RX = '7e570002-2f5c-4b0a-9c1e-8d3f5a6b7c10'; // host → pen, write w/o response
export const BLE_TX = '7e570003-2f5c-4b0a-9c1e-8d3f5a6b7c10'; // pen → host, notify
export const BLE_INFO = '7e570004-2f5c-4b0a-9c1e-8d3f5a6b7c10'; // read: the INFO payload

export const MAX_NAME = 32; // bytes of the pen's UTF-8 name in INFO

/** Bad bytes: a malformed COBS block or a payload of the wrong length (ValueError in Python). */
export class ProtocolError extends Error {
  /** @param {string} message */
  constructor(message) {
    super(message);
    this.name = 'ProtocolError';
  }
}

/**
 * @param {BytesLike} data
 * @returns {Bytes} the same bytes, not copied where they are a Uint8Array or a view already
 */
function bytesOf(data) {
  if (data instanceof Uint8Array) return /** @type {Bytes} */ (data);
  if (data instanceof ArrayBuffer) return new Uint8Array(data);
  if (ArrayBuffer.isView(data)) {
    return new Uint8Array(/** @type {ArrayBuffer} */ (data.buffer), data.byteOffset,
      data.byteLength);
  }
  if (Array.isArray(data)) return Uint8Array.from(data);
  throw new TypeError('expected bytes (Uint8Array, ArrayBuffer, DataView or an array)');
}

/**
 * @param {...Uint8Array} parts
 * @returns {Bytes}
 */
function concat(...parts) {
  const out = new Uint8Array(parts.reduce((n, p) => n + p.length, 0));
  let at = 0;
  for (const part of parts) {
    out.set(part, at);
    at += part.length;
  }
  return out;
}

// ---- checksums ------------------------------------------------------------------------------

/** CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no final XOR) of `data`;
 *  `crc` continues a previous result. "123456789" → 0x29B1.
 * @param {BytesLike} data
 * @param {number} [crc]
 * @returns {number}
 */
export function crc16(data, crc = 0xffff) {
  const bytes = bytesOf(data);
  for (let i = 0; i < bytes.length; i += 1) {
    crc ^= bytes[i] << 8;
    for (let bit = 0; bit < 8; bit += 1) {
      crc = crc & 0x8000 ? ((crc << 1) ^ 0x1021) & 0xffff : (crc << 1) & 0xffff;
    }
  }
  return crc;
}

const CRC32_TABLE = (() => {
  const table = new Uint32Array(256);
  for (let n = 0; n < 256; n += 1) {
    let c = n;
    for (let k = 0; k < 8; k += 1) c = c & 1 ? 0xedb88320 ^ (c >>> 1) : c >>> 1;
    table[n] = c >>> 0;
  }
  return table;
})();

/** CRC-32 as zlib.crc32 / binascii.crc32 compute it (of a pattern's sample bytes), unsigned;
 *  `crc` continues a previous result.
 * @param {BytesLike} data
 * @param {number} [crc]
 * @returns {number}
 */
export function crc32(data, crc = 0) {
  const bytes = bytesOf(data);
  let c = (crc ^ 0xffffffff) >>> 0;
  for (let i = 0; i < bytes.length; i += 1) c = CRC32_TABLE[(c ^ bytes[i]) & 0xff] ^ (c >>> 8);
  return (c ^ 0xffffffff) >>> 0;
}

// ---- COBS -----------------------------------------------------------------------------------

/** Consistent Overhead Byte Stuffing: `data` without any 0x00 (the delimiter is not added).
 *  Data that ends exactly at a full block of 254 gets no empty block after it.
 * @param {BytesLike} data
 * @returns {Bytes}
 */
export function cobsEncode(data) {
  const bytes = bytesOf(data);
  const out = new Uint8Array(bytes.length + Math.floor(bytes.length / 254) + 1);
  let codeAt = 0;
  let at = 1;
  let code = 1;
  let afterFullBlock = false;
  for (let i = 0; i < bytes.length; i += 1) {
    afterFullBlock = false;
    if (bytes[i] === 0) {
      out[codeAt] = code;
      codeAt = at;
      at += 1;
      code = 1;
    } else {
      out[at] = bytes[i];
      at += 1;
      code += 1;
      if (code === 0xff) {
        out[codeAt] = code;
        codeAt = at;
        at += 1;
        code = 1;
        afterFullBlock = true;
      }
    }
  }
  if (afterFullBlock) return out.slice(0, codeAt);
  out[codeAt] = code;
  return out.slice(0, at);
}

/** The bytes a COBS block stands for; throws ProtocolError when it is malformed (a 0x00
 *  inside, or a block that runs past the end).
 * @param {BytesLike} data
 * @returns {Bytes}
 */
export function cobsDecode(data) {
  const bytes = bytesOf(data);
  const out = new Uint8Array(bytes.length);
  let at = 0;
  let i = 0;
  while (i < bytes.length) {
    const code = bytes[i];
    if (code === 0) throw new ProtocolError(`COBS: zero byte at ${i}`);
    const end = i + code;
    if (end > bytes.length) throw new ProtocolError(`COBS: block at ${i} runs past the end`);
    for (let j = i + 1; j < end; j += 1) {
      if (bytes[j] === 0) throw new ProtocolError(`COBS: zero byte at ${j}`);
      out[at] = bytes[j];
      at += 1;
    }
    i = end;
    if (code !== 0xff && i < bytes.length) {
      out[at] = 0;
      at += 1;
    }
  }
  return out.slice(0, at);
}

// ---- frames ---------------------------------------------------------------------------------

/** One frame on the wire: COBS(type, seq, payload, CRC-16 LE) + 0x00; throws ProtocolError
 *  for a frame longer than MAX_FRAME.
 * @param {number} ftype
 * @param {number} seq
 * @param {BytesLike} [payload]
 * @returns {Bytes}
 */
export function encodeFrame(ftype, seq, payload = new Uint8Array(0)) {
  const body = bytesOf(payload);
  if (body.length + 4 > MAX_FRAME) {
    throw new ProtocolError(`frame of ${body.length + 4} bytes is larger than ${MAX_FRAME}`);
  }
  const raw = new Uint8Array(body.length + 4);
  raw[0] = ftype & 0xff;
  raw[1] = seq & 0xff;
  raw.set(body, 2);
  const crc = crc16(raw.subarray(0, body.length + 2));
  raw[body.length + 2] = crc & 0xff;
  raw[body.length + 3] = crc >> 8;
  return concat(cobsEncode(raw), Uint8Array.of(0));
}

/**
 * Frames out of a byte stream cut anywhere (serial reads, BLE notifications): feed() returns
 * the complete frames as [ftype, seq, payload] and keeps the rest for the next call. A bad
 * frame (COBS, CRC, shorter than type + seq + CRC, longer than maxFrame bytes once decoded, an
 * encoded block longer than a frame of maxFrame bytes can become) is dropped and counted in
 * `errors`; decoding starts again after the next 0x00. The buffer is fixed: no input makes it
 * grow.
 */
export class FrameDecoder {
  /** @param {number} [maxFrame] the largest decoded frame accepted, bytes */
  constructor(maxFrame = MAX_FRAME) {
    this.maxFrame = maxFrame;
    this.limit = maxFrame + Math.floor(maxFrame / 254) + 2; // as protocol.py's max_encoded
    this.buffer = new Uint8Array(this.limit);
    this.length = 0;
    this.overflow = false;
    this.errors = 0;
  }

  /**
   * @param {BytesLike} data the next bytes of the stream
   * @returns {Frame[]} the frames they complete
   */
  feed(data) {
    const bytes = bytesOf(data);
    /** @type {Frame[]} */
    const frames = [];
    for (let i = 0; i < bytes.length; i += 1) {
      const byte = bytes[i];
      if (byte !== 0) {
        if (this.length < this.limit) {
          this.buffer[this.length] = byte;
          this.length += 1;
        } else {
          this.overflow = true;
        }
        continue;
      }
      const frame = this.finish();
      if (frame) frames.push(frame);
    }
    return frames;
  }

  /** @returns {Frame | null} the frame the buffer holds at a delimiter, if it is good */
  finish() {
    const { length, overflow } = this;
    this.length = 0;
    this.overflow = false;
    if (length === 0 && !overflow) return null; // back-to-back delimiters: nothing lost
    if (overflow) {
      this.errors += 1;
      return null;
    }
    let raw;
    try {
      raw = cobsDecode(this.buffer.subarray(0, length));
    } catch {
      this.errors += 1;
      return null;
    }
    // The encoded limit lets through a few bytes more than maxFrame decodes to (COBS adds at
    // least one): a well-formed frame that decodes longer is as bad as protocol.py finds it.
    if (raw.length < 4 || raw.length > this.maxFrame) {
      this.errors += 1;
      return null;
    }
    const end = raw.length - 2;
    if (crc16(raw.subarray(0, end)) !== (raw[end] | (raw[end + 1] << 8))) {
      this.errors += 1;
      return null;
    }
    return [raw[0], raw[1], raw.slice(2, end)];
  }
}

// ---- messages -------------------------------------------------------------------------------

/**
 * @param {number} size
 * @returns {[Bytes, DataView<ArrayBuffer>]} a zeroed payload and a view to fill it
 */
function newPayload(size) {
  const bytes = new Uint8Array(size);
  return [bytes, new DataView(bytes.buffer)];
}

/**
 * @param {BytesLike} p a payload
 * @param {number} size the bytes it must have (at least, with `atLeast`)
 * @param {string} what the message, for the error
 * @param {boolean} [atLeast]
 * @returns {[Bytes, DataView<ArrayBuffer>]}
 */
function view(p, size, what, atLeast = false) {
  const bytes = bytesOf(p);
  if (atLeast ? bytes.length < size : bytes.length !== size) {
    throw new ProtocolError(`${what}: payload of ${bytes.length} bytes, expected `
      + `${atLeast ? 'at least ' : ''}${size}`);
  }
  return [bytes, new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength)];
}

/** @param {number} value */
function u16(value) { return Number(value) & 0xffff; }
/** @param {number} value */
function u32(value) { return Number(value) >>> 0; }

/** HELLO {version u16}.
 * @param {number} version
 * @returns {Bytes}
 */
export function packHello(version) {
  const [bytes, dv] = newPayload(2);
  dv.setUint16(0, u16(version), true);
  return bytes;
}

/**
 * @param {BytesLike} p
 * @returns {number} version
 */
export function unpackHello(p) {
  const [, dv] = view(p, 2, 'HELLO');
  return dv.getUint16(0, true);
}

/** INFO {protocol u16, fw major/minor/patch u8, sample_rate u32 (Hz), max_pattern_bytes u32,
 *  features u32} + name (UTF-8, at most MAX_NAME bytes).
 * @param {number} protocol
 * @param {number} fwMajor
 * @param {number} fwMinor
 * @param {number} fwPatch
 * @param {number} sampleRate Hz
 * @param {number} maxPatternBytes
 * @param {number} features FEATURE_* bits
 * @param {string | BytesLike} name
 * @returns {Bytes}
 */
export function packInfo(protocol, fwMajor, fwMinor, fwPatch, sampleRate, maxPatternBytes,
  features, name) {
  const text = typeof name === 'string' ? new TextEncoder().encode(name) : bytesOf(name);
  if (text.length > MAX_NAME) throw new ProtocolError(`name longer than ${MAX_NAME} bytes`);
  const [bytes, dv] = newPayload(17 + text.length);
  dv.setUint16(0, u16(protocol), true);
  dv.setUint8(2, fwMajor & 0xff);
  dv.setUint8(3, fwMinor & 0xff);
  dv.setUint8(4, fwPatch & 0xff);
  dv.setUint32(5, u32(sampleRate), true);
  dv.setUint32(9, u32(maxPatternBytes), true);
  dv.setUint32(13, u32(features), true);
  bytes.set(text, 17);
  return bytes;
}

/**
 * @param {BytesLike} p
 * @returns {[protocol: number, fwMajor: number, fwMinor: number, fwPatch: number,
 *   sampleRate: number, maxPatternBytes: number, features: number, name: string]}
 */
export function unpackInfo(p) {
  const [bytes, dv] = view(p, 17, 'INFO', true);
  if (bytes.length > 17 + MAX_NAME) {
    throw new ProtocolError(`INFO: payload of ${bytes.length} bytes, expected at most `
      + `${17 + MAX_NAME}`);
  }
  let name;
  try {
    name = new TextDecoder('utf-8', { fatal: true }).decode(bytes.subarray(17));
  } catch {
    throw new ProtocolError('INFO: the name is not UTF-8');
  }
  return [dv.getUint16(0, true), dv.getUint8(2), dv.getUint8(3), dv.getUint8(4),
    dv.getUint32(5, true), dv.getUint32(9, true), dv.getUint32(13, true), name];
}

/** PATTERN_BEGIN {id u16, length u32 (samples), rate u32 (Hz), format u8, crc32 u32}.
 * @param {number} pid
 * @param {number} length samples
 * @param {number} rate Hz
 * @param {number} fmt FORMAT_*
 * @param {number} crc CRC-32 of the sample bytes
 * @returns {Bytes}
 */
export function packPatternBegin(pid, length, rate, fmt, crc) {
  const [bytes, dv] = newPayload(15);
  dv.setUint16(0, u16(pid), true);
  dv.setUint32(2, u32(length), true);
  dv.setUint32(6, u32(rate), true);
  dv.setUint8(10, fmt & 0xff);
  dv.setUint32(11, u32(crc), true);
  return bytes;
}

/**
 * @param {BytesLike} p
 * @returns {[pid: number, length: number, rate: number, fmt: number, crc: number]}
 */
export function unpackPatternBegin(p) {
  const [, dv] = view(p, 15, 'PATTERN_BEGIN');
  return [dv.getUint16(0, true), dv.getUint32(2, true), dv.getUint32(6, true), dv.getUint8(10),
    dv.getUint32(11, true)];
}

/** PATTERN_CHUNK {offset u32 (bytes)} + 1 … MAX_CHUNK pattern bytes.
 * @param {number} offset bytes into the pattern
 * @param {BytesLike} data
 * @returns {Bytes}
 */
export function packPatternChunk(offset, data) {
  const body = bytesOf(data);
  if (body.length > MAX_CHUNK) {
    throw new ProtocolError(`chunk of ${body.length} bytes is larger than ${MAX_CHUNK}`);
  }
  const [bytes, dv] = newPayload(4 + body.length);
  dv.setUint32(0, u32(offset), true);
  bytes.set(body, 4);
  return bytes;
}

/**
 * @param {BytesLike} p
 * @returns {[offset: number, data: Bytes]}
 */
export function unpackPatternChunk(p) {
  const [bytes, dv] = view(p, 5, 'PATTERN_CHUNK', true);
  if (bytes.length > 4 + MAX_CHUNK) {
    throw new ProtocolError(`PATTERN_CHUNK: payload of ${bytes.length} bytes, expected at most `
      + `${4 + MAX_CHUNK}`);
  }
  return [dv.getUint32(0, true), bytes.slice(4)];
}

/** PATTERN_COMMIT {id u16}.
 * @param {number} pid
 * @returns {Bytes}
 */
export function packPatternCommit(pid) {
  const [bytes, dv] = newPayload(2);
  dv.setUint16(0, u16(pid), true);
  return bytes;
}

/**
 * @param {BytesLike} p
 * @returns {number} pid
 */
export function unpackPatternCommit(p) {
  const [, dv] = view(p, 2, 'PATTERN_COMMIT');
  return dv.getUint16(0, true);
}

/** SET_STATE {playing u8, gain u16 (GAIN_ONE = full), rate u16 (Q12), fade_ms u16}.
 * @param {number} playing 0 or 1
 * @param {number} gain 0 … GAIN_ONE
 * @param {number} rate Q12, RATE_ONE plays the pattern as stored
 * @param {number} fadeMs
 * @returns {Bytes}
 */
export function packSetState(playing, gain, rate, fadeMs) {
  const [bytes, dv] = newPayload(7);
  dv.setUint8(0, playing & 0xff);
  dv.setUint16(1, u16(gain), true);
  dv.setUint16(3, u16(rate), true);
  dv.setUint16(5, u16(fadeMs), true);
  return bytes;
}

/**
 * @param {BytesLike} p
 * @returns {[playing: number, gain: number, rate: number, fadeMs: number]}
 */
export function unpackSetState(p) {
  const [, dv] = view(p, 7, 'SET_STATE');
  return [dv.getUint8(0), dv.getUint16(1, true), dv.getUint16(3, true), dv.getUint16(5, true)];
}

/** PING {token u32}.
 * @param {number} token
 * @returns {Bytes}
 */
export function packPing(token) {
  const [bytes, dv] = newPayload(4);
  dv.setUint32(0, u32(token), true);
  return bytes;
}

/**
 * @param {BytesLike} p
 * @returns {number} token
 */
export function unpackPing(p) {
  const [, dv] = view(p, 4, 'PING');
  return dv.getUint32(0, true);
}

/** PONG {token u32, device_us u32 (µs, wraps at 2**32)}.
 * @param {number} token
 * @param {number} deviceUs
 * @returns {Bytes}
 */
export function packPong(token, deviceUs) {
  const [bytes, dv] = newPayload(8);
  dv.setUint32(0, u32(token), true);
  dv.setUint32(4, u32(deviceUs), true);
  return bytes;
}

/**
 * @param {BytesLike} p
 * @returns {[token: number, deviceUs: number]}
 */
export function unpackPong(p) {
  const [, dv] = view(p, 8, 'PONG');
  return [dv.getUint32(0, true), dv.getUint32(4, true)];
}

/** ACK {ftype u8}: the frame type acknowledged.
 * @param {number} ftype
 * @returns {Bytes}
 */
export function packAck(ftype) {
  return Uint8Array.of(ftype & 0xff);
}

/**
 * @param {BytesLike} p
 * @returns {number} ftype
 */
export function unpackAck(p) {
  const [bytes] = view(p, 1, 'ACK');
  return bytes[0];
}

/** NACK {ftype u8, code u8}.
 * @param {number} ftype
 * @param {number} code E_*
 * @returns {Bytes}
 */
export function packNack(ftype, code) {
  return Uint8Array.of(ftype & 0xff, code & 0xff);
}

/**
 * @param {BytesLike} p
 * @returns {[ftype: number, code: number]}
 */
export function unpackNack(p) {
  const [bytes] = view(p, 2, 'NACK');
  return [bytes[0], bytes[1]];
}

/** EVENT {kind u8, value u32}.
 * @param {number} kind EV_*
 * @param {number} value
 * @returns {Bytes}
 */
export function packEvent(kind, value) {
  const [bytes, dv] = newPayload(5);
  dv.setUint8(0, kind & 0xff);
  dv.setUint32(1, u32(value), true);
  return bytes;
}

/**
 * @param {BytesLike} p
 * @returns {[kind: number, value: number]}
 */
export function unpackEvent(p) {
  const [, dv] = view(p, 5, 'EVENT');
  return [dv.getUint8(0), dv.getUint32(1, true)];
}

/** CAPTURE_START {range_g u8, rate_hz u16}.
 * @param {number} rangeG full scale in g, one of CAPTURE_RANGES
 * @param {number} rateHz output rate in Hz, one of CAPTURE_RATES
 * @returns {Bytes}
 */
export function packCaptureStart(rangeG, rateHz) {
  const [bytes, dv] = newPayload(3);
  dv.setUint8(0, rangeG & 0xff);
  dv.setUint16(1, u16(rateHz), true);
  return bytes;
}

/**
 * @param {BytesLike} p
 * @returns {[rangeG: number, rateHz: number]}
 */
export function unpackCaptureStart(p) {
  const [, dv] = view(p, 3, 'CAPTURE_START');
  return [dv.getUint8(0), dv.getUint16(1, true)];
}

/** CAPTURE_STOP: no payload; the pen's ACK follows the capture's last SAMPLES block.
 * @returns {Bytes}
 */
export function packCaptureStop() {
  return new Uint8Array(0);
}

/**
 * @param {BytesLike} p
 * @returns {null} (protocol.py's None), after checking that the payload is empty
 */
export function unpackCaptureStop(p) {
  view(p, 0, 'CAPTURE_STOP');
  return null;
}

/**
 * @param {number} count sample bytes of a SAMPLES block
 * @returns {boolean} whether they are 1 … MAX_BLOCK_SAMPLES whole samples
 */
function wholeBlock(count) {
  return count > 0 && count % SAMPLE_BYTES === 0 && count <= MAX_BLOCK_SAMPLES * SAMPLE_BYTES;
}

/** SAMPLES {first u32, t_us u32, range_g u8, flags u8} + 1 … MAX_BLOCK_SAMPLES samples of
 *  x, y, z (int16 LE, left-justified as the sensor gives them).
 * @param {number} first index of the block's first sample since CAPTURE_START (wraps at 2**32)
 * @param {number} tUs the pen's clock in µs when the FIFO level was read (wraps at 2**32)
 * @param {number} rangeG full scale in g
 * @param {number} flags SAMPLES_OVERRUN
 * @param {BytesLike} data the samples' bytes
 * @returns {Bytes}
 */
export function packSamples(first, tUs, rangeG, flags, data) {
  const body = bytesOf(data);
  if (!wholeBlock(body.length)) throw new ProtocolError(`SAMPLES data of ${body.length} bytes`);
  const [bytes, dv] = newPayload(10 + body.length);
  dv.setUint32(0, u32(first), true);
  dv.setUint32(4, u32(tUs), true);
  dv.setUint8(8, rangeG & 0xff);
  dv.setUint8(9, flags & 0xff);
  bytes.set(body, 10);
  return bytes;
}

/**
 * @param {BytesLike} p
 * @returns {[first: number, tUs: number, rangeG: number, flags: number, data: Bytes]}
 */
export function unpackSamples(p) {
  const [bytes, dv] = view(p, 10, 'SAMPLES', true);
  if (!wholeBlock(bytes.length - 10)) {
    throw new ProtocolError(`SAMPLES: payload of ${bytes.length} bytes`);
  }
  return [dv.getUint32(0, true), dv.getUint32(4, true), dv.getUint8(8), dv.getUint8(9),
    bytes.slice(10)];
}

/**
 * Each message's pack and unpack function by protocol.py's name of its pack function
 * ('pack_hello' → [packHello, unpackHello]), as the test vectors name them.
 * @type {Readonly<Record<string, [(...fields: any[]) => Bytes, (p: BytesLike) => unknown]>>}
 */
export const MESSAGES = {
  pack_hello: [packHello, unpackHello],
  pack_info: [packInfo, unpackInfo],
  pack_pattern_begin: [packPatternBegin, unpackPatternBegin],
  pack_pattern_chunk: [packPatternChunk, unpackPatternChunk],
  pack_pattern_commit: [packPatternCommit, unpackPatternCommit],
  pack_set_state: [packSetState, unpackSetState],
  pack_ping: [packPing, unpackPing],
  pack_pong: [packPong, unpackPong],
  pack_ack: [packAck, unpackAck],
  pack_nack: [packNack, unpackNack],
  pack_event: [packEvent, unpackEvent],
  pack_capture_start: [packCaptureStart, unpackCaptureStart],
  pack_capture_stop: [packCaptureStop, unpackCaptureStop],
  pack_samples: [packSamples, unpackSamples],
};

/** "0a1b…" ↔ bytes: the test vectors carry bytes as hex.
 * @param {BytesLike} data
 * @returns {string}
 */
export function toHex(data) {
  return Array.from(bytesOf(data), (b) => b.toString(16).padStart(2, '0')).join('');
}

/**
 * @param {string} text
 * @returns {Bytes}
 */
export function fromHex(text) {
  const clean = String(text).replace(/\s+/g, '');
  if (clean.length % 2 || /[^0-9a-fA-F]/.test(clean)) throw new ProtocolError(`not hex: ${text}`);
  const out = new Uint8Array(clean.length / 2);
  for (let i = 0; i < out.length; i += 1) out[i] = parseInt(clean.slice(2 * i, 2 * i + 2), 16);
  return out;
}
