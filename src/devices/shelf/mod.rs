//! The shelf storage PLC adapter (spec: shelf-plc.md): hands jobs over through task slots
//! and follows them by polling the same slots.
//!
//! Answers to the questions the spec leaves open:
//! - **Task id**: derived from the job id ([`slot::task_id_for`], 1..=65535), not the slot
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
//!   `lost`, for an operator to check.

mod handover;
mod poll;
pub mod slot;

use std::sync::{Arc, Mutex};

use sqlx::SqlitePool;
use tokio::sync::{Notify, mpsc};
use tokio::time::{Instant, sleep_until};

use super::DeviceRequest;
use super::config::{ShelfConfig, WordsError, check_words};
use super::status::DeviceStatus;
use crate::protocols::{Address, PlcError, PlcMemory, Protocol};
use crate::store::writer::Writer;

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

/// One shelf PLC: its link, its slots and the job writer.
pub struct Shelf {
    config: ShelfConfig,
    plc: Arc<dyn PlcMemory>,
    base: Address,
    writer: Writer,
    pool: SqlitePool,
    status: Arc<Mutex<DeviceStatus>>,
    slots: Vec<Slot>,
}

/// Where the task slots sit by default on each protocol: slot 1's task id and the words
/// from one slot to the next. Modbus UDP/TCP: the seed's PLC, `4x4000` (MW4000), 100;
/// Modbus RTU: an S7-1200 Modbus_Slave, whose holding registers start at its slot data
/// block, `4x0`, 100; PPI: an S7-200, `VW1000`, 50 (60 slots of 100 words would not fit its
/// V memory); MEWTOCOL: `DT4000`, 100; MC: `D4000`, 100.
pub fn default_layout(protocol: Protocol) -> (&'static str, u16) {
    match protocol {
        Protocol::ModbusUdp | Protocol::ModbusTcp => ("4x4000", 100),
        Protocol::ModbusRtu | Protocol::ModbusRtuTcp => ("4x0", 100),
        Protocol::Ppi | Protocol::PpiTcp => ("VW1000", 50),
        Protocol::Mewtocol | Protocol::MewtocolTcp => ("DT4000", 100),
        Protocol::Mc3e | Protocol::Mc3eUdp => ("D4000", 100),
    }
}

/// Checks, without a connection, that the slot area is writable words of the protocol and
/// that every slot fits inside its memory area.
pub fn check_layout(config: &ShelfConfig) -> Result<(), WordsError> {
    let words = config.slots as u32 * config.slot_stride() as u32;
    check_words(config.link.protocol, "base", config.slot_base(), words, true)
}

impl Shelf {
    /// A shelf adapter; nothing is sent until [`Shelf::run`].
    pub fn new(
        config: ShelfConfig,
        plc: Arc<dyn PlcMemory>,
        writer: Writer,
        pool: SqlitePool,
        status: Arc<Mutex<DeviceStatus>>,
    ) -> Result<Shelf, PlcError> {
        let base = plc.parse_address(config.slot_base())?;
        let slots = vec![Slot::Unknown; config.slots as usize];
        Ok(Shelf { config, plc, base, writer, pool, status, slots })
    }

    /// Runs the device until the task is aborted: recover, then dispatch on every wake-up
    /// and poll at the configured period.
    pub async fn run(mut self, wake: Arc<Notify>, mut requests: mpsc::Receiver<DeviceRequest>) {
        let period = self.config.poll();
        while let Err(e) = self.recover().await {
            tracing::warn!(device = %self.config.id, error = %e, "recovery failed; retrying");
            tokio::time::sleep(period).await;
        }
        let mut next_poll = Instant::now() + period;
        loop {
            tokio::select! {
                Some(request) = requests.recv() => self.handle(request).await,
                _ = wake.notified() => {}
                _ = sleep_until(next_poll) => {
                    self.poll().await;
                    next_poll = Instant::now() + period;
                }
            }
            if self.may_dispatch()
                && let Err(e) = self.dispatch().await
            {
                tracing::warn!(device = %self.config.id, error = %e, "dispatch stopped");
            }
            self.update_status(|s| {
                s.slots_in_use = self.slots.iter().filter(|s| matches!(s, Slot::Held { .. })).count() as u16
            });
        }
    }

    async fn handle(&mut self, request: DeviceRequest) {
        match request {
            DeviceRequest::Cancel { job, reply } => {
                let _ = reply.send(self.cancel(job).await);
            }
        }
    }

    fn may_dispatch(&self) -> bool {
        let s = self.status.lock().unwrap_or_else(|p| p.into_inner());
        s.online && !s.paused && self.slots.contains(&Slot::Free)
    }

    /// Where slot `k` (0-based) starts; `stride` counts words, whatever the protocol's
    /// address step (PPI numbers bytes).
    fn slot_address(&self, k: usize) -> Address {
        self.plc.word_address(&self.base, k as u32 * self.config.slot_stride() as u32)
    }

    /// Reads words, keeping the device's contact status.
    async fn read(&self, at: &Address, count: u16) -> Result<Vec<u16>, PlcError> {
        let result = self.plc.read_words(at, count).await;
        self.contact(result.as_ref().map(|_| ()).map_err(|e| e.to_string()));
        result
    }

    /// Writes words, keeping the device's contact status.
    async fn write(&self, at: &Address, values: &[u16]) -> Result<(), PlcError> {
        let result = self.plc.write_words(at, values).await;
        self.contact(result.as_ref().map(|_| ()).map_err(|e| e.to_string()));
        result
    }

    fn contact(&self, result: Result<(), String>) {
        let offline_after = self.config.offline_after;
        let id = self.config.id.clone();
        self.update_status(|s| {
            let up = s.record_contact(result, offline_after, s.online);
            if up != s.online {
                match up {
                    true => tracing::info!(device = %id, "device online"),
                    false => tracing::warn!(device = %id, error = ?s.last_error, "device offline"),
                }
            }
            s.online = up;
        });
    }

    fn update_status(&self, f: impl FnOnce(&mut DeviceStatus)) {
        f(&mut self.status.lock().unwrap_or_else(|p| p.into_inner()));
    }
}
