// The node the page talks to, when it is one of a hot-standby cluster: its name and role
// (`active`: it drives the machines; `standby`: it serves the API and stands by), from
// `GET /api/v1/cluster`, read again every few seconds so a takeover shows. A rackd that is
// not in a cluster answers 404 and the badge stays hidden.

import { api } from './api.js';

export class ClusterBadge {
  constructor(element) {
    this.element = element;
    this.element.hidden = true;
  }

  /** Reads the cluster now, then every `every` ms (once started, only now). */
  start(every = 5000) {
    this.load();
    if (!this.timer) this.timer = setInterval(() => this.load(), every);
  }

  async load() {
    let view;
    try {
      view = await api('GET', '/api/v1/cluster');
    } catch (e) {
      if (e.status === 404) this.element.hidden = true;
      return;
    }
    this.show(view);
  }

  show(view) {
    this.element.hidden = false;
    this.element.dataset.role = view.role;
    this.element.textContent = `node ${view.node} · ${view.role}`;
    const lease = view.lease;
    const holder = lease ? `lease: ${lease.holder}, epoch ${lease.epoch}, renewed ${lease.age_ms} ms ago` : 'no lease yet';
    const others = (view.nodes || []).filter((n) => n.name !== view.node);
    const standing = others.map((n) => `${n.name}: ${n.role} (seen ${Math.round(n.seen_ms_ago / 1000)} s ago)`);
    this.element.title = [holder, ...standing].join('\n');
  }
}
