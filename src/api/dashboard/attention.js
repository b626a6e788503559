// The jobs that need a person, on the first screen: failed in the last hour (newest
// first), running on a device in alarm, then waiting (in queue order, oldest first), each
// as a card with its reference, where it goes, why, and Cancel or Retry for operators.
// Above them, one chip per reason with its count: fourteen jobs behind one offline shelf
// read as one line. A card of a job past its deadline says how late it is.
//
// Cards are kept per job and refilled only when the job or its reason changed, so an armed
// Cancel survives the redraws of a busy store. At most MAX_SHOWN cards are drawn; the
// chips still count every job.

import { JobActions } from './actions.js';
import { clock, el, jobWhere, setText } from './dom.js';
import { lateBadge, setJobLate } from './late.js';
import { REASONS, attention } from './reasons.js';

/** How many cards the list draws at most. */
const MAX_SHOWN = 100;

const ORDER = { failed: 0, alarm: 1, waiting: 2 };

export class Attention {
  constructor(root, model, notify) {
    this.root = root;
    this.model = model;
    this.actions = new JobActions(model, notify);
    this.reasons = document.getElementById('attention-reasons');
    this.summary = document.getElementById('attention-summary');
    this.cards = new Map();
  }

  /** The jobs that need attention now, in the order the list shows them. */
  list() {
    const now = Date.now();
    const found = [];
    for (const job of this.model.jobs.values()) {
      const why = attention(job, this.model, now);
      if (why) found.push({ job, why });
    }
    return found.sort(
      (a, b) =>
        ORDER[a.why.kind] - ORDER[b.why.kind] || (a.why.kind === 'failed' ? b.job.id - a.job.id : a.job.id - b.job.id),
    );
  }

  render() {
    const found = this.list();
    this.chips(found);
    setText(this.summary, found.length ? `${found.length}` : '');
    this.summary.className = found.length ? 'pill bad' : 'pill';
    const shown = found.slice(0, MAX_SHOWN);
    const keep = new Set(shown.map((f) => f.job.id));
    for (const [id, card] of this.cards) {
      if (!keep.has(id)) {
        card.li.remove();
        this.cards.delete(id);
      }
    }
    let previous = null;
    for (const { job, why } of shown) {
      let card = this.cards.get(job.id);
      if (!card) {
        card = this.card(job.id);
        this.cards.set(job.id, card);
      }
      const key = `${why.kind}|${why.text}`;
      if (card.job !== job || card.key !== key) this.fill(card, job, why, key);
      const place = previous ? previous.nextSibling : this.root.firstChild;
      if (place !== card.li) this.root.insertBefore(card.li, place);
      previous = card.li;
    }
    const empty = this.root.querySelector(':scope > .empty');
    if (shown.length === 0 && !empty) this.root.append(el('li', { class: 'empty', text: 'Nothing is stuck.' }));
    if (shown.length > 0 && empty) empty.remove();
    if (found.length > shown.length && shown.length) {
      this.root.append(el('li', { class: 'empty more', text: `and ${found.length - shown.length} more` }));
    }
  }

  /** One chip per reason: `14 · device offline`. */
  chips(found) {
    const counts = new Map();
    for (const { why } of found) counts.set(why.reason, (counts.get(why.reason) || 0) + 1);
    this.reasons.replaceChildren(
      ...[...counts].map(([reason, n]) =>
        el(
          'span',
          { class: `chip reason-${reason}`, dataset: { reason } },
          el('b', { text: String(n) }),
          ` ${reason === 'failed' ? 'failed' : REASONS[reason] || 'waiting'}`,
        ),
      ),
    );
    this.root.querySelectorAll(':scope > .more').forEach((n) => n.remove());
  }

  card(id) {
    const c = {};
    c.title = el('span', { class: 'att-title' });
    c.state = el('span', { class: 'state' });
    c.where = el('span', { class: 'att-where' });
    c.late = lateBadge();
    c.why = el('div', { class: 'att-why' });
    c.buttons = { root: el('span', { class: 'att-actions' }), cancel: null, retry: null };
    c.li = el(
      'li',
      { class: 'att-item', dataset: { jobId: id } },
      el('div', { class: 'att-head' }, c.title, c.state, c.late, c.where),
      el('div', { class: 'att-foot' }, c.why, c.buttons.root),
    );
    return c;
  }

  fill(c, job, why, key) {
    c.job = job;
    c.key = key;
    c.li.className = `att-item att-${why.kind}`;
    c.li.dataset.reason = why.reason;
    setText(c.title, `${job.id}${job.reference ? ` · ${job.reference}` : ''} · ${job.kind}`);
    setText(c.state, job.state);
    c.state.className = `state state-${job.state}`;
    setJobLate(c.late, job);
    setText(c.where, `${jobWhere(job)}${job.device ? ` on ${job.device}` : ''}`);
    setText(c.why, `${why.text} · since ${clock(job.updated_at)}`);
    this.actions.update(c.buttons, job);
  }
}
