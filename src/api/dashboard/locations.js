// A location's dialog, opened by clicking its box position in the racks: what rackd knows
// of it (box, reservation, lights, lock) and, for operators, Lock (with the reason the API
// requires) or Unlock once a person has checked it, each asking for a second click. The
// answer of the API updates the racks at once; the `location.updated` event follows.

import { api } from './api.js';
import { confirmButton, el, locName, setText } from './dom.js';

export class LocationDialog {
  constructor(dialog, model, notify) {
    this.dialog = dialog;
    this.model = model;
    this.notify = notify;
    this.title = dialog.querySelector('#location-title');
    this.facts = dialog.querySelector('#location-facts');
    this.lockForm = dialog.querySelector('#location-lock');
    this.reason = dialog.querySelector('#location-reason');
    this.actions = dialog.querySelector('#location-actions');
    this.current = null;
    model.subscribe((kind, item) => {
      if (kind === 'location' && this.dialog.open && this.current && samePlace(item, this.current)) this.fill(item);
    });
  }

  /** Opens the dialog on location `l`. */
  open(l) {
    this.reason.value = '';
    this.fill(l);
    if (!this.dialog.open) this.dialog.showModal();
  }

  fill(l) {
    this.current = l;
    setText(this.title, `Location ${locName(l)}`);
    const facts = [l.occupied ? `Box ${l.barcode || '(no barcode)'}` : 'Empty'];
    if (l.reserved_by) facts.push(`Reserved by job ${l.reserved_by}`);
    if (l.red) facts.push('Red light on');
    if (l.green) facts.push('Green light on');
    if (l.lock) facts.push(`Locked by ${l.lock.by}${l.lock.reason ? `: ${l.lock.reason}` : ''}`);
    this.facts.replaceChildren(...facts.map((f) => el('p', { text: f })));
    this.lockForm.hidden = Boolean(l.lock);
    const path = `/api/v1/locations/${l.aisle}/${l.row}/${l.bay}/${l.level}/${l.position}`;
    const button = l.lock
      ? confirmButton('Unlock', 'Confirm unlock: checked', 'unlock op', (b) => this.call(`${path}/unlock`, undefined, b))
      : confirmButton('Lock', 'Confirm lock', 'lock op', (b) => {
        const reason = this.reason.value.trim();
        if (!reason) {
          this.notify('A lock needs a reason.');
          this.reason.focus();
          return;
        }
        this.call(`${path}/lock`, { reason }, b);
      });
    const close = el('button', { type: 'submit', value: 'close', text: 'Close' });
    this.actions.replaceChildren(button, close);
  }

  async call(path, body, button) {
    button.disabled = true;
    try {
      const state = await api('POST', path, body);
      if (state) this.model.applyLocation(state);
    } catch (e) {
      this.notify(`${path.endsWith('unlock') ? 'Unlock' : 'Lock'} ${locName(this.current)}: ${e.message}`);
    } finally {
      button.disabled = false;
    }
  }
}

function samePlace(a, b) {
  return a.aisle === b.aisle && a.row === b.row && a.bay === b.bay && a.level === b.level && a.position === b.position;
}
