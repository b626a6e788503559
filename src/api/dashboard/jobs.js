// The live job table: newest first, filtered by state (or late), kind, device and why a job
// waits, with Cancel (jobs not ended) and Retry (failed jobs) for operators; a job past its
// deadline has a late badge beside its state. Rows are kept per job
// and only refilled when the job changed, so a busy store does not rebuild the table every
// event. On a tablet the stylesheet turns each row into a card; every cell carries its
// heading (`data-label`) for that.

import { JobActions } from './actions.js';
import { clock, el, jobWhere, setText } from './dom.js';
import { lateBadge, setJobLate } from './late.js';
import { MAX_JOBS, TERMINAL, lateBy } from './model.js';
import { REASONS, waiting } from './reasons.js';

const STATES = ['queued', 'dispatched', 'running', 'cancelling', 'completed', 'failed', 'cancelled'];
const KINDS = ['store', 'retrieve', 'move', 'clear', 'light', 'travel'];

/** The table's columns: class suffix (`c-<name>`) and heading. */
const COLUMNS = [
  ['id', 'Job'],
  ['reference', 'Reference'],
  ['kind', 'Kind'],
  ['barcode', 'Barcode'],
  ['where', 'Where'],
  ['device', 'Device'],
  ['priority', 'Prio'],
  ['state', 'State'],
  ['detail', 'Why / detail'],
  ['created', 'Created'],
  ['updated', 'Updated'],
  ['action', ''],
];

export class Jobs {
  constructor(root, model, notify) {
    this.model = model;
    this.actions = new JobActions(model, notify);
    this.rows = new Map();
    this.state = this.select('state', [
      ['', 'all states'],
      ['active', 'active'],
      ['late', 'late (not ended)'],
      ...STATES.map((s) => [s, s]),
    ]);
    this.kind = this.select('kind', [['', 'all kinds'], ...KINDS.map((k) => [k, k])]);
    this.device = this.select('device', [['', 'all devices']]);
    this.why = this.select('waiting', [['', 'waiting or not'], ['any', 'waiting: any reason'],
      ...Object.entries(REASONS).map(([r, label]) => [r, `waiting: ${label}`])]);
    this.counts = el('div', { class: 'counts' });
    this.note = el('p', { class: 'note' });
    this.body = el('tbody');
    this.empty = el('p', { class: 'empty', text: 'No jobs to show.' });
    const head = COLUMNS.map(([name, title]) => el('th', { class: `c-${name}`, text: title }));
    root.replaceChildren(
      el('div', { class: 'filters' }, this.state, this.kind, this.device, this.why, this.counts),
      el(
        'div',
        { class: 'table-wrap' },
        el('table', { class: 'jobs' }, el('thead', {}, el('tr', {}, ...head)), this.body),
      ),
      this.empty,
      this.note,
    );
  }

  select(name, options) {
    const select = el('select', { id: `filter-${name}`, 'aria-label': `filter by ${name}` });
    for (const [value, label] of options) select.append(el('option', { value, text: label }));
    select.addEventListener('change', () => this.render());
    return select;
  }

  matches(job) {
    const state = this.state.value;
    if (state === 'active' && TERMINAL.has(job.state)) return false;
    if (state === 'late' && (TERMINAL.has(job.state) || lateBy(job) === null)) return false;
    if (state && state !== 'active' && state !== 'late' && job.state !== state) return false;
    if (this.kind.value && job.kind !== this.kind.value) return false;
    if (this.device.value && job.device !== this.device.value) return false;
    if (this.why.value) {
      const w = waiting(job);
      if (!w || (this.why.value !== 'any' && w.reason !== this.why.value)) return false;
    }
    return true;
  }

  /** Keeps the device filter's options to the devices known. */
  deviceOptions() {
    const ids = new Set(this.model.devices.keys());
    for (const job of this.model.jobs.values()) if (job.device) ids.add(job.device);
    const have = [...this.device.options].slice(1).map((o) => o.value);
    const want = [...ids].sort();
    if (have.join('\n') === want.join('\n')) return;
    const chosen = this.device.value;
    this.device.replaceChildren(this.device.options[0], ...want.map((id) => el('option', { value: id, text: id })));
    this.device.value = want.includes(chosen) ? chosen : '';
  }

  render() {
    this.deviceOptions();
    const list = [...this.model.jobs.values()].filter((j) => this.matches(j)).sort((a, b) => b.id - a.id);
    const shown = new Set(list.map((j) => j.id));
    for (const [id, row] of this.rows) {
      if (!this.model.jobs.has(id)) this.rows.delete(id);
      if (!shown.has(id)) row.tr.remove();
    }
    let previous = null;
    for (const job of list) {
      let row = this.rows.get(job.id);
      if (!row) {
        row = this.row(job.id);
        this.rows.set(job.id, row);
      }
      if (row.job !== job) this.fill(row, job);
      const place = previous ? previous.nextSibling : this.body.firstChild;
      if (place !== row.tr) this.body.insertBefore(row.tr, place);
      previous = row.tr;
    }
    this.empty.hidden = list.length > 0;

    const counts = new Map(STATES.map((s) => [s, 0]));
    for (const job of this.model.jobs.values()) counts.set(job.state, (counts.get(job.state) || 0) + 1);
    this.counts.replaceChildren(
      ...STATES.filter((s) => counts.get(s)).map((s) =>
        el('span', { class: `count state-${s}` }, el('b', { text: String(counts.get(s)) }), ` ${s}`),
      ),
    );
    const notes = [];
    if (this.model.jobsTruncated) notes.push('The server holds more active jobs than it sent; the oldest are not shown.');
    if (this.model.jobs.size >= MAX_JOBS) notes.push(`The table keeps the last ${MAX_JOBS} jobs (active ones first).`);
    setText(this.note, notes.join(' '));
    this.note.hidden = notes.length === 0;
  }

  row(id) {
    const cells = {};
    const tr = el('tr', { dataset: { jobId: id } });
    for (const [name, title] of COLUMNS) {
      cells[name] = el('td', { class: `c-${name}`, dataset: { label: title } });
      tr.append(cells[name]);
    }
    const late = lateBadge();
    cells.state.append(el('span', { class: 'state' }), late);
    return { tr, cells, late, job: null, buttons: { root: cells.action, cancel: null, retry: null } };
  }

  fill(row, job) {
    const c = row.cells;
    row.job = job;
    setText(c.id, job.id);
    setText(c.reference, job.reference || '');
    setText(c.kind, job.kind);
    setText(c.barcode, job.barcode || '');
    setText(c.where, jobWhere(job));
    setText(c.device, job.device || '');
    setText(c.priority, job.priority);
    const badge = c.state.firstChild;
    setText(badge, job.forced ? `${job.state} (forced)` : job.state);
    badge.className = `state state-${job.state}`;
    row.tr.className = `job-${job.state}`;
    setJobLate(row.late, job);
    const f = job.failure;
    const w = waiting(job);
    const detail = w ? w.text : f ? `${f.kind}${f.code !== null && f.code !== undefined ? ` ${f.code}` : ''}: ${f.text}` : '';
    setText(c.detail, detail);
    c.detail.className = `c-detail${w ? ` waiting reason-${w.reason}` : ''}`;
    c.detail.title = detail;
    setText(c.created, clock(job.created_at));
    setText(c.updated, clock(job.updated_at));
    this.actions.update(row.buttons, job);
  }
}
