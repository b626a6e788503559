// Which configuration the node runs: the first characters of the hash of its `[site]` and
// `[[devices]]` and when it was loaded (the start, or the last reload), from
// `GET /api/v1/config`; read again when a `config.reloaded` event comes. Two nodes of a
// cluster that show different hashes run different sites (the `config_drift` alarm).

import { api } from './api.js';

export class ConfigBadge {
  constructor(element) {
    this.element = element;
    this.element.hidden = true;
  }

  async load() {
    let loaded;
    try {
      loaded = await api('GET', '/api/v1/config');
    } catch {
      return;
    }
    this.show(loaded);
  }

  show(loaded) {
    this.element.hidden = false;
    const at = new Date(loaded.loaded_at);
    this.element.textContent = `config ${loaded.hash.slice(0, 8)} · ${at.toLocaleTimeString()}`;
    this.element.title = `configuration ${loaded.hash}\nloaded ${at.toLocaleString()}`;
  }
}
