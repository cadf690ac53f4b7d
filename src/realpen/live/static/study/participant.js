// The participant screen of a study session: /study/participant?session=ID (docs/studies.md).
//
// A big Start (browsers start audio only from a user gesture), then trial after trial as the
// server hands them out (GET …/next): the trial's pen, feedback modality, ink and tactile pattern
// are set, its task is shown, the participant writes, taps "Done writing", answers the trial's
// questions, and the answer goes to the server with the response time: ms from the moment the
// trial was on screen and ready (performance.now()) to the final answer (the tap on a choice;
// the tap on Next when there are several questions or a scale to confirm).
//
// Nothing the participant sees names the design, the condition, the modality or the pen: only
// the task. A pen is named only as the design labels it for the participant (its `label`, or a
// choice as the design wrote it): never by its id or its profile's name, not even in an error,
// which says "this trial's pen" (the details go to the browser's console, for the experimenter).
// The layout is symmetric (nothing on one side only) so it favours neither hand.
//
// The trial's pen is played from its profile (`next.profile`); the pen's id (`next.pen`) is what
// the server stores with the answers.
//
// Strokes go through the writing page's own pipeline (writer.js, link.js): stored exactly as
// there, each pen_down naming the study session and the trial.
//
// Surviving a reload and a server restart: the answer about to be sent is kept in
// sessionStorage until the server has taken it (201) or says it has it (409), and sent again,
// first thing, after a reload; a request that fails on the network is tried again until it
// goes through, with "Reconnecting…" on screen; the trial shown is always the server's `next`.
// When the operator pauses the session, the screen says "Please wait" (between trials, or at
// once during one, whose clock then starts again when the session resumes).
//
// window.realpen exposes the live state (as on the writing page) and, under `study`, the
// screen, the trial, its start time, and the answers sent, for tests.

import { Smoother } from '../coupling.js';
import { CSS_PX_PER_MM } from '../pen.js';
import { AudioEngine, startOnActivation } from '../audio.js';
import { Ink } from '../ink.js';
import { Link } from '../link.js';
import { MODALITIES, Writer, liveState, modalityName } from '../writer.js';
import { bytes, call, forgetTokenInAddress, Refused, sleep, Unreachable, withToken } from './api.js';

const PAUSED_POLL_MS = 1000;  // while paused: ask again every second
const WATCH_MS = 1000;        // during a trial: is the session still running?
const RETRY_MS = [250, 500, 1000, 2000];  // waits between tries of a request that did not get through

const $ = (id) => document.getElementById(id);
const query = new URLSearchParams(window.location.search);
const sessionId = /^[1-9][0-9]{0,14}$/.test(query.get('session') || '')
  ? Number(query.get('session')) : null;
const PENDING = `realpen.study.pending.${sessionId}`;

function stored(key, fallback) {
  try {
    const value = window.localStorage.getItem(`realpen.${key}`);
    return value === null ? fallback : JSON.parse(value);
  } catch { return fallback; }
}

// The calibration is the one made on the writing page of this browser (same origin).
const savedPxPerMm = stored('pxPerMm', null);
const calibrated = Number.isFinite(savedPxPerMm) && savedPxPerMm > 0;

const study = {
  session: sessionId,
  screen: 'start',    // start | loading | wait | trial | feedback | done | error
  step: null,         // loading | write | answer | sending (within a trial)
  trial: null,        // the trial number shown
  next: null,         // the server's description of it
  t0: null,           // performance.now() when it was on screen and ready
  strokes: 0,         // strokes drawn in this trial
  answers: {},
  reconnecting: false,
  retries: 0,
  problem: null,
  sent: [],           // { trial, answers, rt_ms, status } of every answer the server took
  feedback: null,     // the last training feedback shown: { correct, answer }
};

const state = liveState({
  pxPerMm: calibrated ? savedPxPerMm : CSS_PX_PER_MM,
  calibrated,
  study,
});
window.realpen = state;

const audio = new AudioEngine();
const smoother = new Smoother(audio.sampleRate, 5);
const ink = new Ink($('ink'));
const link = new Link(
  withToken(`${window.location.protocol === 'https:' ? 'wss' : 'ws'}://${window.location.host}/ws`),
  { client: `realpen-study/1 ${navigator.userAgent}`.slice(0, 200) });
state.stroke = link.lastStroke; // the same page after a reload: its stroke numbers go on

Object.defineProperties(state, {
  gain: { enumerable: true, get: () => audio.soundGain.gain.value },
  tactileGain: { enumerable: true, get: () => audio.tactileGain.gain.value },
  audio: { enumerable: true, get: () => audio.report() },
  link: { enumerable: true, get: () => link.stats },
  inkedPixels: { value: () => ink.inkedPixels() },
});

const writer = new Writer(state, {
  surface: $('surface'), ink, audio, smoother, link,
  enabled: () => study.screen === 'trial' && (study.step === 'write' || study.step === 'answer')
    && writes(study.next),
  extra: () => ({ study_session: sessionId, trial: study.trial }),
  onDown: () => {
    study.strokes += 1;
    $('done').disabled = false;
  },
});
writer.setPxPerMm(state.pxPerMm);
document.documentElement.style.setProperty('--px-per-mm', String(state.pxPerMm));
startOnActivation(audio);

// ---- screens ----------------------------------------------------------------------------------

const SCREENS = {
  loading: ['One moment…', ''],
  wait: ['Please wait', 'The session will continue in a moment.'],
  done: ['Thank you', 'You have finished. Please let the experimenter know.'],
};

function showScreen(screen, title = null, text = null) {
  study.screen = screen;
  document.body.dataset.screen = screen;
  const [defaultTitle, defaultText] = SCREENS[screen] || ['', ''];
  $('screen-title').textContent = title ?? defaultTitle;
  $('screen-text').textContent = text ?? defaultText;
  $('start').hidden = screen !== 'start';
  $('continue').hidden = screen !== 'feedback';
}

const sentence = (text) => `${text.charAt(0).toUpperCase()}${text.slice(1)}`;

function fail(title, text) {
  text = sentence(text);
  state.error = `${title}: ${text}`;
  showScreen('error', title, text);
}

function setReconnecting(on) {
  study.reconnecting = on;
  $('reconnecting').hidden = !on;
}

function showProblem(text) {
  study.problem = text;
  $('problem').textContent = text || '';
  $('problem').hidden = !text;
}

/** `operation` until it gets through to the server ("Reconnecting…" while it does not).
 *  Rejects only with what the server answered (Refused). */
async function persist(operation) {
  for (let attempt = 0; ; attempt += 1) {
    try {
      const result = await operation();
      setReconnecting(false);
      return result;
    } catch (error) {
      if (!(error instanceof Unreachable)) {
        setReconnecting(false);
        throw error;
      }
      study.retries += 1;
      setReconnecting(true);
      await sleep(RETRY_MS[Math.min(attempt, RETRY_MS.length - 1)]);
    }
  }
}

const nextFrame = () => new Promise((resolve) => { window.requestAnimationFrame(() => resolve()); });

// ---- answers: kept until the server has them --------------------------------------------------

function keepPending(pending) {
  try { window.sessionStorage.setItem(PENDING, JSON.stringify(pending)); } catch { /* private mode */ }
}

function dropPending() {
  try { window.sessionStorage.removeItem(PENDING); } catch { /* private mode */ }
}

function pendingAnswer() {
  try {
    const pending = JSON.parse(window.sessionStorage.getItem(PENDING));
    return pending && Number.isInteger(pending.trial) && pending.answers ? pending : null;
  } catch { return null; }
}

/**
 * Send an answer until the server has it: 201 (stored now) or 409 (stored before, or not the
 * next trial: either way the server's `next` says what comes). Rejects with Refused for
 * anything else (422: an invalid answer; 404: no such session), the pending answer dropped.
 */
async function send(pending) {
  keepPending(pending);
  let status;
  let body = null;
  try {
    const reply = await persist(() => call('POST', `/api/sessions/${sessionId}/trials/${pending.trial}`,
      { answers: pending.answers, rt_ms: pending.rt_ms }));
    status = reply.status;
    body = reply.body;
  } catch (error) {
    if (!(error instanceof Refused && error.status === 409)) {
      dropPending();
      throw error;
    }
    status = 409;
  }
  dropPending();
  study.sent.push({ ...pending, status });
  return { status, body };
}

// ---- a trial ----------------------------------------------------------------------------------

const soundBuffers = new Map(); // sound URL → Promise<AudioBuffer> (a pen's sound never changes)
let tactileLoaded = { url: null, buffer: null };

async function decode(url) {
  const data = await persist(() => bytes(url));
  return audio.ctx.decodeAudioData(data);
}

function soundOf(profile) {
  const url = `/${profile.sound.url}`;
  if (!soundBuffers.has(url)) {
    const loading = decode(url);
    soundBuffers.set(url, loading);
    loading.catch(() => soundBuffers.delete(url));
  }
  return soundBuffers.get(url);
}

/** A trial's pen could not be loaded; its message names no pen (the participant reads it). */
class PenUnavailable extends Error {
  constructor() {
    super("this trial's pen could not be loaded");
    this.name = 'PenUnavailable';
  }
}

/** Whether the participant writes in this trial: the server's `writing` when it says, else
 *  when the trial has a pen and some feedback (a questionnaire-only trial has modality none). */
function writes(next) {
  if (!next) return false;
  if (typeof next.writing === 'boolean') return next.writing;
  return Boolean(next.pen) && next.live_modality !== 'none' && next.modality !== 'none';
}

/** Set the trial's pen, feedback and ink, and load its sound and tactile pattern. */
async function prepare(next) {
  const modality = modalityName(next.live_modality);
  state.modality = MODALITIES.includes(modality) ? modality : 'none';
  state.ink = next.ink === 'hidden' ? 'hidden' : 'visible';
  if (!writes(next)) return;
  // A server from before `profile` was sent named the profile by the pen.
  const wanted = next.profile || next.pen;
  const profile = state.profiles.find((p) => p.name === wanted);
  if (!profile) {
    console.warn(`realpen study: trial ${next.trial} plays the pen profile '${wanted}', which `
      + 'this server does not offer');
    throw new PenUnavailable();
  }
  // The trial's own tactile pattern (a study condition's); without one, the pen's.
  const tactileUrl = next.tactile_url || `/${profile.tactile.url}`;
  let sound;
  let tactile;
  try {
    [sound, tactile] = await Promise.all([
      soundOf(profile),
      tactileLoaded.url === tactileUrl ? tactileLoaded.buffer : decode(tactileUrl),
    ]);
  } catch (error) {
    // The server's reason may name the profile: the console has it, the screen does not.
    console.warn(`realpen study: trial ${next.trial}'s pen (profile '${wanted}') did not load:`,
      error);
    throw new PenUnavailable();
  }
  tactileLoaded = { url: tactileUrl, buffer: tactile };
  Object.assign(state, { pen: profile.name, profileVersion: profile.version,
    coupling: profile.coupling });
  smoother.configure(audio.sampleRate, profile.coupling.smoothing_ms);
  audio.use({ sound, tactile }, profile.coupling, profile.name);
}

function button(label, value, className = '') {
  const element = document.createElement('button');
  element.type = 'button';
  element.className = className;
  element.dataset.value = String(value);
  element.setAttribute('role', 'radio');
  element.setAttribute('aria-checked', 'false');
  element.textContent = label;
  return element;
}

const capitalised = (text) => text.charAt(0).toUpperCase() + text.slice(1);

/** What the participant reads for a choice: the server's label for it (a labelled pen's
 *  label), else the choice as the design wrote it. */
function choiceLabel(question, choice) {
  const index = (question.choices || []).indexOf(choice);
  const label = index >= 0 && Array.isArray(question.labels) ? question.labels[index] : null;
  return typeof label === 'string' && label ? label : String(choice);
}

/** The feedback's sentence for the right pen: its label as the design wrote it ("It was Pen
 *  A."), the choice it was shown as ("It was the ballpoint."), or none when the participant was
 *  never shown a name for it. */
function feedbackText(question, pen) {
  if (!question || !(question.choices || []).includes(pen)) return '';
  const label = choiceLabel(question, pen);
  return label === pen ? `It was the ${pen}.` : `It was ${label}.`;
}

/** One question's element; `onAnswer(value)` hears each answer given. */
function questionElement(question, onAnswer) {
  const box = document.createElement('div');
  box.className = `question question-${question.type}`;
  box.dataset.id = question.id;
  const text = document.createElement('p');
  text.className = 'question-text';
  text.id = `q-${question.id}`;
  text.textContent = question.text;
  box.append(text);
  const pick = (group, element, value) => {
    for (const other of group.querySelectorAll('button')) {
      other.setAttribute('aria-checked', String(other === element));
    }
    onAnswer(value);
  };
  if (question.type === 'likert') {
    const points = Math.max(2, Math.min(Number(question.points) || 5, 11));
    const scale = document.createElement('div');
    scale.className = 'scale';
    scale.setAttribute('role', 'radiogroup');
    scale.setAttribute('aria-labelledby', text.id);
    scale.style.gridTemplateColumns = `repeat(${points}, var(--point))`;
    for (let point = 1; point <= points; point += 1) {
      const element = button(String(point), point, 'point');
      element.addEventListener('click', () => pick(scale, element, point));
      scale.append(element);
    }
    for (const [point, label] of Object.entries(question.anchors || {})) {
      const column = Number(point);
      if (!Number.isInteger(column) || column < 1 || column > points) continue;
      const anchor = document.createElement('span');
      anchor.className = 'anchor';
      anchor.textContent = label;
      anchor.style.gridColumn = String(column);
      scale.append(anchor);
    }
    box.append(scale);
  } else if (question.type === 'choice') {
    const group = document.createElement('div');
    group.className = 'choices';
    group.setAttribute('role', 'radiogroup');
    group.setAttribute('aria-labelledby', text.id);
    for (const choice of question.choices || []) {
      const element = button(capitalised(choiceLabel(question, choice)), choice, 'choice');
      element.addEventListener('click', () => pick(group, element, choice));
      group.append(element);
    }
    box.append(group);
  } else {
    const area = document.createElement('textarea');
    area.rows = 4;
    area.maxLength = 2000;
    area.setAttribute('aria-labelledby', text.id);
    area.addEventListener('input', () => onAnswer(area.value));
    box.append(area);
  }
  return box;
}

let finishTrial = null; // resolves the running trial's promise
let watch = null;

function answered(question) {
  const value = study.answers[question.id];
  if (question.type === 'text') return typeof value === 'string' && value.trim() !== '';
  return value !== undefined && value !== null;
}

function complete(next) {
  return next.questions.every((q) => q.required === false || answered(q));
}

function toAnswerStep() {
  if (study.step !== 'write' || state.down) return; // a palm on the button while writing
  study.step = 'answer';
  document.body.dataset.step = 'answer';
  const first = $('questions').querySelector('textarea');
  if (first) first.focus();
}

function render(next) {
  $('task').textContent = next.task || '';
  const writing = writes(next);
  // One choice, nothing else: tapping it is the answer. Otherwise Next confirms.
  const single = next.questions.length === 1 && next.questions[0].type === 'choice';
  document.body.classList.toggle('no-writing', !writing);
  document.body.classList.toggle('single', single);
  $('questions').replaceChildren(...next.questions.map((question) => questionElement(question,
    (value) => {
      if (study.step !== 'answer') return;
      study.answers[question.id] = value;
      showProblem(null);
      if (single) submit(next);
      else $('next').disabled = !complete(next);
    })));
  $('done').textContent = next.questions.length ? 'Done writing' : 'Done';
  $('done').disabled = true;
  $('next').disabled = !complete(next);
  study.step = writing ? 'write' : 'answer';
  document.body.dataset.step = study.step;
  showProblem(null);
}

function collect(next) {
  const answers = {};
  for (const question of next.questions) {
    const value = study.answers[question.id];
    if (!answered(question)) continue; // an optional question left empty is not answered
    answers[question.id] = question.type === 'text' ? value.trim() : value;
  }
  return answers;
}

/** The final answer: its time is now. */
async function submit(next) {
  if (study.step !== 'answer' || study.trial !== next.trial) return;
  const rtMs = performance.now() - study.t0;
  study.step = 'sending';
  document.body.dataset.sending = 'true';
  const pending = { trial: next.trial, answers: collect(next), rt_ms: rtMs };
  try {
    const { body } = await send(pending);
    await showFeedback(body && body.feedback, next);
    endTrial('answered');
  } catch (error) {
    delete document.body.dataset.sending;
    if (error instanceof Refused && error.status === 422) {
      study.step = 'answer'; // the participant can answer again; the clock goes on
      showProblem(error.message);
      return;
    }
    endTrial(error);
  }
}

/** A training trial's feedback (the right pen), shown after the answer until Continue. */
async function showFeedback(feedback, next) {
  const shown = Object.entries(feedback || {});
  if (!shown.length) return;
  const [questionId, { correct, answer }] = shown[0];
  study.feedback = { correct, answer };
  const question = next.questions.find((q) => q.id === questionId);
  showScreen('feedback', correct ? 'Right' : 'Not quite', feedbackText(question, answer));
  // The participant reads it at their own pace; the trial's time was taken at the answer.
  await new Promise((resolve) => {
    $('continue').addEventListener('click', resolve, { once: true });
  });
}

function endTrial(outcome) {
  if (watch !== null) window.clearInterval(watch);
  watch = null;
  delete document.body.dataset.sending;
  const resolve = finishTrial;
  finishTrial = null;
  if (resolve) resolve(outcome);
}

/** While a trial runs, the operator may pause or finish the session: then it stops at once. */
function watchSession() {
  watch = window.setInterval(async () => {
    if (study.step === 'sending') return;
    try {
      const { body } = await call('GET', `/api/sessions/${sessionId}`);
      if (body.state !== 'running' && study.step !== 'sending') endTrial('interrupted');
    } catch { /* the server is away: the trial goes on, its answer will be retried */ }
  }, WATCH_MS);
}

/** Show a trial and wait for its answer: resolves 'answered' or 'interrupted'. */
async function runTrial(next) {
  study.step = 'loading';
  study.t0 = null;
  study.next = next;
  study.trial = next.trial;
  const slow = window.setTimeout(() => showScreen('loading'), 300);
  try {
    await prepare(next);
  } finally {
    window.clearTimeout(slow);
  }
  ink.clear();
  study.strokes = 0;
  study.answers = {};
  render(next);
  showScreen('trial');
  if (study.step === 'answer') $('questions').querySelector('textarea')?.focus();
  await nextFrame(); // on screen: the trial's clock starts
  study.t0 = performance.now();
  const outcome = new Promise((resolve) => { finishTrial = resolve; });
  watchSession();
  const result = await outcome;
  if (result instanceof Error) throw result;
  return result;
}

// ---- the session ------------------------------------------------------------------------------

async function run() {
  showScreen('loading');
  try {
    const pending = pendingAnswer();
    if (pending) {
      try {
        await send(pending);
      } catch (error) {
        // 422: it can never be taken; the trial comes again from `next`.
        if (!(error instanceof Refused && error.status === 422)) throw error;
      }
    }
    for (;;) {
      const { body: next } = await persist(() => call('GET', `/api/sessions/${sessionId}/next`));
      if (next.done) {
        study.next = null;
        showScreen('done');
        return;
      }
      if (next.state === 'paused') {
        showScreen('wait');
        await sleep(PAUSED_POLL_MS);
        continue;
      }
      await runTrial(next);
    }
  } catch (error) {
    console.warn('realpen study:', error);
    const detail = error instanceof Refused ? error.message : String(error.message || error);
    fail('The session cannot go on', `${detail}. Please let the experimenter know.`);
  }
}

async function start() {
  if (sessionId === null) {
    fail('No session', 'Open this screen from the operator console (…/study/participant?session=ID).');
    return;
  }
  try {
    const [config, profiles, progress] = await persist(() => Promise.all([
      call('GET', '/api/config'), call('GET', '/api/profiles'),
      call('GET', `/api/sessions/${sessionId}`)]));
    state.config = config.body;
    state.profiles = profiles.body.profiles;
    const tactile = query.get('tactile');
    state.tactileAudio = tactile ? tactile === 'audio' : state.config.tactile === 'audio';
    audio.routeTactile(state.tactileAudio);
    await forgetTokenInAddress();
    state.ready = true;
    if (progress.body.next === null && !pendingAnswer()) {
      showScreen('done');
      return;
    }
    const resuming = progress.body.answered > 0 || pendingAnswer() !== null;
    showScreen('start', resuming ? 'Welcome back' : 'Welcome',
      'Tap the button when you are ready.');
    $('start').textContent = resuming ? 'Continue' : 'Start';
    $('start').disabled = false;
  } catch (error) {
    console.warn('realpen study:', error);
    if (error instanceof Refused && error.status === 404) {
      fail('No such session', `${error.message}. Please let the experimenter know.`);
    } else {
      fail('Could not start', `${error.message || error}. Please let the experimenter know.`);
    }
  }
}

$('start').addEventListener('click', () => {
  audio.resume(); // inside the tap's user activation
  $('start').disabled = true;
  run();
});
$('done').addEventListener('click', () => {
  const next = study.next;
  if (!next) return;
  if (next.questions.length === 0) {
    if (study.step === 'write') {
      study.step = 'answer';
      submit(next);
    }
    return;
  }
  toAnswerStep();
});
$('next').addEventListener('click', () => {
  const next = study.next;
  if (next && complete(next)) submit(next);
});

start();
