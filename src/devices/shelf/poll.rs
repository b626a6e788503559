//! Following tasks by polling their slots, and recovering after a restart.

use std::collections::HashMap;

use super::slot::{ExecState, SLOT_WORDS, SlotView, task_id_for};
use super::{Shelf, Slot};
use crate::devices::follow::Reported;
use crate::domain::{Failure, JobState};
use crate::protocols::PlcError;
use crate::store::jobs;

/// The failure a PLC failure kind stands for.
pub fn failure(kind: u16) -> Failure {
    let (class, text) = match kind {
        1 => ("device_fault", "PLC system fault (failure kind 1)".to_owned()),
        2 => (
            "rejected",
            "the PLC rejected the command: its data disagrees with rackd's (failure kind 2); check the location"
                .to_owned(),
        ),
        other => ("device_fault", format!("the PLC reported failure kind {other}")),
    };
    Failure { kind: class.into(), code: Some(kind as i64), text }
}

impl Shelf {
    /// Reads every slot that holds work (and those held by unknown work, to see them free
    /// up); with nothing to read, one word to keep track of the link.
    pub(super) async fn poll(&mut self) {
        let mut read_any = false;
        for k in 0..self.slots.len() {
            if !matches!(self.slots[k], Slot::Held { .. } | Slot::Foreign | Slot::Unknown) {
                continue;
            }
            let at = self.slot_address(k);
            let Ok(words) = self.read(&at, SLOT_WORDS as u16).await else { return };
            read_any = true;
            if let Err(e) = self.follow(k, &words).await {
                tracing::warn!(device = %self.config.id, slot = k + 1, error = %e, "following a slot failed");
            }
        }
        if !read_any {
            let _ = self.read(&self.base.clone(), 1).await;
        }
    }

    /// Brings rackd's record of slot `k` in line with what the PLC shows.
    async fn follow(&mut self, k: usize, words: &[u16]) -> Result<(), super::handover::DispatchError> {
        let view = SlotView::parse(words).ok_or(PlcError::Malformed("short slot read"))?;
        let Slot::Held { job: id, task, confirmed } = self.slots[k] else {
            self.slots[k] = if view.is_free() { Slot::Free } else { Slot::Foreign };
            return Ok(());
        };
        let store = |e: sqlx::Error| super::handover::DispatchError::Store(e.to_string());
        let Some(job) = jobs::get(&self.pool, id).await.map_err(store)? else {
            self.slots[k] = Slot::Foreign;
            return Ok(());
        };
        let slot_no = k + 1;
        if view.task_id != task {
            self.slots[k] = if view.is_free() { Slot::Free } else { Slot::Foreign };
            if !confirmed && view.task_id == 0 {
                return Ok(()); // the id write never arrived: the job is still queued
            }
            let text = format!("slot {slot_no} no longer holds task {task} (it holds {})", view.task_id);
            let lost = Failure { kind: "lost".into(), code: None, text: text.clone() };
            return self.record(&job, Reported::Failed(lost), &text).await;
        }
        self.slots[k] = Slot::Held { job: id, task, confirmed: true };
        match view.state {
            ExecState::NotStarted => {
                self.record(&job, Reported::Taken, &format!("found in slot {slot_no}")).await
            }
            ExecState::Running => self.record(&job, Reported::Running, "the PLC runs it").await,
            ExecState::Finished => {
                self.record(&job, Reported::Finished { forced: false }, "the PLC finished it").await?;
                self.release(k, self.config.clear_finished).await
            }
            ExecState::Failed => {
                let f = failure(view.failure_kind);
                let cause = format!("the PLC failed it: {}", f.text);
                self.record(&job, Reported::Failed(f), &cause).await?;
                self.release(k, true).await
            }
            ExecState::Unknown(v) => {
                self.update_status(|s| {
                    s.last_error = Some(format!("slot {slot_no}: unknown execution state {v}"))
                });
                Ok(())
            }
        }
    }

    /// Frees slot `k` after its task was recorded, clearing its task id when `clear`.
    async fn release(&mut self, k: usize, clear: bool) -> Result<(), super::handover::DispatchError> {
        if clear {
            self.write(&self.slot_address(k), &[0]).await?;
        }
        self.slots[k] = Slot::Free;
        Ok(())
    }

    /// On start: reads every slot and reconciles it with the stored jobs, so work finished
    /// while rackd was down is recorded, running work is followed, nothing is handed over
    /// twice and a job whose task vanished is failed as `lost`.
    pub(super) async fn recover(&mut self) -> Result<(), super::handover::DispatchError> {
        let store = |e: sqlx::Error| super::handover::DispatchError::Store(e.to_string());
        let unfinished = jobs::unfinished(&self.pool, &self.config.id).await.map_err(store)?;
        let by_task: HashMap<u16, i64> = unfinished.iter().map(|j| (task_id_for(j.id), j.id)).collect();
        let mut reads = Vec::with_capacity(self.slots.len());
        for k in 0..self.slots.len() {
            reads.push(self.read(&self.slot_address(k), SLOT_WORDS as u16).await?);
        }
        for (k, words) in reads.iter().enumerate() {
            let view = SlotView::parse(words).ok_or(PlcError::Malformed("short slot read"))?;
            match by_task.get(&view.task_id) {
                _ if view.task_id == 0 => self.slots[k] = Slot::Free,
                Some(&job) => {
                    self.slots[k] = Slot::Held { job, task: view.task_id, confirmed: false };
                    self.follow(k, words).await?;
                }
                None if view.state == ExecState::Finished => {
                    self.release(k, self.config.clear_finished).await?
                }
                None if view.state == ExecState::Failed => self.release(k, true).await?,
                None => {
                    tracing::warn!(device = %self.config.id, slot = k + 1, task = view.task_id, "slot holds unknown work");
                    self.slots[k] = Slot::Foreign;
                }
            }
        }
        for job in unfinished.iter().filter(|j| j.state != JobState::Queued) {
            let held = self.slots.iter().any(|s| matches!(s, Slot::Held { job: id, .. } if *id == job.id));
            if !held {
                let text = format!("after a restart no slot holds task {}", task_id_for(job.id));
                let lost = Failure { kind: "lost".into(), code: None, text: text.clone() };
                self.record(job, Reported::Failed(lost), &text).await?;
            }
        }
        tracing::info!(device = %self.config.id, slots = self.slots.len(), "recovered");
        Ok(())
    }
}
