// Web Audio: the pen's sound unit and tactile pattern, looping, their gains following Eq. 1.
//
//   sound unit   → soundGain   ─┬─ (tactile over audio off) → destination (both channels)
//                               └─ (on) → merger input 0 = LEFT ─┐
//   tactile loop → tactileGain ──────── → merger input 1 = RIGHT ─┴→ destination
//
// With tactile over audio on, the right channel drives an actuator through an amplifier (the
// common research set-up) and the left channel carries the sound. The context is created with
// the interactive latency hint; browsers keep it suspended until a user gesture, so it starts
// on the first touch (`resume`). Both loops run from then on; the gains (smoothed by
// setTargetAtTime with the profile's time constant, which is the smoother of coupling.js)
// make them silent whenever the pen is lifted.
//
// Levels: the sound unit is normalised to -20 dBFS RMS, so gain 1 plays it at that level; the
// tactile pattern is peak-normalised, so its gain is the Eq. 1 gain over a_max (full drive at
// a_max) and never clips.

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
    this.sound = null;
    this.tau = 0.005;
    this.routeTactile(false);
  }

  get sampleRate() {
    return this.ctx.sampleRate;
  }

  /** Start (or restart) audio: call from a user gesture. */
  async resume() {
    if (this.ctx.state !== 'running') {
      try { await this.ctx.resume(); } catch (error) { console.warn('audio:', error); }
    }
    return this.ctx.state;
  }

  /** Decode a profile's sound unit and tactile pattern (Web Audio resamples the 8 kHz one). */
  async load(profile, fetchBytes) {
    const [sound, tactile] = await Promise.all([profile.sound.url, profile.tactile.url].map(
      async (url) => this.ctx.decodeAudioData(await fetchBytes(url))));
    return { sound, tactile };
  }

  /** Loop these buffers from now on, replacing the previous pen's. */
  use(buffers, coupling) {
    for (const source of this.sources) {
      try { source.stop(); } catch { /* never started */ }
      source.disconnect();
    }
    this.tau = coupling.smoothing_ms / 1000;
    this.sound = new AudioBufferSourceNode(this.ctx, { buffer: buffers.sound, loop: true });
    const tactile = new AudioBufferSourceNode(this.ctx, { buffer: buffers.tactile, loop: true });
    this.sound.connect(this.soundGain);
    tactile.connect(this.tactileGain);
    this.sound.start();
    tactile.start();
    this.sources = [this.sound, tactile];
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
    };
  }
}
