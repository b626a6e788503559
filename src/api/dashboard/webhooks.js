// The webhook subscriptions that push events to the WMS, from `GET /api/v1/webhooks`: one
// tile each with its URL, its state (failing and paused stand out), how far behind it is
// (events and seconds), its last success and its last error, and an alarm badge while its
// `webhook` alarm is active. Webhooks have no live event of their own, so the list is read
// every few seconds while the page is visible (and at once when it shows again). No
// subscription configured, or a rackd without webhooks (404): the panel stays hidden.
//
// Each tile's **Delivery log** disclosure reads the newest tries
// (`GET /api/v1/webhooks/{name}/deliveries`) when opened and again at each read while open.
// Administrators get Pause, Resume and Replay from an event's seq (each asking for a
// second click, with an optional reason for the audit log); those carry the class
// `admin-op` (see roles.js). Tiles are kept per subscription, so an open log, a typed seq
// and an armed button survive the reads.

import { api } from './api.js';
import { ago, clock, confirmButton, duration, el, setText } from './dom.js';

/** How often the list is read while the page is visible. */
const REFRESH_MS = 5000;
/** How many tries the delivery log shows. */
const LOG_LIMIT = 50;

const STATES = { delivering: 'delivering', caught_up: 'caught up', failing: 'failing', paused: 'paused' };

/** `n events` / `1 event`. */
function events(n) {
  return `${n} event${n === 1 ? '' : 's'}`;
}

export class Webhooks {
  constructor(panel, root, model, notify) {
    this.panel = panel;
    this.root = root;
    this.model = model;
    this.notify = notify;
    this.summary = panel.querySelector('#webhook-summary');
    this.tiles = new Map();
    /** The last list read, by name, in rackd's order. */
    this.list = [];
    this.timer = null;
    this.panel.hidden = true;
    document.addEventListener('visibilitychange', () => {
      if (!document.hidden && this.timer) this.load();
    });
  }

  /** Reads the list now, then every few seconds while the page is visible. */
  start(every = REFRESH_MS) {
    this.load();
    if (!this.timer) {
      this.timer = setInterval(() => {
        if (!document.hidden) this.load();
      }, every);
    }
  }

  async load() {
    let answer;
    try {
      answer = await api('GET', '/api/v1/webhooks');
    } catch (e) {
      // An older rackd has no webhooks; any other failure keeps the last list until the
      // next read (the page says elsewhere when rackd cannot be reached).
      if (e.status === 404) this.show([]);
      return;
    }
    this.show(answer.webhooks || []);
  }

  /** Shows `list` (the answer's `webhooks`). */
  show(list) {
    this.list = list;
    this.panel.hidden = list.length === 0;
    this.render();
    for (const w of list) {
      const tile = this.tiles.get(w.name);
      if (tile && tile.log.open) this.loadLog(w.name, tile);
    }
  }

  /** Puts one subscription as an action answered it into the list. */
  replace(w) {
    this.list = this.list.map((old) => (old.name === w.name ? w : old));
    this.render();
  }

  /** Redraws every tile from the last list and the model's alarms. */
  render() {
    const names = new Set(this.list.map((w) => w.name));
    for (const [name, tile] of this.tiles) {
      if (!names.has(name)) {
        tile.root.remove();
        this.tiles.delete(name);
      }
    }
    this.list.forEach((w, index) => {
      let tile = this.tiles.get(w.name);
      if (!tile) {
        tile = this.tile(w.name);
        this.tiles.set(w.name, tile);
      }
      if (this.root.children[index] !== tile.root) this.root.insertBefore(tile.root, this.root.children[index] || null);
      this.fill(tile, w);
    });
    const failing = this.list.filter((w) => w.state === 'failing').length;
    const paused = this.list.filter((w) => w.state === 'paused').length;
    const behind = this.list.filter((w) => w.state === 'delivering').length;
    setText(
      this.summary,
      failing ? `${failing} failing` : paused ? `${paused} paused` : behind ? `${behind} delivering` : 'caught up',
    );
    this.summary.className = failing ? 'pill bad' : paused ? 'pill warn' : 'pill';
  }

  /** Only the "… ago" texts, once a second. */
  tick() {
    for (const w of this.list) {
      const tile = this.tiles.get(w.name);
      if (tile) this.fillTimes(tile, w);
    }
  }

  tile(name) {
    const t = {};
    t.state = el('span', { class: 'badge' });
    t.alarm = el('span', { class: 'badge alarm', text: 'alarm' });
    t.url = el('div', { class: 'webhook-url' });
    t.events = el('span', { class: 'v' });
    t.behind = el('span', { class: 'v webhook-behind' });
    t.ok = el('span', { class: 'v webhook-ok' });
    t.paused = el('p', { class: 'webhook-paused' });
    t.error = el('p', { class: 'error-text webhook-error' });
    t.rows = el('tbody');
    t.logNote = el('p', { class: 'empty', text: 'Reading…' });
    t.log = el(
      'details',
      { class: 'webhook-log' },
      el('summary', { text: `Delivery log (newest ${LOG_LIMIT} tries)` }),
      t.logNote,
      el(
        'div',
        { class: 'log-wrap' },
        el(
          'table',
          { class: 'deliveries' },
          el(
            'thead',
            {},
            el(
              'tr',
              {},
              ...[
                ['Time', 'c-time'],
                ['Seq', 'c-num'],
                ['Try', 'c-num'],
                ['Status', 'c-num'],
                ['Outcome', 'c-outcome'],
                ['Latency', 'c-num'],
                ['Error', 'c-error'],
              ].map(([h, c]) => el('th', { class: c, text: h })),
            ),
          ),
          t.rows,
        ),
      ),
    );
    t.log.addEventListener('toggle', () => {
      if (t.log.open) this.loadLog(name, t);
    });
    t.reason = el('input', { type: 'text', maxlength: 500, autocomplete: 'off', placeholder: 'Reason (optional)', 'aria-label': `reason for ${name}` });
    t.seq = el('input', { type: 'number', min: 1, step: 1, class: 'webhook-seq', placeholder: 'seq' });
    t.pause = confirmButton('Pause', 'Confirm pause', 'pause', (b) => this.act(name, 'pause', {}, b));
    t.resume = confirmButton('Resume', 'Confirm resume', 'resume', (b) => this.act(name, 'resume', {}, b));
    t.replay = confirmButton('Replay', 'Confirm replay', 'replay', (b) => {
      const seq = Number(t.seq.value);
      if (!t.seq.value || !Number.isInteger(seq) || seq < 1) {
        this.notify(`Replay ${name}: give the seq of the first event to send again.`);
        t.seq.focus();
        return;
      }
      this.act(name, 'replay', { from_seq: seq }, b);
    });
    t.root = el(
      'article',
      { class: 'webhook', dataset: { webhook: name } },
      el('header', {}, el('span', { class: 'name', text: name }), el('span', { class: 'badges' }, t.state, t.alarm)),
      t.url,
      el(
        'div',
        { class: 'facts' },
        el('span', { class: 'k', text: 'Events' }),
        t.events,
        el('span', { class: 'k', text: 'Behind' }),
        t.behind,
        el('span', { class: 'k', text: 'Last success' }),
        t.ok,
      ),
      t.paused,
      t.error,
      t.log,
      el(
        'div',
        { class: 'webhook-actions admin-op' },
        t.reason,
        el('label', { class: 'replay-from' }, 'From seq ', t.seq),
        t.replay,
        t.pause,
        t.resume,
      ),
    );
    return t;
  }

  fill(t, w) {
    t.root.dataset.state = w.state;
    t.root.classList.toggle('is-failing', w.state === 'failing');
    t.root.classList.toggle('is-paused', w.state === 'paused');
    setText(t.state, STATES[w.state] || w.state);
    t.state.className = `badge webhook-state wh-${w.state}`;
    setText(t.url, w.url);
    t.url.title = w.url;
    setText(t.events, (w.events || []).join(', '));
    const alarmed = [...this.model.alarms.values()].some((a) => a.device === `webhook:${w.name}` && !a.cleared_at);
    t.alarm.hidden = !alarmed;
    t.root.classList.toggle('in-alarm', alarmed);
    t.paused.hidden = w.state !== 'paused';
    // A receiver's 410 is told from an administrator's pause: its events are held for it.
    t.root.dataset.pausedBy = w.paused_by || '';
    const paused =
      w.paused_by === 'receiver' ? 'Paused by its receiver (its events are held until it is resumed)' : 'Paused';
    setText(t.paused, w.paused_reason ? `${paused}: ${w.paused_reason}` : `${paused}: nothing is delivered until it is resumed.`);
    t.pause.hidden = w.state === 'paused';
    t.resume.hidden = w.state !== 'paused';
    this.fillTimes(t, w);
  }

  /** The texts that age: lag, last success, last error. */
  fillTimes(t, w) {
    setText(
      t.behind,
      w.behind > 0 ? `${events(w.behind)} · oldest ${duration(w.behind_secs * 1000)}` : `none (cursor ${w.cursor})`,
    );
    t.behind.classList.toggle('lagging', w.behind > 0);
    setText(t.ok, w.last_ok_at ? `${clock(w.last_ok_at)} (${ago(w.last_ok_at)})` : 'never');
    // The last error stays shown once delivery is back, in grey: what last went wrong.
    t.error.hidden = !w.last_error;
    t.error.classList.toggle('past', w.state !== 'failing');
    const since = w.failing_since && w.state === 'failing' ? ` · failing since ${clock(w.failing_since)}` : '';
    setText(t.error, w.last_error ? `Last error ${clock(w.last_error_at)} (${ago(w.last_error_at)})${since}: ${w.last_error}` : '');
  }

  /** Reads the newest tries into an open log. */
  async loadLog(name, t) {
    let page;
    try {
      page = await api('GET', `/api/v1/webhooks/${encodeURIComponent(name)}/deliveries?limit=${LOG_LIMIT}`);
    } catch (e) {
      setText(t.logNote, `The delivery log could not be read: ${e.message}`);
      t.logNote.hidden = false;
      return;
    }
    const tries = page.deliveries || [];
    setText(t.logNote, 'No delivery tried yet.');
    t.logNote.hidden = tries.length > 0;
    t.rows.replaceChildren(
      ...tries.map((d) =>
        el(
          'tr',
          { class: `outcome-${d.outcome}`, dataset: { seq: d.seq } },
          el('td', { class: 'c-time', text: clock(d.at) }),
          el('td', { class: 'c-num', text: String(d.seq) }),
          el('td', { class: 'c-num', text: String(d.attempt) }),
          el('td', { class: 'c-num', text: d.status === null || d.status === undefined ? '–' : String(d.status) }),
          el('td', { class: 'c-outcome', text: d.outcome }),
          el('td', { class: 'c-num', text: `${d.latency_ms} ms` }),
          el('td', { class: 'c-error', text: d.error || '' }),
        ),
      ),
    );
  }

  async act(name, what, body, button) {
    const reason = this.tiles.get(name)?.reason.value.trim();
    if (reason) body.reason = reason;
    button.disabled = true;
    try {
      const w = await api('POST', `/api/v1/webhooks/${encodeURIComponent(name)}/${what}`, body);
      if (w && w.name) this.replace(w);
      const tile = this.tiles.get(name);
      if (tile) {
        tile.reason.value = '';
        if (what === 'replay') tile.seq.value = '';
        if (tile.log.open) this.loadLog(name, tile);
      }
    } catch (e) {
      const verb = { pause: 'Pause', resume: 'Resume', replay: 'Replay' }[what];
      this.notify(`${verb} webhook ${name}: ${e.message}`);
    } finally {
      button.disabled = false;
    }
  }
}
