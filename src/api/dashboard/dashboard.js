// rackd's operator dashboard: wires the live connection, the model and the parts of the
// page. Everything on the page comes from the server: the WebSocket snapshot and events,
// plus recent finished jobs and past alarms read over HTTP (the snapshot holds only what is
// active).

import { adoptTokenFromUrl, api, getKey, onUnauthorized, setKey } from './dashboard/api.js';
import { Alarms } from './dashboard/alarms.js';
import { Devices } from './dashboard/devices.js';
import { clock, el, throttle } from './dashboard/dom.js';
import { Jobs } from './dashboard/jobs.js';
import { Live } from './dashboard/live.js';
import { Model } from './dashboard/model.js';
import { Racks } from './dashboard/racks.js';

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

adoptTokenFromUrl();
const model = new Model();
const racks = new Racks($('racks'), model);
const devices = new Devices($('devices'), model, notify);
const jobs = new Jobs($('jobs'), model, notify);
const alarms = new Alarms($('alarms'), model);

// What changed since the last frame; drawn once per animation frame.
const dirty = { jobs: false, devices: false, alarms: false, cranes: false };
const render = throttle(() => {
  if (dirty.jobs) jobs.render();
  if (dirty.devices) devices.render();
  if (dirty.alarms) alarms.render();
  if (dirty.cranes) racks.devices();
  Object.keys(dirty).forEach((k) => {
    dirty[k] = false;
  });
});
const mark = (...parts) => {
  for (const p of parts) dirty[p] = true;
  render();
};

model.subscribe((kind, item) => {
  switch (kind) {
    case 'snapshot':
      racks.rebuild();
      mark('jobs', 'devices', 'alarms', 'cranes');
      loadHistory();
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
    default:
      break;
  }
});

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
function showConn(state, detail) {
  connState = state;
  $('conn').dataset.state = state;
  $('conn-text').textContent = CONN_TEXT[state](detail);
  document.body.classList.toggle('stale', state !== 'live');
  if (state === 'key') askKey(getKey() ? 'The key was not accepted. Enter another one.' : undefined);
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
  } else if (dialog.returnValue === 'forget') {
    setKey('');
    live.restart();
  }
  showKeyState();
});
onUnauthorized(() => {
  if (!dialog.open) askKey(getKey() ? 'The key was not accepted. Enter another one.' : undefined);
});

setInterval(() => {
  $('clock').textContent = clock(new Date().toISOString());
  devices.tick();
}, 1000);

showKeyState();
live.restart();

// For the browser console (and the browser test): the state and the connection.
window.rackd = { model, live };
