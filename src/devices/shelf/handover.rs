//! Handing jobs to free slots, and withdrawing them again.

use std::collections::HashSet;

use futures::future::join_all;

use super::slot::{self, ExecState, SLOT_WORDS, SlotView, task_id_for};
use super::{Shelf, Slot};
use crate::devices::follow::{Reported, advance};
use crate::domain::{Failure, JobState};
use crate::protocols::PlcError;
use crate::service::dispatch::next_jobs;
use crate::store::writer::Change;
use crate::store::{Job, jobs};

/// Why a dispatch round stopped early.
#[derive(Debug, thiserror::Error)]
pub enum DispatchError {
    /// The PLC did not answer or refused.
    #[error(transparent)]
    Plc(#[from] PlcError),
    /// The database or writer failed.
    #[error("storage: {0}")]
    Store(String),
}

impl Shelf {
    /// Fills free slots with the best eligible queued jobs.
    pub(super) async fn dispatch(&mut self) -> Result<(), DispatchError> {
        let window = jobs::dispatch_window(&self.pool, &self.config.id, self.config.dispatch_window)
            .await
            .map_err(|e| DispatchError::Store(e.to_string()))?;
        let held: HashSet<i64> = self
            .slots
            .iter()
            .filter_map(|s| match s {
                Slot::Held { job, .. } => Some(*job),
                _ => None,
            })
            .collect();
        let free: Vec<usize> = (0..self.slots.len()).filter(|&k| self.slots[k] == Slot::Free).collect();
        let candidates: Vec<_> = next_jobs(&window, usize::MAX)
            .into_iter()
            .filter(|j| !held.contains(&j.id))
            .take(free.len())
            .collect();
        let mut taken = Vec::new();
        let mut failed = None;
        for (k, job) in free.into_iter().zip(candidates) {
            match self.hand_over(k, job).await {
                Ok(Some(report)) => taken.push(report),
                Ok(None) => {}
                Err(e) => {
                    failed = Some(e);
                    break;
                }
            }
        }
        // Recorded together, so one commit covers the whole round.
        let writer = &self.writer;
        for result in
            join_all(taken.iter().map(|(job, to, cause)| advance(writer, job, to.clone(), cause))).await
        {
            result.map_err(|e| DispatchError::Store(e.to_string()))?;
        }
        failed.map_or(Ok(()), Err)
    }

    /// Writes `job` into slot `k` in the safe order (see the module doc); returns what to
    /// record for it.
    async fn hand_over(
        &mut self,
        k: usize,
        job: &Job,
    ) -> Result<Option<(Job, Reported, String)>, DispatchError> {
        let Some(spec) = job.spec() else { return Ok(None) };
        let body = match slot::encode_body(&spec, job.priority, job.barcode.as_deref()) {
            Ok(body) => body,
            Err(why) => {
                let failure = Failure { kind: "unsupported".into(), code: None, text: why.into() };
                let cause = "the shelf PLC cannot run this job".to_owned();
                return Ok(Some((job.clone(), Reported::Failed(failure), cause)));
            }
        };
        let task = task_id_for(job.id);
        let at = self.slot_address(k);
        let words = self.read(&at, SLOT_WORDS as u16).await?;
        let view = SlotView::parse(&words).ok_or(PlcError::Malformed("short slot read"))?;
        if !view.is_free() {
            tracing::warn!(device = %self.config.id, slot = k + 1, task = view.task_id, "slot busy with unknown work");
            self.slots[k] = Slot::Foreign;
            return Ok(None);
        }
        if view.task_id != 0 {
            self.write(&at, &[0]).await?;
        }
        self.write(&self.plc.word_address(&at, 1), &body).await?;
        // From here the PLC may hold the task: the slot is ours until a read says otherwise.
        self.slots[k] = Slot::Held { job: job.id, task, confirmed: false };
        self.write(&at, &[task]).await?;
        self.slots[k] = Slot::Held { job: job.id, task, confirmed: true };
        Ok(Some((job.clone(), Reported::Taken, format!("handed to slot {} as task {task}", k + 1))))
    }

    /// Records a device report for a job.
    pub(super) async fn record(&self, job: &Job, to: Reported, cause: &str) -> Result<(), DispatchError> {
        advance(&self.writer, job, to, cause)
            .await
            .map(|_| ())
            .map_err(|e| DispatchError::Store(e.to_string()))
    }

    /// Cancels a job of this device: at once while queued; a task in a slot only if the
    /// PLC has not started it and withdrawing is allowed.
    pub(super) async fn cancel(&mut self, id: i64) -> Result<(), String> {
        let job = jobs::get(&self.pool, id).await.map_err(|e| e.to_string())?.ok_or("no such job")?;
        let slot = self.slots.iter().position(|s| matches!(s, Slot::Held { job, .. } if *job == id));
        if job.state.is_terminal() {
            return Err(format!("job {id} is already {}", job.state));
        }
        let Some(k) = slot else {
            if job.state != JobState::Queued {
                return Err(format!("job {id} is {} but no slot holds it", job.state));
            }
            let change = Change::cancel_queued();
            return self.writer.change(id, change).await.map(|_| ()).map_err(|e| e.to_string());
        };
        if !self.config.withdraw {
            return Err(format!(
                "job {id} is in slot {} and withdrawing tasks is disabled for this device",
                k + 1
            ));
        }
        let Slot::Held { task, .. } = self.slots[k] else { return Err("slot state changed".into()) };
        let at = self.slot_address(k);
        let view = self.read(&at, SLOT_WORDS as u16).await.map_err(|e| e.to_string())?;
        let view = SlotView::parse(&view).ok_or("short slot read")?;
        match view.state {
            _ if view.task_id != task => return Err(format!("slot {} no longer holds task {task}", k + 1)),
            ExecState::NotStarted => {}
            ExecState::Running => {
                return Err(format!("the PLC is running job {id}; a shelf PLC cannot stop a running task"));
            }
            _ => {
                return Err(format!(
                    "job {id} has already ended on the PLC; it is recorded at the next poll"
                ));
            }
        }
        self.write(&at, &[0]).await.map_err(|e| format!("clearing slot {}: {e}", k + 1))?;
        let back = self.read(&at, SLOT_WORDS as u16).await.map_err(|e| e.to_string())?;
        let back = SlotView::parse(&back).ok_or("short slot read")?;
        if back.task_id != 0 || back.state != ExecState::NotStarted {
            return Err(format!("the PLC took job {id} while it was being withdrawn"));
        }
        self.slots[k] = Slot::Free;
        let cause = format!("withdrawn from slot {} before it started (cancelled through the API)", k + 1);
        self.record(&job, Reported::Cancelled, &cause).await.map_err(|e| e.to_string())
    }
}
