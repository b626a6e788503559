// rackd's operator dashboard: wires the live connection, the model and the parts of the
// page. Everything on the page comes from the server: the WebSocket snapshot and events,
// plus recent finished jobs and past alarms read over HTTP (the snapshot holds only what is
// active), the KPIs, the webhook subscriptions, and who the key belongs to (which buttons
// to show).

import { api, getKey, onUnauthorized, setKey, takeTokenFromUrl, whoIs } from './dashboard/api.js';
import { Alarms } from './dashboard/alarms.js';
import { Attention } from './dashboard/attention.js';
import { ClusterBadge } from './dashboard/cluster.js';
import { ConfigBadge } from './dashboard/config.js';
import { Counters } from './dashboard/counters.js';
import { Devices } from './dashboard/devices.js';
import { clock, el, throttle } from './dashboard/dom.js';
import { Jobs } from './dashboard/jobs.js';
import { Kpi } from './dashboard/kpi.js';
import { tickLate } from './dashboard/late.js';
import { Live } from './dashboard/live.js';
import { LocationDialog } from './dashboard/locations.js';
import { Model } from './dashboard/model.js';
import { Racks } from './dashboard/racks.js';
import { Who } from './dashboard/roles.js';
import { Sequences } from './dashboard/sequences.js';
import { Webhooks } from './dashboard/webhooks.js';

const $ = (id) => document.getElementById(id);

/** Shows a message for a while (failed cancels, refused pauses, lost key). */
function notify(text) {
  const toast = el('div', { class: 'toast', role: 'alert', text });
  $('toasts').append(toast);
  setTimeout(() => toast.remove(), 8000);
}

// A fault in the page itself is shown, not hidden in the console.
window.addEventListener('error', (e) => notify(`Dashboard error: ${e.message}`));
window.addEventListener('unhandledrejection', (e) => notify(`Dashboard error: ${e.reason}`));

// A key offered in the address leaves it at once; it is used only once the operator says so.
const offered = takeTokenFromUrl();
const model = new Model();
const locationDialog = new LocationDialog($('location-dialog'), model, notify);
const racks = new Racks($('racks'), model, (l) => locationDialog.open(l), notify);
const devices = new Devices($('devices'), model, notify);
const jobs = new Jobs($('jobs'), model, notify);
const sequences = new Sequences($('sequences-panel'), $('sequences'), model);
const alarms = new Alarms($('alarms'), model, notify);
const attention = new Attention($('attention'), model, notify);
const counters = new Counters($('counters'), model);
const kpi = new Kpi($('kpi-panel'), $('kpi'), (hour) => counters.setStats(hour));
const webhooks = new Webhooks($('webhooks-panel'), $('webhooks'), model, notify);
const who = new Who((w) => {
  $('who').textContent = w.role ? `${w.name ? `${w.name} · ` : ''}${w.role}` : '';
});

// What changed since the last frame; drawn once per animation frame. The header counters
// and the attention list follow jobs, devices and alarms alike.
const dirty = { jobs: false, devices: false, alarms: false, cranes: false };
const render = throttle(() => {
  if (dirty.jobs) {
    jobs.render();
    sequences.render();
  }
  if (dirty.devices) devices.render();
  if (dirty.alarms) {
    alarms.render();
    webhooks.render();
  }
  if (dirty.cranes) racks.devices();
  if (dirty.jobs || dirty.devices || dirty.alarms) {
    attention.render();
    counters.render();
  }
  Object.keys(dirty).forEach((k) => {
    dirty[k] = false;
  });
});
const mark = (...parts) => {
  for (const p of parts) dirty[p] = true;
  render();
};

/**
 * Asks rackd, once per key, who the key is, the KPIs (read every minute from then on), the
 * webhook subscriptions (every few seconds from then on) and whether it exports alarms: at
 * the first snapshot, and again when the key changes.
 */
let asked = false;
const node = new ClusterBadge($('node'));
const config = new ConfigBadge($('config'));
function askServer() {
  asked = true;
  node.start();
  config.load();
  who.load();
  kpi.load();
  webhooks.start();
  alarms.findExport();
}

/**
 * The banner saying the store cannot commit (`fault`: the server's `store` message), or
 * none. While it shows, nothing moves: the machines are held until their reports are
 * recorded, and the API answers 503.
 */
function showStore(fault) {
  const banner = $('store-down');
  banner.hidden = fault === null;
  if (fault === null) return;
  const since = fault.since ? ` since ${clock(fault.since)}` : '';
  banner.textContent =
    `The store cannot commit${since}: ${fault.message}. The machines are held until what they ` +
    'report is recorded; new jobs are refused (503) until then.';
}

model.subscribe((kind, item) => {
  switch (kind) {
    case 'snapshot':
      racks.rebuild();
      mark('jobs', 'devices', 'alarms', 'cranes');
      loadHistory();
      if (!asked) askServer();
      break;
    case 'job':
    case 'jobs':
      mark('jobs', 'cranes');
      break;
    case 'device':
      mark('devices', 'cranes');
      break;
    case 'alarm':
    case 'alarms':
      mark('alarms', 'devices');
      break;
    case 'location':
      racks.update(item);
      mark('cranes');
      break;
    case 'store':
      showStore(item);
      break;
    case 'config':
      config.show(item);
      loadAisles(item.aisles);
      mark('devices', 'cranes');
      break;
    default:
      break;
  }
});

/**
 * After a reload: the locations of the aisles it added or resized, read over HTTP (new
 * locations send no event), and those of removed aisles dropped; the racks drawn again.
 */
async function loadAisles(aisles) {
  if (!aisles) return;
  for (const [key, location] of model.locations) {
    if (aisles.removed.includes(location.aisle)) model.locations.delete(key);
  }
  const changed = [...aisles.added, ...aisles.changed.map((c) => c.aisle)];
  for (const aisle of changed) {
    try {
      const locations = await api('GET', `/api/v1/locations?aisle=${aisle}`);
      for (const [key, location] of model.locations) {
        if (location.aisle === aisle) model.locations.delete(key);
      }
      for (const location of locations) model.applyLocation(location);
    } catch (e) {
      notify(`The locations of aisle ${aisle} could not be read: ${e.message}`);
    }
  }
  racks.rebuild();
}

/**
 * Reads what the snapshot leaves out: jobs that ended recently (the newest window of the
 * last hour that fits a few pages) and the latest alarms, active or cleared.
 */
async function loadHistory() {
  try {
    for (const minutes of [60, 10, 1]) {
      const from = new Date(Date.now() - minutes * 60000).toISOString();
      const found = [];
      let cursor = '';
      let pages = 0;
      do {
        const page = await api('GET', `/api/v1/jobs?limit=1000&created_from=${encodeURIComponent(from)}${cursor}`);
        found.push(...page.jobs);
        cursor = page.next_cursor ? `&cursor=${encodeURIComponent(page.next_cursor)}` : '';
        pages += 1;
      } while (cursor && pages < 3);
      if (!cursor || minutes === 1) {
        model.addJobs(found);
        break;
      }
    }
    const page = await api('GET', '/api/v1/alarms?limit=100');
    model.addAlarms(page.alarms);
  } catch (e) {
    if (e.status !== 401) notify(`Reading recent jobs and alarms: ${e.message}`);
  }
}

// The connection indicator.
const CONN_TEXT = {
  connecting: () => 'Connecting…',
  live: () => `Live · event ${model.seq === null ? '–' : model.seq}`,
  waiting: (s) => `Disconnected · retry in ${s} s`,
  key: () => 'API key needed',
};
let connState = 'connecting';
/** Until when the page was last live (its data is as of then), or null: never yet. */
let liveUntil = null;
function showConn(state, detail) {
  if (connState === 'live' && state !== 'live') liveUntil = new Date().toISOString();
  connState = state;
  $('conn').dataset.state = state;
  $('conn-text').textContent = CONN_TEXT[state](detail);
  const stale = state !== 'live';
  document.body.classList.toggle('stale', stale);
  const asOf = !stale ? '' : liveUntil ? `as of ${clock(liveUntil)}` : 'no data yet';
  $('as-of').textContent = asOf;
  devices.stale(asOf);
  // While a key offered by a link waits for the operator, that question comes first.
  if (state === 'key' && !tokenDialog.open) {
    askKey(getKey() ? 'The key was not accepted. Enter another one.' : undefined);
  }
}
model.subscribe(() => {
  if (connState === 'live') $('conn-text').textContent = CONN_TEXT.live();
});

const live = new Live(model, showConn);

// The key dialog: opened by the button, by a 401 from the API, or by a refused WebSocket.
const dialog = $('key-dialog');
function askKey(message) {
  $('key-message').textContent =
    message ||
    'This rackd needs an API key. A viewer key shows the store; an operator key also cancels jobs and pauses devices.';
  $('key-input').value = '';
  // Escape closes without setting a return value: forget the last one.
  dialog.returnValue = '';
  if (!dialog.open) dialog.showModal();
  $('key-input').focus();
}
function showKeyState() {
  $('key-button').textContent = getKey() ? 'API key ✓' : 'API key';
}
$('key-button').addEventListener('click', () => askKey('Enter the API key for this rackd (kept in this browser).'));
dialog.addEventListener('close', () => {
  if (dialog.returnValue === 'save' && $('key-input').value.trim()) {
    setKey($('key-input').value);
    live.restart();
    askServer();
  } else if (dialog.returnValue === 'forget') {
    setKey('');
    live.restart();
    askServer();
  }
  showKeyState();
});
onUnauthorized(() => {
  if (!dialog.open && !tokenDialog.open) askKey(getKey() ? 'The key was not accepted. Enter another one.' : undefined);
});

// A key offered by a link (`/?token=KEY`): the operator sees whose it is and decides.
// Until then the page goes on with the key it had, if any; ignored, the offer is gone.
const tokenDialog = $('token-dialog');
async function offerKey(candidate) {
  $('token-who').textContent = 'Checking the key with rackd…';
  $('token-use').disabled = false;
  tokenDialog.returnValue = '';
  tokenDialog.showModal();
  const owner = await whoIs(candidate);
  if (owner && owner.role) {
    $('token-who').textContent = `It is the key “${owner.name}” (${owner.role}).`;
  } else if (owner && owner.status === 401) {
    $('token-who').textContent = 'rackd does not know this key: it would not work.';
    $('token-use').disabled = true;
  } else {
    $('token-who').textContent = 'rackd could not say whose key it is.';
  }
  tokenDialog.addEventListener(
    'close',
    () => {
      if (tokenDialog.returnValue === 'use') {
        setKey(candidate);
        live.restart();
        askServer();
      } else {
        notify('The key in the link was not used.');
        if (connState === 'key') askKey();
      }
      showKeyState();
    },
    { once: true },
  );
}

let ticks = 0;
$('clock').textContent = clock(new Date().toISOString());
setInterval(() => {
  $('clock').textContent = clock(new Date().toISOString());
  devices.tick();
  webhooks.tick();
  // Lateness grows without events: the late badges and the late counter follow the clock.
  tickLate(document.body);
  counters.render();
  // Failed jobs leave the attention list and the counter an hour after they failed.
  ticks += 1;
  if (ticks % 10 === 0) mark('jobs');
}, 1000);

showKeyState();
live.restart();
if (offered) offerKey(offered);

// For the browser console (and the browser tests): the state, the connection, the role,
// the webhook subscriptions.
window.rackd = { model, live, who, webhooks };
