// Why a job is not moving, in plain words, and which jobs need a person.
//
// A job's `waiting` comes from the dispatcher: an object `{reason, text, device, code, job,
// by}` (a rackd before it sent a plain sentence, shown as is; none at all shows nothing).
// A job that runs has no `waiting`, but if its device is in alarm it is stuck too: the
// page says so from the device's active alarms.

import { ms } from './dom.js';
import { TERMINAL } from './model.js';

/** Each waiting reason in a few words (the filter's labels and the reason chips). */
export const REASONS = {
  device_offline: 'device offline',
  device_paused: 'device paused',
  aisle_paused: 'aisle paused',
  device_alarm: 'device in alarm',
  location_locked: 'location locked',
  behind_job: 'behind another job',
  slots_busy: 'all slots busy',
  no_device: 'no device serves the aisle',
  no_place: 'no free location',
  dependency: 'after another job',
  sequence: 'sequence order',
};

/** How long a failed job stays among those that need attention (as the header counts it). */
export const FAILED_WINDOW_MS = 3600 * 1000;

/** A sentence for a waiting object that came without one. */
function describe(w) {
  const device = w.device || 'its device';
  switch (w.reason) {
    case 'device_offline':
      return `${device} is offline`;
    case 'device_paused':
      return `${device} is paused`;
    case 'aisle_paused':
      return 'its aisle is paused';
    case 'device_alarm':
      return `${device} is in alarm${w.code ? ` ${w.code}` : ''}`;
    case 'location_locked':
      return w.job ? `location locked after job ${w.job} failed` : `location locked${w.by ? ` by ${w.by}` : ''}`;
    case 'behind_job':
      return w.job ? `behind job ${w.job} on the same location` : 'behind another job on the same location';
    case 'slots_busy':
      return `every slot of ${device} is busy`;
    case 'no_device':
      return 'no device serves its aisle';
    case 'no_place':
      return 'no free location for it';
    case 'dependency':
      return w.job ? `waits for job ${w.job} to complete` : 'waits for another job to complete';
    case 'sequence':
      return w.job ? `job ${w.job} goes first in its sequence` : 'an earlier member of its sequence goes first';
    default:
      return 'waiting';
  }
}

/** The job's waiting reason as `{reason, text}`, or null while it moves. */
export function waiting(job) {
  const w = job.waiting;
  if (!w) return null;
  if (typeof w === 'string') return { reason: 'other', text: w };
  return { reason: w.reason || 'other', text: w.text || describe(w) };
}

/** The active alarm that holds a running job's device, if any (a degraded link does not). */
function deviceAlarm(job, model) {
  if (!job.device || TERMINAL.has(job.state) || job.state === 'queued') return null;
  for (const alarm of model.alarms.values()) {
    if (alarm.device === job.device && !alarm.cleared_at && alarm.kind !== 'degraded') return alarm;
  }
  return null;
}

/**
 * Why `job` needs a person, or null: `{kind, reason, text}` with kind `failed` (in the
 * last hour), `alarm` (it runs on a device in alarm) or `waiting`.
 */
export function attention(job, model, now = Date.now()) {
  if (job.state === 'failed') {
    if (now - ms(job.updated_at) > FAILED_WINDOW_MS) return null;
    const f = job.failure;
    const text = f ? `${f.kind}${f.code !== null && f.code !== undefined ? ` ${f.code}` : ''}: ${f.text}` : 'failed';
    return { kind: 'failed', reason: 'failed', text };
  }
  const alarm = deviceAlarm(job, model);
  if (alarm) {
    // An alarm's sentence usually names its device already.
    const text = alarm.text.includes(alarm.device) ? alarm.text : `${alarm.device} in alarm: ${alarm.text}`;
    return { kind: 'alarm', reason: 'device_alarm', text };
  }
  const w = waiting(job);
  return w ? { kind: 'waiting', ...w } : null;
}
