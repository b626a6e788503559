// The header's counters, readable across a control room: active alarms by class, devices
// offline, degraded and paused, jobs queued, running, late (unfinished and past their
// deadline, by the page's clock: `render` runs every second) and failed in the last hour.
//
// All but one come from what the page already holds. Failed in the last hour is counted
// from the jobs the page holds (the last hour's are read at start) and from
// `GET /api/v1/stats?since=1h` when rackd has it: the larger wins, since the page keeps
// only its newest 500 jobs.

import { el, ms, setText } from './dom.js';
import { TERMINAL, lateBy } from './model.js';
import { FAILED_WINDOW_MS } from './reasons.js';

/** The counters: id (`data-counter`), group, label. */
const COUNTERS = [
  ['alarms-hardware', 'Alarms', 'hardware'],
  ['alarms-business', 'Alarms', 'business'],
  ['alarms-link', 'Alarms', 'link'],
  ['devices-offline', 'Devices', 'offline'],
  ['devices-degraded', 'Devices', 'degraded'],
  ['devices-paused', 'Devices', 'paused'],
  ['jobs-queued', 'Jobs', 'queued'],
  ['jobs-running', 'Jobs', 'running'],
  ['jobs-late', 'Jobs', 'late'],
  ['jobs-failed', 'Jobs', 'failed 1 h'],
];

/** Counters that are bad news when not zero. */
const BAD = new Set(['alarms-hardware', 'alarms-link', 'devices-offline', 'jobs-late', 'jobs-failed']);
const WARN = new Set(['alarms-business', 'devices-degraded', 'devices-paused']);

export class Counters {
  constructor(root, model) {
    this.model = model;
    /** Failed jobs in the last hour by `GET /api/v1/stats`, while rackd answers it. */
    this.statsFailed = null;
    this.values = new Map();
    const groups = new Map();
    for (const [id, group, label] of COUNTERS) {
      if (!groups.has(group)) groups.set(group, el('div', { class: 'counter-group' }, el('span', { class: 'group', text: group })));
      const value = el('b', { text: '–' });
      this.values.set(id, value);
      groups.get(group).append(el('span', { class: 'counter', dataset: { counter: id } }, value, ` ${label}`));
    }
    root.replaceChildren(...groups.values());
  }

  /** The stats of the last hour (or null when rackd has none): failures summed by device
   * (the aisles' figures count the same jobs again). */
  setStats(stats) {
    this.statsFailed = stats ? (stats.devices || []).reduce((n, s) => n + (s.failed || 0), 0) : null;
    this.render();
  }

  counts() {
    const c = Object.fromEntries(COUNTERS.map(([id]) => [id, 0]));
    for (const a of this.model.alarms.values()) {
      if (!a.cleared_at && c[`alarms-${a.class}`] !== undefined) c[`alarms-${a.class}`] += 1;
    }
    for (const d of this.model.devices.values()) {
      if (!d.online) c['devices-offline'] += 1;
      if (d.link && d.link.degraded) c['devices-degraded'] += 1;
      if (d.paused || (d.paused_aisles && d.paused_aisles.length)) c['devices-paused'] += 1;
    }
    const now = Date.now();
    for (const j of this.model.jobs.values()) {
      if (j.state === 'queued') c['jobs-queued'] += 1;
      else if (['dispatched', 'running', 'cancelling'].includes(j.state)) c['jobs-running'] += 1;
      else if (j.state === 'failed' && now - ms(j.updated_at) <= FAILED_WINDOW_MS) c['jobs-failed'] += 1;
      if (!TERMINAL.has(j.state) && lateBy(j, now) !== null) c['jobs-late'] += 1;
    }
    if (this.statsFailed !== null) c['jobs-failed'] = Math.max(c['jobs-failed'], this.statsFailed);
    return c;
  }

  render() {
    const c = this.counts();
    for (const [id, value] of this.values) {
      const more = this.model.jobsTruncated && ['jobs-queued', 'jobs-running', 'jobs-late'].includes(id) ? '+' : '';
      setText(value, `${c[id]}${more}`);
      const counter = value.parentElement;
      counter.classList.toggle('bad', c[id] > 0 && BAD.has(id));
      counter.classList.toggle('warn', c[id] > 0 && WARN.has(id));
      counter.classList.toggle('zero', c[id] === 0);
    }
  }
}
