// Web Audio: the pen's sound unit and tactile pattern, looping, their gains following Eq. 1.
//
//   sound unit   → soundGain   ─┬─ (tactile over audio off) → destination (both channels)
//                               └─ (on) → merger input 0 = LEFT ─┐
//   tactile loop → tactileGain ──────── → merger input 1 = RIGHT ─┴→ destination
//
// A profile with a vibration grid (grid.js) has one tactile loop per (speed, force) point
// instead: all start at the same instant, each through its own gain, sqrt(w_i) at the pen's
// speed and force (smoothed like the other gains, with the profile's time constant), into
// tactileGain (realpen.tactile.stroke renders the same mix offline):
//
//   point i loop → pointGains[i] ─┐
//   point j loop → pointGains[j] ─┴→ tactileGain → …
//
// With tactile over audio on, the right channel drives an actuator through an amplifier (the
// common research set-up) and the left channel carries the sound. The context is created with
// the interactive latency hint; browsers keep it suspended until the page has user activation,
// so `startOnActivation` calls `resume` from every event that may carry it until the context
// runs (see "starting audio" below). Both loops run from then on; the gains (smoothed by
// setTargetAtTime with the profile's time constant, which is the smoother of coupling.js)
// make them silent whenever the pen is lifted.
//
// Levels: the sound unit is normalised to -20 dBFS RMS, so gain 1 plays it at that level; the
// tactile pattern is peak-normalised, so its gain is the Eq. 1 gain over a_max (full drive at
// a_max) and never clips. A grid's mix keeps the power of one loop (equal-power gains of
// uncorrelated loops) but not its peak: where the loops happen to align it can reach the sum of
// the gains times their peak (up to √3 between three points). The grid bus therefore carries
// the grid's mix_gain (VibrationGrid.mix_gain: the mix peaks no higher than its loudest loop).

import { VibrationGrid } from './grid.js';

// The point loops start this long after `use` is called, all at that one instant: a start time
// already past would start each at whichever render quantum its start() reached.
const SYNC_LEAD_S = 0.02;

export class AudioEngine {
  constructor() {
    const Context = window.AudioContext || window.webkitAudioContext;
    this.ctx = new Context({ latencyHint: 'interactive' });
    this.soundGain = new GainNode(this.ctx, { gain: 0 });
    this.tactileGain = new GainNode(this.ctx, { gain: 0 });
    this.merger = new ChannelMergerNode(this.ctx, { numberOfInputs: 2 });
    this.merger.connect(this.ctx.destination);
    this.tactileAudio = null;
    this.sources = [];
    this.tactileSources = [];
    this.pointGains = [];
    this.grid = null;
    this.sound = null;
    this.playing = null;
    this.buffers = null;
    this.tau = 0.005;
    this.routeTactile(false);
  }

  get sampleRate() {
    return this.ctx.sampleRate;
  }

  get state() {
    return this.ctx.state;
  }

  /** Call `listener(state)` whenever the context starts, suspends or is interrupted. */
  onStateChange(listener) {
    this.ctx.addEventListener('statechange', () => listener(this.ctx.state));
  }

  /**
   * Ask the browser to start (or restart) audio. It must be called synchronously from the
   * handler of an event that gives the page user activation, or the browser refuses: the
   * refusal is quiet (the promise stays pending in Chrome and rejects in Safari), and the next
   * gesture asks again. Returns the state at the time of the call.
   */
  resume() {
    const before = this.ctx.state;
    if (before === 'running' || before === 'closed') return before;
    try {
      const pending = this.ctx.resume();
      if (pending && typeof pending.catch === 'function') pending.catch(() => {});
    } catch { /* refused: the next gesture asks again */ }
    return before;
  }

  /** Decode a profile's sound unit and tactile pattern (the server sends both at 3 kHz or
   *  more, which every browser decodes; Web Audio resamples them to the context's rate), or,
   *  for a profile with a vibration grid, every point's loop (`points`, with `grid`; `tactile`
   *  is then the reference point's). Rejects (e.g. EncodingError) when any does not decode. */
  async load(profile, fetchBytes) {
    const grid = profile.grid ? new VibrationGrid(profile.grid) : null;
    const urls = grid ? profile.grid.points.map((p) => p.url) : [profile.tactile.url];
    const [sound, ...tactile] = await Promise.all([profile.sound.url, ...urls].map(
      async (url) => this.ctx.decodeAudioData(await fetchBytes(url))));
    if (!grid) return { sound, tactile: tactile[0] };
    return { sound, tactile: tactile[grid.reference], points: tactile, grid,
      mixGain: profile.grid.mix_gain ?? 1 };
  }

  /** Loop these buffers (of the pen `name`) from now on, replacing the previous pen's. */
  use(buffers, coupling, name = null) {
    for (const source of this.sources) {
      try { source.stop(); } catch { /* never started */ }
      source.disconnect();
    }
    for (const gain of this.pointGains) gain.disconnect();
    if (this.gridBus) this.gridBus.disconnect();
    this.gridBus = null;
    this.tau = coupling.smoothing_ms / 1000;
    this.sound = new AudioBufferSourceNode(this.ctx, { buffer: buffers.sound, loop: true });
    this.sound.connect(this.soundGain);
    this.sound.start();
    this.grid = buffers.grid || null;
    const loops = this.grid ? buffers.points : [buffers.tactile];
    this.tactileSources = loops.map((buffer) => new AudioBufferSourceNode(this.ctx,
      { buffer, loop: true }));
    if (this.grid) {
      // Until the pen says otherwise, the reference point (the profile's own tactile pattern).
      this.pointGains = loops.map((_, i) => new GainNode(this.ctx,
        { gain: i === this.grid.reference ? 1 : 0 }));
      this.gridBus = new GainNode(this.ctx, { gain: buffers.mixGain ?? 1 });
      this.gridBus.connect(this.tactileGain);
      this.pointGains.forEach((gain, i) => {
        this.tactileSources[i].connect(gain);
        gain.connect(this.gridBus);
      });
      const at = this.ctx.currentTime + SYNC_LEAD_S;
      for (const source of this.tactileSources) source.start(at);
    } else {
      this.pointGains = [];
      this.tactileSources[0].connect(this.tactileGain);
      this.tactileSources[0].start();
    }
    this.sources = [this.sound, ...this.tactileSources];
    this.playing = name;
    this.buffers = buffers;
  }

  /** The pen's speed (mm/s) and pressure (0-1): new targets for the point gains of a grid.
   *  Returns the targets (sqrt of the weights, one per point), or null without a grid. */
  follow(speed, pressure) {
    if (!this.grid) return null;
    const targets = this.grid.gains(speed, this.grid.forceOf(pressure));
    const now = this.ctx.currentTime;
    this.pointGains.forEach((gain, i) => {
      if (this.tau > 0) gain.gain.setTargetAtTime(targets[i], now, this.tau);
      else gain.gain.setValueAtTime(targets[i], now);
    });
    return targets;
  }

  /** Tactile pattern on the right channel (sound on the left), or no tactile audio. */
  routeTactile(on) {
    if (on === this.tactileAudio) return;
    this.tactileAudio = on;
    this.soundGain.disconnect();
    this.tactileGain.disconnect();
    if (on) {
      this.soundGain.connect(this.merger, 0, 0);
      this.tactileGain.connect(this.merger, 0, 1);
    } else {
      this.soundGain.connect(this.ctx.destination);
    }
  }

  /** New targets: sound gain, tactile gain (0-1 drive) and the sound's playback rate. */
  set(soundGain, tactileGain, rate) {
    const now = this.ctx.currentTime;
    const params = [[this.soundGain.gain, soundGain], [this.tactileGain.gain, tactileGain]];
    if (this.sound) params.push([this.sound.playbackRate, rate]);
    for (const [param, value] of params) {
      if (this.tau > 0) param.setTargetAtTime(value, now, this.tau);
      else param.setValueAtTime(value, now);
    }
  }

  report() {
    return {
      state: this.ctx.state,
      sampleRate: this.ctx.sampleRate,
      baseLatency: this.ctx.baseLatency ?? null,
      outputLatency: this.ctx.outputLatency ?? null,
      soundGain: this.soundGain.gain.value,
      tactileGain: this.tactileGain.gain.value,
      tactileAudio: this.tactileAudio,
      playing: this.playing,
      tactileLoops: this.tactileSources.length,
      pointGains: this.grid ? this.pointGains.map((gain) => gain.gain.value) : null,
      mixGain: this.gridBus ? this.gridBus.gain.value : null,
      buffers: this.buffers && Object.fromEntries(['sound', 'tactile'].map((part) => {
        const b = this.buffers[part];
        return [part, { sampleRate: b.sampleRate, length: b.length, duration: b.duration }];
      })),
    };
  }
}

// ---- starting audio -------------------------------------------------------------------------
// Browsers start an AudioContext only while the page has user activation, and which events give
// it depends on the pointer: under the HTML rules a mouse's pointerdown (or mousedown) does, but
// a pen's or a finger's pointerdown does not — their pointerup and touchend do (and the click
// that follows is still inside the activation). Chrome on a desktop is lenient; Safari on an
// iPad is not. So every one of these events, anywhere on the page and in the capture phase (no
// handler can hide it), asks for a resume until the context runs: a pen's first pointerdown
// is refused quietly and its pointerup starts the audio. If the browser suspends the context
// later (iOS after a call, a page in the background), the listeners are armed again.

const ACTIVATION_EVENTS = ['pointerdown', 'mousedown', 'pointerup', 'touchend', 'click', 'keydown'];
const LISTEN = { capture: true, passive: true };

/** Start `audio` (an AudioEngine) at the first event that may give user activation, and again
 *  whenever the browser suspends it; `onChange(state)` hears every change of its state. */
export function startOnActivation(audio, onChange = () => {}) {
  let armed = false;
  const start = () => audio.resume();
  const arm = (on) => {
    if (on === armed) return;
    armed = on;
    for (const type of ACTIVATION_EVENTS) {
      if (on) window.addEventListener(type, start, LISTEN);
      else window.removeEventListener(type, start, LISTEN);
    }
  };
  audio.onStateChange((audioState) => {
    arm(audioState !== 'running' && audioState !== 'closed');
    onChange(audioState);
  });
  arm(audio.state !== 'running');
}
