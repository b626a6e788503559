//! Jobs withheld from their devices while cancels decide on them.
//!
//! A cancel withholds the jobs it decides on before it asks their devices whether they hold
//! them ([`super::cancel`], [`super::bulk`]): from then on no device takes them, so a
//! device's "not held" stays true until the cancel is committed. When the cancel ends, it
//! lets them go and their devices are woken, since a job let go may be theirs to take.
//!
//! Decisions:
//! - **Each cancel holds its own.** Holds are counted per job: a job is offered to its
//!   device again, and the device woken, only when the last cancel that holds it lets go.
//!   Cancels of one job overlap in practice: a WMS that sends a slow cancel again after its
//!   own timeout, an operator's bulk cancel beside the WMS's cancel of one job. With a plain
//!   set of withheld jobs (before issue 50), the first of them to end let the job go for
//!   all: a bulk cancel refused, failed or dropped woke the device while another cancel was
//!   between its device's "not held" and its commit; an idle crane or shelf took the job and
//!   began the hand-over, and the commit then recorded `cancelled` a job the machine ran.
//! - **A hold is a guard ([`Withheld`]), let go when dropped**, however its cancel ends:
//!   answered, refused, failed, or dropped with its request (a client's timeout or
//!   disconnect drops the handler's future). So a cancel lets go exactly once, exactly
//!   what it took, and never leaves a job withheld for good (the single cancel let go by
//!   hand before, and a dropped one left its job withheld until it ended otherwise).
//! - **Kept by job id, apart from the queues.** A commit (the job dispatched, ended, or
//!   failed and retried) does not clear a hold, and neither does a reload that removes or
//!   adds the job's device: only the cancel that took it lets it go. A job retried while a
//!   cancel still decides on it waits for that cancel. The map holds an entry per job that
//!   some cancel decides on right now, so it is as small as the cancels in flight.

use std::collections::HashMap;
use std::sync::MutexGuard;

use super::queues::Queues;

impl Queues {
    /// Withholds each `(device, job)` from its device until the returned guard is dropped
    /// (see the module doc); other cancels' holds of the same jobs are counted apart.
    #[must_use = "the jobs are let go when the guard is dropped"]
    pub fn withhold(&self, jobs: Vec<(String, i64)>) -> Withheld {
        let mut withheld = self.withheld();
        for (_, id) in &jobs {
            *withheld.entry(*id).or_default() += 1;
        }
        Withheld { queues: self.clone(), jobs }
    }

    /// How many cancels hold each withheld job. Taken alone, or inside the queues' lock
    /// (a dispatch round), never around it.
    pub(super) fn withheld(&self) -> MutexGuard<'_, HashMap<i64, usize>> {
        self.0.withheld.lock().unwrap_or_else(|p| p.into_inner())
    }
}

/// One cancel's hold on its jobs: each is let go when this is dropped, and its device woken
/// once no other cancel holds it.
pub struct Withheld {
    queues: Queues,
    jobs: Vec<(String, i64)>,
}

impl Drop for Withheld {
    fn drop(&mut self) {
        let mut free: Vec<&str> = Vec::new();
        {
            let mut withheld = self.queues.withheld();
            for (device, id) in &self.jobs {
                let Some(count) = withheld.get_mut(id) else { continue };
                *count -= 1;
                if *count == 0 {
                    withheld.remove(id);
                    if !free.contains(&device.as_str()) {
                        free.push(device);
                    }
                }
            }
        }
        for device in free {
            self.queues.wake(device);
        }
    }
}
