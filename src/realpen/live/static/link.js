// The WebSocket to the server: typed messages (see realpen/live/messages.py), numbered by `seq`,
// each answered by `ack` or `error`.
//
// Nothing is lost: every message is kept until the server acknowledges it. At most WINDOW
// messages are in flight; the rest wait in order (the server reads one message at a time, so
// a page that writes faster than the server stores simply waits here). When the socket closes,
// what was in flight goes back to the front of the queue and is sent again after the reconnect,
// which names the page (`hello.page`) so the server stores each stroke and sample once. When the
// store cannot record a message (`error` with code `store`), the server closes the socket, and
// that message and everything after it go again after the reconnect, in order.
//
// A reload keeps all of it: when the page goes away, its id, its last stroke number and what is
// not acknowledged are kept in sessionStorage (this tab only), and the reloaded page sends them
// first, as the same page. Closing the tab while messages are unacknowledged asks first.

const WINDOW = 64;
const RTT_KEPT = 256;
const SAVED = 'realpen.link';

function randomId() {
  // crypto.getRandomValues works on plain http (a tablet on the LAN); randomUUID does not.
  const bytes = crypto.getRandomValues(new Uint8Array(16));
  return Array.from(bytes, (b) => b.toString(16).padStart(2, '0')).join('');
}

export class Link {
  constructor(url, { client, onChange } = {}) {
    this.url = url;
    this.client = client || 'realpen-page';
    this.onChange = onChange || (() => {});
    this.page = randomId();
    this.seq = 0;
    this.lastStroke = 0;       // the highest stroke number sent
    this.outbox = [];          // [seq, text] not yet sent on the current socket, in seq order
    this.inFlight = new Map(); // seq → [text, sentAt] sent and not yet acknowledged
    this.hellos = new Set();
    this.restore();
    this.stats = { state: 'connecting', sent: 0, acked: 0, errors: 0, resent: this.outbox.length,
      unacked: this.outbox.length, lastError: null, rtt: [], session: null, lastStrokeId: null,
      page: this.page };
    window.addEventListener('pagehide', () => this.save());
    window.addEventListener('beforeunload', (event) => {
      if (this.stats.unacked > 0) event.preventDefault(); // the browser asks "leave the page?"
    });
    this.retry = 500;
    this.connect();
  }

  /** What a previous load of this page in this tab left: its id, strokes and unsent messages. */
  restore() {
    let saved;
    try { saved = JSON.parse(sessionStorage.getItem(SAVED)); } catch { saved = null; }
    if (!saved || typeof saved.page !== 'string') return;
    this.page = saved.page;
    this.seq = saved.seq || 0;
    this.lastStroke = saved.lastStroke || 0;
    this.outbox = Array.isArray(saved.outbox) ? saved.outbox : [];
  }

  save() {
    const unsent = [...this.inFlight.entries()]
      .filter(([seq]) => !this.hellos.has(seq))
      .map(([seq, [text]]) => [seq, text]);
    const outbox = [...unsent, ...this.outbox].sort((a, b) => a[0] - b[0]);
    try {
      sessionStorage.setItem(SAVED, JSON.stringify({ page: this.page, seq: this.seq,
        lastStroke: this.lastStroke, outbox }));
    } catch (error) { console.warn(`realpen: could not keep unsent messages: ${error}`); }
  }

  connect() {
    const ws = new WebSocket(this.url);
    this.ws = ws;
    this.stats.state = 'connecting';
    ws.onopen = () => {
      this.stats.state = 'open';
      this.retry = 500;
      const hello = { type: 'hello', seq: this.seq++, client: this.client, protocol: 1,
        page: this.page };
      this.hellos = new Set([hello.seq]);
      this.transmit(hello.seq, JSON.stringify(hello));
      this.pump();
      this.onChange(this.stats);
    };
    ws.onmessage = (event) => this.reply(event.data);
    ws.onclose = () => {
      if (this.ws !== ws) return;
      this.stats.state = 'closed';
      // What the server may not have stored goes out again, first and in order.
      const unsure = [...this.inFlight.entries()]
        .filter(([seq]) => !this.hellos.has(seq))
        .map(([seq, [text]]) => [seq, text]);
      this.stats.resent += unsure.length;
      this.outbox = [...unsure, ...this.outbox].sort((a, b) => a[0] - b[0]);
      this.inFlight.clear();
      this.updateUnacked();
      this.onChange(this.stats);
      setTimeout(() => this.connect(), this.retry);
      this.retry = Math.min(this.retry * 2, 10000);
    };
  }

  /** Send a message (its `seq` is added); returns the seq. It is kept until acknowledged. */
  send(message) {
    const seq = this.seq++;
    if (Number.isInteger(message.stroke)) this.lastStroke = Math.max(this.lastStroke, message.stroke);
    this.outbox.push([seq, JSON.stringify({ ...message, seq })]);
    this.pump();
    this.updateUnacked();
    return seq;
  }

  pump() {
    if (!this.ws || this.ws.readyState !== WebSocket.OPEN) return;
    while (this.outbox.length && this.inFlight.size < WINDOW) {
      const [seq, text] = this.outbox.shift();
      this.transmit(seq, text);
    }
  }

  transmit(seq, text) {
    this.ws.send(text);
    this.stats.sent += 1;
    this.inFlight.set(seq, [text, performance.now()]);
  }

  reply(data) {
    let message;
    try { message = JSON.parse(data); } catch { return; }
    const entry = this.inFlight.get(message.seq);
    // A message the store could not record stays in flight: the server closes the socket, and
    // it goes again with everything after it.
    if (!(message.type === 'error' && message.code === 'store')) this.inFlight.delete(message.seq);
    if (message.type === 'ack') {
      this.stats.acked += 1;
      if (entry !== undefined) {
        this.stats.rtt.push(performance.now() - entry[1]);
        if (this.stats.rtt.length > RTT_KEPT) this.stats.rtt.shift();
      }
      if (message.session) this.stats.session = message.session;
      if (message.stroke_id !== undefined) this.stats.lastStrokeId = message.stroke_id;
    } else if (message.type === 'error') {
      this.stats.errors += 1;
      this.stats.lastError = message;
      console.warn(`realpen server: ${message.code}: ${message.message}`);
    }
    this.pump();
    this.updateUnacked();
    this.onChange(this.stats);
  }

  updateUnacked() {
    this.stats.unacked = this.outbox.length + this.inFlight.size;
  }

  /** Median round trip of the recent acknowledged messages, in ms. */
  medianRtt() {
    const sorted = [...this.stats.rtt].sort((a, b) => a - b);
    return sorted.length ? sorted[Math.floor(sorted.length / 2)] : null;
  }
}
