// The RealPen page: pick a pen, a feedback modality and the ink, then write.
//
// Each pen sample goes three ways: the ink (ink.js), the audio graph (Eq. 1 gain of the sound
// unit and the tactile loop, audio.js) and the server (pen_down / samples / gain / pen_up over
// the WebSocket, link.js), which stores the stroke and drives the pen's actuator.
//
// window.realpen exposes the live state for tests and for the curious: pen, modality, ink,
// calibration, the latest pressure and speed, the Eq. 1 target gain, the smoothed gain (the
// documented recursion on the event clock) and the audio gain actually applied, a trace of every
// sample, and the coupling functions themselves (model.*).
//
// URL parameters preset the page for a study: ?pen=marker&modality=tactile&ink=hidden&tactile=audio

import { alpha, gainRaw, onePole, playbackRate, Smoother } from './coupling.js';
import { CSS_PX_PER_MM, MOUSE_PRESSURE, PenTracker, SPEED_WINDOW_MS } from './pen.js';
import { AudioEngine } from './audio.js';
import { Ink, inkStyle } from './ink.js';
import { Link } from './link.js';

const MODALITIES = ['tactile', 'auditory', 'auditory-tactile', 'none'];
const INKS = ['visible', 'hidden'];
const POINTER_TYPES = ['pen', 'touch', 'mouse'];
const TRACE_LIMIT = 20000;

const query = new URLSearchParams(window.location.search);
const token = query.get('token');
const $ = (id) => document.getElementById(id);

function withToken(url) {
  return token ? `${url}${url.includes('?') ? '&' : '?'}token=${encodeURIComponent(token)}` : url;
}

async function getJson(url) {
  const response = await fetch(withToken(url));
  if (!response.ok) throw new Error(`${url}: HTTP ${response.status}`);
  return response.json();
}

async function getBytes(url) {
  const response = await fetch(withToken(url));
  if (!response.ok) throw new Error(`${url}: HTTP ${response.status}`);
  return response.arrayBuffer();
}

const saved = {
  get(key, fallback) {
    try {
      const value = window.localStorage.getItem(`realpen.${key}`);
      return value === null ? fallback : JSON.parse(value);
    } catch { return fallback; }
  },
  set(key, value) {
    try { window.localStorage.setItem(`realpen.${key}`, JSON.stringify(value)); } catch { /* private mode */ }
  },
};

const pick = (value, allowed, fallback) => (allowed.includes(value) ? value : fallback);

const state = {
  ready: false,
  error: null,
  config: null,
  profiles: [],
  pen: null,
  profileVersion: null,
  coupling: null,
  modality: pick(query.get('modality'), MODALITIES, pick(saved.get('modality'), MODALITIES, 'auditory-tactile')),
  ink: pick(query.get('ink'), INKS, pick(saved.get('ink'), INKS, 'visible')),
  tactileAudio: false,
  pxPerMm: saved.get('pxPerMm', CSS_PX_PER_MM),
  calibrated: saved.get('pxPerMm', null) !== null,
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
  playbackRate: 1,
  trace: [],
  model: { gainRaw, playbackRate, alpha, onePole, MOUSE_PRESSURE, SPEED_WINDOW_MS, CSS_PX_PER_MM },
};
window.realpen = state;

const audio = new AudioEngine();
const smoother = new Smoother(audio.sampleRate, 5);
const ink = new Ink($('ink'));
const buffers = new Map();
let lastSentTarget = null;

Object.defineProperties(state, {
  gain: { enumerable: true, get: () => audio.soundGain.gain.value },
  tactileGain: { enumerable: true, get: () => audio.tactileGain.gain.value },
  audio: { enumerable: true, get: () => audio.report() },
  link: { enumerable: true, get: () => link && link.stats },
  inkedPixels: { value: () => ink.inkedPixels() },
});

const link = new Link(
  withToken(`${window.location.protocol === 'https:' ? 'wss' : 'ws'}://${window.location.host}/ws`),
  { client: `realpen-page/1 ${navigator.userAgent}`.slice(0, 200), onChange: scheduleStatus });

const soundOn = () => state.modality === 'auditory' || state.modality === 'auditory-tactile';
const tactileOn = () => state.modality === 'tactile' || state.modality === 'auditory-tactile';
const profile = () => state.profiles.find((p) => p.name === state.pen);

// ---- pen samples → ink, audio, server -------------------------------------------------------

function apply(samples) {
  const c = state.coupling;
  let target = 0;
  for (const s of samples) {
    target = gainRaw(c, s.pressure, s.speed);
    const smoothed = smoother.advanceTo(s.t);
    smoother.set(target);
    record(s.t, s.pressure, s.speed, target, smoothed);
  }
  const last = samples[samples.length - 1];
  Object.assign(state, { pressure: last.pressure, speed: last.speed, tiltX: last.tilt_x,
    tiltY: last.tilt_y, targetGain: target, playbackRate: playbackRate(c, last.speed) });
  state.tactileTarget = tactileOn() && state.tactileAudio ? target / c.a_max : 0;
  audio.set(soundOn() ? target : 0, state.tactileTarget, state.playbackRate);
  if (target !== lastSentTarget) {
    link.send({ type: 'gain', stroke: state.stroke, t: last.t, target });
    lastSentTarget = target;
  }
  const limit = (state.config && state.config.max_samples) || 512;
  for (let i = 0; i < samples.length; i += limit) {
    link.send({ type: 'samples', stroke: state.stroke,
      samples: samples.slice(i, i + limit).map(({ t, x, y, pressure, tilt_x, tilt_y, speed }) => (
        { t, x, y, pressure, tilt_x, tilt_y, speed })) });
  }
  scheduleStatus();
}

function record(t, pressure, speed, target, smoothed) {
  state.smoothedGain = smoothed;
  state.trace.push({ stroke: state.stroke, t, k: smoother.index, rate: smoother.rate, pressure,
    speed, target, smoothed });
  if (state.trace.length > TRACE_LIMIT) state.trace.splice(0, state.trace.length - TRACE_LIMIT);
}

function penDown(info, sample) {
  startAudio();
  if (!state.coupling) return;
  $('hint').classList.add('gone');
  state.stroke += 1;
  state.strokes += 1;
  state.down = true;
  state.pointerType = info.pointerType;
  lastSentTarget = null;
  link.send({ type: 'pen_down', stroke: state.stroke, t: sample.t, pen: state.pen,
    profile_version: state.profileVersion, modality: state.modality, ink: state.ink,
    pointer_type: pick(info.pointerType, POINTER_TYPES, 'unknown'), px_per_mm: state.pxPerMm,
    calibrated: state.calibrated });
  ink.begin(inkStyle(profile()), state.pxPerMm, sample, state.ink === 'visible');
  apply([sample]);
}

function penSamples(samples) {
  if (!state.down) return;
  ink.add(samples);
  apply(samples);
}

function penUp(t) {
  startAudio();
  if (!state.down) return;
  state.down = false;
  const smoothed = smoother.advanceTo(t);
  smoother.set(0);
  record(t, 0, 0, 0, smoothed);
  Object.assign(state, { pressure: 0, speed: 0, targetGain: 0, tactileTarget: 0 });
  audio.set(0, 0, state.playbackRate);
  link.send({ type: 'pen_up', stroke: state.stroke, t });
  ink.end();
  scheduleStatus();
}

const tracker = new PenTracker($('surface'), {
  pxPerMm: state.pxPerMm, onDown: penDown, onSamples: penSamples, onUp: penUp });

function startAudio() {
  audio.resume().then(scheduleStatus);
}

// ---- pickers ------------------------------------------------------------------------------

function mark(group, value) {
  for (const button of $(group).querySelectorAll('button')) {
    button.setAttribute('aria-checked', String(button.dataset.value === value));
  }
}

function onPick(group, handler) {
  $(group).addEventListener('click', (event) => {
    const button = event.target.closest('button[data-value]');
    if (button) {
      startAudio();
      handler(button.dataset.value);
    }
  });
}

async function selectPen(name) {
  const chosen = state.profiles.find((p) => p.name === name) || state.profiles[0];
  Object.assign(state, { pen: chosen.name, profileVersion: chosen.version, coupling: chosen.coupling });
  smoother.configure(audio.sampleRate, chosen.coupling.smoothing_ms);
  mark('pens', chosen.name);
  saved.set('pen', chosen.name);
  if (!buffers.has(chosen.name)) buffers.set(chosen.name, audio.load(chosen, getBytes));
  const decoded = await buffers.get(chosen.name);
  if (state.pen === chosen.name) audio.use(decoded, chosen.coupling);
}

function selectModality(value) {
  state.modality = value;
  mark('modalities', value);
  saved.set('modality', value);
}

function selectInk(value) {
  state.ink = value;
  mark('inks', value);
  document.body.classList.toggle('ink-hidden', value === 'hidden');
  saved.set('ink', value);
  scheduleStatus();
}

function setTactileAudio(on) {
  state.tactileAudio = on;
  audio.routeTactile(on);
  $('tactile-audio').setAttribute('aria-pressed', String(on));
  scheduleStatus();
}

function buildPenPicker() {
  const group = $('pens');
  group.replaceChildren(...state.profiles.map((p) => {
    const button = document.createElement('button');
    button.type = 'button';
    button.setAttribute('role', 'radio');
    button.dataset.value = p.name;
    button.title = p.description || p.tool;
    const swatch = document.createElement('i');
    swatch.className = 'swatch';
    swatch.style.background = inkStyle(p).color;
    button.append(swatch, p.name.charAt(0).toUpperCase() + p.name.slice(1));
    return button;
  }));
}

// ---- calibration --------------------------------------------------------------------------

function setCalibration(pxPerMm, calibrated) {
  state.pxPerMm = pxPerMm;
  state.calibrated = calibrated;
  tracker.pxPerMm = pxPerMm;
  document.documentElement.style.setProperty('--px-per-mm', String(pxPerMm));
  scheduleStatus();
}

function openCalibration() {
  const dialog = $('calibration');
  const range = $('cal-range');
  const show = () => {
    const reference = Number($('cal-ref').value);
    const value = Number(range.value);
    $('cal-bar').style.width = `${value * reference}px`;
    $('cal-value').textContent = `${value.toFixed(3)} CSS px per mm`;
  };
  range.value = state.pxPerMm;
  range.oninput = show;
  $('cal-ref').onchange = show;
  $('cal-minus').onclick = () => { range.value = Number(range.value) - 0.01; show(); };
  $('cal-plus').onclick = () => { range.value = Number(range.value) + 0.01; show(); };
  dialog.onclose = () => {
    if (dialog.returnValue === 'save') {
      saved.set('pxPerMm', Number(range.value));
      setCalibration(Number(range.value), true);
    } else if (dialog.returnValue === 'reset') {
      try { window.localStorage.removeItem('realpen.pxPerMm'); } catch { /* private mode */ }
      setCalibration(CSS_PX_PER_MM, false);
    }
  };
  show();
  dialog.showModal();
}

// ---- status bar -----------------------------------------------------------------------------

let statusQueued = false;
function scheduleStatus() {
  if (statusQueued) return;
  statusQueued = true;
  window.requestAnimationFrame(() => { statusQueued = false; renderStatus(); });
}

function renderStatus() {
  const stats = link.stats;
  const linkPill = $('st-link');
  linkPill.dataset.state = stats.state;
  const rtt = link.medianRtt();
  let text = stats.state === 'open' ? 'link' : stats.state === 'closed' ? 'reconnecting…' : 'connecting…';
  if (stats.state === 'open' && rtt !== null) text += ` ${rtt.toFixed(1)} ms`;
  if (stats.errors) text += ` · ${stats.errors} error${stats.errors > 1 ? 's' : ''}`;
  linkPill.querySelector('b').textContent = text;
  linkPill.title = stats.lastError ? `${stats.lastError.code}: ${stats.lastError.message}` : '';
  const a = audio.report();
  const latency = (a.baseLatency || 0) + (a.outputLatency || 0);
  const audioPill = $('st-audio');
  audioPill.textContent = a.state === 'running' ? `audio ${(latency * 1000).toFixed(0)} ms` : 'audio starts on first touch';
  audioPill.title = a.state === 'running'
    ? `${(a.sampleRate / 1000).toFixed(1)} kHz; base latency ${(a.baseLatency * 1000).toFixed(1)} ms, output latency ${(a.outputLatency * 1000).toFixed(1)} ms`
    : 'Browsers start audio with a user gesture: the first stroke or tap';
  const calibrate = $('calibrate');
  calibrate.textContent = state.calibrated ? `${state.pxPerMm.toFixed(2)} px/mm` : 'Calibrate';
  calibrate.classList.toggle('warn', !state.calibrated);
  const shown = state.coupling ? Math.min(state.targetGain / state.coupling.a_max, 1) : 0;
  $('st-gain-bar').style.width = `${(shown * 100).toFixed(1)}%`;
  $('st-gain-value').textContent = state.targetGain.toFixed(2);
}

// ---- start ---------------------------------------------------------------------------------

async function start() {
  try {
    const [config, list] = await Promise.all([getJson('api/config'), getJson('api/profiles')]);
    state.config = config;
    state.profiles = list.profiles;
    buildPenPicker();
    onPick('pens', selectPen);
    onPick('modalities', selectModality);
    onPick('inks', selectInk);
    $('tactile-audio').addEventListener('click', () => { startAudio(); setTactileAudio(!state.tactileAudio); });
    $('calibrate').addEventListener('click', openCalibration);
    $('clear').addEventListener('click', () => ink.clear());
    selectModality(state.modality);
    selectInk(state.ink);
    setCalibration(state.pxPerMm, state.calibrated);
    const tactileParam = query.get('tactile');
    setTactileAudio(tactileParam ? tactileParam === 'audio' : config.tactile === 'audio');
    await selectPen(query.get('pen') || saved.get('pen', state.profiles[0].name));
    state.ready = true;
  } catch (error) {
    state.error = String(error);
    $('hint').textContent = `Could not start: ${error.message || error}`;
    console.error(error);
  }
  scheduleStatus();
}

start();
