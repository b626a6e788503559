// The buttons that change a job, shared by the job table and the attention list: Cancel on
// a job not yet ended, Retry on a failed one, each asking for a second click. They carry
// the class `op` (operators only; see roles.js). A row keeps its buttons while the job
// keeps its state, so an armed button survives the redraws of a busy store.

import { api } from './api.js';
import { confirmButton } from './dom.js';
import { TERMINAL } from './model.js';

/** Job buttons calling the API, putting answers into `model` and failures into `notify`. */
export class JobActions {
  constructor(model, notify) {
    this.model = model;
    this.notify = notify;
  }

  /** Keeps the buttons in `slot` (`{root, cancel, retry}`) right for `job`. */
  update(slot, job) {
    const cancellable = !TERMINAL.has(job.state) && job.state !== 'cancelling';
    if (cancellable && !slot.cancel) {
      slot.cancel = confirmButton('Cancel', 'Confirm cancel', 'cancel op', (b) => this.call(job.id, 'cancel', b));
      slot.root.append(slot.cancel);
    } else if (!cancellable && slot.cancel) {
      slot.cancel.remove();
      slot.cancel = null;
    }
    const retryable = job.state === 'failed';
    if (retryable && !slot.retry) {
      slot.retry = confirmButton('Retry', 'Confirm retry', 'retry op', (b) => this.call(job.id, 'retry', b));
      slot.root.append(slot.retry);
    } else if (!retryable && slot.retry) {
      slot.retry.remove();
      slot.retry = null;
    }
  }

  async call(id, what, button) {
    button.disabled = true;
    try {
      const job = await api('POST', `/api/v1/jobs/${id}/${what}`);
      if (job && job.id) this.model.addJobs([job]);
    } catch (e) {
      this.notify(`${what === 'cancel' ? 'Cancel' : 'Retry'} job ${id}: ${e.message}`);
    } finally {
      button.disabled = false;
    }
  }
}
