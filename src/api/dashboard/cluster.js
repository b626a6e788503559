// The node the page talks to, when it is one of a hot-standby cluster: its name and role
// (`active`: it drives the machines; `standby`: it serves the API and stands by), from
// `GET /api/v1/cluster`, read again every few seconds so a takeover shows, and whether the
// nodes run different configurations (`config_drift`). A rackd that is not in a cluster
// answers 404 and the badge stays hidden.

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
    this.element.dataset.drift = view.config_drift ? 'yes' : 'no';
    const drift = view.config_drift ? ' · config differs' : '';
    this.element.textContent = `node ${view.node} · ${view.role}${drift}`;
    const lease = view.lease;
    const holder = lease ? `lease: ${lease.holder}, epoch ${lease.epoch}, renewed ${lease.age_ms} ms ago` : 'no lease yet';
    const others = (view.nodes || []).filter((n) => n.name !== view.node);
    const config = (hash) => (hash ? `config ${hash.slice(0, 8)}` : 'config not told');
    const standing = others.map(
      (n) => `${n.name}: ${n.role} (seen ${Math.round(n.seen_ms_ago / 1000)} s ago, ${config(n.config_hash)})`,
    );
    this.element.title = [holder, ...standing].join('\n');
  }
}
