// Late jobs: a badge that says by how much a job (or a sequence) is past its deadline. The
// server tells `late_by_s` only with a job's events, so for an unfinished job the page
// counts from the deadline and its own clock: the badge carries the deadline
// (`data-deadline`, Unix ms) and `tickLate`, called every second, keeps its words current.
// An ended job's badge says how late it ended, as the server said, and does not change.

import { duration, ms } from './dom.js';
import { TERMINAL } from './model.js';

/** `late by 40 s`, `late by 4 min`, `late by 2 h 5 min`. */
export function lateText(seconds) {
  return `late by ${seconds < 120 ? `${seconds} s` : duration(seconds * 1000)}`;
}

/** A badge for `setLate`, hidden until it has something to say. */
export function lateBadge() {
  const badge = document.createElement('span');
  badge.className = 'late';
  badge.hidden = true;
  return badge;
}

/**
 * Makes `badge` follow `deadline` (Unix ms: how late it is now, kept current by `tickLate`)
 * or, with a null deadline, say `seconds` (how late it ended; null or 0: hidden).
 */
export function setLate(badge, deadline, seconds = null) {
  if (deadline === null || deadline === undefined || Number.isNaN(deadline)) {
    delete badge.dataset.deadline;
    badge.classList.add('ended');
    show(badge, seconds);
  } else {
    badge.dataset.deadline = String(deadline);
    badge.classList.remove('ended');
    show(badge, lateness(deadline, Date.now()));
  }
}

/** Makes `badge` say how late `job` is: now, while it is unfinished; when it ended, after. */
export function setJobLate(badge, job) {
  if (TERMINAL.has(job.state)) setLate(badge, null, job.late_by_s);
  else setLate(badge, ms(job.deadline));
}

/** Keeps every badge under `root` that follows a deadline current at `now`. */
export function tickLate(root, now = Date.now()) {
  for (const badge of root.querySelectorAll('.late[data-deadline]')) {
    show(badge, lateness(Number(badge.dataset.deadline), now));
  }
}

/** Whole seconds past `deadline` at `now`, rounded up as the server does, or null. */
function lateness(deadline, now) {
  return now > deadline ? Math.ceil((now - deadline) / 1000) : null;
}

function show(badge, seconds) {
  const text = seconds ? lateText(seconds) : '';
  if (badge.textContent !== text) badge.textContent = text;
  badge.hidden = !seconds;
}
