// @ts-nocheck — runs in the AudioWorkletGlobalScope, whose globals the DOM types lack.
// The microphone's samples for the "Record a pen" page (record.js), collected on the audio
// rendering thread: while recording, every 128-frame render quantum of the first input channel
// is copied into blocks of BLOCK frames that go to the page (their buffers transferred). On
// {record: false} the part-filled block is sent too, then {done: frames}.
/* global registerProcessor, AudioWorkletProcessor */

const BLOCK = 8192; // frames per message: ~6 messages a second at 48 kHz

class PcmCollector extends AudioWorkletProcessor {
  constructor() {
    super();
    this.recording = false;
    this.block = new Float32Array(BLOCK);
    this.filled = 0;
    this.frames = 0;
    this.port.onmessage = (event) => {
      if (event.data.record === true) {
        this.recording = true;
        this.filled = 0;
        this.frames = 0;
      } else if (event.data.record === false && this.recording) {
        this.recording = false;
        this.flush();
        this.port.postMessage({ done: this.frames });
      }
    };
  }

  flush() {
    if (!this.filled) return;
    const samples = this.block.slice(0, this.filled);
    this.port.postMessage({ samples }, [samples.buffer]);
    this.filled = 0;
  }

  process(inputs) {
    const channel = inputs[0] && inputs[0][0];
    if (this.recording && channel) {
      let at = 0;
      while (at < channel.length) {
        const n = Math.min(channel.length - at, BLOCK - this.filled);
        this.block.set(channel.subarray(at, at + n), this.filled);
        this.filled += n;
        at += n;
        if (this.filled === BLOCK) this.flush();
      }
      this.frames += channel.length;
    }
    return true; // keep running while the page lives
  }
}

registerProcessor('realpen-pcm-collector', PcmCollector);
