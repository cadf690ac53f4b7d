// The study pages' side of the HTTP API (docs/studies.md): JSON requests that carry the LAN
// token when the page was opened with one, and that tell a network failure (the server is away
// or restarting: try again) from an answer of the server (keep it).

const query = new URLSearchParams(window.location.search);

/** The LAN token this page was opened with (…?token=…), or null. */
export const token = query.get('token');

/** `url` with the token added (LAN mode), else `url`. */
export function withToken(url) {
  return token ? `${url}${url.includes('?') ? '&' : '?'}token=${encodeURIComponent(token)}` : url;
}

/** The server could not be reached (or answered 5xx): the request may be tried again. */
export class Unreachable extends Error {
  constructor(message) {
    super(message);
    this.name = 'Unreachable';
  }
}

/** An answer of the server that is not a success: `status`, the body, and its one-line detail. */
export class Refused extends Error {
  constructor(status, body) {
    super((body && typeof body.detail === 'string') ? body.detail : `HTTP ${status}`);
    this.name = 'Refused';
    this.status = status;
    this.body = body || {};
  }
}

/**
 * One JSON request. Resolves to { status, body } for 2xx; rejects with Refused for 4xx and with
 * Unreachable for a network failure or 5xx (a server starting, stopping or overwhelmed).
 */
export async function call(method, url, body = undefined) {
  let response;
  try {
    response = await fetch(withToken(url), {
      method,
      headers: body === undefined ? {} : { 'Content-Type': 'application/json' },
      body: body === undefined ? undefined : JSON.stringify(body),
      cache: 'no-store',
      credentials: 'same-origin',
    });
  } catch (error) {
    throw new Unreachable(`${method} ${url}: ${error.message || error}`);
  }
  let parsed;
  try { parsed = await response.json(); } catch { parsed = null; }
  if (response.status >= 500) throw new Unreachable(`${method} ${url}: HTTP ${response.status}`);
  if (!response.ok) throw new Refused(response.status, parsed);
  return { status: response.status, body: parsed };
}

/** The bytes at `url` (a WAV); rejects like `call`. */
export async function bytes(url) {
  let response;
  try {
    response = await fetch(withToken(url), { cache: 'no-store', credentials: 'same-origin' });
  } catch (error) {
    throw new Unreachable(`GET ${url}: ${error.message || error}`);
  }
  if (response.status >= 500) throw new Unreachable(`GET ${url}: HTTP ${response.status}`);
  if (!response.ok) {
    let parsed;
    try { parsed = await response.json(); } catch { parsed = null; }
    throw new Refused(response.status, parsed);
  }
  return response.arrayBuffer();
}

export const sleep = (ms) => new Promise((resolve) => { setTimeout(resolve, ms); });

/**
 * With --lan the page was opened as …?token=…; the server set its cookie on that response. Once
 * a request without the token succeeds (the cookie works), the token leaves the address bar and
 * the history (not kept in bookmarks or screenshots); the page keeps it in memory. Resolves to
 * whether it was removed.
 */
export async function forgetTokenInAddress() {
  if (!token) return false;
  try {
    const response = await fetch('/api/config', { credentials: 'same-origin', cache: 'no-store' });
    if (!response.ok) return false; // no cookie (blocked?): keep the token so that a reload works
  } catch { return false; }
  const url = new URL(window.location.href);
  url.searchParams.delete('token');
  window.history.replaceState(window.history.state, '', `${url.pathname}${url.search}${url.hash}`);
  return true;
}
