// The store drawn as the operator sees it: per aisle, each row as a grid of bays (across)
// and levels (up), each cell showing its box positions; between the rows the aisle itself,
// with the bay numbers and, under them on a track of its own, the crane where one runs.
// Each aisle folds away (a <details>) behind a summary line: the devices serving it, its
// occupancy, its locks, the crane's state, its pause, and for operators Pause/Resume.
// Clicking a box position opens the location's dialog (lock and unlock; see locations.js).
//
// A crane reports its axes in its own units (D220/D221), which say nothing about bays, so
// the crane is drawn where its work puts it: by its action state, at the pick or put
// location of the task it holds once there (with an arrow to it while travelling); idle,
// where it last stopped, or at the station end when both axes read zero (home). Its label
// starts at its bay's left edge in the left half of the aisle and ends at its bay's right
// edge in the right half, so it never runs past the aisle's end; being on its own track,
// it never covers the bay numbers.

import { api } from './api.js';
import { confirmButton, el, locKey, locName, ms, rowName, setText } from './dom.js';
import { TERMINAL } from './model.js';

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

/** Where a crane picks and puts for a job (stations are bay 0). */
function ends(job) {
  const station = job.to || job.from ? { ...(job.to || job.from), bay: 0, level: 0 } : null;
  switch (job.kind) {
    case 'store':
      return { pick: station, put: job.to };
    case 'retrieve':
      return { pick: job.from, put: station };
    case 'move':
      return { pick: job.from, put: job.to };
    default:
      return { pick: job.to, put: job.to };
  }
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
    /** Where each crane was last drawn, so an idle crane stays where it stopped. */
    this.cranePlaces = new Map();
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
    const section = el('details', { class: 'aisle', dataset: { aisle: a.aisle }, open: true }, summary, block);
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
      this.crane(lane, crane);
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

  crane(lane, device) {
    if (!device) {
      lane.marker.hidden = true;
      lane.track.hidden = true;
      lane.mast.hidden = true;
      setText(lane.info, '');
      return;
    }
    const c = device.crane;
    const work = this.craneWork(device);
    let at = this.cranePlaces.get(device.id) || null;
    if (work && (work.arrived || !at)) at = work.target;
    else if (!work) at = this.idlePlace(device, at);
    if (at) this.cranePlaces.set(device.id, at);
    const travelling = Boolean(work && !work.arrived);
    lane.track.hidden = false;
    lane.marker.hidden = !at;
    lane.mast.hidden = !at;
    lane.marker.classList.toggle('moving', travelling);
    lane.marker.classList.toggle('alarm', Boolean(c.alarm_code));
    lane.marker.classList.toggle('offline', !device.online);
    if (at) {
      // In the right half the label ends at the bay's right edge, so it stays in the aisle.
      const right = at.bay > lane.bays / 2;
      lane.marker.classList.toggle('at-station', at.bay === 0);
      lane.marker.classList.toggle('from-right', right);
      if (at.bay === 0) lane.marker.style.left = '0px';
      else lane.marker.style.left = right ? 'auto' : `calc${bayLeft(at.bay, lane.bays)}`;
      lane.marker.style.right = right ? `calc(100% - ${bayLeft(at.bay, lane.bays)} - ${bayWidth(lane.bays)})` : 'auto';
      lane.mast.style.left = at.bay === 0 ? '0px' : `calc${bayLeft(at.bay, lane.bays)}`;
      lane.mast.style.width = at.bay === 0 ? 'var(--lbl)' : `calc${bayWidth(lane.bays)}`;
      const label = travelling && work.target !== at ? `${placeName(at)} → ${placeName(work.target)}` : placeName(at);
      setText(lane.marker.firstChild, `${device.id} · ${label}`);
    }
    const parts = [`${device.id}: ${c.action}`];
    const job = this.model.craneJob(device);
    if (job) parts.push(`job ${job.id} ${job.kind}${job.barcode ? ` ${job.barcode}` : ''}`);
    parts.push(`travel ${c.travel_position}`, `lift ${c.lift_position}`, c.load ? 'loaded' : 'empty');
    if (c.alarm_code) parts.push(`alarm ${c.alarm_code} ${c.alarm_text || ''}`.trim());
    if (!device.online) parts.push('offline');
    setText(lane.info, parts.join(' · '));
    lane.info.classList.toggle('alarm', Boolean(c.alarm_code));
  }

  /** Where the crane's current work takes it, and whether it is there: by action state. */
  craneWork(device) {
    const s = device.crane.action_state;
    if (s === 100) return { target: HOME, arrived: false };
    const job = this.model.craneJob(device);
    if (!job) return null;
    const { pick, put } = ends(job);
    if (s === 1 || s === 2) return { target: pick, arrived: false };
    if (s >= 3 && s <= 8) return { target: pick, arrived: true };
    if (s === 11 || s === 12) return { target: put, arrived: false };
    if ((s >= 13 && s <= 18) || s === 20) return { target: put, arrived: true };
    return null;
  }

  /**
   * An idle crane: home when both axes read zero; else where it was last seen working,
   * or, after a reload, where its last completed job put the load.
   */
  idlePlace(device, known) {
    const c = device.crane;
    if (c.travel_position === 0 && c.lift_position === 0) return HOME;
    if (known && known !== HOME) return known;
    let last = null;
    for (const j of this.model.jobs.values()) {
      if (j.device === device.id && TERMINAL.has(j.state) && (!last || ms(j.updated_at) > ms(last.updated_at))) last = j;
    }
    return last && last.state === 'completed' ? ends(last).put : null;
  }
}

/** A crane's state in a few words for its aisle's summary. */
function craneState(d) {
  const c = d.crane;
  if (!d.online) return `${d.id} offline`;
  if (c.alarm_code) return `${d.id} alarm ${c.alarm_code}${c.alarm_text ? ` ${c.alarm_text}` : ''}`;
  return `${d.id}: ${c.action}`;
}

/** The crane's home: the travel origin, at the station end of the aisle. */
const HOME = { bay: 0, level: 0, home: true };

function placeName(p) {
  if (p.home) return 'home';
  return p.bay === 0 ? 'P&D' : `bay ${p.bay} L${p.level}`;
}

/** Where bay `bay` starts across a grid of `bays` bays after the label column (CSS). */
function bayLeft(bay, bays) {
  return `(var(--lbl) + var(--gap) + ${bay - 1} * (${bayWidth(bays)} + var(--gap)))`;
}

/** The width of one bay's column (CSS). */
function bayWidth(bays) {
  return `((100% - var(--lbl) - ${bays} * var(--gap)) / ${bays})`;
}
