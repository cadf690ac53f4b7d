// The stroke pipeline that the writing page and the study's participant screen share: every pen
// sample goes three ways, to the ink (ink.js), the audio graph (Eq. 1 gain of the sound unit and
// the tactile loop, audio.js) and the server (pen_down / samples / gain / pen_up over the
// acknowledged WebSocket, link.js), so a stroke is stored the same way whichever page drew it.
//
// The writer reads the page's live state (pen, profileVersion, coupling, profiles, modality,
// ink, tactileAudio, pxPerMm, calibrated, config) and writes into it what tests and status bars
// read (stroke, strokes, down, pointerType, pressure, speed, tiltX, tiltY, targetGain,
// smoothedGain, tactileTarget, pointTargets, playbackRate, trace). pointTargets: with a pen whose
// profile has a vibration grid, the target gain of each point's tactile loop at the latest
// sample's speed and force (audio.js, grid.js); null otherwise.

import { gainRaw, playbackRate } from './coupling.js';
import { CSS_PX_PER_MM, PenTracker } from './pen.js';
import { inkStyle } from './ink.js';

export const TRACE_LIMIT = 20000;
const POINTER_TYPES = ['pen', 'touch', 'mouse'];

/**
 * A page's live state (window.realpen): the fields the writer reads and writes, at their
 * starting values, with the page's own `fields` over them.
 */
export function liveState(fields) {
  return {
    ready: false,
    error: null,
    config: null,
    profiles: [],
    pen: null,
    profileVersion: null,
    coupling: null,
    modality: 'none',
    ink: 'visible',
    tactileAudio: false,
    pxPerMm: CSS_PX_PER_MM,
    calibrated: false,
    down: false,
    stroke: 0,
    strokes: 0,
    pointerType: null,
    pressure: 0,
    speed: 0,
    tiltX: 0,
    tiltY: 0,
    targetGain: 0,
    smoothedGain: 0,
    tactileTarget: 0,
    pointTargets: null,
    playbackRate: 1,
    trace: [],
    ...fields,
  };
}

/** The feedback modalities, as the server's messages name them (realpen.defaults.MODALITIES). */
export const MODALITIES = ['tactile', 'auditory', 'audio-tactile', 'none'];
/** Names earlier releases used (in saved settings, bookmarked URLs): read as today's. */
export const OLD_MODALITY_NAMES = { 'auditory-tactile': 'audio-tactile' };

/** A modality's current name: an old spelling becomes today's; anything else is returned as it is. */
export const modalityName = (name) => (Object.hasOwn(OLD_MODALITY_NAMES, name)
  ? OLD_MODALITY_NAMES[name] : name);

export const soundOn = (modality) => modality === 'auditory' || modality === 'audio-tactile';
export const tactileOn = (modality) => modality === 'tactile' || modality === 'audio-tactile';

export class Writer {
  /**
   * state: the page's live state (see the module note).
   * surface: the element whose pointer events are strokes; ink, audio, smoother, link: the
   * page's Ink, AudioEngine, Smoother and Link.
   * onChange(): something shown changed; onDown(): a stroke started;
   * enabled(): whether a pen-down starts a stroke now (default: once a pen is loaded);
   * extra(): fields added to each pen_down (a study's session and trial);
   * onGain(down, target): every sample's Eq. 1 target gain while the pen is down, and
   * (false, 0) at pen up (the page's direct pen link follows them).
   */
  constructor(state, { surface, ink, audio, smoother, link, onChange = () => {}, onDown = () => {},
    enabled = () => true, extra = () => ({}), onGain = () => {} }) {
    Object.assign(this, { state, ink, audio, smoother, link, onChange, onDown, enabled, extra,
      onGain });
    this.lastSentTarget = null;
    this.sampleIndex = 0; // samples of the current stroke sent so far
    this.tracker = new PenTracker(surface, { pxPerMm: state.pxPerMm,
      onDown: (info, sample) => this.penDown(info, sample),
      onSamples: (samples) => this.penSamples(samples),
      onUp: (t) => this.penUp(t) });
  }

  /** The calibration changed (CSS px per mm). */
  setPxPerMm(pxPerMm) {
    this.tracker.pxPerMm = pxPerMm;
  }

  apply(samples) {
    const { state, smoother } = this;
    const c = state.coupling;
    let target = 0;
    for (const s of samples) {
      target = gainRaw(c, s.pressure, s.speed);
      const smoothed = smoother.advanceTo(s.t);
      smoother.set(target);
      this.record(s.t, s.pressure, s.speed, target, smoothed);
    }
    const last = samples[samples.length - 1];
    Object.assign(state, { pressure: last.pressure, speed: last.speed, tiltX: last.tilt_x,
      tiltY: last.tilt_y, targetGain: target, playbackRate: playbackRate(c, last.speed) });
    state.tactileTarget = tactileOn(state.modality) && state.tactileAudio ? target / c.a_max : 0;
    this.audio.set(soundOn(state.modality) ? target : 0, state.tactileTarget, state.playbackRate);
    state.pointTargets = this.audio.follow(last.speed, last.pressure);
    this.onGain(true, target);
    if (target !== this.lastSentTarget) {
      this.link.send({ type: 'gain', stroke: state.stroke, t: last.t, target });
      this.lastSentTarget = target;
    }
    // Batches stay under the server's message size too: a sample's JSON is at most ~200 bytes.
    const config = state.config || {};
    const limit = Math.min(config.max_samples || 512,
      Math.floor((config.max_message_bytes || 65536) / 200));
    for (let i = 0; i < samples.length; i += limit) {
      const batch = samples.slice(i, i + limit);
      // `index` numbers the samples within the stroke: a batch sent again is stored once.
      this.link.send({ type: 'samples', stroke: state.stroke, index: this.sampleIndex,
        samples: batch.map(({ t, x, y, pressure, tilt_x, tilt_y, speed }) => (
          { t, x, y, pressure, tilt_x, tilt_y, speed })) });
      this.sampleIndex += batch.length;
    }
    this.onChange();
  }

  record(t, pressure, speed, target, smoothed) {
    const { state, smoother } = this;
    state.smoothedGain = smoothed;
    state.trace.push({ stroke: state.stroke, t, k: smoother.index, rate: smoother.rate, pressure,
      speed, target, smoothed });
    if (state.trace.length > TRACE_LIMIT) state.trace.splice(0, state.trace.length - TRACE_LIMIT);
  }

  penDown(info, sample) {
    const { state } = this;
    if (!state.coupling || !this.enabled()) return;
    this.onDown();
    state.stroke += 1;
    state.strokes += 1;
    state.down = true;
    state.pointerType = info.pointerType;
    this.lastSentTarget = null;
    this.sampleIndex = 0;
    const pointerType = POINTER_TYPES.includes(info.pointerType) ? info.pointerType : 'unknown';
    this.link.send({ type: 'pen_down', stroke: state.stroke, t: sample.t, pen: state.pen,
      profile_version: state.profileVersion, modality: state.modality, ink: state.ink,
      pointer_type: pointerType, px_per_mm: state.pxPerMm, calibrated: state.calibrated,
      ...this.extra() });
    const profile = state.profiles.find((p) => p.name === state.pen);
    this.ink.begin(inkStyle(profile), state.pxPerMm, sample, state.ink === 'visible');
    this.apply([sample]);
  }

  penSamples(samples) {
    if (!this.state.down) return;
    this.ink.add(samples);
    this.apply(samples);
  }

  penUp(t) {
    const { state, smoother } = this;
    if (!state.down) return;
    state.down = false;
    const smoothed = smoother.advanceTo(t);
    smoother.set(0);
    this.record(t, 0, 0, 0, smoothed);
    Object.assign(state, { pressure: 0, speed: 0, targetGain: 0, tactileTarget: 0 });
    this.audio.set(0, 0, state.playbackRate);
    this.onGain(false, 0);
    this.link.send({ type: 'pen_up', stroke: state.stroke, t });
    this.ink.end();
    this.onChange();
  }
}
