// The live connection: `GET /api/v1/ws`, a snapshot first, then events in `seq` order.
// When the socket closes (resync, server restart, network) it reconnects by itself with
// `?since=<last seq>` so the server replays what was missed, backing off up to 15 s.

import { api, wsUrl } from './api.js';

const BACKOFF_MS = [500, 1000, 2000, 4000, 8000, 15000];

/**
 * One live connection feeding `model`. `onState(state, detail)` tells the page how it goes:
 * `connecting`, `live`, `waiting` (detail: seconds until the next try), `key` (the server
 * wants a key: nothing is tried until `restart()`).
 */
export class Live {
  constructor(model, onState) {
    this.model = model;
    this.onState = onState;
    this.socket = null;
    this.failures = 0;
    this.timer = null;
    this.stopped = false;
    /** How the last connection started: `snapshot` (with its reason) or `replay`. */
    this.lastStart = null;
  }

  /** Connects now (again), forgetting any wait; used at start and after a new key. */
  restart() {
    this.stopped = false;
    this.failures = 0;
    clearTimeout(this.timer);
    this.timer = null;
    if (this.socket) {
      const old = this.socket;
      this.socket = null;
      old.close(1000, 'reconnecting');
    }
    this.connect();
  }

  connect() {
    if (this.stopped) return;
    this.onState('connecting');
    const socket = new WebSocket(wsUrl(this.model.seq));
    this.socket = socket;
    let opened = false;
    socket.addEventListener('open', () => {
      // Live once open: a replay of nothing sends nothing.
      if (this.socket !== socket) return;
      opened = true;
      this.failures = 0;
      this.lastStart = this.model.seq === null ? 'snapshot' : 'replay';
      // The server tells a store fault right after the start: until then, none is known.
      this.model.applyStore({ ok: true });
      this.onState('live');
    });
    socket.addEventListener('message', (event) => {
      if (this.socket !== socket) return;
      let message;
      try {
        message = JSON.parse(event.data);
      } catch {
        return;
      }
      this.receive(socket, message);
    });
    socket.addEventListener('close', (event) => {
      if (this.socket !== socket) return;
      this.socket = null;
      this.closed(opened, event.code);
    });
  }

  receive(socket, message) {
    if (message.type === 'snapshot') {
      this.lastStart = `snapshot (${message.reason})`;
      this.model.applySnapshot(message);
    } else if (typeof message.seq === 'number' && message.data !== undefined) {
      const expected = this.model.seq === null ? null : this.model.seq + 1;
      if (expected !== null && message.seq < expected) return;
      if (expected !== null && message.seq > expected) {
        // Never expected (the server sends without gaps): reconnect from what we have.
        socket.close(4001, 'gap');
        return;
      }
      this.model.applyEvent(message);
    } else if (message.type === 'store') {
      this.model.applyStore(message);
    }
    // `resync` needs nothing: the server closes with 4000 next and the reconnect asks for
    // what follows the last event applied.
  }

  async closed(opened, code) {
    if (this.stopped) return;
    if (!opened) {
      // The upgrade itself failed and a browser does not say why: ask the HTTP API.
      try {
        await api('GET', '/api/v1/alarms?limit=1');
      } catch (e) {
        if (e.status === 401) {
          this.stopped = true;
          this.onState('key');
          return;
        }
      }
    }
    const delay = code === 4000 ? 0 : BACKOFF_MS[Math.min(this.failures, BACKOFF_MS.length - 1)];
    this.failures += 1;
    this.wait(delay);
  }

  wait(delay) {
    const until = Date.now() + delay;
    const tick = () => {
      const left = until - Date.now();
      if (left <= 0) {
        this.timer = null;
        this.connect();
        return;
      }
      this.onState('waiting', Math.ceil(left / 1000));
      this.timer = setTimeout(tick, Math.min(left, 1000));
    };
    tick();
  }
}
