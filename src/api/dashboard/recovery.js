// Unlock and retry after a PLC lost its memory: the way back the memory-loss alarm offers.
// Each job the PLC held failed as `lost` and locked its locations, so the later jobs there
// wait. The operator first sees what one bulk action would do (a dry run of
// `POST /api/v1/jobs/retry` with `unlock`: the jobs the device lost around the alarm and
// the locations their failures locked), is asked to check the aisle, then confirms with a
// second click. Exactly the jobs listed are retried (by id, not by the filter again, so a
// failure after the check is not swept in), their locks lifted in the same commit: each
// runs before the later jobs on its locations, in the order the WMS sent them.
//
// A panel is kept per alarm and handed back across redraws of the alarm list, so a plan
// being read stays open while the alarm changes (acknowledged, cleared).

import { api } from './api.js';
import { clock, confirmButton, el, jobWhere, locName, ms } from './dom.js';

/** How long before the alarm a lost job may have failed (the alarm and the failures are
 * recorded apart, a moment apart). */
const SLACK_MS = 60 * 1000;

/** The memory-loss alarms' Unlock and retry, calling the API and putting answers into `model`. */
export class Recovery {
  constructor(model, notify) {
    this.model = model;
    this.notify = notify;
    /** The control of each alarm that has one, by alarm id. */
    this.boxes = new Map();
  }

  /** Whether alarm `a` offers Unlock and retry: a PLC's memory loss. */
  static offers(a) {
    return a.kind === 'memory_lost';
  }

  /** The control for alarm `a`: its button and, once asked, the plan; the same node each time. */
  control(a) {
    let box = this.boxes.get(a.id);
    if (!box) {
      box = el('div', { class: 'recovery' });
      const button = el('button', {
        type: 'button',
        class: 'recover op',
        text: 'Unlock and retry…',
        onclick: () => this.plan(a, box, button),
      });
      box.append(button);
      this.boxes.set(a.id, box);
    }
    return box;
  }

  /** Forgets the controls of alarms no longer listed. */
  keep(ids) {
    for (const id of this.boxes.keys()) if (!ids.has(id)) this.boxes.delete(id);
  }

  /** Asks for the dry run and shows it. */
  async plan(a, box, button) {
    button.disabled = true;
    const since = new Date(ms(a.raised_at) - SLACK_MS).toISOString();
    const body = { device: a.device, failure: 'lost', since, unlock: true, dry_run: true };
    try {
      this.show(a, box, since, await api('POST', '/api/v1/jobs/retry', body));
    } catch (e) {
      this.notify(`Unlock and retry (${a.device}): ${e.message}`);
    } finally {
      button.disabled = false;
    }
  }

  show(a, box, since, plan) {
    box.querySelectorAll('.recovery-plan').forEach((n) => n.remove());
    const panel = el('div', { class: 'recovery-plan' });
    const close = el('button', { type: 'button', class: 'link-button', text: 'Close', onclick: () => panel.remove() });
    box.append(panel);
    if (plan.jobs.length === 0) {
      panel.append(el('p', { text: `Nothing to retry: no job of ${a.device} was lost since ${clock(since)}.` }), close);
      return;
    }
    const n = plan.jobs.length;
    const aisles = [...new Set(plan.unlocked.map((u) => u.location.aisle))].sort((x, y) => x - y);
    const where = aisles.length ? `aisle ${aisles.join(', ')}` : 'the aisle';
    panel.append(
      el('p', {
        class: 'recovery-check',
        text: `Check ${where} first: each location below should hold what rackd says, with nothing in the way. Then unlock and retry.`,
      }),
      el('h4', { text: `${n} job${n === 1 ? '' : 's'} to retry, in the order they were sent` }),
      el(
        'ul',
        { class: 'recovery-list recovery-jobs' },
        ...plan.jobs.map((j) => el('li', {}, el('b', { text: `#${j.id}` }), ` ${j.reference || ''} ${j.kind} ${jobWhere(j)}`)),
      ),
      el('h4', { text: `${plan.unlocked.length} location${plan.unlocked.length === 1 ? '' : 's'} to unlock` }),
      el(
        'ul',
        { class: 'recovery-list recovery-locations' },
        ...plan.unlocked.map((u) => el('li', {}, el('b', { text: locName(u.location) }), ` ${u.lock.reason}`)),
      ),
      el(
        'div',
        { class: 'recovery-foot' },
        confirmButton(`Aisle checked: unlock and retry ${n}`, `Confirm: unlock and retry ${n}`, 'recover-apply op', (b) =>
          this.apply(a, panel, plan, b),
        ),
        close,
      ),
    );
  }

  /** Retries exactly the jobs of the plan, unlocking their locations. */
  async apply(a, panel, plan, button) {
    button.disabled = true;
    const body = {
      jobs: plan.jobs.map((j) => j.id),
      unlock: true,
      reason: `aisle checked after ${a.device} lost its memory (alarm ${a.id})`,
    };
    try {
      const done = await api('POST', '/api/v1/jobs/retry', body);
      this.model.addJobs(done.jobs);
      panel.replaceChildren(
        el('p', {
          class: 'recovery-done',
          text: `${done.jobs.length} jobs queued again, ${done.unlocked.length} locations unlocked.`,
        }),
        el('button', { type: 'button', class: 'link-button', text: 'Close', onclick: () => panel.remove() }),
      );
    } catch (e) {
      // Refused whole (a job moved meanwhile, say): nothing was done; the message says why.
      panel.querySelectorAll('.recovery-error').forEach((n) => n.remove());
      const text = e.code === 'bulk_refused' ? e.message : `Unlock and retry failed, nothing was done: ${e.message}`;
      panel.prepend(el('p', { class: 'recovery-error', role: 'alert', text }));
      button.disabled = false;
    }
  }
}
