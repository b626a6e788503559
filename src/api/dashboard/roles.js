// Who the page's key belongs to and what it may do, so the page shows only the buttons the
// key may use. `GET /api/v1/whoami` says it; a rackd without that endpoint (404) is asked
// with a harmless probe instead: cancelling job 0, which never exists, answers 403 to a
// viewer (the role is checked before the job is looked up) and 404 to an operator.
//
// Until the role is known the page shows no buttons: a viewer never sees one flash by.
// Action buttons carry the class `op`; the stylesheet hides them unless the body's
// `data-role` is `operator` or `admin`. The few that are an administrator's alone (a
// webhook's Pause, Resume and Replay) carry `admin-op`, hidden unless it is `admin`.

import { api } from './api.js';

/** The roles, weakest first. */
export const ROLES = ['viewer', 'operator', 'admin'];

export class Who {
  constructor(onChange) {
    this.onChange = onChange;
    /** The key's name, when rackd says it. */
    this.name = null;
    /** `viewer`, `operator`, `admin`, or null while unknown. */
    this.role = null;
  }

  /** The key's role covers `role`. */
  can(role) {
    return this.role !== null && ROLES.indexOf(this.role) >= ROLES.indexOf(role);
  }

  set(name, role) {
    this.name = name;
    this.role = ROLES.includes(role) ? role : null;
    document.body.dataset.role = this.role || 'none';
    this.onChange(this);
  }

  /** Asks rackd (again, e.g. after a new key). */
  async load() {
    this.set(null, null);
    try {
      const me = await api('GET', '/api/v1/whoami');
      this.set(me.name || null, me.role);
      return;
    } catch (e) {
      if (e.status !== 404) return;
    }
    try {
      await api('POST', '/api/v1/jobs/0/cancel');
      this.set(null, 'operator');
    } catch (e) {
      if (e.status === 403) this.set(null, 'viewer');
      else if (e.status === 404 || e.status === 409) this.set(null, 'operator');
    }
  }
}
