// The alarm list: active alarms first (newest first), then the recent past. Each says in
// plain words what happened and where, what to do (`action`, when rackd gives one: the
// crane catalogue's hardware alarms need a person at the crane), who acknowledged it and
// when; the protocol's own words sit behind a disclosure. Operators get Acknowledge on an
// alarm nobody acknowledged yet (active or cleared: a hardware alarm that cleared by
// itself may still want a look); a rackd without acknowledgements (no `acknowledged_by`
// in its alarms) shows none.
//
// A PLC's memory loss also offers Unlock and retry… (recovery.js): the dry run's jobs and
// locations, then, once the aisle is checked, one action that unlocks and retries them.
//
// Items are kept per alarm and rebuilt only when the alarm changed, keeping an open
// disclosure (and an open Unlock and retry plan) open.

import { api, download, probe } from './api.js';
import { clock, duration, el, ms } from './dom.js';
import { Recovery } from './recovery.js';

/** How far back the CSV export reaches. */
const EXPORT_HOURS = 24;

export class Alarms {
  constructor(root, model, notify) {
    this.root = root;
    this.model = model;
    this.notify = notify;
    this.items = new Map();
    this.recovery = new Recovery(model, notify);
    this.summary = document.getElementById('alarm-summary');
    this.export = document.getElementById('alarm-export');
    this.export.addEventListener('click', () => this.download());
  }

  /** Shows the export button when rackd has the export (asked with HEAD). */
  async findExport() {
    const status = await probe(`/api/v1/alarms/export.csv?since=${encodeURIComponent(new Date().toISOString())}`);
    this.export.hidden = status !== 200;
  }

  async download() {
    const until = new Date();
    const since = new Date(until.getTime() - EXPORT_HOURS * 3600 * 1000);
    const q = `since=${encodeURIComponent(since.toISOString())}&until=${encodeURIComponent(until.toISOString())}`;
    try {
      await download(`/api/v1/alarms/export.csv?${q}`, `rackd-alarms-${until.toISOString().slice(0, 10)}.csv`);
    } catch (e) {
      this.notify(`Alarm export: ${e.message}`);
    }
  }

  render() {
    const all = [...this.model.alarms.values()];
    const active = all.filter((a) => !a.cleared_at).sort((a, b) => b.id - a.id);
    const past = all.filter((a) => a.cleared_at).sort((a, b) => ms(b.cleared_at) - ms(a.cleared_at) || b.id - a.id);
    if (this.summary) {
      this.summary.textContent = active.length ? `${active.length} active` : 'none active';
      this.summary.className = active.length ? 'pill bad' : 'pill';
    }
    for (const [id, item] of this.items) {
      if (!this.model.alarms.has(id)) {
        item.li.remove();
        this.items.delete(id);
      }
    }
    this.recovery.keep(new Set(this.model.alarms.keys()));
    const order = [...active, ...past].map((a) => {
      let item = this.items.get(a.id);
      if (!item || item.alarm !== a) {
        const fresh = { alarm: a, li: this.item(a) };
        if (item) {
          const open = item.li.querySelector('details');
          const details = fresh.li.querySelector('details');
          if (open && details) details.open = open.open;
          item.li.replaceWith(fresh.li);
        }
        item = fresh;
        this.items.set(a.id, item);
      }
      return item.li;
    });
    if (order.length === 0) {
      this.root.replaceChildren(el('li', { class: 'empty', text: 'No alarms.' }));
      return;
    }
    this.root.querySelectorAll(':scope > .empty').forEach((n) => n.remove());
    order.forEach((li, i) => {
      if (this.root.children[i] !== li) this.root.insertBefore(li, this.root.children[i] || null);
    });
  }

  item(a) {
    const cleared = Boolean(a.cleared_at);
    const lasted = cleared ? `cleared ${clock(a.cleared_at)} (after ${duration(ms(a.cleared_at) - ms(a.raised_at))})` : 'active';
    const knowsAck = Object.prototype.hasOwnProperty.call(a, 'acknowledged_by');
    const acked = a.acknowledged_by
      ? el('div', { class: 'alarm-ack', text: `acknowledged by ${a.acknowledged_by} at ${clock(a.acknowledged_at)}` })
      : null;
    const ack =
      knowsAck && !a.acknowledged_by
        ? el('button', { type: 'button', class: 'ack op', text: 'Acknowledge', onclick: (e) => this.acknowledge(a.id, e.target) })
        : null;
    return el(
      'li',
      { class: `alarm-item ${cleared ? 'cleared' : 'active'} class-${a.class}`, dataset: { alarmId: a.id } },
      el(
        'div',
        { class: 'alarm-head' },
        el('span', { class: 'alarm-device', text: a.device }),
        el('span', { class: 'code', text: a.kind === 'device' || !a.kind ? String(a.code) : a.kind.replace('_', ' ') }),
        el('span', { class: 'class', text: a.class }),
      ),
      el('div', { class: 'alarm-text', text: a.text }),
      a.action ? el('div', { class: 'alarm-action' }, el('b', { text: 'To do: ' }), a.action) : null,
      a.detail ? el('details', { class: 'alarm-detail' }, el('summary', { text: 'Protocol detail' }), el('code', { text: a.detail })) : null,
      el(
        'div',
        { class: 'alarm-foot' },
        el('span', { class: 'alarm-times' }, `raised ${clock(a.raised_at)} · `, el('span', { class: 'lasted', text: lasted })),
        ack,
      ),
      acked,
      Recovery.offers(a) ? this.recovery.control(a) : null,
    );
  }

  async acknowledge(id, button) {
    button.disabled = true;
    try {
      const alarm = await api('POST', `/api/v1/alarms/${id}/acknowledge`);
      if (alarm && alarm.id) this.model.addAlarms([alarm]);
    } catch (e) {
      this.notify(`Acknowledge alarm ${id}: ${e.message}`);
      button.disabled = false;
    }
  }
}
