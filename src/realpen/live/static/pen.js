// Pointer Events → pen samples: position in mm, pressure, tilt and speed in mm/s.
//
// Pen, touch and mouse all arrive as Pointer Events. Every pointermove carries the coalesced
// events since the previous one (a pen reports at 120-240 Hz while the page sees ~60 events per
// second), and each coalesced event becomes one sample, so the stroke keeps the pen's full rate.
//
// Pressure: a pen's own pressure (0-1). A mouse has none: it uses MOUSE_PRESSURE, the value the
// Pointer Events spec gives hardware without pressure sensing while a button is down; a touch
// that reports 0 uses it too.
//
// Speed: CSS pixels become mm with the calibration (px per mm, measured once on screen and kept
// in the browser). The speed of a sample is the path length over the last SPEED_WINDOW_MS
// divided by the time it spans (at least one step back): a stylus moves a fraction of a pixel per
// coalesced sample, so a single step's distance is mostly rounding; 20 ms smooths that without
// audible lag. It is 0 at the pen-down sample (the pen has not slid yet).

export const MOUSE_PRESSURE = 0.5;
export const SPEED_WINDOW_MS = 20;
export const CSS_PX_PER_MM = 96 / 25.4; // CSS reference pixel: the default before calibration

/** Normalised pressure of a pointer event (see the module note). */
export function pressureOf(event) {
  if (event.pointerType === 'mouse') return MOUSE_PRESSURE;
  const p = event.pressure;
  if (event.pointerType === 'touch' && !(p > 0)) return MOUSE_PRESSURE;
  return Math.min(Math.max(Number.isFinite(p) ? p : 0, 0), 1);
}

/** Speed over a sliding window of recent positions (mm, s) → mm/s. */
export class SpeedMeter {
  constructor(windowMs = SPEED_WINDOW_MS) {
    this.window = windowMs / 1000;
    this.reset();
  }

  reset() {
    this.points = [];
    this.speed = 0;
  }

  push(t, x, y) {
    const last = this.points[this.points.length - 1];
    const travelled = last ? last.d + Math.hypot(x - last.x, y - last.y) : 0;
    this.points.push({ t, x, y, d: travelled });
    while (this.points.length > 2 && this.points[1].t <= t - this.window) this.points.shift();
    const first = this.points[0];
    const span = t - first.t;
    if (span > 0) this.speed = (travelled - first.d) / span;
    return this.speed;
  }
}

/**
 * Follows one pointer at a time on `surface` and reports its strokes:
 *   onDown(info, sample), onSamples(samples), onUp(t)
 * info: { pointerType }; sample: { t (s, page clock), x, y (mm), px, py (CSS px), pressure,
 * tilt_x, tilt_y (deg), speed (mm/s) }.
 * Palm rejection: once a pen has been seen, touches do not write.
 */
export class PenTracker {
  constructor(surface, { pxPerMm, onDown, onSamples, onUp }) {
    this.surface = surface;
    this.pxPerMm = pxPerMm;
    this.onDown = onDown;
    this.onSamples = onSamples;
    this.onUp = onUp;
    this.pointerId = null;
    this.penSeen = false;
    this.meter = new SpeedMeter();
    this.rect = surface.getBoundingClientRect();
    const listen = (type, handler) => surface.addEventListener(type, handler.bind(this));
    listen('pointerdown', this.down);
    listen('pointermove', this.move);
    listen('pointerup', this.up);
    listen('pointercancel', this.up);
    listen('lostpointercapture', this.up);
    surface.addEventListener('contextmenu', (e) => e.preventDefault());
  }

  get active() {
    return this.pointerId !== null;
  }

  sample(event) {
    const px = event.clientX - this.rect.left;
    const py = event.clientY - this.rect.top;
    const t = event.timeStamp / 1000;
    const x = px / this.pxPerMm;
    const y = py / this.pxPerMm;
    return {
      t, x, y, px, py,
      pressure: pressureOf(event),
      tilt_x: event.tiltX || 0,
      tilt_y: event.tiltY || 0,
      speed: this.meter.push(t, x, y),
    };
  }

  down(event) {
    if (event.pointerType === 'pen') this.penSeen = true;
    if (this.active || (event.pointerType === 'touch' && this.penSeen)) return;
    if (event.pointerType === 'mouse' && event.button !== 0) return;
    event.preventDefault();
    this.pointerId = event.pointerId;
    try { this.surface.setPointerCapture(event.pointerId); } catch { /* synthetic pointer */ }
    this.rect = this.surface.getBoundingClientRect();
    this.meter.reset();
    this.onDown({ pointerType: event.pointerType || 'unknown' }, this.sample(event));
  }

  move(event) {
    if (event.pointerId !== this.pointerId) return;
    const list = typeof event.getCoalescedEvents === 'function' ? event.getCoalescedEvents() : [];
    const events = list.length ? list : [event];
    this.onSamples(events.map((e) => this.sample(e)));
  }

  up(event) {
    if (event.pointerId !== this.pointerId) return;
    this.pointerId = null;
    this.onUp(event.timeStamp / 1000);
  }
}
