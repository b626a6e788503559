// What the page knows, built from the snapshot and the events (and, for what the snapshot
// leaves out, recent history read over HTTP): jobs, devices, alarms and locations by id.
// Views subscribe and redraw what changed. What follows from the jobs (the sequences under
// way, how late a job is now) is derived here too, from the jobs held.

import { locKey, ms } from './dom.js';

/** States a job never leaves. */
export const TERMINAL = new Set(['completed', 'failed', 'cancelled']);

/** How many jobs the page keeps: active ones first, then the newest ended ones. */
export const MAX_JOBS = 500;

/** How many alarms the page keeps: active ones, then the newest cleared ones. */
export const MAX_ALARMS = 200;

export class Model {
  constructor() {
    /** The last event applied (or the snapshot's), for `?since=`. */
    this.seq = null;
    this.jobs = new Map();
    this.devices = new Map();
    this.alarms = new Map();
    this.locations = new Map();
    /** The server had more active jobs than its snapshot holds. */
    this.jobsTruncated = false;
    /** Why the store cannot commit (the server's `store` message), or null. */
    this.storeFault = null;
    this.listeners = [];
  }

  /**
   * `listener(kind, item)` with kind `snapshot`, `job`, `device`, `alarm`, `location`,
   * `config` or `store`.
   */
  subscribe(listener) {
    this.listeners.push(listener);
  }

  emit(kind, item) {
    for (const listener of this.listeners) listener(kind, item);
  }

  /**
   * Replaces the state with a snapshot. Ended jobs and cleared alarms already shown are
   * kept (they never change again); active ones not in the snapshot have ended since and
   * come back with their final state from the history read after it.
   */
  applySnapshot(snapshot) {
    const data = snapshot.data || {};
    if (snapshot.reason === 'since_unknown') {
      // Our `since` is beyond the server's log: another database. Nothing we hold is its.
      this.jobs.clear();
      this.alarms.clear();
    }
    this.seq = snapshot.seq;
    if (data.jobs) {
      for (const [id, job] of this.jobs) if (!TERMINAL.has(job.state)) this.jobs.delete(id);
      for (const job of data.jobs) this.jobs.set(job.id, job);
      this.jobsTruncated = Boolean(data.jobs_truncated);
      this.trimJobs();
    }
    if (data.devices) {
      this.devices.clear();
      for (const device of data.devices) this.devices.set(device.id, device);
    }
    if (data.alarms) {
      for (const [id, alarm] of this.alarms) if (!alarm.cleared_at) this.alarms.delete(id);
      for (const alarm of data.alarms) this.alarms.set(alarm.id, alarm);
      this.trimAlarms();
    }
    if (data.locations) {
      this.locations.clear();
      for (const location of data.locations) this.locations.set(locKey(location), location);
    }
    this.emit('snapshot', snapshot);
  }

  /** Applies one event `{seq, time, type, data}`; the caller keeps `seq` order. */
  applyEvent(event) {
    this.seq = event.seq;
    const data = event.data;
    switch (event.type) {
      case 'job.updated':
      case 'job.late':
        // `job.late` carries the job as it was when it passed its deadline.
        if (this.mergeJob(data, true)) this.emit('job', this.jobs.get(data.id));
        break;
      case 'device.updated':
        this.updateDevice(data);
        break;
      case 'alarm.raised':
      case 'alarm.cleared':
      case 'alarm.updated':
        this.alarms.set(data.id, data);
        this.trimAlarms();
        this.emit('alarm', data);
        break;
      case 'location.updated':
        this.applyLocation(data);
        break;
      case 'config.reloaded':
        // A removed device sends no more updates: it leaves the page with the reload.
        for (const change of data.devices || []) {
          if (change.change === 'removed') this.devices.delete(change.id);
        }
        this.emit('config', data);
        this.emit('device');
        break;
      default:
        break;
    }
  }

  /** The server's `store` message: whether the store commits, and if not why. */
  applyStore(state) {
    const fault = state.ok ? null : state;
    if (fault === null && this.storeFault === null) return;
    this.storeFault = fault;
    this.emit('store', fault);
  }

  /** A location's state from an event or from a lock/unlock answer. */
  applyLocation(location) {
    this.locations.set(locKey(location), location);
    this.emit('location', location);
  }

  /** A device status from an event or from a pause/resume answer. */
  updateDevice(device) {
    this.devices.set(device.id, device);
    this.emit('device', device);
  }

  /** Jobs read over HTTP (recent history, a cancel's answer): merged, newest wins. */
  addJobs(jobs) {
    let changed = false;
    for (const job of jobs) changed = this.mergeJob(job, false) || changed;
    if (changed) this.emit('jobs');
  }

  /** Alarms read over HTTP (the recent past, an acknowledgement's answer): merged, a
   * cleared or acknowledged one wins. */
  addAlarms(alarms) {
    for (const alarm of alarms) {
      const known = this.alarms.get(alarm.id);
      const news = !known || (alarm.cleared_at && !known.cleared_at) || (alarm.acknowledged_at && !known.acknowledged_at);
      if (!news) continue;
      const merged = { ...alarm };
      for (const field of ['cleared_at', 'acknowledged_at', 'acknowledged_by']) {
        if (known && known[field] && !merged[field]) merged[field] = known[field];
      }
      this.alarms.set(alarm.id, merged);
    }
    this.trimAlarms();
    this.emit('alarms');
  }

  /**
   * Keeps the newer of two versions of a job: an event replaces a version as old as it,
   * an HTTP read only an older one; an ended job is never taken back to an active state,
   * except by a later attempt (a retry).
   */
  mergeJob(job, fromEvent) {
    const known = this.jobs.get(job.id);
    if (known) {
      // A retry queues a failed job again as its next attempt: the only way back.
      const attempt = (job.attempt || 1) - (known.attempt || 1);
      if (attempt < 0) return false;
      if (attempt === 0) {
        if (TERMINAL.has(known.state) && !TERMINAL.has(job.state)) return false;
        const age = ms(job.updated_at) - ms(known.updated_at);
        if (age < 0 || (age === 0 && !fromEvent)) return false;
      }
    }
    this.jobs.set(job.id, job);
    if (!known && this.jobs.size > MAX_JOBS) this.trimJobs();
    return this.jobs.has(job.id);
  }

  /** Drops the oldest ended jobs, then the oldest active ones, down to MAX_JOBS. */
  trimJobs() {
    if (this.jobs.size <= MAX_JOBS) return;
    const order = [...this.jobs.values()].sort(
      (a, b) => Number(TERMINAL.has(a.state)) - Number(TERMINAL.has(b.state)) || b.id - a.id,
    );
    for (const job of order.slice(MAX_JOBS)) this.jobs.delete(job.id);
  }

  /** Drops the oldest cleared alarms down to MAX_ALARMS (active ones always stay). */
  trimAlarms() {
    if (this.alarms.size <= MAX_ALARMS) return;
    const cleared = [...this.alarms.values()].filter((a) => a.cleared_at).sort((a, b) => a.id - b.id);
    for (const alarm of cleared.slice(0, this.alarms.size - MAX_ALARMS)) this.alarms.delete(alarm.id);
  }

  /**
   * The sequences under way: each sequence with an unfinished member among the jobs held,
   * as `{name, members, due, dueJob, oldest, deadline, late}` (see `sequenceOf`), those held
   * by a failed member first, then the oldest.
   */
  sequences(now = Date.now()) {
    const groups = new Map();
    for (const job of this.jobs.values()) {
      const name = job.sequence && job.sequence.name;
      if (!name) continue;
      if (!groups.has(name)) groups.set(name, []);
      groups.get(name).push(job);
    }
    const found = [];
    for (const [name, members] of groups) {
      if (members.some((j) => !TERMINAL.has(j.state))) found.push(sequenceOf(name, members, now));
    }
    const held = (s) => Number(!(s.dueJob && s.dueJob.state === 'failed'));
    return found.sort((a, b) => held(a) - held(b) || a.oldest - b.oldest);
  }

  /** The job a crane holds as its task number (task numbers come from job ids). */
  craneJob(device) {
    const task = device.crane ? device.crane.task : 0;
    if (!task) return null;
    for (const job of this.jobs.values()) {
      if (job.device === device.id && !TERMINAL.has(job.state) && ((job.id - 1) % 65535) + 1 === task) return job;
    }
    return null;
  }
}

/**
 * Whole seconds `job` is past its deadline, or null when it is not late (or has none): from
 * `now` (Unix ms) for an unfinished job, since the server's `late_by_s` changes only with
 * the job's events; as the server said for an ended job (how late it ended).
 */
export function lateBy(job, now = Date.now()) {
  if (TERMINAL.has(job.state)) return job.late_by_s || null;
  const deadline = ms(job.deadline);
  if (Number.isNaN(deadline) || now <= deadline) return null;
  return Math.ceil((now - deadline) / 1000);
}

/**
 * One sequence from the members the page holds (`jobs`, at least one unfinished):
 *
 * - `members`: by position, each `{position, job, status}`, status `delivered` (completed),
 *   `passed` (cancelled), `failed`, `due` or `waiting`; plus `{position, job: null, status:
 *   'missing'}` for a due position not posted yet;
 * - `due`: the position due, as the server reckons it: the lowest position neither
 *   delivered nor passed. The page may not hold every member (one that ended before the
 *   page's history began), so a position it does not hold counts as due only when the
 *   lowest member it holds waits for a position not posted (`waiting.reason` `sequence`
 *   without a `job`);
 * - `dueJob`: the due member's job, or null when it is not posted;
 * - `oldest`: the id of its oldest unfinished member (for the order);
 * - `deadline`: the earliest deadline (Unix ms) of its unfinished members, or null;
 *   `late`: how late its latest unfinished member is now, in whole seconds, or null.
 */
function sequenceOf(name, jobs, now) {
  const byPosition = new Map();
  for (const job of jobs) {
    const known = byPosition.get(job.sequence.position);
    // Two jobs at one position should not happen; the newer one is the one that counts.
    if (!known || job.id > known.id) byPosition.set(job.sequence.position, job);
  }
  const positions = [...byPosition.keys()].sort((a, b) => a - b);
  const ended = (job) => job.state === 'completed' || job.state === 'cancelled';
  const open = positions.find((p) => !ended(byPosition.get(p)));
  let due = open;
  const w = open === undefined ? null : byPosition.get(open).waiting;
  if (w && typeof w === 'object' && w.reason === 'sequence' && !w.job) {
    for (let p = 1; p < open; p += 1) {
      if (!byPosition.has(p)) {
        due = p;
        break;
      }
    }
  }
  const STATUS = { completed: 'delivered', cancelled: 'passed', failed: 'failed' };
  const members = positions.map((position) => {
    const job = byPosition.get(position);
    return { position, job, status: STATUS[job.state] || (position === due ? 'due' : 'waiting') };
  });
  if (due !== undefined && !byPosition.has(due)) {
    const at = members.findIndex((m) => m.position > due);
    members.splice(at < 0 ? members.length : at, 0, { position: due, job: null, status: 'missing' });
  }
  const unfinished = jobs.filter((j) => !TERMINAL.has(j.state));
  const deadlines = unfinished.map((j) => ms(j.deadline)).filter((d) => !Number.isNaN(d));
  const late = Math.max(0, ...unfinished.map((j) => lateBy(j, now) || 0));
  return {
    name,
    members,
    due: due === undefined ? null : due,
    dueJob: byPosition.get(due) || null,
    oldest: Math.min(...unfinished.map((j) => j.id)),
    deadline: deadlines.length ? Math.min(...deadlines) : null,
    late: late || null,
  };
}
