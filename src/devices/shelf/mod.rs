//! The shelf storage PLC adapter (spec: shelf-plc.md): hands jobs over through task slots
//! and follows them by polling the same slots.
//!
//! Answers to the questions the spec leaves open:
//! - **Task id**: derived from the job id ([`crate::wire::task_id_for`], 1..=65535), not the slot
//!   number, so a slot's task id leads back to its job after a restart with no extra record.
//! - **Write order**: read the slot; only if free (task id 0 or state 2): if its task id is
//!   not 0, write task id := 0 first; then write words 1..34 (body, state 0, failure 0) in
//!   one request; then the task id alone in a separate request. While the id is 0 the PLC
//!   ignores the slot, so it never sees a half-written task. A lost reply to the id write is
//!   settled by reading the slot back on the next poll: our id there means the PLC has it,
//!   0 means it never arrived (the job stays queued). The body is never rewritten once the id
//!   is set, so a repeated hand-over cannot reset a task the PLC has started.
//! - **Finished slots**: after recording a finished task rackd sets its task id to 0
//!   (`clear_finished`, default on; off leaves it for the PLC, and the slot is free anyway by
//!   rule 1). A failed slot (state 3) is always cleared after recording, since by rule 1 it
//!   would otherwise never be free again.
//! - **Withdraw**: a cancel of a task the PLC has not started clears its task id
//!   (`withdraw`, default on). There is no atomic compare-and-set over Modbus: if the PLC
//!   starts the task in the few milliseconds between rackd's read and write, the read-back
//!   shows it and the cancel is refused. Sites whose PLC may not have ids cleared turn
//!   `withdraw` off; cancels of tasks in slots are then refused with the reason.
//! - **Lost work**: a slot that no longer holds rackd's task id fails the job with kind
//!   `lost`, for an operator to check (its locations lock: see the service's dispatcher).
//! - **A PLC that lost its memory** (a power cycle: registers back to zero): when every slot
//!   rackd had a task in reads empty at once, and at least two did, that is one decision:
//!   every such job fails as `lost` with the words "the PLC lost its task memory (power
//!   cycle?)", their locations lock for a person to check, and the device status carries
//!   `memory_lost_at` (one `memory_lost` alarm) until the PLC takes new work. The same
//!   holds at a restart that finds every task gone. Jobs not yet handed over stay queued
//!   (those on a locked location wait), so no cascade of rejections follows.
//! - **A hand-over cut by a restart** (slot written, reply lost, rackd stopped before it
//!   recorded the job as dispatched): safe, decided from the slots alone, and unlike the
//!   crane's strobe nothing of rackd's own needs undoing. The PLC acts on a slot only once
//!   its task id is set, and the id is the last write; so on start a slot showing the
//!   job's task id is the job's (`recover` marks it held, the job moves to dispatched or
//!   running as the slot shows, and the slot is never written while it holds the task),
//!   while a slot showing id 0 only holds a body the PLC never looked at: the job is still
//!   queued and is handed over again, into whatever slot is free, with the body rewritten
//!   before the id. A restart cannot make rackd write into a slot the PLC holds, since
//!   only a slot read back free (id 0 or state 2) is written.

mod handover;
mod poll;

use std::sync::Arc;

use tokio::sync::mpsc;
use tokio::time::{Instant, sleep_until};

use super::DeviceRequest;
use super::port::Port;
use super::repeats::Repeats;
use super::status::StatusCell;
use crate::config::devices::ShelfConfig;
use crate::protocols::{Address, PlcError, PlcMemory};

/// What rackd knows of one task slot.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Slot {
    /// Not read yet.
    Unknown,
    /// Free for new work.
    Free,
    /// Holds a task of rackd's; `confirmed` once the PLC was seen to hold it.
    Held { job: i64, task: u16, confirmed: bool },
    /// Holds a task rackd does not know; left alone until it is free.
    Foreign,
}

/// One shelf PLC: its link, its slots and its port to the dispatcher.
pub struct Shelf {
    config: ShelfConfig,
    plc: Arc<dyn PlcMemory>,
    base: Address,
    port: Arc<dyn Port>,
    status: StatusCell,
    slots: Vec<Slot>,
    /// Failures of recovery, polls and hand-overs, logged without flooding.
    repeats: Repeats,
}

impl Shelf {
    /// A shelf adapter; nothing is sent until [`Shelf::run`].
    pub fn new(
        config: ShelfConfig,
        plc: Arc<dyn PlcMemory>,
        port: Arc<dyn Port>,
        status: StatusCell,
    ) -> Result<Shelf, PlcError> {
        let base = plc.parse_address(config.slot_base())?;
        let slots = vec![Slot::Unknown; config.slots as usize];
        Ok(Shelf { config, plc, base, port, status, slots, repeats: Repeats::default() })
    }

    /// Runs the device until the task is aborted or asked to stop: recover, then dispatch
    /// whenever work may be waiting and poll at the configured period. A stop
    /// ([`DeviceRequest::Stop`]) ends it between two rounds: every task written is in its
    /// slot with its id, and the next start reconciles from the slots as after a restart.
    pub async fn run(mut self, mut requests: mpsc::Receiver<DeviceRequest>) {
        let period = self.config.poll();
        let mut later = Vec::new();
        while let Err(e) = self.recover().await {
            self.repeats.failed("recovery failed; retrying", &e);
            if super::wait_recovering(period, &mut requests, &mut later).await {
                return;
            }
        }
        self.repeats.recovered();
        for request in later {
            if self.handle(request).await {
                return;
            }
        }
        let mut next_poll = Instant::now() + period;
        loop {
            let port = self.port.clone();
            tokio::select! {
                Some(request) = requests.recv() => if self.handle(request).await {
                    tracing::info!("stopped (reload)");
                    return;
                },
                _ = port.work_waiting() => {}
                _ = sleep_until(next_poll) => {
                    // Polls keep their pace: time a poll spends on retries comes out of
                    // the wait for the next one, not on top of it.
                    let started = Instant::now();
                    self.poll().await;
                    next_poll = (started + period).max(Instant::now());
                }
            }
            if self.may_dispatch()
                && let Err(e) = self.dispatch().await
            {
                self.repeats.failed("dispatch stopped", &e);
            }
            let in_use = self.slots.iter().filter(|s| matches!(s, Slot::Held { .. })).count() as u16;
            self.status.update(|s| s.slots_in_use = in_use);
        }
    }

    /// Answers a request; true for a stop (the task ends).
    async fn handle(&mut self, request: DeviceRequest) -> bool {
        match request {
            DeviceRequest::Cancel { job, reply } => {
                let _ = reply.send(self.cancel(job).await);
            }
            DeviceRequest::Holding { mut jobs, reply } => {
                jobs.retain(|id| self.slots.iter().any(|s| matches!(s, Slot::Held { job, .. } if job == id)));
                let _ = reply.send(jobs);
            }
            DeviceRequest::Stop => return true,
        }
        false
    }

    fn may_dispatch(&self) -> bool {
        self.status.get().online && self.slots.contains(&Slot::Free)
    }

    /// Where slot `k` (0-based) starts; `stride` counts words, whatever the protocol's
    /// address step (PPI numbers bytes).
    fn slot_address(&self, k: usize) -> Address {
        self.plc.word_address(&self.base, k as u32 * self.config.slot_stride() as u32)
    }

    /// Reads words, keeping the device's contact status.
    async fn read(&mut self, at: &Address, count: u16) -> Result<Vec<u16>, PlcError> {
        let result = self.plc.read_words(at, count).await;
        self.contact(result.as_ref().map(|_| ()));
        result
    }

    /// Writes words, keeping the device's contact status.
    async fn write(&mut self, at: &Address, values: &[u16]) -> Result<(), PlcError> {
        let result = self.plc.write_words(at, values).await;
        self.contact(result.as_ref().map(|_| ()));
        result
    }

    fn contact(&mut self, result: Result<(), &PlcError>) {
        let offline_after = self.config.offline_after;
        let link = self.plc.link_stats();
        self.status.update(|s| {
            let up = s.record_contact(result, offline_after, s.online, link);
            if up != s.online {
                match up {
                    true => tracing::info!("device online"),
                    false => tracing::warn!(error = ?s.last_error, "device offline"),
                }
            }
            s.online = up;
        });
    }
}
