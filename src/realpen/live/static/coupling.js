// @ts-check
// Eq. 1 of the RealPen method, its smoother and the playback rate: the same numbers as
// realpen.coupling (Python). Tests evaluate these functions in the page and compare them with
// Coupling.gain_raw, Coupling.playback_rate and one_pole.
//
//   target = 0 if P <= 0 else min(max(c_p*(P - c_op) + c_x*(v - c_ov), 0), a_max)
//   alpha  = 1 - exp(-1 / (fs * smoothing_ms / 1000))     (one pole, time constant tau)
//   gain   = gain + alpha * (target - gain)                (per audio sample; gain starts at 0)
//   rate   = min(max((v / rate_speed_ref) ** rate_exponent, rate_min), rate_max)
//
// P: normalised pressure 0-1; v: speed in mm/s; c: the profile's coupling JSON
// (realpen.coupling/1). Web Audio's setTargetAtTime(target, t, tau) with
// tau = smoothing_ms / 1000 is this recursion exactly, so the audio graph uses it.

/**
 * The profile's coupling (realpen.coupling/1), as the page reads it: the fields used here.
 * @typedef {object} Coupling
 * @property {number} c_p gain per unit of normalised pressure
 * @property {number} c_op pressure offset (0-1)
 * @property {number} c_x gain per mm/s
 * @property {number} c_ov speed offset, mm/s
 * @property {number} a_max the gain's ceiling
 * @property {number} smoothing_ms the smoother's time constant, ms
 * @property {number} rate_speed_ref mm/s at which the sound plays as recorded
 * @property {number} rate_exponent
 * @property {number} rate_min
 * @property {number} rate_max
 */

/**
 * Eq. 1 before smoothing: clamped to [0, a_max], 0 when the pen is lifted (P <= 0).
 * @param {Coupling} c
 * @param {number} pressure normalised, 0-1
 * @param {number} speed mm/s
 * @returns {number}
 */
export function gainRaw(c, pressure, speed) {
  if (!(pressure > 0)) return 0;
  const value = c.c_p * (pressure - c.c_op) + c.c_x * (speed - c.c_ov);
  return Math.min(Math.max(value, 0), c.a_max);
}

/**
 * Playback rate of the sound unit (1 = as recorded) for a speed in mm/s, before smoothing.
 * @param {Coupling} c
 * @param {number} speed mm/s
 * @returns {number}
 */
export function playbackRate(c, speed) {
  const ratio = Math.max(speed, 0) / c.rate_speed_ref;
  return Math.min(Math.max(ratio ** c.rate_exponent, c.rate_min), c.rate_max);
}

/**
 * The smoother's per-sample coefficient at `rate` Hz (1 when smoothing_ms is 0: no smoothing).
 * @param {number} rate Hz
 * @param {number} smoothingMs
 * @returns {number}
 */
export function alpha(rate, smoothingMs) {
  return 1 - Math.exp(-1 / (rate * smoothingMs / 1000));
}

/**
 * The one-pole low-pass over a per-sample control signal, as realpen.coupling.one_pole.
 * @param {ArrayLike<number>} values one per sample
 * @param {number} rate Hz
 * @param {number} smoothingMs
 * @param {number} [initial] the output before the first sample
 * @returns {number[]}
 */
export function onePole(values, rate, smoothingMs, initial = 0) {
  if (!(smoothingMs > 0)) return Array.from(values);
  const a = alpha(rate, smoothingMs);
  const out = new Array(values.length);
  let y = initial;
  for (let i = 0; i < values.length; i += 1) {
    y += a * (values[i] - y);
    out[i] = y;
  }
  return out;
}

/**
 * The smoother evaluated on the page's event clock: what the audio gain is at an event.
 *
 * Time is counted in whole audio samples (index k = round(t * rate)). Between two events the
 * held target acts for every sample, so advancing n samples is the recursion applied n times:
 * gain = target + (gain - target) * (1 - alpha) ** n. `advanceTo(t)` returns the smoothed gain at
 * t under the previous target; `set(target)` then holds the new target from the next sample on.
 */
export class Smoother {
  /**
   * @param {number} rate Hz
   * @param {number} smoothingMs
   */
  constructor(rate, smoothingMs) {
    this.rate = rate;
    this.smoothingMs = smoothingMs;
    this.alpha = alpha(rate, smoothingMs);
    this.value = 0;
    this.target = 0;
    /** @type {number | null} the audio sample of the last event */
    this.index = null;
  }

  /**
   * @param {number} rate Hz
   * @param {number} smoothingMs
   */
  configure(rate, smoothingMs) {
    this.rate = rate;
    this.smoothingMs = smoothingMs;
    this.alpha = alpha(rate, smoothingMs);
  }

  /**
   * @param {number} t s, on the page's event clock
   * @returns {number} the smoothed gain at t
   */
  advanceTo(t) {
    const index = Math.round(t * this.rate);
    if (this.index === null) {
      this.index = index;
      return this.value;
    }
    const n = index - this.index;
    if (n > 0) {
      this.value = this.target + (this.value - this.target) * (1 - this.alpha) ** n;
      this.index = index;
    }
    return this.value;
  }

  /** @param {number} target */
  set(target) {
    this.target = target;
  }
}
