// Small helpers for building the page. Text always goes through textContent (or an
// attribute), never through HTML parsing: barcodes and references come from the WMS.

/**
 * Makes an element: `el('td', {class: 'x', title: 't', dataset: {id: 1}}, 'text', child)`.
 * Strings among the children become text nodes; null and false children are skipped.
 */
export function el(tag, props = {}, ...children) {
  const node = document.createElement(tag);
  for (const [name, value] of Object.entries(props)) {
    if (value === null || value === undefined || value === false) continue;
    if (name === 'class') node.className = value;
    else if (name === 'dataset') Object.assign(node.dataset, value);
    else if (name === 'text') node.textContent = value;
    else if (name.startsWith('on')) node.addEventListener(name.slice(2), value);
    else node.setAttribute(name, value === true ? '' : String(value));
  }
  for (const child of children) {
    if (child === null || child === undefined || child === false) continue;
    node.append(typeof child === 'string' || typeof child === 'number' ? String(child) : child);
  }
  return node;
}

/** Sets an element's text only when it changed (keeps the DOM quiet). */
export function setText(node, text) {
  const value = text === null || text === undefined ? '' : String(text);
  if (node.textContent !== value) node.textContent = value;
}

/** Milliseconds since the epoch of an RFC 3339 time, or NaN. */
export function ms(time) {
  return time ? Date.parse(time) : NaN;
}

const pad = (n, width = 2) => String(n).padStart(width, '0');

/** A time as local `HH:MM:SS`, with the date in front when it is not today. */
export function clock(time) {
  const t = ms(time);
  if (Number.isNaN(t)) return '';
  const d = new Date(t);
  const hms = `${pad(d.getHours())}:${pad(d.getMinutes())}:${pad(d.getSeconds())}`;
  const today = new Date();
  if (d.toDateString() === today.toDateString()) return hms;
  return `${d.getFullYear()}-${pad(d.getMonth() + 1)}-${pad(d.getDate())} ${hms}`;
}

/** A duration in words: `0.4 s`, `12 s`, `3 min`, `2 h 5 min`, `3 d`. */
export function duration(millis) {
  const s = Math.max(0, millis) / 1000;
  if (s < 10) return `${s.toFixed(1)} s`;
  if (s < 120) return `${Math.round(s)} s`;
  const min = Math.floor(s / 60);
  if (min < 120) return `${min} min`;
  const h = Math.floor(min / 60);
  if (h < 48) return `${h} h ${min % 60} min`;
  return `${Math.floor(h / 24)} d`;
}

/** How long ago `time` was, in words (`3 s ago`), or `never`. */
export function ago(time) {
  const t = ms(time);
  return Number.isNaN(t) ? 'never' : `${duration(Date.now() - t)} ago`;
}

/** Row 1 is A (left), row 2 is B (right), and so on. */
export function rowName(row) {
  return row >= 1 && row <= 26 ? String.fromCharCode(64 + row) : `R${row}`;
}

/** A location in the short form operators read: `1-A-03-02-1`; bay 0 is the station. */
export function locName(l) {
  if (!l) return '';
  if (l.bay === 0) return `${l.aisle}-${rowName(l.row)}-station`;
  return `${l.aisle}-${rowName(l.row)}-${pad(l.bay)}-${pad(l.level)}-${l.position}`;
}

/** What a job does, where, in one line: `→ 1-A-03-02-1`, `1-A-03-02-1 red on`. */
export function jobWhere(job) {
  switch (job.kind) {
    case 'store':
    case 'travel':
      return `→ ${locName(job.to)}`;
    case 'retrieve':
      return `${locName(job.from)} →`;
    case 'move':
      return `${locName(job.from)} → ${locName(job.to)}`;
    case 'light':
      return `${locName(job.location)} ${job.color || ''} ${job.on ? 'on' : 'off'}`;
    default:
      return locName(job.location);
  }
}

/** The key of a location in maps and `data-loc` attributes: `aisle-row-bay-level-position`. */
export function locKey(l) {
  return `${l.aisle}-${l.row}-${l.bay}-${l.level}-${l.position}`;
}

/** Calls `render` at most once per animation frame, however often `schedule` is called. */
export function throttle(render) {
  let pending = false;
  return function schedule() {
    if (pending) return;
    pending = true;
    requestAnimationFrame(() => {
      pending = false;
      render();
    });
  };
}

/** A button that asks for a second click within 4 s before it runs `action`. */
export function confirmButton(label, confirmLabel, className, action) {
  let armed = null;
  const button = el('button', { type: 'button', class: className, text: label });
  button.addEventListener('click', () => {
    if (!armed) {
      button.textContent = confirmLabel;
      button.classList.add('armed');
      armed = setTimeout(() => {
        armed = null;
        button.textContent = label;
        button.classList.remove('armed');
      }, 4000);
      return;
    }
    clearTimeout(armed);
    armed = null;
    button.textContent = label;
    button.classList.remove('armed');
    action(button);
  });
  return button;
}
