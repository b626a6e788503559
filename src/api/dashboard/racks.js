// The store drawn as the operator sees it: per aisle, each row as a grid of bays (across)
// and levels (up), each cell showing its box positions; between the rows the aisle itself,
// with the bay numbers and, under them on a track of its own, the crane where one runs
// (see crane.js). Each aisle folds away (a <details>, remembered in local storage) behind a
// summary line: the devices serving it, its occupancy, its locks, the crane's state, its
// pause, and for operators Pause/Resume. Clicking a box position opens the location's
// dialog (lock and unlock; see locations.js).

import { api } from './api.js';
import { Cranes, craneState } from './crane.js';
import { confirmButton, el, locKey, locName, rowName, setText } from './dom.js';

/** The shape of each aisle, from the locations the server knows. */
function layout(locations) {
  const aisles = new Map();
  for (const l of locations.values()) {
    const a = aisles.get(l.aisle) || { aisle: l.aisle, rows: 0, bays: 0, levels: 0, positions: 0 };
    a.rows = Math.max(a.rows, l.row);
    a.bays = Math.max(a.bays, l.bay);
    a.levels = Math.max(a.levels, l.level);
    a.positions = Math.max(a.positions, l.position);
    aisles.set(l.aisle, a);
  }
  return [...aisles.values()].sort((x, y) => x.aisle - y.aisle);
}

export class Racks {
  /** `open(location)` shows a location's dialog; `notify` tells of a refused pause. */
  constructor(root, model, open, notify) {
    this.root = root;
    this.model = model;
    this.notify = notify;
    root.addEventListener('click', (e) => {
      const pos = e.target.closest('.pos[data-loc]');
      const l = pos && this.model.locations.get(pos.dataset.loc);
      if (l) open(l);
    });
    this.shape = '';
    this.cells = new Map();
    this.lanes = new Map();
    this.cranes = new Cranes(model);
  }

  /** Builds the grids again when the set of locations changed shape, then fills them. */
  rebuild() {
    const aisles = layout(this.model.locations);
    const shape = JSON.stringify(aisles);
    if (shape !== this.shape) {
      this.shape = shape;
      this.cells.clear();
      this.lanes.clear();
      this.root.replaceChildren(...aisles.map((a) => this.aisle(a)));
      if (aisles.length === 0) this.root.append(el('p', { class: 'empty', text: 'No locations configured.' }));
    }
    for (const l of this.model.locations.values()) this.update(l);
    this.devices();
  }

  aisle(a) {
    const block = el('div', { class: 'aisle-block' });
    block.style.setProperty('--bays', a.bays);
    block.style.setProperty('--positions', a.positions);
    for (let row = 1; row <= a.rows; row += 1) {
      block.append(this.row(a, row));
      if (row === 1) block.append(this.lane(a));
    }
    const mast = el('div', { class: 'mast', hidden: true });
    block.append(mast);
    const s = {
      served: el('span', { class: 'served' }),
      fill: el('span', { class: 'fill' }),
      locks: el('span', { class: 'locks' }),
      crane: el('span', { class: 'crane-state' }),
      paused: el('span', { class: 'badge paused aisle-paused', text: 'paused' }),
    };
    const pause = confirmButton('Pause aisle', 'Confirm pause', 'pause op', (b) => this.pause(a.aisle, true, b));
    const resume = confirmButton('Resume aisle', 'Confirm resume', 'resume op', (b) => this.pause(a.aisle, false, b));
    const summary = el(
      'summary',
      { class: 'aisle-summary' },
      el('span', { class: 'aisle-name', text: `Aisle ${a.aisle}` }),
      s.served,
      s.paused,
      s.crane,
      s.locks,
      s.fill,
      el('span', { class: 'aisle-actions' }, pause, resume),
    );
    // A click on a button in the summary is the button's, not a fold.
    summary.addEventListener('click', (e) => {
      if (e.target.closest('button')) e.preventDefault();
    });
    const section = el('details', { class: 'aisle', dataset: { aisle: a.aisle }, open: !folded().has(a.aisle) }, summary, block);
    section.addEventListener('toggle', () => fold(a.aisle, !section.open));
    const lane = this.lanes.get(a.aisle);
    Object.assign(lane, s, { mast, pause, resume, size: a.rows * a.bays * a.levels * a.positions });
    return section;
  }

  row(a, row) {
    const grid = el('div', { class: 'rack', 'aria-label': `aisle ${a.aisle} row ${rowName(row)}` });
    for (let level = a.levels; level >= 1; level -= 1) {
      grid.append(el('div', { class: 'lbl level', text: level === a.levels ? `${rowName(row)} ${level}` : level }));
      for (let bay = 1; bay <= a.bays; bay += 1) {
        const cell = el('div', { class: 'cell' });
        for (let position = 1; position <= a.positions; position += 1) {
          const l = { aisle: a.aisle, row, bay, level, position };
          const pos = el('div', { class: 'pos', dataset: { loc: locKey(l) } });
          cell.append(pos);
          this.cells.set(locKey(l), pos);
        }
        grid.append(cell);
      }
    }
    return grid;
  }

  lane(a) {
    const marker = el('div', { class: 'crane-marker', hidden: true }, el('span', { class: 'crane-id' }));
    const info = el('div', { class: 'lane-info' });
    const lane = el('div', { class: 'lane' }, el('div', { class: 'lbl station', text: 'P&D', title: 'station (bay 0)' }));
    for (let bay = 1; bay <= a.bays; bay += 1) lane.append(el('div', { class: 'lbl bay', text: bay }));
    const track = el('div', { class: 'track' }, marker);
    this.lanes.set(a.aisle, { marker, track, info, bays: a.bays });
    return el('div', { class: 'lane-wrap' }, lane, track, info);
  }

  /** Draws one location's state onto its position box. */
  update(l) {
    const pos = this.cells.get(locKey(l));
    if (!pos) return;
    pos.classList.toggle('occ', l.occupied);
    pos.classList.toggle('res', l.reserved_by !== null && l.reserved_by !== undefined);
    pos.classList.toggle('red', l.red);
    pos.classList.toggle('green', l.green);
    pos.classList.toggle('locked', Boolean(l.lock));
    const lines = [locName(l), l.occupied ? `box ${l.barcode || '(no barcode)'}` : 'empty'];
    if (l.lock) lines.push(`LOCKED by ${l.lock.by}: ${l.lock.reason}`);
    if (l.reserved_by) lines.push(`reserved by job ${l.reserved_by}`);
    if (l.red) lines.push('red light on');
    if (l.green) lines.push('green light on');
    const title = lines.join('\n');
    if (pos.title !== title) pos.title = title;
  }

  /** The aisles' summaries (devices, fill, locks, pause, crane) and the cranes in their lanes. */
  devices() {
    const byAisle = new Map();
    for (const d of this.model.devices.values()) {
      for (const aisle of d.aisles || []) {
        if (!byAisle.has(aisle)) byAisle.set(aisle, []);
        byAisle.get(aisle).push(d);
      }
    }
    const filled = new Map();
    const locked = new Map();
    for (const l of this.model.locations.values()) {
      if (l.occupied) filled.set(l.aisle, (filled.get(l.aisle) || 0) + 1);
      if (l.lock) locked.set(l.aisle, (locked.get(l.aisle) || 0) + 1);
    }
    for (const [aisle, lane] of this.lanes) {
      const devices = byAisle.get(aisle) || [];
      setText(lane.served, devices.length ? devices.map((d) => `${d.id} (${d.kind})`).join(', ') : 'no device');
      const n = filled.get(aisle) || 0;
      setText(lane.fill, `${n} / ${lane.size} occupied (${Math.round((100 * n) / (lane.size || 1))} %)`);
      const locks = locked.get(aisle) || 0;
      setText(lane.locks, locks ? `${locks} locked` : 'no locks');
      lane.locks.classList.toggle('bad', locks > 0);
      const paused = devices.some((d) => (d.paused_aisles || []).includes(aisle));
      lane.paused.hidden = !paused;
      lane.pause.hidden = paused || devices.length === 0;
      lane.resume.hidden = !paused;
      const crane = devices.find((d) => d.crane);
      setText(lane.crane, crane ? craneState(crane) : '');
      lane.crane.classList.toggle('bad', Boolean(crane && (!crane.online || crane.crane.alarm_code)));
      this.cranes.draw(lane, crane);
    }
  }

  async pause(aisle, paused, button) {
    button.disabled = true;
    try {
      await api('POST', `/api/v1/aisles/${aisle}/${paused ? 'pause' : 'resume'}`);
    } catch (e) {
      this.notify(`${paused ? 'Pause' : 'Resume'} aisle ${aisle}: ${e.message}`);
    } finally {
      button.disabled = false;
    }
  }
}

/** Where this browser keeps the aisles folded away, so a reload keeps them so. */
const FOLDED = 'rackd.folded';

/** The aisles folded away in this browser. */
function folded() {
  try {
    return new Set(JSON.parse(localStorage.getItem(FOLDED) || '[]'));
  } catch {
    return new Set();
  }
}

function fold(aisle, away) {
  const set = folded();
  if (away) set.add(aisle);
  else set.delete(aisle);
  try {
    localStorage.setItem(FOLDED, JSON.stringify([...set]));
  } catch {
    // Local storage can be disabled: the fold then lasts as long as the page.
  }
}

