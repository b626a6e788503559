// The sequences under way: one line per sequence with an unfinished member among the jobs
// the page holds (the model groups them by `sequence.name`), with its members as position
// chips coloured by state, the position due, why that one is not moving and, when a member
// is past its deadline, how late. The panel shows only while there is such a sequence.
//
// Lines are kept per sequence and refilled only when what they show changed; the late
// badge keeps itself current (late.js).

import { el, setText } from './dom.js';
import { lateBadge, setLate } from './late.js';
import { waiting } from './reasons.js';

/** How many lines the panel draws at most. */
const MAX_SHOWN = 50;

/** How many chips a line draws at most: a few delivered before the one due, then on. */
const MAX_CHIPS = 24;
const CHIPS_BEFORE_DUE = 4;

const STATUS_TEXT = {
  delivered: 'delivered',
  passed: 'passed (cancelled)',
  failed: 'failed',
  due: 'due',
  waiting: 'waiting',
  missing: 'not posted yet',
};

export class Sequences {
  constructor(panel, root, model) {
    this.panel = panel;
    this.root = root;
    this.model = model;
    this.summary = document.getElementById('sequence-summary');
    this.lines = new Map();
  }

  render() {
    const found = this.model.sequences();
    this.panel.hidden = found.length === 0;
    setText(this.summary, found.length ? `${found.length}` : '');
    const shown = found.slice(0, MAX_SHOWN);
    const keep = new Set(shown.map((s) => s.name));
    for (const [name, line] of this.lines) {
      if (!keep.has(name)) {
        line.li.remove();
        this.lines.delete(name);
      }
    }
    let previous = null;
    for (const sequence of shown) {
      let line = this.lines.get(sequence.name);
      if (!line) {
        line = this.line(sequence.name);
        this.lines.set(sequence.name, line);
      }
      const why = holding(sequence);
      const key = JSON.stringify([sequence.members.map((m) => [m.position, m.status, m.job && m.job.id]), why, sequence.deadline]);
      if (line.key !== key) this.fill(line, sequence, why, key);
      const place = previous ? previous.nextSibling : this.root.firstChild;
      if (place !== line.li) this.root.insertBefore(line.li, place);
      previous = line.li;
    }
    this.root.querySelectorAll(':scope > .more').forEach((n) => n.remove());
    if (found.length > shown.length) {
      this.root.append(el('li', { class: 'empty more', text: `and ${found.length - shown.length} more` }));
    }
  }

  line(name) {
    const c = {};
    c.name = el('span', { class: 'seq-name', text: name });
    c.due = el('span', { class: 'seq-next' });
    c.late = lateBadge();
    c.chips = el('span', { class: 'seq-chips' });
    c.why = el('div', { class: 'seq-why' });
    c.li = el(
      'li',
      { class: 'seq', dataset: { sequence: name } },
      el('div', { class: 'seq-head' }, c.name, c.due, c.late, c.chips),
      c.why,
    );
    return c;
  }

  fill(c, sequence, why, key) {
    c.key = key;
    const held = sequence.dueJob && sequence.dueJob.state === 'failed';
    c.li.classList.toggle('is-held', Boolean(held));
    setText(c.due, sequence.due === null ? '' : `due ${sequence.due}`);
    c.due.dataset.position = sequence.due === null ? '' : String(sequence.due);
    // Unfinished members only: a sequence's badge says how late it is still.
    setLate(c.late, sequence.deadline, null);
    const { members } = sequence;
    const at = Math.max(0, members.findIndex((m) => m.position === sequence.due) - CHIPS_BEFORE_DUE);
    const from = Math.max(0, Math.min(at, members.length - MAX_CHIPS));
    const chips = members.slice(from, from + MAX_CHIPS).map((m) => chip(m, sequence.due));
    if (from > 0) chips.unshift(el('span', { class: 'seq-more', text: `${from} more…` }));
    const after = members.length - from - MAX_CHIPS;
    if (after > 0) chips.push(el('span', { class: 'seq-more', text: `…${after} more` }));
    c.chips.replaceChildren(...chips);
    setText(c.why, why.text);
    c.why.className = `seq-why tone-${why.tone}`;
    c.why.hidden = !why.text;
  }
}

/** A member's chip: its position, coloured by its status; the tooltip says the rest. */
function chip(member, due) {
  const { job } = member;
  const what = job ? `job ${job.id}${job.reference ? ` · ${job.reference}` : ''} · ${job.state}` : '';
  return el('span', {
    class: `seq-pos seq-${member.status}${member.position === due ? ' is-due' : ''}`,
    dataset: { position: member.position, status: member.status },
    title: `position ${member.position}: ${STATUS_TEXT[member.status]}${what ? ` (${what})` : ''}`,
    text: String(member.position),
  });
}

/**
 * Why the position due is not moving, as `{text, tone}`: tone `wait` (its job's waiting
 * reason, or not posted yet), `bad` (its job failed: the sequence is held) or `moving` (its
 * job is on its machine); no text while it is about to be handed out.
 */
function holding(sequence) {
  const job = sequence.dueJob;
  if (!job) {
    // Not posted yet: the member after it says so in its own reason.
    const next = sequence.members.find((m) => m.job && m.status !== 'delivered' && m.status !== 'passed');
    const w = next ? waiting(next.job) : null;
    return { text: w ? w.text : `position ${sequence.due} is not posted yet`, tone: 'wait' };
  }
  if (job.state === 'failed') {
    const f = job.failure;
    return { text: `job ${job.id} failed${f ? ` (${f.text})` : ''}: retry it, or cancel the sequence`, tone: 'bad' };
  }
  const w = waiting(job);
  if (w) return { text: w.text, tone: 'wait' };
  if (job.state === 'queued') return { text: '', tone: 'wait' };
  return { text: `job ${job.id} ${job.state}${job.device ? ` on ${job.device}` : ''}`, tone: 'moving' };
}
