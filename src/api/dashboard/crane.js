// Where a stacker crane is drawn in its aisle, and its state in words.
//
// A crane reports its axes in its own units (D220/D221), which say nothing about bays, so
// the crane is drawn where its work puts it: by its action state, at the pick or put
// location of the task it holds once there (with an arrow to it while travelling); idle,
// at the put location of its last job if that completed, else where it last stopped, or at
// the station end when both axes read zero (home). Its label sits on a track of its own
// under the bay numbers (never covering them); it starts at its bay's left edge in the left
// half of the aisle and ends at its bay's right edge in the right half, so it never runs
// past the aisle's end. The raw axis values are written under the aisle.

import { ms, setText } from './dom.js';
import { TERMINAL } from './model.js';

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

/** Draws the cranes of the page's aisles; remembers where each was last drawn. */
export class Cranes {
  constructor(model) {
    this.model = model;
    /** Where each crane was last drawn, so an idle crane stays where it stopped. */
    this.places = new Map();
  }

  /** Draws `device` (or no crane) in `lane`: `{marker, track, mast, info, bays}`. */
  draw(lane, device) {
    if (!device) {
      lane.marker.hidden = true;
      lane.track.hidden = true;
      lane.mast.hidden = true;
      setText(lane.info, '');
      return;
    }
    const c = device.crane;
    const work = this.craneWork(device);
    let at = this.places.get(device.id) || null;
    if (work && (work.arrived || !at)) at = work.target;
    else if (!work) at = this.idlePlace(device, at);
    if (at) this.places.set(device.id, at);
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
   * An idle crane: home when both axes read zero; else where its last job put the load if
   * that job completed, whether or not the page saw it there (it draws once per frame from
   * the newest status the server sent, and a loaded server or browser can skip the whole
   * put); else (a job cancelled or failed on the way) where it was last seen working.
   */
  idlePlace(device, known) {
    const c = device.crane;
    if (c.travel_position === 0 && c.lift_position === 0) return HOME;
    let last = null;
    for (const j of this.model.jobs.values()) {
      if (j.device === device.id && TERMINAL.has(j.state) && (!last || ms(j.updated_at) > ms(last.updated_at))) last = j;
    }
    if (last && last.state === 'completed') return ends(last).put;
    return known && known !== HOME ? known : null;
  }
}

/** A crane's state in a few words for its aisle's summary. */
export function craneState(d) {
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
