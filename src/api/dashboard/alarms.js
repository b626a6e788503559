// The alarm list: active alarms first (newest first), then the recent past, each with its
// device, code, class, text, and raised and cleared times.

import { clock, duration, el, ms } from './dom.js';

export class Alarms {
  constructor(root, model) {
    this.root = root;
    this.model = model;
    this.summary = document.getElementById('alarm-summary');
  }

  render() {
    const all = [...this.model.alarms.values()];
    const active = all.filter((a) => !a.cleared_at).sort((a, b) => b.id - a.id);
    const past = all.filter((a) => a.cleared_at).sort((a, b) => ms(b.cleared_at) - ms(a.cleared_at) || b.id - a.id);
    if (this.summary) {
      this.summary.textContent = active.length ? `${active.length} active` : 'none active';
      this.summary.className = active.length ? 'pill bad' : 'pill';
    }
    if (all.length === 0) {
      this.root.replaceChildren(el('li', { class: 'empty', text: 'No alarms.' }));
      return;
    }
    this.root.replaceChildren(...active.map((a) => this.item(a)), ...past.map((a) => this.item(a)));
  }

  item(a) {
    const cleared = Boolean(a.cleared_at);
    const lasted = cleared ? `cleared ${clock(a.cleared_at)} (after ${duration(ms(a.cleared_at) - ms(a.raised_at))})` : 'active';
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
      a.detail ? el('div', { class: 'alarm-detail', text: a.detail }) : '',
      el('div', { class: 'alarm-times' }, `raised ${clock(a.raised_at)} · `, el('span', { class: 'lasted', text: lasted })),
    );
  }
}
