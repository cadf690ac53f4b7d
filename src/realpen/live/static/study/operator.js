// The operator console of RealPen's studies (/study): start or resume a participant's session
// (or a pilot session), follow its progress and current trial, pause, resume, finish or abandon
// it, withdraw a participant, and open the participant screen (on this computer or, with --lan,
// on a tablet: its address typed or its QR code scanned). Everything goes through the study
// HTTP API (docs/studies.md); the sessions table is read again every POLL_MS and can be
// filtered by design and by status.
//
// window.realpenStudy exposes what the console knows (designs, sessions, the filters, the
// selected session's progress, the participant screen's URL and QR code), for tests.

import { call, forgetTokenInAddress, Refused, token, withToken } from './api.js';

const POLL_MS = 2000;
const LIST_LIMIT = 200; // what GET /api/sessions returns by default: the newest sessions
const TOKEN_KEY = 'realpen.study.token';
const HANDEDNESS = ['right', 'left', 'ambidextrous'];
const GENDERS = ['female', 'male', 'non-binary', 'prefer not to say'];
const STATE_TEXT = {
  running: 'Running', paused: 'Paused', finished: 'Finished', abandoned: 'Abandoned',
  withdrawn: 'Withdrawn',
};
// A session in these states has a next trial; the others have ended.
const ACTIVE = new Set(['running', 'paused']);
// The status filter: every state, and pilot sessions (whatever their state); '' shows all.
const STATUSES = [...Object.keys(STATE_TEXT), 'pilot'];
const LOOPBACK = new Set(['127.0.0.1', 'localhost', '[::1]']);
const TABLE_COLUMNS = ['Session', 'Design', 'Participant', 'Site', 'State', 'Current trial',
  'Answered', 'Started'];
// Columns of what the operator typed: one long word may break anywhere (study.css td.typed).
const TYPED_COLUMNS = new Set(['Participant', 'Site']);

const $ = (id) => document.getElementById(id);

const ui = {
  ready: false,
  config: null,
  designs: [],
  sessions: [],
  selected: null,     // the selected session's id
  progress: null,     // its progress
  participantUrl: null,
  participantQr: null, // the QR code's address (GET /api/sessions/{id}/participant-qr.svg)
  filter: { design: '', status: '' },
  visible: [],        // the ids of the sessions the table shows (after the filters)
  reachable: true,
  polls: 0,
};
window.realpenStudy = ui;

// With --lan the console was opened with ?token=…; the token leaves the address bar (see
// api.js) but the tablet's URL needs it, so this tab keeps it for a reload.
let lanToken = token;
try {
  if (token) window.sessionStorage.setItem(TOKEN_KEY, token);
  else lanToken = window.sessionStorage.getItem(TOKEN_KEY);
} catch { /* private mode: the URL is shown without the token after a reload */ }

const describe = (error) => (error instanceof Refused ? error.message
  : 'the server is not reachable; try again in a moment');

function when(iso) {
  if (!iso) return '';
  const date = new Date(iso);
  if (Number.isNaN(date.getTime())) return iso;
  const pad = (n) => String(n).padStart(2, '0');
  return `${date.getFullYear()}-${pad(date.getMonth() + 1)}-${pad(date.getDate())} `
    + `${pad(date.getHours())}:${pad(date.getMinutes())}`;
}

function element(tag, className = '', text = null) {
  const node = document.createElement(tag);
  if (className) node.className = className;
  if (text !== null) node.textContent = text;
  return node;
}

// ---- the new-session form ---------------------------------------------------------------------

function currentDesign() {
  return ui.designs.find((d) => d.name === $('design').value) || null;
}

function demographicField(name) {
  const label = element('label', '', name.charAt(0).toUpperCase() + name.slice(1));
  let input;
  if (name === 'age') {
    input = element('input');
    Object.assign(input, { type: 'number', min: '1', max: '149', step: '1', inputMode: 'numeric' });
  } else if (name === 'handedness') {
    input = element('select');
    input.append(new Option('—', ''), ...HANDEDNESS.map((h) => new Option(h, h)));
  } else {
    input = element('input');
    Object.assign(input, { type: 'text', maxLength: 100, autocomplete: 'off' });
    if (name === 'gender') {
      const list = element('datalist');
      list.id = 'gender-options';
      list.append(...GENDERS.map((g) => new Option(g)));
      input.setAttribute('list', list.id);
      label.append(list);
    }
  }
  input.id = `demo-${name}`;
  input.dataset.field = name;
  label.append(input);
  return label;
}

function showDesign() {
  const design = currentDesign();
  const fields = (design && design.participant_fields) || {};
  $('design-description').textContent = design
    ? [design.description, design.participants ? `${design.participants} participants planned.` : '']
      .filter(Boolean).join(' ') : '';
  const demographics = Array.isArray(fields.demographics) ? fields.demographics : [];
  $('demographic-fields').replaceChildren(...demographics.map(demographicField));
  $('demographics').hidden = demographics.length === 0;
  const consent = typeof fields.consent === 'string' ? fields.consent.trim() : '';
  $('consent-text').textContent = consent;
  $('consent-box').hidden = !consent;
  $('consent').checked = false;
}

function formBody() {
  const design = currentDesign();
  if (!design) throw new Error('choose a design');
  const participant = $('participant').value.trim();
  if (!participant) throw new Error('participant: enter the participant ID (e.g. P01)');
  const body = { design: design.name, participant, site: $('site').value.trim() };
  const demographics = {};
  for (const input of $('demographic-fields').querySelectorAll('[data-field]')) {
    const value = input.value.trim();
    if (value === '') continue;
    if (input.dataset.field === 'age') {
      const age = Number(value);
      if (!Number.isInteger(age) || age < 1 || age > 149) {
        throw new Error('age: enter a whole number of years (1–149)');
      }
      demographics.age = age;
    } else {
      demographics[input.dataset.field] = value;
    }
  }
  body.demographics = demographics;
  // A new session of a design that asks for consent needs the box ticked (the server says so);
  // resuming a session does not.
  body.consent = !$('consent-box').hidden && $('consent').checked;
  const index = $('index').value.trim();
  if (index !== '') {
    const row = Number(index);
    if (!Number.isInteger(row) || row < 0) throw new Error('plan index: a whole number from 0');
    body.index = row;
  } else {
    body.index = null;
  }
  // Sent only when ticked: a pilot takes no plan row and stays out of exports and statistics.
  if ($('pilot').checked) body.pilot = true;
  return body;
}

async function startSession(event) {
  event.preventDefault();
  $('form-error').textContent = '';
  $('form-note').textContent = '';
  let request;
  try {
    request = formBody();
  } catch (error) {
    $('form-error').textContent = error.message;
    return;
  }
  $('start').disabled = true;
  try {
    const { status, body } = await call('POST', '/api/sessions', request);
    // A new session needs consent; an existing one (resumed) was given it when it started.
    $('form-note').textContent = status === 201
      ? `${body.pilot ? 'Pilot session' : 'Session'} ${body.session} started for ${body.participant}.`
      : `${body.participant} already has session ${body.session}: resumed.`;
    $('participant').value = '';
    $('index').value = '';
    $('consent').checked = false;
    $('pilot').checked = false;
    for (const input of $('demographic-fields').querySelectorAll('[data-field]')) input.value = '';
    select(body.session, body);
    poll();
  } catch (error) {
    $('form-error').textContent = describe(error);
  } finally {
    $('start').disabled = false;
  }
}

// ---- the selected session -----------------------------------------------------------------

function participantUrl(id) {
  const url = new URL('/study/participant', window.location.origin);
  url.searchParams.set('session', String(id));
  if (lanToken && ui.config && ui.config.token_required) url.searchParams.set('token', lanToken);
  return url.href;
}

function select(id, progress = null) {
  ui.selected = id;
  if (progress) ui.progress = progress;
  else if (!ui.progress || ui.progress.session !== id) ui.progress = null;
  $('state-error').textContent = '';
  window.history.replaceState(window.history.state, '', `#session=${id}`);
  renderCurrent();
  renderTable();
}

function stateText(p) {
  return STATE_TEXT[p.state] || p.state;
}

function progressText(p) {
  if (p.state === 'withdrawn') return 'Withdrawn: the participant\'s answers and strokes were deleted';
  if (p.state === 'abandoned') return `Abandoned: ${p.answered} of ${p.trials} trials answered`;
  if (p.state === 'finished' || p.next === null) {
    return p.answered === p.trials ? `Complete: all ${p.trials} trials answered`
      : `Finished: ${p.answered} of ${p.trials} trials answered`;
  }
  return `Trial ${p.next} of ${p.trials} · ${p.answered} answered`;
}

function bar(fraction, done) {
  const wrap = element('span', `bar${done ? ' done' : ''}`);
  const fill = element('i');
  fill.style.width = `${(Math.max(0, Math.min(fraction, 1)) * 100).toFixed(1)}%`;
  wrap.append(fill);
  return wrap;
}

// What the operator reads of the current trial: its place in the plan, then what it plays.
// The console may name pen ids and profiles; the participant screen never does.

function penText(c) {
  if (!c.pen) return 'none';
  return [c.pen, c.profile && c.profile !== c.pen ? `profile ${c.profile}` : '',
    c.pen_label ? `shown as “${c.pen_label}”` : ''].filter(Boolean).join(' · ');
}

/** One line for the table: trial n of N, then the block, condition, modality and pen (each once). */
function trialSummary(c) {
  if (!c) return '—';
  const named = [];
  for (const name of [c.block, c.condition, c.modality, c.pen]) {
    if (name && !named.includes(name)) named.push(name);
  }
  return [`${c.n} of ${c.of}`, ...named].join(' · ');
}

function renderTrial(p) {
  const c = ACTIVE.has(p.state) ? p.current : null;
  $('cur-trial').hidden = !c;
  if (!c) return;
  $('cur-trial-title').textContent = p.state === 'paused' ? 'Paused at' : 'Current trial';
  $('now-trial').textContent = `${c.n} of ${c.of}${c.phase ? ` · ${c.phase}` : ''}`;
  $('now-block').textContent = `${c.block} · trial ${c.block_n} of ${c.block_of}`;
  $('now-condition').textContent = c.condition
    ? [c.condition, c.condition_label].filter(Boolean).join(' — ') : '—';
  $('now-modality').textContent = c.modality || 'none';
  $('now-pen').textContent = penText(c);
}

function renderHandoff(id) {
  ui.participantUrl = participantUrl(id);
  $('participant-url').textContent = ui.participantUrl;
  $('url-note').hidden = !LOOPBACK.has(window.location.hostname);
  const qr = withToken(`/api/sessions/${id}/participant-qr.svg`);
  if (qr !== ui.participantQr) { // once per session: the image is not fetched at every poll
    ui.participantQr = qr;
    $('participant-qr').src = qr;
  }
}

function renderCurrent() {
  const p = ui.progress;
  $('current-empty').hidden = p !== null;
  $('current-body').hidden = p === null;
  if (!p) {
    $('current-title').textContent = ui.selected ? `Session ${ui.selected}` : 'Session';
    return;
  }
  $('current-title').textContent = `Session ${p.session}`;
  $('cur-participant').textContent = p.participant;
  $('cur-design').textContent = p.title ? `${p.title} (${p.design})` : p.design;
  $('cur-site').textContent = p.site || '—';
  $('cur-index').textContent = String(p.index);
  $('cur-started').textContent = when(p.started_at)
    + (p.finished_at ? ` · finished ${when(p.finished_at)}` : '');
  $('cur-state').textContent = stateText(p);
  $('cur-state').dataset.state = p.state;
  $('cur-pilot').hidden = !p.pilot;
  $('pause').disabled = p.state !== 'running';
  $('resume').disabled = p.state !== 'paused';
  $('finish').disabled = !ACTIVE.has(p.state);
  $('abandon').disabled = !ACTIVE.has(p.state);
  $('withdraw').disabled = p.state === 'withdrawn';
  $('cur-progress').textContent = progressText(p);
  const complete = p.trials > 0 && p.answered === p.trials;
  $('cur-bar-wrap').classList.toggle('done', complete);
  $('cur-bar').style.width = `${p.trials ? (100 * p.answered / p.trials).toFixed(1) : 0}%`;
  renderTrial(p);
  $('cur-blocks').replaceChildren(...(p.blocks || []).map((block) => {
    const item = element('li');
    item.append(element('span', '', block.block),
      bar(block.trials ? block.answered / block.trials : 0, block.answered === block.trials),
      element('span', '', `${block.answered} / ${block.trials}`));
    return item;
  }));
  renderHandoff(p.session);
}

async function setState(state) {
  const id = ui.selected;
  if (!id) return;
  $('state-error').textContent = '';
  try {
    const { body } = await call('POST', `/api/sessions/${id}/state`, { state });
    if (ui.selected === id) {
      ui.progress = body;
      renderCurrent();
    }
    poll();
  } catch (error) {
    $('state-error').textContent = describe(error);
  }
}

function askFinish() {
  const p = ui.progress;
  if (!p) return;
  $('finish-text').textContent = `${p.participant}: ${p.answered} of ${p.trials} trials answered. `
    + 'A finished session offers no more trials and cannot be resumed.';
  $('finish-dialog').returnValue = '';
  $('finish-dialog').showModal();
}

function askAbandon() {
  const p = ui.progress;
  if (!p) return;
  $('abandon-text').textContent = `${p.participant}: ${p.answered} of ${p.trials} trials answered. `
    + 'An abandoned session offers no more trials and cannot be resumed; its answers are kept '
    + '(the export marks the session abandoned).';
  $('abandon-dialog').returnValue = '';
  $('abandon-dialog').showModal();
}

function askWithdraw() {
  const p = ui.progress;
  if (!p) return;
  $('withdraw-text').textContent = `${p.participant} takes back their consent: session `
    + `${p.session}'s answers (${p.answered} of ${p.trials} trials answered), response times and `
    + 'pen strokes, and the participant\'s ID and demographics, are deleted from the store. What '
    + 'stays is a record that the session was withdrawn, and when (its site, start and plan row), '
    + 'without any of their data; the plan row is free for the next participant. This cannot be '
    + 'undone.';
  $('withdraw-code').value = '';
  $('withdraw-code').placeholder = p.participant;
  $('withdraw-confirm').disabled = true;
  $('withdraw-error').textContent = '';
  $('withdraw-dialog').showModal();
  $('withdraw-code').focus();
}

function typedCodeMatches() {
  const p = ui.progress;
  return Boolean(p) && $('withdraw-code').value.trim() === p.participant;
}

async function withdraw(event) {
  event.preventDefault();
  const p = ui.progress;
  if (!p || !typedCodeMatches()) return;
  $('withdraw-confirm').disabled = true;
  $('withdraw-error').textContent = '';
  try {
    await call('POST', `/api/sessions/${p.session}/withdraw`,
      { confirm: $('withdraw-code').value.trim() });
    $('withdraw-dialog').close();
    poll();
  } catch (error) {
    $('withdraw-error').textContent = describe(error);
    $('withdraw-confirm').disabled = !typedCodeMatches();
  }
}

async function copyUrl() {
  const text = ui.participantUrl;
  if (!text) return;
  try {
    await navigator.clipboard.writeText(text);
    $('copy-url').textContent = 'Copied';
  } catch {
    // No clipboard on plain http from another machine: select the address for a manual copy.
    const range = document.createRange();
    range.selectNodeContents($('participant-url'));
    window.getSelection().removeAllRanges();
    window.getSelection().addRange(range);
    $('copy-url').textContent = 'Selected';
  }
  window.setTimeout(() => { $('copy-url').textContent = 'Copy'; }, 1500);
}

// ---- the sessions table -------------------------------------------------------------------

let tableKey = '';
let filterKey = '';

function matchesStatus(p, status) {
  return !status || (status === 'pilot' ? p.pilot === true : p.state === status);
}

function countBy(sessions, key) {
  const counts = {};
  for (const p of sessions) counts[key(p)] = (counts[key(p)] || 0) + 1;
  return counts;
}

/** The design filter (sessions per design) and the status chips (per status, in that design). */
function renderFilters() {
  const byDesign = countBy(ui.sessions, (p) => p.design);
  const names = [...new Set([...ui.designs.map((d) => d.name), ...Object.keys(byDesign)])];
  const title = (name) => {
    const design = ui.designs.find((d) => d.name === name);
    const listed = ui.sessions.find((p) => p.design === name);
    return (design && design.title) || (listed && listed.title) || name;
  };
  const inDesign = ui.sessions.filter((p) => !ui.filter.design || p.design === ui.filter.design);
  const byState = countBy(inDesign, (p) => p.state);
  byState.pilot = inDesign.filter((p) => p.pilot === true).length;
  const key = JSON.stringify([byDesign, names, byState, ui.filter]);
  if (key === filterKey) return;
  filterKey = key;
  $('filter-design').replaceChildren(
    new Option(`All designs (${ui.sessions.length})`, ''),
    ...names.map((name) => new Option(`${title(name)} (${byDesign[name] || 0})`, name)));
  $('filter-design').value = ui.filter.design;
  const chip = (status, label, count) => {
    const button = element('button', 'chip');
    button.type = 'button';
    button.dataset.status = status;
    button.setAttribute('aria-pressed', String(ui.filter.status === status));
    if (status && status !== 'pilot') button.dataset.state = status;
    button.append(element('span', '', label), element('b', '', String(count)));
    if (!count && ui.filter.status !== status) button.classList.add('none');
    return button;
  };
  $('filter-state').replaceChildren(chip('', 'All', inDesign.length),
    ...STATUSES.map((status) => chip(status, status === 'pilot' ? 'Pilot' : STATE_TEXT[status],
      byState[status] || 0)));
}

function renderTable() {
  renderFilters();
  const shown = ui.sessions.filter((p) => (!ui.filter.design || p.design === ui.filter.design)
    && matchesStatus(p, ui.filter.status));
  ui.visible = shown.map((p) => p.session);
  $('sessions-note').hidden = ui.sessions.length < LIST_LIMIT;
  $('sessions-note').textContent = `The newest ${LIST_LIMIT} sessions are listed.`;
  const key = JSON.stringify([shown, ui.selected]);
  if (key === tableKey) return; // unchanged: keep the rows (and a click in progress)
  tableKey = key;
  const body = $('sessions').tBodies[0];
  if (!shown.length) {
    const row = element('tr', 'empty');
    const cell = element('td', '', ui.sessions.length ? 'No sessions match these filters.'
      : 'No sessions yet.');
    cell.colSpan = TABLE_COLUMNS.length;
    row.append(cell);
    body.replaceChildren(row);
    return;
  }
  body.replaceChildren(...shown.map((p) => {
    const row = element('tr');
    row.dataset.session = String(p.session);
    row.tabIndex = 0;
    row.setAttribute('aria-selected', String(p.session === ui.selected));
    const state = element('span', 'badge', stateText(p));
    state.dataset.state = p.state;
    const states = p.pilot ? [state, ' ', element('span', 'badge pilot', 'Pilot')] : [state];
    const cells = [String(p.session), p.title || p.design, p.participant, p.site || '—', states,
      ACTIVE.has(p.state) ? trialSummary(p.current) : '—', `${p.answered} / ${p.trials}`,
      when(p.started_at)];
    row.append(...cells.map((content, i) => {
      const cell = element('td');
      cell.dataset.label = TABLE_COLUMNS[i]; // the heading of a cell on a phone's stacked rows
      if (TYPED_COLUMNS.has(TABLE_COLUMNS[i])) cell.className = 'typed';
      cell.append(...[content].flat());
      return cell;
    }));
    return row;
  }));
}

function setFilter(change) {
  Object.assign(ui.filter, change);
  renderTable();
}

function pickRow(event) {
  const row = event.target.closest('tr[data-session]');
  if (!row) return;
  if (event.type === 'keydown' && event.key !== 'Enter' && event.key !== ' ') return;
  const id = Number(row.dataset.session);
  select(id, ui.sessions.find((p) => p.session === id) || null);
}

// ---- polling ------------------------------------------------------------------------------

let polling = false;

async function poll() {
  if (polling) return;
  polling = true;
  try {
    const { body } = await call('GET', '/api/sessions');
    ui.sessions = body.sessions || [];
    ui.polls += 1;
    setReachable(true);
    if (ui.selected) {
      const listed = ui.sessions.find((p) => p.session === ui.selected);
      ui.progress = listed || (await call('GET', `/api/sessions/${ui.selected}`)).body;
      renderCurrent();
    }
    renderTable();
  } catch (error) {
    if (error instanceof Refused && error.status === 404 && ui.selected) {
      ui.selected = null; // the selected session is gone (another store?)
      ui.progress = null;
      renderCurrent();
    } else {
      setReachable(false);
    }
  } finally {
    polling = false;
  }
}

function setReachable(on) {
  ui.reachable = on;
  $('server').dataset.state = on ? 'up' : 'down';
  $('server').textContent = on ? 'Connected' : 'Server unreachable: retrying…';
}

async function start() {
  try {
    const [config, studies] = await Promise.all([call('GET', '/api/config'),
      call('GET', '/api/studies')]);
    ui.config = config.body;
    ui.designs = studies.body.designs || [];
    await forgetTokenInAddress();
  } catch (error) {
    $('form-error').textContent = `Could not load the designs: ${describe(error)}`;
    setReachable(error instanceof Refused);
    window.setTimeout(start, POLL_MS);
    return;
  }
  $('design').replaceChildren(...ui.designs.map((d) => new Option(
    d.title ? `${d.title} (${d.name})` : d.name, d.name)));
  showDesign();
  const hash = /^#session=(\d{1,15})$/.exec(window.location.hash);
  if (hash) select(Number(hash[1]));
  await poll();
  window.setInterval(poll, POLL_MS);
  ui.ready = true;
}

$('design').addEventListener('change', showDesign);
$('new-session').addEventListener('submit', startSession);
$('pause').addEventListener('click', () => setState('paused'));
$('resume').addEventListener('click', () => setState('running'));
$('finish').addEventListener('click', askFinish);
$('finish-dialog').addEventListener('close', () => {
  if ($('finish-dialog').returnValue === 'finish') setState('finished');
});
$('abandon').addEventListener('click', askAbandon);
$('abandon-dialog').addEventListener('close', () => {
  if ($('abandon-dialog').returnValue === 'abandon') setState('abandoned');
});
$('withdraw').addEventListener('click', askWithdraw);
$('withdraw-code').addEventListener('input', () => {
  $('withdraw-confirm').disabled = !typedCodeMatches();
});
$('withdraw-form').addEventListener('submit', withdraw);
$('withdraw-cancel').addEventListener('click', () => $('withdraw-dialog').close());
$('filter-design').addEventListener('change', () => setFilter({ design: $('filter-design').value }));
$('filter-state').addEventListener('click', (event) => {
  const chip = event.target.closest('button[data-status]');
  if (!chip) return;
  // The chip pressed again shows every status.
  const status = chip.dataset.status === ui.filter.status ? '' : chip.dataset.status;
  setFilter({ status });
});
$('open-participant').addEventListener('click', () => {
  if (ui.participantUrl) window.open(ui.participantUrl, '_blank', 'noopener');
});
$('copy-url').addEventListener('click', copyUrl);
$('sessions').addEventListener('click', pickRow);
$('sessions').addEventListener('keydown', pickRow);

start();
