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

pub mod engine;

use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use tokio::sync::Notify;
use tokio::task::JoinHandle;

use crate::protocols::faults::{Fault, Faults, SharedFaults};
use crate::protocols::mc3e::{Bank, Device, Mc3eServer, ServerState, SharedBank, TransportKind, WriteEvent};
use engine::Engine;
pub use engine::Hold;

/// Whether a code is a business alarm of the catalogue.
pub fn is_business(code: u16) -> bool {
    code != 0 && crate::wire::alarms::lookup(code).class == crate::wire::alarms::AlarmClass::Business
}

/// How the simulated crane is set up.
#[derive(Clone, Debug)]
pub struct CraneSimOptions {
    /// TCP or UDP.
    pub transport: TransportKind,
    /// Time of each action state.
    pub step: Duration,
    /// The crane's watchdog on rackd's heartbeat: alarm 7020 when D0 stalls this long
    /// (cleared when it moves again). None: no watchdog.
    pub wcs_timeout: Option<Duration>,
}

impl Default for CraneSimOptions {
    fn default() -> Self {
        CraneSimOptions { transport: TransportKind::Tcp, step: Duration::from_millis(500), wcs_timeout: None }
    }
}

/// Why a text command was refused.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum CommandError {
    /// `alarm` with something other than a number.
    #[error("not an alarm code: {0}")]
    AlarmCode(String),
    /// Not one of the commands.
    #[error(
        "unknown command {0:?} (alarm CODE, clear, heartbeat on|off, handshake on|off, hold ack|start|off, force, drop, link on|off, status)"
    )]
    Unknown(String),
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
        let addr: SocketAddr =
            addr.parse().map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidInput, e))?;
        let bank = Bank::default().shared();
        let mut engine = Engine::new(options.step);
        engine.wcs_timeout = options.wcs_timeout;
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
        let server = match options.transport {
            TransportKind::Tcp => Mc3eServer::bind_tcp(addr, state).await?,
            TransportKind::Udp => Mc3eServer::bind_udp(addr, state).await?,
        };
        let tick = (options.step / 5).clamp(Duration::from_millis(1), Duration::from_millis(20));
        let ticker = tokio::spawn(run_ticks(bank.clone(), engine.clone(), kick, tick));
        Ok(CraneSim { server: Some(server), bank, engine, ticker, drop_rate: Mutex::new(0.0), cut })
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
    }

    /// Clears the alarm (a person reset the crane).
    pub fn clear_alarm(&self) {
        self.set(205, 0);
    }

    /// Stops or restarts answering the heartbeat.
    pub fn set_heartbeat(&self, on: bool) {
        self.engine.lock().unwrap_or_else(|p| p.into_inner()).heartbeat_on = on;
    }

    /// Stops or restarts answering the hand-over strobe.
    pub fn set_handshake(&self, on: bool) {
        self.engine.lock().unwrap_or_else(|p| p.into_inner()).handshake_on = on;
    }

    /// Freezes the crane's side of the hand-over at a step (`None`: reacts again, at once).
    pub fn hold(&self, hold: Option<Hold>) {
        self.engine.lock().unwrap_or_else(|p| p.into_inner()).hold = hold;
    }

    /// A slow crane program: task words shown in D208..D217 only when the task starts,
    /// one step after ACK was cleared (step 4), instead of as soon as they are taken.
    pub fn set_late_start(&self, on: bool) {
        self.engine.lock().unwrap_or_else(|p| p.into_inner()).late_start = on;
    }

    /// Takes the link down (as `link off`) right after the next write of the WCS that
    /// leaves D register `n` at `value`; that write is carried out and answered, nothing
    /// after it until [`CraneSim::set_link`] brings the link back.
    pub fn cut_link_after(&self, n: u32, value: u16) {
        *self.cut.lock().unwrap_or_else(|p| p.into_inner()) = Some((n, value));
    }

    /// Whether an armed [`CraneSim::cut_link_after`] has fired.
    pub fn link_cut(&self) -> bool {
        self.cut.lock().unwrap_or_else(|p| p.into_inner()).is_none()
    }

    /// Breaches of the interface by the WCS so far (tests assert none).
    pub fn violations(&self) -> u32 {
        self.violation_log().len() as u32
    }

    /// The breaches, in words, in order.
    pub fn violation_log(&self) -> Vec<String> {
        self.engine.lock().unwrap_or_else(|p| p.into_inner()).violations.clone()
    }

    /// Presses "force complete": the task under way ends in state 30. False if none.
    pub fn force_complete(&self) -> bool {
        let mut bank = self.bank.lock().unwrap_or_else(|p| p.into_inner());
        self.engine.lock().unwrap_or_else(|p| p.into_inner()).force_complete(&mut bank)
    }

    /// Sets the standing link faults (`rackd sim crane`'s fault flags).
    pub fn set_faults(&self, faults: Faults) {
        *self.drop_rate.lock().unwrap_or_else(|p| p.into_inner()) = faults.drop_rate;
        if let Some(s) = &self.server {
            s.faults().set(faults);
        }
    }

    /// Closes the TCP connection (loses the next request over UDP).
    pub fn drop_link(&self) {
        if let Some(s) = &self.server {
            s.faults().push(Fault::Close);
        }
    }

    /// Ignores every request (`false`) or answers again (`true`, at the configured drop
    /// rate).
    pub fn set_link(&self, up: bool) {
        let configured = *self.drop_rate.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(s) = &self.server {
            s.faults().update(|f| f.drop_rate = if up { configured } else { 1.0 });
        }
    }

    /// How many times task `number` was handed over (mode 1 or 2).
    pub fn received(&self, number: u16) -> u32 {
        self.engine.lock().unwrap_or_else(|p| p.into_inner()).received.get(&number).copied().unwrap_or(0)
    }

    /// Cancels (mode 3) received.
    pub fn cancels(&self) -> u32 {
        self.engine.lock().unwrap_or_else(|p| p.into_inner()).cancels
    }

    /// Hand-overs refused because the crane was busy (rackd should cause none).
    pub fn refused(&self) -> u32 {
        self.engine.lock().unwrap_or_else(|p| p.into_inner()).refused
    }

    /// Requests that reached the crane's server so far, dropped ones included (0 once it is
    /// shut down). Tests wait on it to know rackd has polled the crane again, instead of
    /// sleeping a fixed time before asserting that something did not happen.
    pub fn requests_seen(&self) -> u64 {
        self.server.as_ref().map_or(0, |s| s.faults().requests_seen())
    }

    /// Action state (D203).
    pub fn action(&self) -> u16 {
        self.word(203)
    }

    /// Runs one text command (see the module doc); returns what to print.
    pub fn command(&self, line: &str) -> Result<String, CommandError> {
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            ["alarm", code] => {
                let code: u16 = code.parse().map_err(|_| CommandError::AlarmCode(code.to_string()))?;
                self.raise_alarm(code);
                Ok(format!("alarm {code}: {}", crate::wire::alarms::lookup(code).text))
            }
            ["clear"] => Ok({
                self.clear_alarm();
                "alarm cleared".into()
            }),
            ["heartbeat", on @ ("on" | "off")] => Ok({
                self.set_heartbeat(*on == "on");
                format!("heartbeat {on}")
            }),
            ["handshake", on @ ("on" | "off")] => Ok({
                self.set_handshake(*on == "on");
                format!("handshake {on}")
            }),
            ["hold", at @ ("ack" | "start" | "off")] => Ok({
                self.hold(match *at {
                    "ack" => Some(Hold::BeforeAck),
                    "start" => Some(Hold::BeforeStart),
                    _ => None,
                });
                format!("hold {at}")
            }),
            ["force"] => Ok(if self.force_complete() { "force-completed (30)" } else { "no task" }.into()),
            ["drop"] => Ok({
                self.drop_link();
                "link dropped once".into()
            }),
            ["link", on @ ("on" | "off")] => Ok({
                self.set_link(*on == "on");
                format!("link {on}")
            }),
            ["status"] => Ok(format!(
                "action {} task {} alarm {} load {} travel {} lift {} stb {} ack {} violations {}",
                self.word(203),
                self.word(208),
                self.word(205),
                self.word(206),
                self.word(220),
                self.word(221),
                self.word(21),
                self.word(225),
                self.violations()
            )),
            _ => Err(CommandError::Unknown(line.to_string())),
        }
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

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn text_commands_hold_the_hand_over_and_status_counts_violations() {
        let sim = CraneSim::start("127.0.0.1:0", CraneSimOptions::default()).await.unwrap();
        let hold = || sim.engine.lock().unwrap().hold;
        assert_eq!(sim.command("hold ack").unwrap(), "hold ack");
        assert_eq!(hold(), Some(Hold::BeforeAck));
        assert_eq!(sim.command("hold start").unwrap(), "hold start");
        assert_eq!(hold(), Some(Hold::BeforeStart));
        assert_eq!(sim.command("hold off").unwrap(), "hold off");
        assert_eq!(hold(), None);
        assert!(matches!(sim.command("hold later"), Err(CommandError::Unknown(_))));
        let status = sim.command("status").unwrap();
        assert!(status.ends_with("stb 0 ack 0 violations 0"), "{status}");
        sim.shutdown().await;
    }
}
