//! Following tasks by polling their slots, and recovering after a restart.
//!
//! A poll cycle reads every slot that matters, decides what each shows, and then records
//! all the reports at once: they reach the job writer together and share one commit, so a
//! cycle that sees sixty tasks finish costs one fsync, not sixty.
//!
//! The slots are read one request each, so a PLC that power-cycles during a cycle can show
//! its first slots as they were and the rest empty. A cycle that sees one of rackd's tasks
//! gone therefore reads every slot once more before it decides (this costs a second round
//! only when a task vanished, which is rare), and a lost memory stays one decision.

use std::collections::{HashMap, HashSet};

use super::handover::DispatchError;
use super::{Shelf, Slot};
use crate::domain::{Failure, FailureKind, Job, JobState, Report, Reported};
use crate::protocols::PlcError;
use crate::wire::slot::{ExecState, SLOT_WORDS, SlotView};
use crate::wire::task_id_for;

/// How many of rackd's tasks must vanish together to call it a lost memory: with one,
/// a task gone missing and a power cycle look the same (and end the same way, but for the
/// alarm).
pub const MEMORY_LOSS_SLOTS: usize = 2;

/// What rackd says of a PLC that lost its task memory.
pub const MEMORY_LOST: &str = "the PLC lost its task memory (power cycle?)";

/// The failure a PLC failure kind stands for.
pub fn failure(kind: u16) -> Failure {
    let (class, text) = match kind {
        1 => (FailureKind::DeviceFault, "PLC system fault (failure kind 1)".to_owned()),
        2 => (
            FailureKind::Rejected,
            "the PLC rejected the command: its data disagrees with rackd's (failure kind 2); check the location"
                .to_owned(),
        ),
        other => (FailureKind::DeviceFault, format!("the PLC reported failure kind {other}")),
    };
    Failure { kind: class, code: Some(kind as i64), text }
}

/// What a slot showed: a job report to record (if the job moved), and whether the slot is
/// free afterwards (`Some(clear)`: whether to set its task id to 0).
struct Seen {
    slot: usize,
    record: Option<Report>,
    release: Option<bool>,
}

impl Shelf {
    /// Reads every slot that holds work (and those held by unknown work, to see them free
    /// up); with nothing to read, one word to keep track of the link.
    pub(super) async fn poll(&mut self) {
        let watched: Vec<usize> = (0..self.slots.len())
            .filter(|&k| matches!(self.slots[k], Slot::Held { .. } | Slot::Foreign | Slot::Unknown))
            .collect();
        if watched.is_empty() {
            match self.read(&self.base.clone(), 1).await {
                Ok(_) => self.repeats.recovered(),
                Err(e) => self.repeats.failed("polling failed", &e),
            }
            return;
        }
        let mut reads = Vec::with_capacity(watched.len());
        let mut link = Ok(());
        for k in watched {
            match self.read(&self.slot_address(k), SLOT_WORDS as u16).await {
                Ok(words) => reads.push((k, words)),
                Err(e) => {
                    link = Err(e);
                    break; // the link is down: the rest would fail too
                }
            }
        }
        // A power cycle between two of this round's reads shows some of rackd's tasks gone
        // and the others not yet: read them all once more before deciding, so that a lost
        // memory is one decision (and one alarm), not a task lost here and there.
        if link.is_ok() && self.vanished(&reads) {
            let mut again = Vec::with_capacity(reads.len());
            for (k, _) in &reads {
                match self.read(&self.slot_address(*k), SLOT_WORDS as u16).await {
                    Ok(words) => again.push((*k, words)),
                    Err(e) => {
                        link = Err(e);
                        break;
                    }
                }
            }
            if link.is_ok() {
                reads = again;
            }
        }
        match (self.settle(reads).await, link) {
            (Err(e), _) => self.repeats.failed("following the slots failed", &e),
            (Ok(()), Err(e)) => self.repeats.failed("polling failed", &e),
            (Ok(()), Ok(())) => self.repeats.recovered(),
        }
    }

    /// Brings rackd's records in line with what the slots show, recording all reports
    /// together.
    async fn settle(&mut self, reads: Vec<(usize, Vec<u16>)>) -> Result<(), DispatchError> {
        let unfinished: HashMap<i64, Job> = self.port.unfinished().into_iter().map(|j| (j.id, j)).collect();
        if self.forgot(&reads) {
            return self.memory_lost(&unfinished).await;
        }
        let mut seen = Vec::new();
        for (k, words) in reads {
            let view = SlotView::parse(&words).ok_or(PlcError::Malformed("short slot read"))?;
            if let Some(s) = self.assess(k, view, &unfinished) {
                seen.push(s);
            }
        }
        let reports = seen.iter_mut().filter_map(|s| s.record.take()).collect();
        self.port.report(reports).await?;
        for report in &seen {
            if let Some(clear) = report.release {
                if clear {
                    self.write(&self.slot_address(report.slot), &[0]).await?;
                }
                self.slots[report.slot] = Slot::Free;
            }
        }
        Ok(())
    }

    /// Whether these reads show a task rackd saw in its slot gone from it.
    fn vanished(&self, reads: &[(usize, Vec<u16>)]) -> bool {
        reads.iter().any(|(k, words)| match self.slots[*k] {
            Slot::Held { task, confirmed: true, .. } => {
                SlotView::parse(words).is_some_and(|v| v.task_id != task)
            }
            _ => false,
        })
    }

    /// Whether these reads show every slot rackd had a task in empty, and at least
    /// [`MEMORY_LOSS_SLOTS`] of them: the PLC lost its memory (a power cycle), rather than
    /// one task gone missing.
    fn forgot(&self, reads: &[(usize, Vec<u16>)]) -> bool {
        let held: Vec<usize> =
            (0..self.slots.len()).filter(|&k| matches!(self.slots[k], Slot::Held { .. })).collect();
        let empty = |k: usize| {
            reads.iter().any(|(r, words)| *r == k && SlotView::parse(words).is_some_and(|v| v.task_id == 0))
        };
        held.len() >= MEMORY_LOSS_SLOTS && held.iter().all(|&k| empty(k))
    }

    /// One decision for every task the PLC forgot: each job fails as `lost` with the same
    /// words (which locks its locations for a person to check), its slot is free, and the
    /// device status says so (one `memory_lost` alarm) until the PLC takes new work.
    async fn memory_lost(&mut self, unfinished: &HashMap<i64, Job>) -> Result<(), DispatchError> {
        let mut reports = Vec::new();
        for k in 0..self.slots.len() {
            let Slot::Held { job, task, .. } = self.slots[k] else { continue };
            self.slots[k] = Slot::Free;
            if unfinished.contains_key(&job) {
                let text =
                    format!("{MEMORY_LOST}: slot {} no longer holds task {task}; check the location", k + 1);
                let lost = Failure { kind: FailureKind::Lost, code: None, text: text.clone() };
                reports.push(Report::new(job, Reported::Failed(lost), text));
            }
        }
        tracing::error!(tasks = reports.len(), "{MEMORY_LOST}");
        self.status
            .update(|s| s.memory_lost_at = Some(crate::domain::time::from_ms(crate::domain::time::now_ms())));
        self.port.report(reports).await?;
        Ok(())
    }

    /// What slot `k` shows, updating rackd's idea of the slot; a report when a job moved.
    fn assess(&mut self, k: usize, view: SlotView, unfinished: &HashMap<i64, Job>) -> Option<Seen> {
        let Slot::Held { job: id, task, confirmed } = self.slots[k] else {
            self.slots[k] = if view.is_free() { Slot::Free } else { Slot::Foreign };
            return None;
        };
        let slot_no = k + 1;
        let Some(job) = unfinished.get(&id).cloned() else {
            // Already recorded as ended, in a cycle whose release did not get through.
            if view.task_id == task {
                return Some(Seen { slot: k, record: None, release: Some(true) });
            }
            self.slots[k] = if view.is_free() { Slot::Free } else { Slot::Foreign };
            return None;
        };
        let report = |to, cause: String, release| {
            Some(Seen { slot: k, record: Some(Report::new(job.id, to, cause)), release })
        };
        if view.task_id != task {
            self.slots[k] = if view.is_free() { Slot::Free } else { Slot::Foreign };
            if !confirmed && view.task_id == 0 {
                return None; // the id write never arrived: the job is still queued
            }
            let text = format!("slot {slot_no} no longer holds task {task} (it holds {})", view.task_id);
            let lost = Failure { kind: FailureKind::Lost, code: None, text: text.clone() };
            return report(Reported::Failed(lost), text, None);
        }
        self.slots[k] = Slot::Held { job: id, task, confirmed: true };
        match view.state {
            ExecState::NotStarted if job.state == JobState::Queued => {
                report(Reported::Taken, format!("found in slot {slot_no}"), None)
            }
            ExecState::NotStarted => None,
            ExecState::Running if matches!(job.state, JobState::Queued | JobState::Dispatched) => {
                report(Reported::Running, "the PLC runs it".into(), None)
            }
            ExecState::Running => None,
            ExecState::Finished => report(
                Reported::Finished { forced: false },
                "the PLC finished it".into(),
                Some(self.config.clear_finished),
            ),
            ExecState::Failed => {
                let f = failure(view.failure_kind);
                let cause = format!("the PLC failed it: {}", f.text);
                report(Reported::Failed(f), cause, Some(true))
            }
            ExecState::Unknown(v) => {
                self.status
                    .update(|s| s.last_error = Some(format!("slot {slot_no}: unknown execution state {v}")));
                None
            }
        }
    }

    /// On start: reads every slot and reconciles it with the stored jobs, so work finished
    /// while rackd was down is recorded, running work is followed, nothing is handed over
    /// twice and a job whose task vanished is failed as `lost`.
    pub(super) async fn recover(&mut self) -> Result<(), DispatchError> {
        let unfinished = self.port.unfinished();
        let by_task: HashMap<u16, i64> = unfinished.iter().map(|j| (task_id_for(j.id), j.id)).collect();
        let mut reads = Vec::with_capacity(self.slots.len());
        for k in 0..self.slots.len() {
            reads.push((k, self.read(&self.slot_address(k), SLOT_WORDS as u16).await?));
        }
        let mut ours = Vec::new();
        // The jobs some slot holds: found, not lost, even if `settle` ends and frees them.
        let mut found = HashSet::new();
        for (k, words) in reads {
            let view = SlotView::parse(&words).ok_or(PlcError::Malformed("short slot read"))?;
            match by_task.get(&view.task_id) {
                _ if view.task_id == 0 => self.slots[k] = Slot::Free,
                Some(&job) => {
                    found.insert(job);
                    self.slots[k] = Slot::Held { job, task: view.task_id, confirmed: false };
                    ours.push((k, words));
                }
                None if matches!(view.state, ExecState::Finished | ExecState::Failed) => {
                    if self.config.clear_finished || view.state == ExecState::Failed {
                        self.write(&self.slot_address(k), &[0]).await?;
                    }
                    self.slots[k] = Slot::Free;
                }
                None => {
                    tracing::warn!(slot = k + 1, task = view.task_id, "slot holds unknown work");
                    self.slots[k] = Slot::Foreign;
                }
            }
        }
        self.settle(ours).await?;
        let lost: Vec<&Job> =
            unfinished.iter().filter(|j| j.state != JobState::Queued && !found.contains(&j.id)).collect();
        // rackd's tasks all gone and the slots empty: the PLC forgot them while rackd was
        // down, one decision as in `memory_lost`. Tasks it finished meanwhile are not gone.
        let forgot = lost.len() >= MEMORY_LOSS_SLOTS && found.is_empty();
        if forgot {
            tracing::error!(tasks = lost.len(), "{MEMORY_LOST}");
            self.status.update(|s| {
                s.memory_lost_at = Some(crate::domain::time::from_ms(crate::domain::time::now_ms()))
            });
        }
        let lost = lost
            .into_iter()
            .map(|job| {
                let text = match forgot {
                    true => format!(
                        "{MEMORY_LOST}: after a restart no slot holds task {}; check the location",
                        task_id_for(job.id)
                    ),
                    false => format!("after a restart no slot holds task {}", task_id_for(job.id)),
                };
                let failure = Failure { kind: FailureKind::Lost, code: None, text: text.clone() };
                Report::new(job.id, Reported::Failed(failure), text)
            })
            .collect();
        self.port.report(lost).await?;
        tracing::info!(slots = self.slots.len(), "recovered");
        Ok(())
    }
}
