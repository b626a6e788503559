//! A simulated shelf storage PLC (spec: shelf-plc.md), for commissioning and tests.
//!
//! It serves the task-slot area over Modbus UDP and answers like the real PLC (MBAP length
//! 0). A task engine takes waiting tasks in priority order (lower first, then slot order),
//! one at a time as the single shelf machine does, and runs each through execution state
//! 0 → 1 → 2 in a configurable time. It keeps its own inventory and lights and rejects
//! commands that disagree with them with failure kind 2 (retrieve from an empty position,
//! store into a full one, move from empty or into full); it can fail tasks with kind 1 at
//! a given rate, and drop or delay datagrams.
//!
//! It also watches the WCS: every write into a busy slot (task id set and not finished) is
//! a violation of rule 1, logged and counted ([`ShelfSim::violations`]). The one write
//! into a busy slot that is allowed is task id := 0 on a task not yet running (a withdraw)
//! or on a failed one (acknowledging the failure).

use std::collections::{BTreeMap, HashMap};
use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use rand::Rng;
use tokio::sync::Notify;
use tokio::task::JoinHandle;

use crate::devices::shelf::slot::{Command, EXEC_STATE, FAILURE_KIND, SLOT_WORDS, Task};
use crate::domain::Location;
use crate::protocols::modbus::exception::Exception;
use crate::protocols::modbus::pdu::{Request, Response};
use crate::protocols::modbus::server::{
    Bank, Faults, Handler, ModbusServer, RegisterBank, ServerHandle, ServerOptions,
};

/// How the simulated PLC is set up.
#[derive(Clone, Debug)]
pub struct ShelfSimOptions {
    /// Number of task slots.
    pub slots: u16,
    /// Holding register of slot 1's task id.
    pub base: u16,
    /// Registers from one slot to the next.
    pub stride: u16,
    /// Modbus unit id.
    pub unit: u8,
    /// Time each task takes (0 = at once).
    pub task_time: Duration,
    /// Fraction of tasks that fail with kind 1 (PLC fault).
    pub fail_rate: f64,
    /// Datagram faults (loss, delay, ...).
    pub faults: Faults,
}

impl Default for ShelfSimOptions {
    fn default() -> Self {
        ShelfSimOptions {
            slots: 60,
            base: 4000,
            stride: 100,
            unit: 1,
            task_time: Duration::from_millis(500),
            fail_rate: 0.0,
            faults: Faults::default(),
        }
    }
}

/// What the simulated shelf holds and has seen.
#[derive(Debug, Default)]
struct World {
    inventory: BTreeMap<Location, String>,
    lights: BTreeMap<(Location, &'static str), bool>,
    violations: u64,
    withdrawals: u64,
    received: HashMap<u16, u32>,
    received_at: HashMap<u16, std::time::Instant>,
    completed: u64,
    failed: u64,
}

/// A running simulated shelf PLC.
pub struct ShelfSim {
    world: Arc<Mutex<World>>,
    bank: Bank,
    server: ServerHandle,
    engine: JoinHandle<()>,
}

struct ShelfHandler {
    bank: Bank,
    world: Arc<Mutex<World>>,
    options: ShelfSimOptions,
    wake: Arc<Notify>,
}

impl ShelfSim {
    /// Starts the simulator on a UDP address (`127.0.0.1:0` for any free port).
    pub async fn start(listen: &str, options: ShelfSimOptions) -> std::io::Result<ShelfSim> {
        let end = options.base as usize + options.slots as usize * options.stride as usize;
        if options.slots == 0 || (options.stride as usize) < SLOT_WORDS || end > 0x1_0000 {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                "the slots must fit the holding registers: slots >= 1, stride >= 35, base + slots * stride <= 65536",
            ));
        }
        let bank = Bank::new();
        let world = Arc::new(Mutex::new(World::default()));
        let wake = Arc::new(Notify::new());
        let handler = ShelfHandler {
            bank: bank.clone(),
            world: world.clone(),
            options: options.clone(),
            wake: wake.clone(),
        };
        let server_options = ServerOptions {
            unit: options.unit,
            length0: true,
            faults: options.faults.clone(),
            ..Default::default()
        };
        let server = ModbusServer::new(Arc::new(handler), server_options).serve_udp(listen).await?;
        let engine = tokio::spawn(run_engine(bank.clone(), world.clone(), options, wake));
        Ok(ShelfSim { world, bank, server, engine })
    }

    /// The UDP address it answers on.
    pub fn local_addr(&self) -> SocketAddr {
        self.server.local_addr().expect("a UDP server has an address")
    }

    /// Boxes on the shelf and their barcodes ("" when unlabelled).
    pub fn inventory(&self) -> BTreeMap<Location, String> {
        self.world().inventory.clone()
    }

    /// Lights that are on, as (location, "red" | "green").
    pub fn lights_on(&self) -> Vec<(Location, &'static str)> {
        self.world().lights.iter().filter(|(_, on)| **on).map(|(k, _)| *k).collect()
    }

    /// Writes into busy slots (rule 1 broken).
    pub fn violations(&self) -> u64 {
        self.world().violations
    }

    /// Tasks withdrawn (task id set to 0 before they ran).
    pub fn withdrawals(&self) -> u64 {
        self.world().withdrawals
    }

    /// How many times a task with this id was handed to a slot.
    pub fn received(&self, task_id: u16) -> u32 {
        self.world().received.get(&task_id).copied().unwrap_or(0)
    }

    /// When a task with this id last reached a slot.
    pub fn received_at(&self, task_id: u16) -> Option<std::time::Instant> {
        self.world().received_at.get(&task_id).copied()
    }

    /// Tasks finished (state 2) and failed (state 3) so far.
    pub fn finished(&self) -> (u64, u64) {
        let w = self.world();
        (w.completed, w.failed)
    }

    /// Puts a box at a location directly (as a person at the shelf would).
    pub fn place(&self, at: Location, barcode: &str) {
        self.world().inventory.insert(at, barcode.to_owned());
    }

    /// Changes the datagram faults while running.
    pub fn set_faults(&self, faults: Faults) {
        self.server.set_faults(faults);
    }

    /// The register bank (to inspect or change slots directly).
    pub fn bank(&self) -> &Bank {
        &self.bank
    }

    /// Stops serving.
    pub async fn shutdown(self) {
        self.engine.abort();
        self.server.shutdown().await;
    }

    fn world(&self) -> std::sync::MutexGuard<'_, World> {
        self.world.lock().unwrap_or_else(|p| p.into_inner())
    }
}

impl ShelfHandler {
    /// Slot number (0-based) and offset of a holding register, if it is in a slot's used words.
    fn slot_of(&self, address: u32) -> Option<(u16, u16)> {
        let o = &self.options;
        let rel = address.checked_sub(o.base as u32)?;
        let (slot, offset) = (rel / o.stride as u32, rel % o.stride as u32);
        (slot < o.slots as u32 && offset < SLOT_WORDS as u32).then_some((slot as u16, offset as u16))
    }

    /// Checks a write of `values` at `address` against rule 1 before it is applied.
    /// Called with the bank locked; locks are always taken bank first, then world.
    fn watch_write(&self, bank: &RegisterBank, address: u16, values: &[u16]) {
        let mut touched: BTreeMap<u16, Vec<(u16, u16)>> = BTreeMap::new();
        for (i, &v) in values.iter().enumerate() {
            if let Some((slot, offset)) = self.slot_of(address as u32 + i as u32) {
                touched.entry(slot).or_default().push((offset, v));
            }
        }
        let mut world = self.world.lock().unwrap_or_else(|p| p.into_inner());
        for (slot, writes) in touched {
            let start = self.options.base as usize + slot as usize * self.options.stride as usize;
            let words = &bank.holding_registers[start..start + SLOT_WORDS];
            let (id, state) = (words[0], words[EXEC_STATE]);
            let busy = id != 0 && state != 2;
            let only_clears_id = writes.iter().all(|&(o, v)| o == 0 && v == 0);
            if busy {
                match (only_clears_id, state) {
                    (true, 0) => world.withdrawals += 1,
                    (true, 3) => {}
                    _ => {
                        world.violations += 1;
                        tracing::warn!(
                            slot = slot + 1,
                            task = id,
                            state,
                            "VIOLATION: write into a busy slot"
                        );
                    }
                }
            }
            let new_id = writes.iter().find(|&&(o, _)| o == 0).map(|&(_, v)| v);
            if let Some(new_id) = new_id.filter(|&v| v != 0 && v != id) {
                *world.received.entry(new_id).or_default() += 1;
                world.received_at.insert(new_id, std::time::Instant::now());
                tracing::info!(slot = slot + 1, task = new_id, "task received");
            }
        }
    }
}

impl Handler for ShelfHandler {
    fn handle(&self, _unit: u8, request: &Request) -> Result<Response, Exception> {
        let mut bank = self.bank.lock();
        match request {
            Request::WriteSingleRegister { address, value } => self.watch_write(&bank, *address, &[*value]),
            Request::WriteMultipleRegisters { address, values } => self.watch_write(&bank, *address, values),
            _ => {}
        }
        let response = bank.apply(request);
        drop(bank);
        if matches!(request, Request::WriteSingleRegister { .. } | Request::WriteMultipleRegisters { .. }) {
            self.wake.notify_one();
        }
        response
    }
}

/// The shelf machine: one task at a time, lowest priority number first.
async fn run_engine(bank: Bank, world: Arc<Mutex<World>>, o: ShelfSimOptions, wake: Arc<Notify>) {
    loop {
        let next = {
            let mut bank = bank.lock();
            let regs = &mut bank.holding_registers;
            let waiting = (0..o.slots).filter_map(|k| {
                let start = o.base as usize + k as usize * o.stride as usize;
                let (id, state) = (regs[start], regs[start + EXEC_STATE]);
                (id != 0 && state == 0).then_some((regs[start + 1], k, start))
            });
            let next = waiting.min();
            if let Some((_, _, start)) = next {
                regs[start + EXEC_STATE] = 1;
            }
            next
        };
        let Some((_, slot, start)) = next else {
            let _ = tokio::time::timeout(Duration::from_millis(50), wake.notified()).await;
            continue;
        };
        if !o.task_time.is_zero() {
            tokio::time::sleep(o.task_time).await;
        }
        let mut bank = bank.lock();
        let regs = &mut bank.holding_registers;
        let Some(task) = Task::decode(&regs[start..start + SLOT_WORDS]) else { continue };
        if task.id == 0 || regs[start + EXEC_STATE] != 1 {
            continue; // withdrawn or overwritten while running (a violation, already counted)
        }
        let mut world = world.lock().unwrap_or_else(|p| p.into_inner());
        let outcome = if rand::rng().random_bool(o.fail_rate.clamp(0.0, 1.0)) {
            Err(1)
        } else {
            perform(&mut world, &task).map_err(|_| 2)
        };
        match outcome {
            Ok(()) => {
                regs[start + EXEC_STATE] = 2;
                world.completed += 1;
            }
            Err(kind) => {
                regs[start + FAILURE_KIND] = kind;
                regs[start + EXEC_STATE] = 3;
                world.failed += 1;
                tracing::info!(slot = slot + 1, task = task.id, kind, "task failed");
            }
        }
    }
}

/// Carries out a task on the simulated shelf, or says why the PLC refuses it.
fn perform(world: &mut World, task: &Task) -> Result<(), &'static str> {
    let inv = &mut world.inventory;
    match (Command::from_code(task.command), task.from, task.to) {
        (Some(Command::Store), _, Some(to)) if !inv.contains_key(&to) => {
            inv.insert(to, task.barcode.clone());
        }
        (Some(Command::Retrieve), Some(from), _) if inv.contains_key(&from) => {
            inv.remove(&from);
        }
        (Some(Command::Move), Some(from), Some(to)) if inv.contains_key(&from) && !inv.contains_key(&to) => {
            let b = inv.remove(&from).unwrap_or_default();
            inv.insert(to, if task.barcode.is_empty() { b } else { task.barcode.clone() });
        }
        (Some(Command::Clear), Some(at), _) => {
            inv.remove(&at);
        }
        (
            Some(c @ (Command::GreenOn | Command::GreenOff | Command::RedOn | Command::RedOff)),
            Some(at),
            None,
        ) => {
            let color = if matches!(c, Command::RedOn | Command::RedOff) { "red" } else { "green" };
            world.lights.insert((at, color), matches!(c, Command::GreenOn | Command::RedOn));
        }
        _ => return Err("the command disagrees with the PLC's own data"),
    }
    Ok(())
}
