//! Handing jobs to free slots, and withdrawing them again.

use std::collections::HashSet;

use tracing::Instrument;

use super::{Shelf, Slot};
use crate::devices::cancel::{CancelRefusal, Withdrawal};
use crate::devices::port::ReportError;
use crate::domain::{Failure, FailureKind, Job, Report, Reported};
use crate::protocols::PlcError;
use crate::wire::slot::{self, ExecState, SLOT_WORDS, SlotView};
use crate::wire::task_id_for;

/// Why a dispatch round stopped early.
#[derive(Debug, thiserror::Error)]
pub enum DispatchError {
    /// The PLC did not answer or refused.
    #[error(transparent)]
    Plc(#[from] PlcError),
    /// The dispatcher could not record a report.
    #[error(transparent)]
    Report(#[from] ReportError),
}

impl Shelf {
    /// Fills free slots with the best eligible queued jobs.
    pub(super) async fn dispatch(&mut self) -> Result<(), DispatchError> {
        let held: HashSet<i64> = self
            .slots
            .iter()
            .filter_map(|s| match s {
                Slot::Held { job, .. } => Some(*job),
                _ => None,
            })
            .collect();
        let free: Vec<usize> = (0..self.slots.len()).filter(|&k| self.slots[k] == Slot::Free).collect();
        let candidates = self.port.next(free.len(), &held);
        let mut taken = Vec::new();
        let mut failed = None;
        for (k, job) in free.into_iter().zip(&candidates) {
            match self.hand_over(k, job).instrument(tracing::info_span!("job", job = job.id)).await {
                Ok(Some(report)) => taken.push(report),
                Ok(None) => {}
                Err(e) => {
                    failed = Some(e);
                    break;
                }
            }
        }
        if !taken.is_empty() && self.status.get().memory_lost_at.is_some() {
            tracing::info!("the PLC takes work again after losing its memory");
            self.status.update(|s| s.memory_lost_at = None);
        }
        // Recorded together, so one commit covers the whole round.
        self.port.report(taken).await?;
        failed.map_or(Ok(()), |e| Err(e.into()))
    }

    /// Writes `job` into slot `k` (see [`Shelf::write_slot`]), its frames marked in the
    /// link's flight recorder as serving the job and its task.
    async fn hand_over(&mut self, k: usize, job: &Job) -> Result<Option<Report>, PlcError> {
        self.plc.serving(Some((job.id, task_id_for(job.id))));
        let result = self.write_slot(k, job).await;
        self.plc.serving(None);
        result
    }

    /// Writes `job` into slot `k` in the safe order (see the module doc); returns what to
    /// record for it.
    async fn write_slot(&mut self, k: usize, job: &Job) -> Result<Option<Report>, PlcError> {
        let Some(spec) = job.spec() else { return Ok(None) };
        let body = match slot::encode_body(&spec, job.priority, job.barcode.as_deref()) {
            Ok(body) => body,
            Err(why) => {
                let failure = Failure { kind: FailureKind::Unsupported, code: None, text: why.into() };
                let cause = "the shelf PLC cannot run this job";
                return Ok(Some(Report::new(job.id, Reported::Failed(failure), cause)));
            }
        };
        let task = task_id_for(job.id);
        let at = self.slot_address(k);
        let words = self.read(&at, SLOT_WORDS as u16).await?;
        let view = SlotView::parse(&words).ok_or(PlcError::Malformed("short slot read"))?;
        if !view.is_free() {
            tracing::warn!(slot = k + 1, task = view.task_id, "slot busy with unknown work");
            self.slots[k] = Slot::Foreign;
            return Ok(None);
        }
        if view.task_id != 0 {
            self.write(&at, &[0]).await?;
        }
        let body_at = self.plc.word_address(&at, 1);
        self.write(&body_at, &body).await?;
        // From here the PLC may hold the task: the slot is ours until a read says otherwise.
        self.slots[k] = Slot::Held { job: job.id, task, confirmed: false };
        self.write(&at, &[task]).await?;
        self.slots[k] = Slot::Held { job: job.id, task, confirmed: true };
        let cause = format!("handed to slot {} as task {task}", k + 1);
        Ok(Some(Report::new(job.id, Reported::Taken, cause)))
    }

    /// Cancels a job this device holds in a slot, if the PLC has not started it and
    /// withdrawing is allowed; a job in no slot is not held (the dispatcher cancels it).
    pub(super) async fn cancel(&mut self, id: i64) -> Result<Withdrawal, CancelRefusal> {
        let slot = self.slots.iter().position(|s| matches!(s, Slot::Held { job, .. } if *job == id));
        let Some(k) = slot else { return Ok(Withdrawal::NotHeld) };
        if !self.config.withdraw {
            return Err(CancelRefusal::WithdrawOff { slot: k + 1 });
        }
        let Slot::Held { task, .. } = self.slots[k] else { return Ok(Withdrawal::NotHeld) };
        let at = self.slot_address(k);
        let words = self.read(&at, SLOT_WORDS as u16).await?;
        let view = SlotView::parse(&words).ok_or(PlcError::Malformed("short slot read"))?;
        match view.state {
            _ if view.task_id != task => return Err(CancelRefusal::Gone { slot: k + 1, task }),
            ExecState::NotStarted => {}
            ExecState::Running => return Err(CancelRefusal::Running),
            _ => return Err(CancelRefusal::Ended),
        }
        self.write(&at, &[0]).await?;
        let back = self.read(&at, SLOT_WORDS as u16).await?;
        let back = SlotView::parse(&back).ok_or(PlcError::Malformed("short slot read"))?;
        if back.task_id != 0 || back.state != ExecState::NotStarted {
            return Err(CancelRefusal::TakenMeanwhile);
        }
        self.slots[k] = Slot::Free;
        let cause = format!("withdrawn from slot {} before it started (cancelled through the API)", k + 1);
        self.port.report(vec![Report::new(id, Reported::Cancelled, cause)]).await?;
        Ok(Withdrawal::Done)
    }
}
