// @ts-check
// The "Record a pen" page: takes of the server's pen's accelerometer and this device's
// microphone, kept or dropped, then Build (a profile, installed and offered at once).
//
// The accelerometer is captured by the server through its pen bridge; the page starts and
// stops takes (POST api/record/takes, …/stop) and polls the live level (GET api/record/live).
// The microphone is recorded here: getUserMedia with echo cancellation, noise suppression and
// automatic gain off (they erase friction sound) into an AudioContext at 48 kHz. Its samples
// are collected by an AudioWorklet (record-worklet.js), not a ScriptProcessorNode: the worklet
// runs on the audio rendering thread, so a busy page (the meters, the uploads) cannot drop
// samples, and ScriptProcessorNode is deprecated. An AnalyserNode gives the live level. After
// a take the samples go to the server as a 16-bit WAV in chunks (record-wav.js).
//
// window.realpenRecord exposes the page's state for tests: mic (its state and settings),
// status (the server's GET api/record), level (the last live reply), building.

import { problem, uploadWav, wav16 } from './record-wav.js';

const $ = (/** @type {string} */ id) => /** @type {HTMLElement} */ (document.getElementById(id));
const query = new URLSearchParams(window.location.search);
const token = query.get('token');
const LIVE_MS = 150; // the accelerometer's level is polled this often during a take
const STATUS_MS = 2000; // the pen's status is polled this often between takes
const BUILD_MS = 250;
const SAMPLE_RATE = 48000;
const G = 9.80665;

/** @param {string} url */
function withToken(url) {
  return token ? `${url}${url.includes('?') ? '&' : '?'}token=${encodeURIComponent(token)}` : url;
}

/**
 * @param {string} url
 * @param {RequestInit} [init]
 * @returns {Promise<any>}
 */
async function api(url, init) {
  const response = await fetch(withToken(url), { cache: 'no-store', ...init });
  if (!response.ok) throw new Error(await problem(response));
  return response.status === 204 ? null : response.json();
}

/** @param {string} url @param {string} method @param {object} body */
const send = (url, method, body) => api(url, {
  method, headers: { 'Content-Type': 'application/json' }, body: JSON.stringify(body),
});

/**
 * @typedef {{ state: string, rate: number, settings: MediaTrackSettings | null,
 *   context: AudioContext | null, analyser: AnalyserNode | null,
 *   collector: AudioWorkletNode | null, stream: MediaStream | null, peakHold: number }} Mic
 */

/** @type {{ mic: Mic, status: any, level: any, building: boolean, take: number | null,
 *   stopping: boolean }} */
const page = {
  mic: { state: 'off', rate: 0, settings: null, context: null, analyser: null, collector: null,
    stream: null, peakHold: 0 },
  status: null,
  level: null,
  building: false,
  take: null,
  stopping: false, // a take's end: its sound is still being sent
};
// @ts-ignore - for tests and the curious
window.realpenRecord = page;

function showNotice(/** @type {string} */ text) {
  $('notice-text').textContent = text;
  $('notice').hidden = false;
}

/** @param {HTMLElement} element @param {string} text @param {string} [kind] */
function say(element, text, kind = '') {
  element.textContent = text;
  element.className = `state ${kind}`.trim();
}

// ---- the microphone --------------------------------------------------------------------------

/** Why this browser cannot record here, or null. */
function micUnavailable() {
  if (!window.isSecureContext) {
    return 'Browsers allow the microphone only on a secure page: open this page as '
      + `http://localhost:${window.location.port || 80}/record on this computer, or over HTTPS.`;
  }
  if (!navigator.mediaDevices || !navigator.mediaDevices.getUserMedia) {
    return 'This browser cannot record from a microphone (no getUserMedia).';
  }
  if (typeof AudioWorkletNode === 'undefined') return 'This browser has no AudioWorklet.';
  return null;
}

async function startMic() {
  const mic = page.mic;
  if (mic.state === 'on' || mic.state === 'starting') return;
  const why = micUnavailable();
  if (why) {
    mic.state = 'unavailable';
    say($('mic-state'), why, 'bad');
    updateRecordButton();
    return;
  }
  mic.state = 'starting';
  say($('mic-state'), 'Asking for the microphone…');
  try {
    const stream = await navigator.mediaDevices.getUserMedia({ audio: {
      echoCancellation: false, noiseSuppression: false, autoGainControl: false,
      sampleRate: SAMPLE_RATE, channelCount: 1,
    } });
    let context;
    try {
      context = new AudioContext({ sampleRate: SAMPLE_RATE });
    } catch { // a browser that cannot run at 48 kHz: its own rate (44.1 kHz is accepted too)
      context = new AudioContext();
    }
    await context.audioWorklet.addModule(withToken('static/record-worklet.js'));
    const source = context.createMediaStreamSource(stream);
    const analyser = context.createAnalyser();
    analyser.fftSize = 2048;
    const collector = new AudioWorkletNode(context, 'realpen-pcm-collector',
      { numberOfInputs: 1, numberOfOutputs: 1, channelCount: 1, channelCountMode: 'explicit' });
    // Through a muted gain to the output, so the graph surely pulls the collector (its output
    // is silence: nothing is heard).
    const mute = context.createGain();
    mute.gain.value = 0;
    source.connect(analyser);
    source.connect(collector).connect(mute).connect(context.destination);
    if (context.state !== 'running') { // started without a tap: the next tap starts it
      context.resume();
      document.addEventListener('pointerdown', () => context.resume(), { once: true });
    }
    const [track] = stream.getAudioTracks();
    Object.assign(mic, { state: 'on', rate: context.sampleRate, stream, context, analyser,
      collector, settings: track.getSettings() });
    track.addEventListener('ended', () => {
      mic.state = 'ended';
      say($('mic-state'), 'The microphone stopped (unplugged, or its permission withdrawn).', 'bad');
      updateRecordButton();
    });
    say($('mic-state'), micLine(track.label, mic.settings, context.sampleRate),
      processingOn(mic.settings) ? 'warn' : 'ok');
    $('mic-start').hidden = true;
    requestAnimationFrame(drawMic);
  } catch (error) {
    const name = error instanceof Error ? error.name : '';
    mic.state = name === 'NotAllowedError' || name === 'SecurityError' ? 'denied' : 'failed';
    say($('mic-state'), mic.state === 'denied'
      ? 'No microphone allowed: takes record the accelerometer only (a tactile-only pen). '
        + 'Allow the microphone in the browser\'s site settings to record sound.'
      : `The microphone did not start (${error instanceof Error ? error.message : error}).`, 'bad');
    $('mic-start').textContent = 'Try the microphone again';
  }
  updateRecordButton();
}

/** Whether the browser kept a processing step on that erases friction sound. */
function processingOn(/** @type {MediaTrackSettings | null} */ s) {
  return Boolean(s && (s.echoCancellation || s.noiseSuppression || s.autoGainControl));
}

/** @param {string} label @param {MediaTrackSettings | null} s @param {number} rate */
function micLine(label, s, rate) {
  const on = s ? [s.echoCancellation && 'echo cancellation', s.noiseSuppression
    && 'noise suppression', s.autoGainControl && 'automatic gain'].filter(Boolean) : [];
  const processing = on.length ? `; the browser kept ${on.join(', ')} on, which erases `
    + 'friction sound' : '; echo cancellation, noise suppression and automatic gain off';
  return `Recording from ${label || 'the microphone'} at ${rate / 1000} kHz${processing}.`;
}

const micBuffer = new Float32Array(2048);

function drawMic() {
  const { analyser } = page.mic;
  if (!analyser || page.mic.state !== 'on') return;
  analyser.getFloatTimeDomainData(micBuffer);
  let sum = 0;
  let peak = 0;
  for (const x of micBuffer) {
    sum += x * x;
    peak = Math.max(peak, Math.abs(x));
  }
  const rms = Math.sqrt(sum / micBuffer.length);
  const db = rms > 0 ? 20 * Math.log10(rms) : -Infinity;
  page.mic.peakHold = Math.max(peak, page.mic.peakHold * 0.97);
  const bar = $('mic-level');
  bar.style.width = `${Math.max(0, Math.min(100, (db + 80) / 80 * 100))}%`; // −80 … 0 dBFS
  bar.className = peak >= 0.999 ? 'clipped' : db > -12 ? 'hot' : '';
  $('mic-level-value').textContent = Number.isFinite(db) ? `${db.toFixed(1)} dBFS` : 'silent';
  if (peak >= 0.999) {
    const clip = $('mic-clip');
    clip.textContent = 'Clipping: move the microphone away or turn its input level down.';
    clip.hidden = false;
  }
  requestAnimationFrame(drawMic);
}

// ---- the pen (the server's) ------------------------------------------------------------------

/** Whether takes capture the server's pen's accelerometer. */
const accelOn = () => Boolean(page.status && page.status.pen.accelerometer !== false);

function showPen() {
  const pen = page.status.pen;
  const line = $('accel-state');
  if (pen.accelerometer === false && !pen.connected) {
    say(line, pen.name === 'log'
      ? 'No pen connected on the server\'s side (start the server with its device option): '
        + 'takes record the microphone only (a sound-only pen).'
      : `The server's pen (${pen.name}) is not connected (${pen.message}): takes record the `
        + 'microphone only until it is.', 'warn');
  } else if (pen.accelerometer === false) {
    say(line, `The server's pen (${pen.name}) has no accelerometer: takes record the microphone`
      + ' only (a sound-only pen).', 'warn');
  } else {
    say(line, `Recording the accelerometer of the server's pen: ${pen.message}.`, 'ok');
  }
  /** @type {HTMLSelectElement} */ ($('range')).disabled = !accelOn();
}

/** @param {any} level */
function showAccel(level) {
  const accel = level && level.accel;
  ['x', 'y', 'z'].forEach((axis, i) => {
    const bar = $(`accel-${axis}`);
    const value = $(`accel-${axis}-value`);
    if (!accel) {
      bar.style.width = '0';
      value.textContent = '–';
      return;
    }
    const rms = accel.rms_ms2[i];
    const full = (accel.range_g || 2) * G;
    const db = rms > 0 ? 20 * Math.log10(rms / full) : -Infinity; // of full scale
    bar.style.width = `${Math.max(0, Math.min(100, (db + 80) / 80 * 100))}%`;
    bar.className = accel.clipped ? 'clipped' : db > -12 ? 'hot' : '';
    value.textContent = `${rms.toFixed(3)} m/s²`;
  });
  const clip = $('accel-clip');
  clip.hidden = !(accel && accel.clipped);
  if (accel && accel.clipped) {
    clip.textContent = `Clipping: ${accel.clipped} samples at full scale; choose a larger range.`;
  }
}

// ---- takes -----------------------------------------------------------------------------------

function updateRecordButton() {
  const button = /** @type {HTMLButtonElement} */ ($('record'));
  const mic = page.mic.state === 'on';
  const running = page.take !== null;
  button.disabled = !running && (page.building || page.stopping || !(mic || accelOn()));
  button.textContent = running ? 'Stop' : 'Record';
  button.classList.toggle('recording', running);
  /** @type {HTMLSelectElement} */ ($('range')).disabled = running || !accelOn();
  if (!running && !mic && !accelOn()) {
    say($('take-state'), 'Nothing to record: no pen on the server\'s side and no microphone. '
      + 'Allow the microphone, or start the server with a pen.', 'bad');
  } else if (!running && $('take-state').classList.contains('bad')) {
    say($('take-state'), '');
  }
}

/** @type {Float32Array[]} */
let micBlocks = [];
let takeHasMic = false; // the running take records the microphone (it was on at the start)
/** @type {((frames: number) => void) | null} */
let micDone = null;
let clockTimer = 0;
let liveTimer = 0;

async function startTake() {
  const mic = page.mic.state === 'on' ? page.mic : null;
  if (mic && mic.context && mic.context.state !== 'running') await mic.context.resume();
  const take = await send('api/record/takes', 'POST', {
    accelerometer: accelOn(), range_g: Number(/** @type {HTMLSelectElement} */ ($('range')).value),
  });
  page.take = take.id;
  micBlocks = [];
  takeHasMic = Boolean(mic && mic.collector);
  if (mic && mic.collector) {
    mic.collector.port.onmessage = (event) => {
      if (event.data.samples) micBlocks.push(event.data.samples);
      if (event.data.done !== undefined && micDone) micDone(event.data.done);
    };
    mic.collector.port.postMessage({ record: true });
  }
  const started = performance.now();
  const longest = page.status ? page.status.limits.max_take_s : 300;
  clockTimer = window.setInterval(() => {
    const seconds = (performance.now() - started) / 1000;
    $('clock').textContent = `${seconds.toFixed(1)} s`;
    if (seconds >= longest && page.take === take.id) stopTake(); // the server keeps no more
  }, 100);
  const parts = [accelOn() && 'the accelerometer', mic && 'the microphone'].filter(Boolean);
  say($('take-state'), `Take ${take.id}: recording ${parts.join(' and ')}. Write now.`, 'ok');
  updateRecordButton();
  pollLive();
  await refresh(); // the running take in the list
}

async function pollLive() {
  if (page.take === null) return;
  try {
    page.level = await api('api/record/live');
    showAccel(page.level);
    if (page.level.accel_problem) say($('accel-state'), page.level.accel_problem, 'warn');
  } catch (error) {
    console.warn('realpen: live level:', error);
  }
  if (page.take !== null) liveTimer = window.setTimeout(pollLive, LIVE_MS);
}

async function stopTake() {
  const takeId = page.take;
  if (takeId === null) return;
  page.take = null;
  page.stopping = true;
  window.clearInterval(clockTimer);
  window.clearTimeout(liveTimer);
  const mic = page.mic;
  /** @type {Promise<number> | null} */
  let flushed = null;
  if (takeHasMic && mic.collector) { // a microphone that stopped mid-take still hands over
    flushed = new Promise((resolve) => {
      micDone = resolve;
      window.setTimeout(() => resolve(-1), 2000); // a worklet that no longer answers: what came
    });
    mic.collector.port.postMessage({ record: false });
  }
  say($('take-state'), `Take ${takeId}: stopping…`);
  updateRecordButton();
  try {
    await send(`api/record/takes/${takeId}/stop`, 'POST', {});
    if (flushed) {
      await flushed;
      const { wav, frames } = wav16(micBlocks, mic.rate);
      micBlocks = [];
      if (frames) {
        await uploadWav(withToken, takeId, wav, (done, total) => say($('take-state'),
          `Take ${takeId}: sending its sound, ${Math.round(done / total * 100)} %`));
      }
    }
    say($('take-state'), `Take ${takeId} recorded.`, 'ok');
  } catch (error) {
    say($('take-state'), `Take ${takeId}: ${error instanceof Error ? error.message : error}`, 'bad');
  } finally {
    page.stopping = false;
  }
  showAccel(null);
  await refresh();
}

/** @param {number | null} x @param {number} [digits] */
const fixed = (x, digits = 1) => (x === null || x === undefined ? '–' : x.toFixed(digits));

/** @param {any} take */
function takeRow(take) {
  const row = document.createElement('tr');
  row.dataset.take = String(take.id);
  row.classList.toggle('left-out', !take.keep);
  const cell = (/** @type {string} */ text, /** @type {string} */ kind = '') => {
    const td = document.createElement('td');
    td.textContent = text;
    if (kind) td.className = kind;
    row.append(td);
    return td;
  };
  cell(String(take.id));
  cell(take.running ? 'recording…' : `${take.seconds.toFixed(1)} s`);
  const accel = take.accel;
  if (accel) {
    const td = cell(`rms ${accel.rms_ms2.map((/** @type {number} */ v) => v.toFixed(2)).join(' / ')} m/s²,`
      + ` peak ${accel.peak_g.toFixed(2)} g, ${accel.rate_hz.toFixed(1)} Hz`
      + (accel.gaps ? `, ${accel.gaps} gaps` : '') + (accel.overruns ? `, ${accel.overruns} overruns` : ''));
    if (accel.clipped) td.append(clipped(accel.clipped));
  } else {
    cell(take.accel_problem || '—', take.accel_problem ? 'problem' : '');
  }
  const sound = take.sound;
  if (sound) {
    const td = cell(`rms ${fixed(sound.rms_dbfs)} dBFS, peak ${fixed(sound.peak_dbfs)} dBFS`);
    if (sound.clipped) td.append(clipped(sound.clipped));
  } else {
    cell('—');
  }
  const keep = document.createElement('input');
  keep.type = 'checkbox';
  keep.checked = take.keep;
  keep.setAttribute('aria-label', `Keep take ${take.id}`);
  keep.disabled = take.running;
  keep.addEventListener('change', () => act(() => send(`api/record/takes/${take.id}`, 'PATCH',
    { keep: keep.checked })));
  cell('').append(keep);
  const drop = document.createElement('button');
  drop.type = 'button';
  drop.className = 'plain';
  drop.textContent = 'Drop';
  drop.disabled = take.running;
  drop.addEventListener('click', () => act(() => api(`api/record/takes/${take.id}`,
    { method: 'DELETE' })));
  cell('').append(drop);
  return row;
}

/** @param {number} count */
function clipped(count) {
  const span = document.createElement('span');
  span.className = 'bad';
  span.textContent = ` clipped (${count} samples)`;
  return span;
}

/** Run a take action, then show the list again; a refusal becomes a notice. */
async function act(/** @type {() => Promise<any>} */ action) {
  try {
    await action();
  } catch (error) {
    showNotice(error instanceof Error ? error.message : String(error));
  }
  await refresh();
}

function showTakes() {
  const takes = page.status.takes;
  $('no-takes').hidden = takes.length > 0;
  $('takes').hidden = takes.length === 0;
  $('takes-body').replaceChildren(...takes.map(takeRow));
}

// ---- build -----------------------------------------------------------------------------------

async function build(/** @type {SubmitEvent} */ event) {
  event.preventDefault();
  const value = (/** @type {string} */ id) => /** @type {HTMLInputElement} */ ($(id)).value.trim();
  try {
    await send('api/record/build', 'POST', { name: value('name'), tool: value('tool'),
      description: value('description'), actuator: value('actuator') });
  } catch (error) {
    say($('build-state'), error instanceof Error ? error.message : String(error), 'bad');
    return;
  }
  page.building = true;
  updateRecordButton();
  pollBuild();
}

async function pollBuild() {
  let job;
  try {
    job = await api('api/record/build');
  } catch (error) {
    say($('build-state'), error instanceof Error ? error.message : String(error), 'bad');
    page.building = false;
    return;
  }
  showBuild(job);
  if (job.state === 'running') {
    window.setTimeout(pollBuild, BUILD_MS);
    return;
  }
  page.building = false;
  updateRecordButton();
}

/** @param {any} job */
function showBuild(job) {
  $('build-progress').hidden = job.state !== 'running';
  $('build-bar').style.width = `${Math.round(job.fraction * 100)}%`;
  /** @type {HTMLButtonElement} */ ($('build')).disabled = job.state === 'running';
  const line = $('build-state');
  if (job.state === 'running') {
    say(line, `Building ${job.name}: ${job.stage} (${Math.round(job.fraction * 100)} %)`);
  } else if (job.state === 'failed') {
    say(line, `${job.name} was not built: ${job.detail}`, 'bad');
  } else {
    say(line, `Installed ${job.profile} (${job.summary}); it is in the pen picker now. `, 'ok');
    const link = document.createElement('a');
    link.href = withToken(`./?pen=${encodeURIComponent(job.profile)}`);
    link.id = 'write-with';
    link.textContent = `Write with ${job.profile} →`;
    line.append(link);
  }
}

// ---- status ----------------------------------------------------------------------------------

async function refresh() {
  try {
    page.status = await api('api/record');
  } catch (error) {
    say($('accel-state'), `The server did not answer (${error instanceof Error ? error.message
      : error}).`, 'bad');
    return;
  }
  if (page.take === null) showPen();
  showTakes();
  updateRecordButton();
}

async function start() {
  $('notice-close').addEventListener('click', () => { $('notice').hidden = true; });
  $('mic-start').addEventListener('click', startMic);
  $('record').addEventListener('click', () => {
    const action = page.take === null ? startTake : stopTake;
    action().catch((error) => {
      page.take = null;
      window.clearInterval(clockTimer);
      say($('take-state'), error instanceof Error ? error.message : String(error), 'bad');
      updateRecordButton();
    });
  });
  $('build-form').addEventListener('submit', (event) => build(/** @type {SubmitEvent} */ (event)));
  const why = micUnavailable();
  if (why) {
    page.mic.state = 'unavailable';
    say($('mic-state'), why, 'bad');
    $('mic-start').hidden = true;
  }
  await refresh();
  /** @type {HTMLInputElement} */ ($('actuator')).value = page.status
    ? page.status.default_actuator : 'lra:f0=175,q=8';
  if (page.status && page.status.build && page.status.build.state !== 'running') {
    showBuild(page.status.build);
  } else if (page.status && page.status.build) {
    page.building = true;
    pollBuild();
  }
  window.setInterval(() => { if (page.take === null && !page.building) refresh(); }, STATUS_MS);
  // A microphone already allowed for this site starts without a click.
  try {
    const permission = await navigator.permissions.query(
      /** @type {PermissionDescriptor} */ ({ name: 'microphone' }));
    if (permission.state === 'granted' && !why) await startMic();
  } catch { /* a browser that cannot say: the button is there */ }
  // @ts-ignore - for tests
  window.realpenRecord.ready = true;
}

start();
