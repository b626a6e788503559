//! A simulated stacker crane (spec: crane-mc3e.md) on the MC 3E server, over TCP or UDP,
//! for commissioning and tests.
//!
//! It implements the whole register interface ([`engine`]): it answers the heartbeat, takes
//! tasks through the STB/ACK hand-over, runs them through the action states 1..8, 11..18
//! (travel: 1, 2) one step per `step` time, shows load (D206) and positions (D220 travel =
//! bay x 1000, D221 lift = level x 500), reports 20/30/40 with D223 set to the same value
//! and clears D223 and its task words once D22 is non-zero, and homes (state 100 for one
//! step) after a cancel. An alarm (D205 non-zero) halts motion; a cancel (mode 3) ends the
//! task in 40 and clears the alarm. It refuses (acknowledges but ignores) a task handed over
//! while it is busy, counts tasks received per task number, and counts every breach of the
//! interface by the WCS ([`CraneSim::violations`]; see [`engine`]).
//!
//! Controls, as methods ([`CraneSim::raise_alarm`], ...) and as text commands
//! ([`CraneSim::command`], read from stdin by `rackd sim crane`): `alarm CODE`, `clear`,
//! `heartbeat off|on`, `handshake off|on` (ignore the strobe), `hold ack|start|off` (freeze
//! the hand-over before step 2 / before step 4), `force`, `drop` (close the connection /
//! lose the next request), `link off|on` (ignore every request), `status` (with the
//! violations counted). For tests, [`CraneSim::cut_link_after`] takes the link down right
//! after a chosen write of the WCS (its reply still goes out), which stops a WCS between
//! two steps of the hand-over as a crash would, and [`CraneSim::set_late_start`] makes a
//! slow crane program that shows a task only as it starts it, a step after clearing ACK.
//! With `wcs_timeout` set the crane watches rackd's heartbeat too and raises 7020 when D0
//! stalls; it clears 7020 itself once D0 moves again (a simplification: a real crane may
//! want a reset).
//!
//! With a motion model ([`CraneSimOptions::motion`]) the action states take the model's
//! times, D220/D221 move with the axes (centimetres; see [`engine`]) and `time_scale` runs
//! simulated time faster than real time (100: a 60 s cycle in 0.6 s), so a benchmark of
//! hundreds of cycles fits in a minute. With an inventory ([`CraneSimOptions::inventory`],
//! [`CraneSim::set_inventory`], the commands `put`/`take`/`inventory`) the crane refuses the
//! impossible with the business alarms 7069/7070 and 7091..7098 ([`inventory`]); without one
//! it tracks nothing and never raises them. [`CraneSim::stats`] counts cycles, busy time,
//! distances and business alarms ([`stats`]); [`CraneSim::record_tasks`] keeps each task's
//! instants as well ([`timeline`]).

mod commands;
pub mod engine;
pub mod inventory;
mod link;
pub mod stats;
pub mod timeline;

use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use tokio::sync::Notify;
use tokio::task::JoinHandle;

use crate::protocols::faults::SharedFaults;
use crate::protocols::mc3e::{Bank, Device, Mc3eServer, ServerState, SharedBank, TransportKind, WriteEvent};
use crate::protocols::transport::DatagramServerPort;
use crate::wire::motion::Motion;
pub use commands::CommandError;
use engine::Engine;
pub use engine::Hold;
use inventory::{Cell, Inventory};
pub use stats::{CraneStats, Pair, Runs, TaskKind};
pub use timeline::TaskTimes;

/// Whether a code is a business alarm of the catalogue.
pub fn is_business(code: u16) -> bool {
    code != 0 && crate::wire::alarms::lookup(code).class == crate::wire::alarms::AlarmClass::Business
}

/// How the simulated crane is set up.
#[derive(Clone, Debug)]
pub struct CraneSimOptions {
    /// TCP or UDP.
    pub transport: TransportKind,
    /// Time of each action state without a motion model.
    pub step: Duration,
    /// The crane's watchdog on rackd's heartbeat: alarm 7020 when D0 stalls this long
    /// (cleared when it moves again). None: no watchdog.
    pub wcs_timeout: Option<Duration>,
    /// The motion model the action states take their times from. None: `step` each.
    pub motion: Option<Motion>,
    /// Simulated seconds per real second (1: real time; 100: a 60 s cycle in 0.6 s). It
    /// scales the action states and homing, `step` as well as the model's times; the
    /// watchdog, the hand-over and `late_start` stay in real time: rackd runs in real time.
    pub time_scale: f64,
    /// The occupied cells `[row, bay, level, side]` at start. None: not tracked (every pick
    /// finds a load, every put fits, no double-deep alarm).
    pub inventory: Option<Vec<Cell>>,
}

impl Default for CraneSimOptions {
    fn default() -> Self {
        CraneSimOptions {
            transport: TransportKind::Tcp,
            step: Duration::from_millis(500),
            wcs_timeout: None,
            motion: None,
            time_scale: 1.0,
            inventory: None,
        }
    }
}

/// A running simulated crane.
pub struct CraneSim {
    server: Option<Mc3eServer>,
    bank: SharedBank,
    engine: Arc<Mutex<Engine>>,
    ticker: JoinHandle<()>,
    /// The drop rate to go back to when the link comes back on (`link on`).
    drop_rate: Mutex<f64>,
    /// A write (register, value) after which the link goes down, once.
    cut: Arc<Mutex<Option<(u32, u16)>>>,
}

impl CraneSim {
    /// Starts a crane listening on `addr` (port 0 picks a free port).
    pub async fn start(addr: &str, options: CraneSimOptions) -> std::io::Result<CraneSim> {
        let invalid = |e: String| std::io::Error::new(std::io::ErrorKind::InvalidInput, e);
        let addr: SocketAddr = addr.parse().map_err(|e| invalid(format!("{e}")))?;
        let transport = options.transport;
        let (state, mut sim) = CraneSim::build(options)?;
        sim.server = Some(match transport {
            TransportKind::Tcp => Mc3eServer::bind_tcp(addr, state).await?,
            TransportKind::Udp => Mc3eServer::bind_udp(addr, state).await?,
        });
        Ok(sim)
    }

    /// Starts a crane answering MC 3E/4E datagrams on a serving port already bound (the
    /// simulated wire of the tests, `protocols::simwire`), known as `addr`.
    pub fn serve_datagrams(
        port: impl DatagramServerPort,
        addr: SocketAddr,
        options: CraneSimOptions,
    ) -> std::io::Result<CraneSim> {
        let (state, mut sim) = CraneSim::build(options)?;
        sim.server = Some(Mc3eServer::serve_datagrams(port, addr, state));
        Ok(sim)
    }

    /// The crane without its server: the state a server serves, and the rest.
    fn build(options: CraneSimOptions) -> std::io::Result<(ServerState, CraneSim)> {
        let invalid = |e: String| std::io::Error::new(std::io::ErrorKind::InvalidInput, e);
        if !(options.time_scale.is_finite() && options.time_scale > 0.0) {
            return Err(invalid(format!("time scale {} is not a positive number", options.time_scale)));
        }
        if options.motion.is_some_and(|m| !m.is_valid()) {
            return Err(invalid("every figure of the motion model must be positive".into()));
        }
        let bank = Bank::default().shared();
        let mut engine = Engine::new(options.step);
        engine.wcs_timeout = options.wcs_timeout;
        engine.set_motion(options.motion);
        engine.time_scale = options.time_scale;
        engine.inventory = options.inventory.map(Inventory::new);
        if options.motion.is_some() {
            // Shows where it stands (D220/D221) before anyone reads it.
            engine.tick(&mut bank.lock().unwrap_or_else(|p| p.into_inner()), tokio::time::Instant::now());
        }
        let engine = Arc::new(Mutex::new(engine));
        let kick = Arc::new(Notify::new());
        let faults = SharedFaults::default();
        let cut: Arc<Mutex<Option<(u32, u16)>>> = Arc::default();
        let hook = {
            let (kick, bank, faults, cut) = (kick.clone(), bank.clone(), faults.clone(), cut.clone());
            move |w: WriteEvent| {
                let mut armed = cut.lock().unwrap_or_else(|p| p.into_inner());
                if let Some((n, v)) = *armed
                    && w.device == Device::D
                    && (w.start..w.start + w.points).contains(&n)
                    && bank.lock().unwrap_or_else(|p| p.into_inner()).word(Device::D, n) == v
                {
                    faults.update(|f| f.drop_rate = 1.0);
                    *armed = None;
                }
                kick.notify_one();
            }
        };
        let state = ServerState::new(bank.clone()).with_faults(faults).on_write(Arc::new(hook));
        // Fine enough for the axes to move smoothly and for a scaled cycle to end on time.
        let tick = match options.motion {
            Some(_) => Duration::from_millis(20).div_f64(options.time_scale.max(1.0)),
            None => options.step / 5,
        }
        .clamp(Duration::from_millis(1), Duration::from_millis(20));
        let ticker = tokio::spawn(run_ticks(bank.clone(), engine.clone(), kick, tick));
        let sim = CraneSim { server: None, bank, engine, ticker, drop_rate: Mutex::new(0.0), cut };
        Ok((state, sim))
    }

    /// The address it listens on.
    pub fn local_addr(&self) -> SocketAddr {
        self.server.as_ref().map(|s| s.local_addr()).unwrap_or_else(|| ([0, 0, 0, 0], 0).into())
    }

    /// Reads one D register.
    pub fn word(&self, n: u32) -> u16 {
        self.bank.lock().unwrap_or_else(|p| p.into_inner()).word(Device::D, n)
    }

    /// Writes one D register as another writer would (tests staging a crashed WCS).
    pub fn set_word(&self, n: u32, v: u16) {
        self.set(n, v);
    }

    fn set(&self, n: u32, v: u16) {
        self.bank.lock().unwrap_or_else(|p| p.into_inner()).set_word(Device::D, n, v);
    }

    /// Raises an alarm (D205 := code); motion halts until it clears or a cancel comes.
    pub fn raise_alarm(&self, code: u16) {
        self.set(205, code);
        self.engine().count_alarm(code);
    }

    fn engine(&self) -> std::sync::MutexGuard<'_, Engine> {
        self.engine.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// The occupied cells, in order; None if the inventory is not tracked.
    pub fn inventory(&self) -> Option<Vec<Cell>> {
        self.engine().cells()
    }

    /// Replaces the inventory (None: stop tracking it). Stations (bay 0) are dropped.
    pub fn set_inventory(&self, cells: Option<Vec<Cell>>) {
        self.engine().inventory = cells.map(Inventory::new);
    }

    /// Puts a load into a cell, tracking the inventory from now on if it was not; false if
    /// the cell was occupied or is a station.
    pub fn put_load(&self, cell: Cell) -> bool {
        self.engine().inventory.get_or_insert_with(Inventory::default).put(cell)
    }

    /// Takes the load out of a cell; None if the inventory is not tracked, else whether
    /// the cell held one.
    pub fn take_load(&self, cell: Cell) -> Option<bool> {
        self.engine().inventory.as_mut().map(|inv| inv.take(cell))
    }

    /// The counters since start (see [`stats`]).
    pub fn stats(&self) -> CraneStats {
        self.engine().stats.clone()
    }

    /// Records each task's instants from now on ([`timeline`]).
    pub fn record_tasks(&self) {
        self.engine().timeline.get_or_insert_with(timeline::Timeline::default);
    }

    /// The tasks recorded since [`CraneSim::record_tasks`], in order (empty if never asked).
    pub fn tasks(&self) -> Vec<TaskTimes> {
        self.engine().timeline.as_ref().map_or_else(Vec::new, |t| t.tasks().to_vec())
    }

    /// Clears the alarm (a person reset the crane).
    pub fn clear_alarm(&self) {
        self.set(205, 0);
    }

    /// Stops or restarts answering the heartbeat.
    pub fn set_heartbeat(&self, on: bool) {
        self.engine().heartbeat_on = on;
    }

    /// Stops or restarts answering the hand-over strobe.
    pub fn set_handshake(&self, on: bool) {
        self.engine().handshake_on = on;
    }

    /// Sets the time of each action state (without a motion model) from the next state on:
    /// a crane made slow for a while, so a task stays under way long enough to act on it.
    pub fn set_step(&self, step: Duration) {
        self.engine().step = step;
    }

    /// Freezes the crane's side of the hand-over at a step (`None`: reacts again, at once).
    pub fn hold(&self, hold: Option<Hold>) {
        self.engine().hold = hold;
    }

    /// A slow crane program: task words shown in D208..D217 only when the task starts,
    /// one step after ACK was cleared (step 4), instead of as soon as they are taken.
    pub fn set_late_start(&self, on: bool) {
        self.engine().late_start = on;
    }

    /// Breaches of the interface by the WCS so far (tests assert none).
    pub fn violations(&self) -> u32 {
        self.violation_log().len() as u32
    }

    /// The breaches, in words, in order.
    pub fn violation_log(&self) -> Vec<String> {
        self.engine().violations.clone()
    }

    /// Presses "force complete": the task under way ends in state 30. False if none.
    pub fn force_complete(&self) -> bool {
        let mut bank = self.bank.lock().unwrap_or_else(|p| p.into_inner());
        self.engine().force_complete(&mut bank)
    }

    /// How many times task `number` was handed over (mode 1 or 2).
    pub fn received(&self, number: u16) -> u32 {
        self.engine().received.get(&number).copied().unwrap_or(0)
    }

    /// Cancels (mode 3) received.
    pub fn cancels(&self) -> u32 {
        self.engine().cancels
    }

    /// Hand-overs refused because the crane was busy (rackd should cause none).
    pub fn refused(&self) -> u32 {
        self.engine().refused
    }

    /// Action state (D203).
    pub fn action(&self) -> u16 {
        self.word(203)
    }

    /// Stops the crane and its server.
    pub async fn shutdown(mut self) {
        self.ticker.abort();
        if let Some(s) = self.server.take() {
            s.shutdown().await;
        }
    }
}

impl Drop for CraneSim {
    fn drop(&mut self) {
        self.ticker.abort();
    }
}

/// Advances the engine after every write from the WCS and at least every `tick`.
async fn run_ticks(bank: SharedBank, engine: Arc<Mutex<Engine>>, kick: Arc<Notify>, tick: Duration) {
    loop {
        tokio::select! {
            _ = kick.notified() => {}
            _ = tokio::time::sleep(tick) => {}
        }
        let mut bank = bank.lock().unwrap_or_else(|p| p.into_inner());
        engine.lock().unwrap_or_else(|p| p.into_inner()).tick(&mut bank, tokio::time::Instant::now());
    }
}
