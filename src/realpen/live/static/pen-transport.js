// @ts-check
// What the pen link and its transports (pen-transport-serial.js, pen-transport-ble.js) share:
// the error the user reads as it is, and how any failure becomes one line of the status.

/** A failure the user should read as it is (no "Error:" prefix, no stack). */
export class PenError extends Error {
  /**
   * @param {string} message the line the status shows
   * @param {{ timeout?: boolean, refused?: boolean, version?: boolean }} [why] `timeout`: the
   *   pen did not answer in time; `refused`: the pen refused a pattern as such (it would refuse
   *   it again); `version`: the pen speaks another protocol version (reconnecting cannot mend it)
   */
  constructor(message, { timeout = false, refused = false, version = false } = {}) {
    super(message);
    this.timeout = timeout;
    this.refused = refused;
    this.version = version;
  }
}

/**
 * One line for any failure: its message, or the thing itself as text.
 * @param {unknown} error
 * @returns {string}
 */
export function describe(error) {
  if (!error) return 'unknown error';
  const { message } = /** @type {{ message?: unknown }} */ (error);
  return message ? String(message) : String(error);
}

/**
 * Whether the user closed the browser's chooser (NotFoundError is also "no adapter", which is
 * said).
 * @param {unknown} error
 * @returns {boolean}
 */
export function cancelled(error) {
  if (!error) return false;
  const { name, message } = /** @type {{ name?: unknown, message?: unknown }} */ (error);
  return name === 'NotFoundError' && /cancel|no port selected/i.test(String(message || ''));
}

/**
 * @param {number} ms
 * @returns {Promise<void>}
 */
export const sleep = (ms) => new Promise((resolve) => { setTimeout(resolve, ms); });
