// The RealPen page: pick a pen, a feedback modality and the ink, then write.
//
// Each pen sample goes three ways (writer.js, which the study's participant screen shares): the
// ink (ink.js), the audio graph (Eq. 1 gain of the sound unit and the tactile loop, audio.js)
// and the server (pen_down / samples / gain / pen_up over the WebSocket, link.js), which stores
// the stroke and drives the pen's actuator.
//
// window.realpen exposes the live state for tests and for the curious: pen, modality, ink,
// calibration, the latest pressure and speed, the Eq. 1 target gain, the smoothed gain (the
// documented recursion on the event clock) and the audio gain actually applied, a trace of every
// sample, and the coupling functions themselves (model.*). With a pen whose profile has a
// vibration grid, pointTargets and pointGains are the target and applied gains of each point's
// tactile loop (model.VibrationGrid computes them).
//
// The Pen panel (footer button "Pen") drives the pen's actuator straight from the page over USB
// serial or Bluetooth (pen-link.js): pen down/up and the gain become SET_STATE, a change of pen
// uploads its pattern. Whatever the pen does, the page's own sound and ink go on. When the
// server itself drives a pen (the serve command's device option), the panel shows that bridge's
// status too. window.realpen.penDevice is the link's status; window.realpen.penLink the link.
// The panel's headline names the pen connected, on the page's side or the server's; with
// Tactile chosen and nothing to play it on (no pen either side, Tactile → R off) the status bar
// says so where the gain meter was.
//
// URL parameters preset the page for a study: ?pen=marker&modality=tactile&ink=hidden&tactile=audio
//
// A pen whose audio does not load (or decode) never breaks the page: picking it keeps the
// current pen, at start-up the page falls back to the first pen that loads, and either way a
// notice says what failed.

import { alpha, gainRaw, onePole, playbackRate, Smoother } from './coupling.js';
import { CSS_PX_PER_MM, MOUSE_PRESSURE, SPEED_WINDOW_MS } from './pen.js';
import { AudioEngine, startOnActivation } from './audio.js';
import { Ink, inkStyle } from './ink.js';
import { Link } from './link.js';
import { MODALITIES, Writer, liveState, modalityName, tactileOn } from './writer.js';
import { PenLink, support as penSupport } from './pen-link.js';
import { VibrationGrid } from './grid.js';

const INKS = ['visible', 'hidden'];

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
const describe = (error) => String((error && error.message && error.name)
  ? `${error.name}: ${error.message}` : error);

const state = liveState({
  notice: null,
  // ?modality=auditory-tactile (the old name) still works, as does a setting saved with it.
  modality: pick(modalityName(query.get('modality')), MODALITIES,
    pick(modalityName(saved.get('modality')), MODALITIES, 'audio-tactile')),
  ink: pick(query.get('ink'), INKS, pick(saved.get('ink'), INKS, 'visible')),
  pxPerMm: saved.get('pxPerMm', CSS_PX_PER_MM),
  calibrated: saved.get('pxPerMm', null) !== null,
  model: { gainRaw, playbackRate, alpha, onePole, MOUSE_PRESSURE, SPEED_WINDOW_MS, CSS_PX_PER_MM,
    VibrationGrid },
});
window.realpen = state;

const audio = new AudioEngine();
const smoother = new Smoother(audio.sampleRate, 5);
const ink = new Ink($('ink'));
const buffers = new Map();
let penRequest = 0;

Object.defineProperties(state, {
  gain: { enumerable: true, get: () => audio.soundGain.gain.value },
  tactileGain: { enumerable: true, get: () => audio.tactileGain.gain.value },
  pointGains: { enumerable: true, get: () => audio.report().pointGains },
  audio: { enumerable: true, get: () => audio.report() },
  link: { enumerable: true, get: () => link && link.stats },
  inkedPixels: { value: () => ink.inkedPixels() },
});

/** A pen's pattern for its own link (int16 LE at `rate` Hz); a refusal says the server's
 *  reason (its one-line `detail`, e.g. a rate the pattern cannot take), not only the status. */
async function getPenPattern(name, rate) {
  const response = await fetch(withToken(
    `api/pens/${encodeURIComponent(name)}/pen-pattern?rate=${rate}`));
  if (!response.ok) {
    let detail = null;
    try { ({ detail } = await response.json()); } catch { /* not JSON */ }
    throw new Error(typeof detail === 'string' && detail ? detail : `HTTP ${response.status}`);
  }
  return response.arrayBuffer();
}

// The pen's own link: it never waits on the page, nor the page on it.
const penLink = new PenLink({ fetchPattern: getPenPattern, onChange: scheduleStatus });
Object.defineProperties(state, {
  penDevice: { enumerable: true, get: () => ({ ...penLink.status }) },
  penLink: { value: penLink },
});

/** The writer's gain → the pen: playing while down with tactile feedback, gain 0-1 of a_max. */
function penGain(down, target) {
  const c = state.coupling;
  if (!c) return;
  penLink.setState(down && tactileOn(state.modality), target / c.a_max,
    Math.max(5, c.smoothing_ms));
}

const link = new Link(
  withToken(`${window.location.protocol === 'https:' ? 'wss' : 'ws'}://${window.location.host}/ws`),
  { client: `realpen-page/1 ${navigator.userAgent}`.slice(0, 200), onChange: scheduleStatus });
// After a reload in this tab the page is the same page: its stroke numbers go on from its last.
state.stroke = link.lastStroke;

const writer = new Writer(state, { surface: $('surface'), ink, audio, smoother, link,
  onChange: scheduleStatus, onDown: () => $('hint').classList.add('gone'), onGain: penGain });

// Audio starts at the first event that may give user activation (see audio.js).
startOnActivation(audio, scheduleStatus);

// ---- pickers ------------------------------------------------------------------------------

function mark(group, value) {
  for (const button of $(group).querySelectorAll('button')) {
    button.setAttribute('aria-checked', String(button.dataset.value === value));
  }
}

function onPick(group, handler) {
  $(group).addEventListener('click', (event) => {
    const button = event.target.closest('button[data-value]');
    if (button) handler(button.dataset.value);
  });
}

function showNotice(text) {
  state.notice = text;
  $('notice-text').textContent = text;
  $('notice').hidden = false;
}

function clearNotice() {
  state.notice = null;
  $('notice').hidden = true;
}

/** A pen's decoded audio (cached; a failed load is forgotten so that a later pick retries). */
function loadBuffers(chosen) {
  if (!buffers.has(chosen.name)) {
    const loading = audio.load(chosen, getBytes);
    buffers.set(chosen.name, loading);
    loading.catch(() => { if (buffers.get(chosen.name) === loading) buffers.delete(chosen.name); });
  }
  return buffers.get(chosen.name);
}

/**
 * Make `chosen` the pen once its audio has decoded: until then (and if it fails, for good) the
 * current pen stays, playing and drawing. Rejects when the audio does not load; resolves to
 * false when a later pick overtook this one.
 */
async function switchPen(chosen) {
  const request = ++penRequest;
  const decoded = await loadBuffers(chosen);
  if (request !== penRequest) return false;
  Object.assign(state, { pen: chosen.name, profileVersion: chosen.version, coupling: chosen.coupling,
    pointTargets: null });
  smoother.configure(audio.sampleRate, chosen.coupling.smoothing_ms);
  audio.use(decoded, chosen.coupling, chosen.name);
  mark('pens', chosen.name);
  saved.set('pen', chosen.name);
  penLink.setPen(chosen.name);
  scheduleStatus();
  return true;
}

/** The pen picker: switch, or keep the current pen and say why not. Never rejects. */
async function selectPen(name) {
  const chosen = state.profiles.find((p) => p.name === name);
  if (!chosen) return;
  try {
    if (await switchPen(chosen)) clearNotice();
  } catch (error) {
    console.warn(`realpen: the ${chosen.name} pen's audio did not load:`, error);
    mark('pens', state.pen);
    showNotice(`Could not load the ${chosen.name} pen's audio (${describe(error)})`
      + (state.pen ? `; still writing with ${state.pen}.` : '.'));
  }
}

/** At start: the pen asked for (URL, else the one saved in this browser), else the first pen
 *  that loads; a pen that fails is reported, never left blocking the page. */
async function startPen(wanted) {
  const problems = [];
  if (wanted && !state.profiles.some((p) => p.name === wanted)) {
    problems.push(`no pen '${wanted}' on this server`);
  }
  const order = [...new Set([wanted, ...state.profiles.map((p) => p.name)])]
    .map((name) => state.profiles.find((p) => p.name === name)).filter(Boolean);
  let failed = 0;
  for (const chosen of order) {
    try {
      await switchPen(chosen); // false: a pick on the picker overtook it, which then rules
      break;
    } catch (error) {
      failed += 1;
      console.warn(`realpen: the ${chosen.name} pen's audio did not load:`, error);
      problems.push(`could not load the ${chosen.name} pen's audio (${describe(error)})`);
    }
  }
  if (failed === order.length) throw new Error(`no pen could be loaded: ${problems.join('; ')}`);
  if (problems.length && state.pen) {
    const text = problems.join('; ');
    showNotice(`${text.charAt(0).toUpperCase()}${text.slice(1)}; writing with ${state.pen}.`);
  }
}

function selectModality(value) {
  state.modality = value;
  mark('modalities', value);
  saved.set('modality', value);
  scheduleStatus();
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

// A pen built on the "Record a pen" page (another tab) is installed while this page is open:
// look at the list again whenever the page comes back into view.
async function refreshPens() {
  if (document.visibilityState !== 'visible' || !state.ready) return;
  try {
    const list = await getJson('api/profiles');
    const names = (/** @type {{name: string}[]} */ (list.profiles)).map((p) => p.name).join('\n');
    if (names === state.profiles.map((p) => p.name).join('\n')) return;
    state.profiles = list.profiles;
    buildPenPicker();
    mark('pens', state.pen);
  } catch (error) {
    console.warn('could not refresh the pens', error);
  }
}

// ---- calibration --------------------------------------------------------------------------

function setCalibration(pxPerMm, calibrated) {
  state.pxPerMm = pxPerMm;
  state.calibrated = calibrated;
  writer.setPxPerMm(pxPerMm);
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

// ---- the pen panel ---------------------------------------------------------------------------

const PEN_KIND = { usb: 'USB', ble: 'Bluetooth' };
let bridge = null; // the server's GET /api/device, when it drives a pen
let bridgeAsked = false; // the server has been asked once: until then its pen is unknown
let bridgeTimer = null;

/** The server's pen device (not its command log, which drives nothing), or null. */
function serverPen() {
  return bridge && bridge.kind !== 'log' ? bridge : null;
}

/** Where the server's pen is, as its device string says ("serial:/dev/ttyACM0" → the port). */
function serverPenPlace(server) {
  if (server.kind === 'sim') return 'simulated';
  if (server.kind === 'ble') return 'Bluetooth';
  const name = String(server.name || '');
  return server.kind === 'serial' ? name.replace(/^serial:/, '') : name;
}

/** "Pen: RealPen (this page, USB)", "Pen: RealPen (server, /dev/ttyACM0)", both when both are
 *  connected, or "Pen: none connected". */
function penHeadline() {
  const s = penLink.status;
  const server = serverPen();
  const pens = [];
  if (penLink.connected && s.info) {
    pens.push(`${s.info.name || 'a pen'} (this page, ${PEN_KIND[s.kind] || s.kind})`);
  }
  if (server && server.connected === true) {
    const name = (server.info && server.info.name) || 'a pen';
    pens.push(`${name} (server, ${serverPenPlace(server)})`);
  }
  return `Pen: ${pens.join(' and ') || 'none connected'}`;
}

/** Whether anything plays the tactile pattern: a pen on either side (a server device that
 *  cannot say whether it is connected is given the benefit of the doubt) or the right audio
 *  channel (Tactile → R). */
function tactileHasOutlet() {
  const server = serverPen();
  return penLink.connected || Boolean(server && server.connected !== false)
    || Boolean(state.tactileAudio);
}

function setupPenPanel() {
  const can = penSupport();
  if (!can.serial || !can.bluetooth) {
    const missing = [!can.serial && 'USB serial (Web Serial)',
      !can.bluetooth && 'Bluetooth (Web Bluetooth)'].filter(Boolean).join(' or ');
    $('pen-note').textContent = `This browser cannot reach a pen over ${missing}. Chrome or `
      + 'Edge on a computer can; or let the server drive the pen (realpen serve\'s device '
      + 'option).';
    $('pen-note').hidden = false;
  }
  const run = (action) => async () => {
    try {
      await action();
    } catch (error) {
      penLink.update({ state: 'error', message: String((error && error.message) || error) });
    }
  };
  $('pen-usb').addEventListener('click', run(() => penLink.connectSerial()));
  $('pen-ble').addEventListener('click', run(() => penLink.connectBluetooth()));
  $('pen-disconnect').addEventListener('click', run(() => penLink.disconnect()));
  $('pen-device').addEventListener('click', () => {
    const panel = $('pen-panel');
    panel.hidden = !panel.hidden;
    $('pen-device').setAttribute('aria-expanded', String(!panel.hidden));
  });
  pollBridge();
}

/** The server's own pen (the serve command's device option), shown in the panel while there
 *  is one; asked every 1.5 s while the panel is open, every 5 s while it is closed. */
async function pollBridge() {
  clearTimeout(bridgeTimer);
  try {
    const response = await fetch(withToken('api/device'), { cache: 'no-store' });
    if (response.status === 404) { // a server without the route: nothing to show
      bridgeAsked = true;
      scheduleStatus();
      return;
    }
    bridge = response.ok ? await response.json() : null;
  } catch { bridge = null; }
  bridgeAsked = true;
  scheduleStatus();
  bridgeTimer = setTimeout(pollBridge, $('pen-panel').hidden ? 5000 : 1500);
}

function renderPen() {
  const s = penLink.status;
  const button = $('pen-device');
  button.dataset.state = s.state;
  const server = serverPen();
  $('pen-panel-title').textContent = penHeadline();
  let short = 'Pen';
  if (penLink.connected) short = `Pen · ${PEN_KIND[s.kind] || s.kind}`;
  else if (s.state === 'connecting') short = 'Pen · connecting…';
  else if (s.state === 'disconnected') short = 'Pen · lost';
  else if (s.state === 'error') short = 'Pen · problem';
  else if (server) short = `Pen · server${server.connected === false ? ' (lost)' : ''}`;
  $('pen-device-text').textContent = short;
  button.dataset.server = server ? String(server.connected) : '';
  // The link's idle line is said of this page: the headline above may name the server's pen.
  $('pen-status').textContent = s.state === 'idle' ? 'No pen connected to this page.' : s.message;
  $('pen-status').dataset.state = s.state;
  const meta = [];
  if (penLink.connected && s.battery !== null) meta.push(`battery ${s.battery} %`);
  if (penLink.connected && s.batteryMv !== null) {
    meta.push(`battery ${(s.batteryMv / 1000).toFixed(2)} V`);
  }
  if (s.underruns) meta.push(`${s.underruns} underrun${s.underruns > 1 ? 's' : ''} at the pen`);
  if (s.errors) meta.push(`${s.errors} bad frame${s.errors > 1 ? 's' : ''} from the pen`);
  $('pen-meta').hidden = !meta.length;
  $('pen-meta').textContent = meta.join(' · ');
  const progress = $('pen-progress');
  progress.hidden = s.progress === null || s.progress === undefined;
  if (!progress.hidden) $('pen-progress-bar').style.width = `${(s.progress * 100).toFixed(1)}%`;
  // While a pen is (being) connected, or the link is reconnecting (Bluetooth; USB after a pen
  // that stopped answering), only Disconnect is offered; otherwise what the browser can (a lost
  // USB port may be picked again).
  const active = penLink.connected || s.state === 'connecting'
    || (s.state === 'disconnected' && !penLink.userClosed
      && (s.kind === 'ble' || Boolean(penLink.reconnecting)));
  const can = penSupport();
  $('pen-disconnect').hidden = !active;
  $('pen-usb').hidden = active || !can.serial;
  $('pen-ble').hidden = active || !can.bluetooth;
  const line = $('pen-bridge');
  line.hidden = !server;
  if (server) {
    // The bridge's message is a whole status line ("connected: RealPen, firmware …",
    // "disconnected: …; reconnecting"); the flag speaks only when it says nothing.
    const how = { true: 'connected', false: 'not connected' }[server.connected] || 'no status';
    line.textContent = `Server pen (${server.name}): ${server.message || how}`;
    line.dataset.connected = String(server.connected);
  }
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
  audioPill.textContent = a.state === 'running' ? `audio ${(latency * 1000).toFixed(0)} ms` : 'tap to start audio';
  audioPill.title = a.state === 'running'
    ? `${(a.sampleRate / 1000).toFixed(1)} kHz; base latency ${(a.baseLatency * 1000).toFixed(1)} ms, output latency ${(a.outputLatency * 1000).toFixed(1)} ms`
    : 'Browsers start audio with a user gesture: a click, or the lift of a pen or finger';
  const calibrate = $('calibrate');
  calibrate.textContent = state.calibrated ? `${state.pxPerMm.toFixed(2)} px/mm` : 'Calibrate';
  calibrate.classList.toggle('warn', !state.calibrated);
  const shown = state.coupling ? Math.min(state.targetGain / state.coupling.a_max, 1) : 0;
  $('st-gain-bar').style.width = `${(shown * 100).toFixed(1)}%`;
  $('st-gain-value').textContent = state.targetGain.toFixed(2);
  // Tactile alone with nowhere to play it: words instead of a meter moving in silence.
  const unplayed = state.modality === 'tactile' && bridgeAsked && !tactileHasOutlet();
  $('st-gain').hidden = unplayed;
  $('st-tactile').hidden = !unplayed;
  $('st-tactile').textContent = unplayed
    ? 'Tactile: no pen connected and Tactile\u00a0\u2192\u00a0R is off \u2014 nothing plays the '
      + 'vibration' : '';
  renderPen();
}

// ---- start ---------------------------------------------------------------------------------

/**
 * With --lan the page was opened as …/?token=…; the server set its cookie on that response.
 * Once a request without the token succeeds (the cookie works), the token leaves the address
 * bar and the history, so it is not kept in bookmarks, shared screenshots or a synced history;
 * the page keeps it in memory for its own requests and reconnects.
 */
async function forgetTokenInAddress() {
  if (!token) return;
  try {
    const response = await fetch('api/config', { credentials: 'same-origin', cache: 'no-store' });
    if (!response.ok) return; // no cookie (blocked?): keep the token so that a reload works
  } catch { return; }
  const url = new URL(window.location.href);
  url.searchParams.delete('token');
  window.history.replaceState(window.history.state, '', `${url.pathname}${url.search}${url.hash}`);
}

async function start() {
  try {
    const [config, list] = await Promise.all([getJson('api/config'), getJson('api/profiles')]);
    state.config = config;
    state.profiles = list.profiles;
    await forgetTokenInAddress();
    buildPenPicker();
    onPick('pens', selectPen);
    onPick('modalities', selectModality);
    onPick('inks', selectInk);
    $('tactile-audio').addEventListener('click', () => setTactileAudio(!state.tactileAudio));
    $('calibrate').addEventListener('click', openCalibration);
    $('clear').addEventListener('click', () => ink.clear());
    $('notice-close').addEventListener('click', clearNotice);
    $('notice').addEventListener('pointerdown', (event) => event.stopPropagation()); // not a stroke
    setupPenPanel();
    selectModality(state.modality);
    selectInk(state.ink);
    setCalibration(state.pxPerMm, state.calibrated);
    const tactileParam = query.get('tactile');
    setTactileAudio(tactileParam ? tactileParam === 'audio' : config.tactile === 'audio');
    await startPen(query.get('pen') || saved.get('pen', null));
    state.ready = true;
    document.addEventListener('visibilitychange', refreshPens);
  } catch (error) {
    state.error = String(error);
    $('hint').textContent = `Could not start: ${error.message || error}`;
    console.error(error);
  }
  scheduleStatus();
}

start();
