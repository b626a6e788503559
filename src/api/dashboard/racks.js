// The store drawn as the operator sees it: per aisle, each row as a grid of bays (across)
// and levels (up), each cell showing its box positions; between the rows the aisle itself,
// with the bay numbers and, where a stacker crane runs, the crane.
//
// A crane reports its axes in its own units (D220/D221), which say nothing about bays, so
// the crane is drawn where its work puts it: by its action state, at the pick or put
// location of the task it holds once there (with an arrow to it while travelling); idle,
// where it last stopped, or at the station end when both axes read zero (home). The raw
// axis values are written under the aisle.

import { el, locKey, locName, ms, rowName, setText } from './dom.js';
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
  constructor(root, model) {
    this.root = root;
    this.model = model;
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
    const served = el('span', { class: 'served' });
    const fill = el('span', { class: 'fill' });
    const section = el(
      'section',
      { class: 'aisle', dataset: { aisle: a.aisle } },
      el('h3', {}, el('span', { text: `Aisle ${a.aisle}` }), served, fill),
      block,
    );
    const lane = this.lanes.get(a.aisle);
    lane.mast = mast;
    lane.served = served;
    lane.fill = fill;
    lane.size = a.rows * a.bays * a.levels * a.positions;
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
    lane.append(marker);
    this.lanes.set(a.aisle, { marker, info, bays: a.bays });
    return el('div', { class: 'lane-wrap' }, lane, info);
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

  /** Device names over each aisle, fill counts, and the cranes in their lanes. */
  devices() {
    const byAisle = new Map();
    for (const d of this.model.devices.values()) {
      for (const aisle of d.aisles || []) {
        if (!byAisle.has(aisle)) byAisle.set(aisle, []);
        byAisle.get(aisle).push(d);
      }
    }
    const filled = new Map();
    for (const l of this.model.locations.values()) if (l.occupied) filled.set(l.aisle, (filled.get(l.aisle) || 0) + 1);
    for (const [aisle, lane] of this.lanes) {
      const devices = byAisle.get(aisle) || [];
      setText(lane.served, devices.length ? devices.map((d) => `${d.id} (${d.kind})`).join(', ') : 'no device');
      setText(lane.fill, `${filled.get(aisle) || 0} / ${lane.size} occupied`);
      const crane = devices.find((d) => d.crane);
      this.crane(lane, crane);
    }
  }

  crane(lane, device) {
    if (!device) {
      lane.marker.hidden = true;
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
    lane.marker.hidden = !at;
    lane.mast.hidden = !at;
    lane.marker.classList.toggle('moving', travelling);
    lane.marker.classList.toggle('alarm', Boolean(c.alarm_code));
    lane.marker.classList.toggle('offline', !device.online);
    if (at) {
      // At the station the marker starts at the aisle's end instead of centring on it.
      lane.marker.classList.toggle('at-station', at.bay === 0);
      lane.marker.style.left = at.bay === 0 ? '0px' : `calc(${bayLeft(at.bay, lane.bays)} + ${bayWidth(lane.bays)} / 2)`;
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
