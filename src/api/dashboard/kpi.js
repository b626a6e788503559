// The store's KPIs from `GET /api/v1/stats?since=`, for the last hour or the last shift
// (8 h): per device and per aisle, jobs completed (and per hour), failures by kind,
// utilisation, and mean and p95 duration by job kind, drawn as small SVG charts made here
// (no chart library: the page is served from the binary and fetches nothing elsewhere).
//
// Read at start, every minute and when the period changes. A rackd without the endpoint
// (404) hides the panel; the last hour's figures also feed the header's failed counter.

import { api } from './api.js';
import { el } from './dom.js';

const SVG = 'http://www.w3.org/2000/svg';
const REFRESH_MS = 60000;

/** An SVG element with attributes. */
function svg(tag, attrs = {}, ...children) {
  const node = document.createElementNS(SVG, tag);
  for (const [name, value] of Object.entries(attrs)) node.setAttribute(name, String(value));
  for (const child of children) node.append(child);
  return node;
}

/** Seconds for people: `0.4 s`, `12 s`, `3.5 min`. */
function seconds(s) {
  if (s < 10) return `${s.toFixed(1)} s`;
  if (s < 120) return `${Math.round(s)} s`;
  return `${(s / 60).toFixed(1)} min`;
}

/** A bar of `share` (0..1) of the width with its percentage. */
function utilisationChart(share) {
  const pct = Math.round(Math.max(0, Math.min(1, share)) * 100);
  return svg(
    'svg',
    { class: 'chart util', viewBox: '0 0 200 16', role: 'img', 'aria-label': `utilisation ${pct} %` },
    svg('rect', { class: 'track', x: 0, y: 2, width: 160, height: 12, rx: 3 }),
    svg('rect', { class: 'fill', x: 0, y: 2, width: (160 * pct) / 100, height: 12, rx: 3 }),
    svg('text', { x: 166, y: 13 }, `${pct} %`),
  );
}

/** Per job kind: a bar for the mean, a tick for the p95, on one scale (the longest p95). */
function durationChart(durations) {
  const rows = durations.filter((d) => d.count > 0);
  const top = Math.max(1, ...rows.map((d) => d.p95_s || d.mean_s || 0));
  const height = rows.length * 18 + 2;
  const chart = svg('svg', {
    class: 'chart durations',
    viewBox: `0 0 300 ${height}`,
    role: 'img',
    'aria-label': rows.map((d) => `${d.kind} mean ${seconds(d.mean_s)} p95 ${seconds(d.p95_s)}`).join(', '),
  });
  rows.forEach((d, i) => {
    const y = i * 18 + 2;
    const scale = (s) => (110 * s) / top;
    chart.append(
      svg('text', { x: 0, y: y + 11, class: 'kind' }, d.kind),
      svg('rect', { class: 'track', x: 60, y: y + 2, width: 110, height: 11, rx: 2 }),
      svg('rect', { class: 'mean', x: 60, y: y + 2, width: scale(d.mean_s), height: 11, rx: 2 }),
      svg('rect', { class: 'p95', x: 60 + scale(d.p95_s) - 1, y, width: 2.5, height: 15 }),
      svg('text', { x: 176, y: y + 11 }, `${seconds(d.mean_s)} · p95 ${seconds(d.p95_s)} · ${d.count}`),
    );
  });
  return chart;
}

/** One device's or aisle's card. */
function card(s, title, data) {
  const failures = Object.entries(s.failures || {}).map(([kind, n]) => `${n} ${kind.replace(/_/g, ' ')}`);
  return el(
    'article',
    { class: 'kpi-card', dataset: data },
    el('h3', { text: title }),
    el(
      'div',
      { class: 'kpi-figures' },
      el('span', { class: 'kpi-completed' }, el('b', { text: String(s.completed) }), ' completed'),
      el('span', {}, el('b', { text: (s.per_hour || 0).toFixed(1) }), ' / h'),
      el('span', { class: s.failed ? 'kpi-failed bad' : 'kpi-failed' }, el('b', { text: String(s.failed) }), ' failed'),
    ),
    failures.length ? el('div', { class: 'kpi-failures', text: failures.join(' · ') }) : null,
    el('div', { class: 'kpi-label', text: 'Utilisation' }),
    utilisationChart(s.utilisation || 0),
    (s.durations || []).some((d) => d.count > 0) ? el('div', { class: 'kpi-label', text: 'Duration: mean, p95, count' }) : null,
    (s.durations || []).some((d) => d.count > 0) ? durationChart(s.durations) : null,
  );
}

export class Kpi {
  /** `onHour(stats | null)` gets the last hour's figures after each read. */
  constructor(panel, root, onHour) {
    this.panel = panel;
    this.root = root;
    this.onHour = onHour;
    this.since = '1h';
    this.timer = null;
    for (const button of panel.querySelectorAll('[data-since]')) {
      button.addEventListener('click', () => {
        this.since = button.dataset.since;
        for (const b of panel.querySelectorAll('[data-since]')) b.setAttribute('aria-pressed', String(b === button));
        this.load();
      });
    }
  }

  /** Reads the figures now and then every minute. */
  async load() {
    clearTimeout(this.timer);
    this.timer = setTimeout(() => this.load(), REFRESH_MS);
    try {
      const hour = await api('GET', '/api/v1/stats?since=1h');
      const shown = this.since === '1h' ? hour : await api('GET', `/api/v1/stats?since=${this.since}`);
      this.onHour(hour);
      this.draw(shown);
      this.panel.hidden = false;
    } catch (e) {
      // Without the endpoint (an older rackd) there is nothing to show; any other failure
      // keeps the last figures until the next read.
      if (e.status === 404) {
        this.panel.hidden = true;
        this.onHour(null);
      }
    }
  }

  draw(stats) {
    const cards = [
      ...(stats.devices || []).map((s) => card(s, s.device, { kpiDevice: s.device })),
      ...(stats.aisles || []).map((s) => card(s, `Aisle ${s.aisle}`, { kpiAisle: s.aisle })),
    ];
    this.root.replaceChildren(...(cards.length ? cards : [el('p', { class: 'empty', text: 'No figures for this period.' })]));
  }
}
