//! A simulated shelf storage PLC (spec: shelf-plc.md), for commissioning and tests.
//!
//! One task-slot PLC behind any of rackd's shelf transports ([`ShelfProtocol`]): Modbus UDP
//! (the seed's PLC, answering with MBAP length 0), Modbus TCP, Modbus RTU on a serial line
//! or over TCP (answering like an S7-1200 Modbus_Slave, see `s7_1200.rs`), S7-200 PPI and
//! Panasonic MEWTOCOL-COM, each on a serial line or over TCP. Where the slots sit in each
//! protocol's memory, and the defaults, are in [`ShelfSimOptions`]'s module (`options.rs`).
//!
//! A task engine takes waiting tasks in priority order (lower first, then slot order), one
//! at a time as the single shelf machine does, and runs each through execution state
//! 0 → 1 → 2 in a configurable time. It keeps its own inventory and lights and rejects
//! commands that disagree with them with failure kind 2 (retrieve from an empty position,
//! store into a full one, move from empty or into full); it can fail tasks with kind 1 at
//! a given rate, and inject the link faults every simulator knows ([`Faults`]).
//!
//! It also watches the WCS: every write into a busy slot (task id set and not finished) is
//! a violation of rule 1, logged and counted ([`ShelfSim::violations`]). The one write
//! into a busy slot that is allowed is task id := 0 on a task not yet running (a withdraw)
//! or on a failed one (acknowledging the failure).
//!
//! # How the transports plug in
//! The engine and the watch work on the slot area as words counted from slot 1's task id
//! (`slots.rs`: `SlotMemory`), whatever bank holds them. Each transport adapter (`modbus.rs`,
//! `ppi.rs`, `mewtocol.rs`) gives its server's bank that face, and hooks into its server's
//! request path (the Modbus `Handler`, the PPI and MEWTOCOL `Handler` closures) to turn
//! each write into `(area word, value)` pairs for the watch before the bank applies it.

mod engine;
mod mewtocol;
mod modbus;
mod options;
mod ppi;
mod s7_1200;
mod slots;
#[cfg(test)]
mod tests;
mod world;

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::sync::Arc;

use tokio::task::JoinHandle;

pub use options::{ShelfProtocol, ShelfSimOptions, UnknownProtocol};

use self::engine::Machine;
use self::options::Family;
use self::slots::{Core, Layout, SlotMemory};
use crate::domain::Location;
use crate::protocols::faults::{Faults, SharedFaults};
use crate::protocols::link::LinkConfig;
use crate::protocols::modbus::server::ServerHandle;
use crate::protocols::transport::{ByteStream, DatagramServerPort, StreamServer};
use crate::protocols::{Protocol, Quirk};
use crate::wire::slot::SLOT_WORDS;

/// Where a transport is served.
enum Endpoint<'a> {
    /// A UDP or TCP address to bind.
    Listen(&'a str),
    /// A serial line already open.
    Stream(Box<dyn ByteStream>),
    /// A serving datagram port already bound (a simulated one).
    Datagrams(Box<dyn DatagramServerPort>),
}

/// What every transport adapter is started with.
#[derive(Clone, Copy)]
struct Setup<'a> {
    protocol: ShelfProtocol,
    /// Slot 1's task id in the protocol's notation.
    base: &'a str,
    unit: u8,
    /// The serial line's baud rate (Modbus RTU times its inter-frame silence by it).
    baud: u32,
    core: &'a Core,
    faults: &'a Faults,
    /// Modbus TCP and UDP: answer with transaction id 0, as the seed's PLC does.
    zero_transaction_id: bool,
}

/// A transport adapter, serving: the slot area over its bank, its server, and the
/// server's faults.
struct Started {
    memory: Arc<dyn SlotMemory>,
    server: Server,
    faults: SharedFaults,
}

/// A running server of either kind.
enum Server {
    Modbus(ServerHandle),
    Line(StreamServer),
}

/// A running simulated shelf PLC.
pub struct ShelfSim {
    core: Core,
    memory: Arc<dyn SlotMemory>,
    server: Server,
    faults: SharedFaults,
    engine: JoinHandle<()>,
    machine: Arc<std::sync::Mutex<Machine>>,
    protocol: ShelfProtocol,
    base: String,
    unit: u8,
    options: ShelfSimOptions,
}

fn invalid(message: &str) -> std::io::Error {
    std::io::Error::new(std::io::ErrorKind::InvalidInput, message.to_owned())
}

impl ShelfSim {
    /// Starts the simulator: on a UDP or TCP address (`127.0.0.1:0` for any free port) for
    /// network protocols, on a serial device it opens (`/dev/ttyUSB0`) for serial ones.
    pub async fn start(listen: &str, options: ShelfSimOptions) -> std::io::Result<ShelfSim> {
        if options.protocol.is_serial() {
            let port = options.serial_or_default().open(listen)?;
            return ShelfSim::launch(Endpoint::Stream(Box::new(port)), options).await;
        }
        ShelfSim::launch(Endpoint::Listen(listen), options).await
    }

    /// Starts a serial-protocol simulator on a stream already open (one end of a pty pair).
    pub async fn serve_stream(
        stream: impl ByteStream + 'static,
        options: ShelfSimOptions,
    ) -> std::io::Result<ShelfSim> {
        if !options.protocol.is_serial() {
            return Err(invalid("only modbus-rtu, ppi and mewtocol are served on a serial stream"));
        }
        ShelfSim::launch(Endpoint::Stream(Box::new(stream)), options).await
    }

    /// Starts a Modbus UDP simulator on a serving datagram port already bound (the
    /// simulated wire of the tests, `protocols::simwire`).
    pub async fn serve_datagrams(
        port: impl DatagramServerPort,
        options: ShelfSimOptions,
    ) -> std::io::Result<ShelfSim> {
        if options.protocol != ShelfProtocol::ModbusUdp {
            return Err(invalid("only modbus-udp is served on datagrams"));
        }
        ShelfSim::launch(Endpoint::Datagrams(Box::new(port)), options).await
    }

    async fn launch(endpoint: Endpoint<'_>, options: ShelfSimOptions) -> std::io::Result<ShelfSim> {
        let stride = options.stride_or_default();
        if options.slots == 0 || (stride as usize) < SLOT_WORDS {
            return Err(invalid("the slots must be at least 1 and the stride at least 35 words"));
        }
        if !(0.0..=1.0).contains(&options.fail_rate) {
            return Err(invalid("the fail rate is a fraction between 0 and 1"));
        }
        options.faults.check().map_err(|e| invalid(&e.to_string()))?;
        let core = Core::new(Layout { slots: options.slots, stride });
        let (protocol, base, unit) = (options.protocol, options.base_text(), options.unit_or_default());
        let baud = options.serial_or_default().baud;
        let setup = Setup {
            protocol,
            base: &base,
            unit,
            baud,
            core: &core,
            faults: &options.faults,
            zero_transaction_id: options.no_transaction_id,
        };
        let Started { memory, server, faults } = match protocol.family() {
            Family::Modbus => modbus::start(endpoint, &setup).await?,
            Family::Ppi => ppi::start(endpoint, &setup).await?,
            Family::Mewtocol => mewtocol::start(endpoint, &setup).await?,
        };
        let machine = Machine { task_time: options.task_time, fail_rate: options.fail_rate };
        let machine = Arc::new(std::sync::Mutex::new(machine));
        let engine = tokio::spawn(engine::run(memory.clone(), core.clone(), machine.clone()));
        Ok(ShelfSim { core, memory, server, faults, engine, machine, protocol, base, unit, options })
    }

    /// The address it answers on (`None` on a serial line).
    pub fn local_addr(&self) -> Option<SocketAddr> {
        match &self.server {
            Server::Modbus(handle) => handle.local_addr(),
            Server::Line(server) => server.local_addr(),
        }
    }

    /// The protocol it speaks.
    pub fn protocol(&self) -> ShelfProtocol {
        self.protocol
    }

    /// Slot 1's task id, in the protocol's notation (`4x4000`, `VW1000`, `DT4000`).
    pub fn base(&self) -> &str {
        &self.base
    }

    /// Words from one slot to the next.
    pub fn stride(&self) -> u16 {
        self.core.layout.stride
    }

    /// The unit, PPI address or MEWTOCOL station it answers.
    pub fn unit(&self) -> u8 {
        self.unit
    }

    /// The link that reaches this simulator at `address` (its [`ShelfSim::local_addr`], or
    /// the serial device at the other end of its line): its protocol, unit, serial settings
    /// and, over Modbus UDP, the `length0` quirk (MBAP length 0 is the UDP PLC's own habit),
    /// with `no-transaction-id` when it answers without them.
    pub fn link(&self, address: &str) -> LinkConfig {
        let protocol = self.protocol.protocol();
        let mut link = LinkConfig::new(protocol, address);
        link.unit = self.unit;
        link.serial = self.options.serial;
        if protocol == Protocol::ModbusUdp {
            link.quirks.insert(Quirk::Length0);
        }
        if self.options.no_transaction_id {
            link.quirks.insert(Quirk::NoTransactionId);
        }
        link.tuning = crate::protocols::transport::LinkTuning::for_replies(link.replies());
        link
    }

    /// How many task slots it has.
    pub fn slots(&self) -> u16 {
        self.core.layout.slots
    }

    /// Boxes on the shelf and their barcodes ("" when unlabelled).
    pub fn inventory(&self) -> BTreeMap<Location, String> {
        self.core.world().inventory.clone()
    }

    /// Lights that are on, as (location, "red" | "green").
    pub fn lights_on(&self) -> Vec<(Location, &'static str)> {
        self.core.world().lights.iter().filter(|(_, on)| **on).map(|(k, _)| *k).collect()
    }

    /// Writes into busy slots (rule 1 broken).
    pub fn violations(&self) -> u64 {
        self.core.world().violations
    }

    /// Tasks withdrawn (task id set to 0 before they ran).
    pub fn withdrawals(&self) -> u64 {
        self.core.world().withdrawals
    }

    /// How many times a task with this id was handed to a slot.
    pub fn received(&self, task_id: u16) -> u32 {
        self.core.world().received.get(&task_id).copied().unwrap_or(0)
    }

    /// When a task with this id last reached a slot.
    pub fn received_at(&self, task_id: u16) -> Option<std::time::Instant> {
        self.core.world().received_at.get(&task_id).copied()
    }

    /// Tasks finished (state 2) and failed (state 3) so far.
    pub fn finished(&self) -> (u64, u64) {
        let w = self.core.world();
        (w.completed, w.failed)
    }

    /// Puts a box at a location directly (as a person at the shelf would).
    pub fn place(&self, at: Location, barcode: &str) {
        self.core.world().inventory.insert(at, barcode.to_owned());
    }

    /// The 35 used words of slot `k` (1-based), whatever the protocol; `None` past the
    /// last slot.
    pub fn slot(&self, k: u16) -> Option<Vec<u16>> {
        let layout = self.core.layout;
        (1..=layout.slots).contains(&k).then(|| self.memory.lock().read(layout.start(k - 1), SLOT_WORDS))
    }

    /// A power cycle: every word of the slot area back to 0, as a PLC without retained
    /// memory comes back; the boxes stay where they are, and a task under way is not
    /// finished (its slot no longer holds it).
    pub fn power_cycle(&self) {
        let layout = self.core.layout;
        let mut words = self.memory.lock();
        for n in 0..layout.words() {
            words.set(n, 0);
        }
        drop(words);
        tracing::warn!("power cycle: the slot area is cleared");
        self.core.wake.notify_one();
    }

    /// Changes the time each task takes from the next task on (the one running keeps
    /// its time): a test holds tasks in their slots, then lets the machine work fast.
    pub fn set_task_time(&self, time: std::time::Duration) {
        self.machine.lock().unwrap_or_else(|p| p.into_inner()).task_time = time;
    }

    /// Changes the standing link faults while running (a queued script stays).
    pub fn set_faults(&self, faults: Faults) {
        self.faults.set(faults);
    }

    /// The server's faults, to script one-off faults or change them in place.
    pub fn faults(&self) -> SharedFaults {
        self.faults.clone()
    }

    /// Stops serving.
    pub async fn shutdown(self) {
        self.engine.abort();
        match self.server {
            Server::Modbus(handle) => handle.shutdown().await,
            Server::Line(server) => server.shutdown().await,
        }
    }
}
