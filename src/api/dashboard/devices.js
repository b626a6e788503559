// One tile per device: link state (and a degraded link), pause, last contact, task slots,
// what a crane reports, a tags device's values, its alarms; pause and resume for operators
// (devices that take jobs: pausing a tags device would change nothing), each asking for a
// second click. While the live connection is down every tile says "as of" when it was
// last current (the stylesheet greys it out).

import { api, getKey } from './api.js';
import { ago, confirmButton, el, setText } from './dom.js';

const KINDS = { shelf: 'shelf PLC', crane: 'stacker crane', tags: 'tag I/O' };

/** A tag's value for people: `on`/`off`, numbers to at most three decimals. */
function tagValue(tag) {
  const v = tag.value;
  if (v === null || v === undefined) return '–';
  if (typeof v === 'boolean') return v ? 'on' : 'off';
  if (typeof v === 'number') return Number.isInteger(v) ? String(v) : String(Number(v.toFixed(3)));
  return String(v);
}

export class Devices {
  constructor(root, model, notify) {
    this.root = root;
    this.model = model;
    this.notify = notify;
    this.tiles = new Map();
    /** "as of HH:MM:SS" while the live connection is down, else ''. */
    this.asOf = '';
  }

  /** Says on every tile since when its data may be stale ('' once live again). */
  stale(asOf) {
    this.asOf = asOf;
    for (const tile of this.tiles.values()) setText(tile.asOf, asOf);
  }

  /** Redraws every tile (cheap: a handful of devices), adding and removing as needed. */
  render() {
    const ids = [...this.model.devices.keys()].sort();
    for (const [id, tile] of this.tiles) {
      if (!this.model.devices.has(id)) {
        tile.root.remove();
        this.tiles.delete(id);
      }
    }
    ids.forEach((id, index) => {
      let tile = this.tiles.get(id);
      if (!tile) {
        tile = this.tile(id);
        this.tiles.set(id, tile);
      }
      if (this.root.children[index] !== tile.root) this.root.insertBefore(tile.root, this.root.children[index] || null);
      this.fill(tile, this.model.devices.get(id));
    });
    if (ids.length === 0 && !this.root.querySelector('.empty')) {
      this.root.append(el('p', { class: 'empty', text: 'No devices yet.' }));
    } else if (ids.length) {
      this.root.querySelectorAll('.empty').forEach((n) => n.remove());
    }
  }

  /** Only the "last contact" times, once a second. */
  tick() {
    for (const [id, tile] of this.tiles) {
      const d = this.model.devices.get(id);
      if (d) setText(tile.contact, ago(d.last_contact));
    }
  }

  tile(id) {
    const t = {};
    t.name = el('span', { class: 'name', text: id });
    t.kind = el('span', { class: 'kind' });
    t.link = el('span', { class: 'badge' });
    t.degraded = el('span', { class: 'badge degraded', text: 'degraded' });
    t.paused = el('span', { class: 'badge paused', text: 'paused' });
    t.alarmBadge = el('span', { class: 'badge alarm', text: 'alarm' });
    t.contact = el('span', { class: 'v contact' });
    t.address = el('span', { class: 'v' });
    t.slotsText = el('span', { class: 'slots-text' });
    t.slotsBar = el('div', { class: 'bar' }, el('span'));
    t.slotsKey = el('span', { class: 'k', text: 'Slots in use' });
    t.slots = el('span', { class: 'v slots' }, t.slotsText, t.slotsBar);
    t.tags = el('table', { class: 'tags' });
    t.crane = el('div', { class: 'crane-info' });
    t.alarms = el('ul', { class: 'device-alarms' });
    t.error = el('p', { class: 'error-text' });
    t.asOf = el('span', { class: 'as-of', text: this.asOf });
    t.pause = confirmButton('Pause', 'Confirm pause', 'pause op', (b) => this.toggle(id, true, b));
    t.resume = confirmButton('Resume', 'Confirm resume', 'resume op', (b) => this.toggle(id, false, b));
    t.capture = el('button', {
      type: 'button',
      class: 'capture op',
      text: 'Capture',
      title: "The last 10 minutes of this device's traffic as a pcapng file, for Wireshark",
    });
    t.capture.addEventListener('click', () => this.download(id, t.capture));
    t.root = el(
      'article',
      { class: 'device', dataset: { device: id } },
      el('header', {}, t.name, t.kind, el('span', { class: 'badges' }, t.link, t.degraded, t.paused, t.alarmBadge)),
      t.asOf,
      el(
        'div',
        { class: 'facts' },
        el('span', { class: 'k', text: 'Last contact' }),
        t.contact,
        t.slotsKey,
        t.slots,
        el('span', { class: 'k', text: 'Link' }),
        t.address,
      ),
      t.crane,
      t.tags,
      t.alarms,
      t.error,
      el('div', { class: 'actions' }, t.pause, t.resume, t.capture),
    );
    return t;
  }

  fill(t, d) {
    setText(t.kind, KINDS[d.kind] || d.kind);
    setText(t.link, d.online ? 'online' : 'offline');
    t.link.className = `badge ${d.online ? 'online' : 'offline'}`;
    const degraded = Boolean(d.online && d.link && d.link.degraded);
    t.degraded.hidden = !degraded;
    t.root.classList.toggle('is-degraded', degraded);
    t.paused.hidden = !d.paused && !(d.paused_aisles && d.paused_aisles.length);
    setText(t.paused, d.pause ? `paused by ${d.pause.by}${d.pause.reason ? `: ${d.pause.reason}` : ''}`
      : d.paused_aisles && d.paused_aisles.length ? `aisle ${d.paused_aisles.join(', ')} paused` : 'paused');
    t.root.classList.toggle('is-offline', !d.online);
    t.root.classList.toggle('is-paused', d.paused);
    setText(t.contact, ago(d.last_contact));
    setText(t.address, `${d.protocol} ${d.address}${d.aisles && d.aisles.length ? ` · aisle ${d.aisles.join(', ')}` : ''}`);
    setText(t.slotsText, `${d.slots_in_use} / ${d.slots_total}`);
    const share = d.slots_total ? Math.min(100, (100 * d.slots_in_use) / d.slots_total) : 0;
    t.slotsBar.firstChild.style.width = `${share}%`;
    const works = d.kind !== 'tags';
    t.slotsKey.hidden = !works;
    t.slots.hidden = !works;
    t.pause.hidden = !works || d.paused;
    t.resume.hidden = !works || !d.paused;
    this.fillTags(t, d.tags);

    const c = d.crane;
    t.crane.hidden = !c;
    if (c) {
      t.crane.replaceChildren(
        el('div', { class: 'action', text: c.action }),
        el(
          'div',
          { class: 'axes' },
          `travel ${c.travel_position} · lift ${c.lift_position} · ${c.load ? 'loaded' : 'empty'}`,
          c.task ? ` · task ${c.task}` : '',
          c.heartbeat_ok ? '' : ' · heartbeat lost',
        ),
      );
    }

    const alarms = [...this.model.alarms.values()].filter((a) => a.device === d.id && !a.cleared_at);
    if (c && c.alarm_code && !alarms.some((a) => a.code === c.alarm_code)) {
      alarms.push({ code: c.alarm_code, class: c.alarm_class || '', text: c.alarm_text || 'unknown alarm' });
    }
    t.alarmBadge.hidden = alarms.length === 0;
    t.root.classList.toggle('in-alarm', alarms.length > 0);
    t.alarms.replaceChildren(
      ...alarms.map((a) =>
        el(
          'li',
          {},
          // The code in front, unless the alarm's sentence says it already.
          a.code && String(a.text).includes(String(a.code)) ? null : el('span', { class: 'code', text: a.code ? `${a.code} ` : `${(a.kind || 'link').replace('_', ' ')} ` }),
          a.text,
          a.class ? el('span', { class: 'class', text: ` (${a.class})` }) : null,
        ),
      ),
    );
    const error = d.online ? '' : d.last_error || '';
    // Plain words on the tile; the protocol's own words (the link alarm's detail) on hover,
    // so the tile does not repeat what the alarm list says.
    setText(t.error, error ? `no answer: ${d.consecutive_failures} requests failed` : '');
    t.error.title = error;
    t.error.hidden = !error;
  }

  /** A tags device's values: name, value, quality (a bad read shows its error on hover). */
  fillTags(t, tags) {
    t.tags.hidden = !tags;
    if (!tags) return;
    t.tags.replaceChildren(
      ...Object.entries(tags).map(([name, tag]) => {
        const on = tag.value === true;
        return el(
          'tr',
          { class: `tag quality-${tag.quality}`, dataset: { tag: name }, title: tag.error || `${tag.address} (${tag.type})` },
          el('td', { class: 'tag-name', text: name }),
          el('td', { class: `tag-value${on ? ' on' : ''}`, text: tagValue(tag) }),
          el('td', { class: 'tag-quality', text: tag.quality }),
        );
      }),
    );
  }

  /** Downloads the device's capture (`GET /api/v1/devices/{id}/capture`, operators). */
  async download(id, button) {
    button.disabled = true;
    try {
      const key = getKey();
      const headers = key ? { Authorization: `Bearer ${key}` } : {};
      const response = await fetch(`/api/v1/devices/${encodeURIComponent(id)}/capture?seconds=600`, { headers });
      if (!response.ok) {
        const body = await response.json().catch(() => null);
        throw new Error(body && body.error ? body.error.message : response.statusText);
      }
      const url = URL.createObjectURL(await response.blob());
      const link = el('a', { href: url, download: `${id}.pcapng` });
      link.click();
      setTimeout(() => URL.revokeObjectURL(url), 1000);
    } catch (e) {
      this.notify(`Capture of ${id}: ${e.message}`);
    } finally {
      button.disabled = false;
    }
  }

  async toggle(id, pause, button) {
    button.disabled = true;
    try {
      const status = await api('POST', `/api/v1/devices/${encodeURIComponent(id)}/${pause ? 'pause' : 'resume'}`);
      this.model.updateDevice(status);
    } catch (e) {
      this.notify(`${pause ? 'Pause' : 'Resume'} ${id}: ${e.message}`);
    } finally {
      button.disabled = false;
    }
  }
}
