// The WebSocket to the server: typed messages (see realpen/live/messages.py), numbered by `seq`,
// each answered by `ack` or `error`. Messages sent while (re)connecting wait in a short queue;
// the link reconnects with a growing delay if the server goes away.

const QUEUE_LIMIT = 2000;
const RTT_KEPT = 256;

export class Link {
  constructor(url, { client, onChange } = {}) {
    this.url = url;
    this.client = client || 'realpen-page';
    this.onChange = onChange || (() => {});
    this.seq = 0;
    this.queue = [];
    this.pending = new Map();
    this.stats = { state: 'connecting', sent: 0, acked: 0, errors: 0, lastError: null,
      rtt: [], session: null, lastStrokeId: null };
    this.retry = 500;
    this.connect();
  }

  connect() {
    const ws = new WebSocket(this.url);
    this.ws = ws;
    this.stats.state = 'connecting';
    ws.onopen = () => {
      this.stats.state = 'open';
      this.retry = 500;
      this.transmit({ type: 'hello', seq: this.seq++, client: this.client, protocol: 1 });
      for (const text of this.queue.splice(0)) this.raw(text);
      this.onChange(this.stats);
    };
    ws.onmessage = (event) => this.reply(event.data);
    ws.onclose = () => {
      if (this.ws !== ws) return;
      this.stats.state = 'closed';
      this.pending.clear();
      this.onChange(this.stats);
      setTimeout(() => this.connect(), this.retry);
      this.retry = Math.min(this.retry * 2, 10000);
    };
  }

  /** Send a message (its `seq` is added); returns the seq. */
  send(message) {
    const seq = this.seq++;
    const text = JSON.stringify({ ...message, seq });
    if (this.ws.readyState === WebSocket.OPEN) this.raw(text, seq);
    else if (this.queue.length < QUEUE_LIMIT) this.queue.push(text);
    return seq;
  }

  transmit(message) {
    this.raw(JSON.stringify(message), message.seq);
  }

  raw(text, seq) {
    this.ws.send(text);
    this.stats.sent += 1;
    this.pending.set(seq ?? JSON.parse(text).seq, performance.now());
  }

  reply(data) {
    let message;
    try { message = JSON.parse(data); } catch { return; }
    const sentAt = this.pending.get(message.seq);
    this.pending.delete(message.seq);
    if (message.type === 'ack') {
      this.stats.acked += 1;
      if (sentAt !== undefined) {
        this.stats.rtt.push(performance.now() - sentAt);
        if (this.stats.rtt.length > RTT_KEPT) this.stats.rtt.shift();
      }
      if (message.session) this.stats.session = message.session;
      if (message.stroke_id !== undefined) this.stats.lastStrokeId = message.stroke_id;
    } else if (message.type === 'error') {
      this.stats.errors += 1;
      this.stats.lastError = message;
      console.warn(`realpen server: ${message.code}: ${message.message}`);
    }
    this.onChange(this.stats);
  }

  /** Median round trip of the recent acknowledged messages, in ms. */
  medianRtt() {
    const sorted = [...this.stats.rtt].sort((a, b) => a - b);
    return sorted.length ? sorted[Math.floor(sorted.length / 2)] : null;
  }
}
