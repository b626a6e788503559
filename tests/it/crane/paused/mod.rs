//! The crane's time logic on paused tokio time, in one process: the real crane adapter
//! ([`Crane`]) drives the real simulator engine ([`Engine`]) through the simulator's own D
//! registers, so a 10 s heartbeat timeout takes milliseconds and its bounds are exact.
//!
//! Why not the MC 3E server over a socket, as the other crane tests do: with paused time tokio
//! advances the clock whenever the runtime is idle, also while it waits on socket I/O, so
//! timeouts would fire at random. The link here is [`Memory`], a `PlcMemory` over the
//! simulator's bank; the crane engine advances as the simulator's own ticker does (after
//! every write from rackd, and every `tick`). The dispatcher is [`TestPort`]: jobs in a map,
//! reports walked through the domain's state machine ([`path`]), pause as a flag. The
//! machine side and the adapter are the real code; the wire (covered end to end over real
//! sockets by the other crane tests) and the database are not in these tests.

mod alarms;
mod handshake;
mod heartbeat;
mod reload;

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use crate::support::eventually_every;
pub use crate::support::port::TestPort;
use async_trait::async_trait;
use rackd::config::devices::{CraneConfig, DeviceKind};
use rackd::devices::crane::Crane;
use rackd::devices::{DeviceRequest, DeviceStatus, StatusCell};
use rackd::domain::{Job, JobSpec, JobState, Location, Reported};
use rackd::protocols::mc3e::{Bank, Device, SharedBank, address};
use rackd::protocols::{Address, PlcError, PlcMemory};
use rackd::sim::crane::engine::Engine;
use tokio::sync::{mpsc, watch};
use tokio::task::JoinHandle;
use tokio::time::Instant;

/// One write rackd made: when, the first D register, the words.
#[derive(Clone, Debug, PartialEq)]
pub struct Write {
    pub at: Instant,
    pub start: u32,
    pub words: Vec<u16>,
}

/// Called with the engine before it sees a write (a test changing the crane's mind at an
/// exact step of the protocol).
pub type Hook = Box<dyn FnMut(&mut Engine, &Write) + Send>;

/// The simulated crane's memory as rackd's `PlcMemory`: reads and writes of D registers,
/// each write followed by an engine step (the simulator's write hook), every write logged.
pub struct Memory {
    bank: SharedBank,
    engine: Arc<Mutex<Engine>>,
    writes: Mutex<Vec<Write>>,
    requests: AtomicU64,
    hook: Mutex<Option<Hook>>,
}

impl Memory {
    fn step(&self) {
        let mut bank = self.bank.lock().unwrap();
        self.engine.lock().unwrap().tick(&mut bank, Instant::now());
    }

    fn d(address: &Address) -> Result<u32, PlcError> {
        match Device::of_area(&address.area)? {
            Device::D => Ok(address.index),
            _ => Err(PlcError::OutOfRange("the crane interface is in D registers")),
        }
    }
}

#[async_trait]
impl PlcMemory for Memory {
    fn parse_address(&self, text: &str) -> Result<Address, PlcError> {
        address::parse_address(text)
    }

    async fn read_words(&self, start: &Address, count: u16) -> Result<Vec<u16>, PlcError> {
        self.requests.fetch_add(1, Ordering::Relaxed);
        let n = Self::d(start)?;
        let bank = self.bank.lock().unwrap();
        bank.read_words(Device::D, n, count).map_err(|_| PlcError::OutOfRange("past the bank"))
    }

    async fn write_words(&self, start: &Address, values: &[u16]) -> Result<(), PlcError> {
        self.requests.fetch_add(1, Ordering::Relaxed);
        let write = Write { at: Instant::now(), start: Self::d(start)?, words: values.to_vec() };
        self.bank
            .lock()
            .unwrap()
            .write_words(Device::D, write.start, values)
            .map_err(|_| PlcError::OutOfRange("past the bank"))?;
        if let Some(hook) = self.hook.lock().unwrap().as_mut() {
            hook(&mut self.engine.lock().unwrap(), &write);
        }
        self.writes.lock().unwrap().push(write);
        self.step();
        Ok(())
    }

    async fn read_bits(&self, _: &Address, _: u16) -> Result<Vec<bool>, PlcError> {
        Err(PlcError::OutOfRange("the crane interface has no bits"))
    }

    async fn write_bits(&self, _: &Address, _: &[bool]) -> Result<(), PlcError> {
        Err(PlcError::OutOfRange("the crane interface has no bits"))
    }
}

/// A crane adapter and a simulated crane in one process.
pub struct Rig {
    pub memory: Arc<Memory>,
    pub port: Arc<TestPort>,
    pub status: watch::Receiver<DeviceStatus>,
    /// The device task's request inbox (kept open).
    pub requests: mpsc::Sender<DeviceRequest>,
    device: JoinHandle<()>,
    ticker: JoinHandle<()>,
}

impl Rig {
    /// Starts the crane (action states of `step`) and rackd's adapter for it, configured as
    /// `edit` says on top of: poll every 100 ms, heartbeat every 100 ms, lost after 10 s,
    /// each hand-over step bounded by 1 s.
    pub fn start(step: Duration, edit: impl FnOnce(&mut CraneConfig)) -> Rig {
        let mut config = CraneConfig::new("crane1", "in-memory", vec![2]);
        config.poll_ms = 100;
        config.heartbeat_ms = 100;
        config.heartbeat_timeout_ms = 10_000;
        config.handshake_timeout_ms = 1000;
        edit(&mut config);
        let memory = Arc::new(Memory {
            bank: Bank::default().shared(),
            engine: Arc::new(Mutex::new(Engine::new(step))),
            writes: Mutex::default(),
            requests: AtomicU64::new(0),
            hook: Mutex::default(),
        });
        // The simulator's ticker: every step / 5, between 1 and 20 ms (`rackd sim crane`).
        let tick = (step / 5).clamp(Duration::from_millis(1), Duration::from_millis(20));
        let ticker = tokio::spawn({
            let memory = memory.clone();
            async move {
                loop {
                    tokio::time::sleep(tick).await;
                    memory.step();
                }
            }
        });
        let port = Arc::new(TestPort::default());
        let status = StatusCell::new(
            DeviceStatus::new("crane1", DeviceKind::Crane, "mc3e", "in-memory", 1),
            Duration::from_secs(5),
        );
        let receiver = status.subscribe();
        let crane = Crane::new(config, memory.clone(), port.clone(), status).unwrap();
        let (requests, inbox) = mpsc::channel(4);
        let device = tokio::spawn(crane.run(inbox));
        Rig { memory, port, status: receiver, requests, device, ticker }
    }

    /// The crane's D register `n`.
    pub fn word(&self, n: u32) -> u16 {
        self.memory.bank.lock().unwrap().word(Device::D, n)
    }

    /// Sets D register `n` as the crane would (an alarm in D205).
    pub fn set_word(&self, n: u32, v: u16) {
        self.memory.bank.lock().unwrap().set_word(Device::D, n, v);
    }

    /// Changes the simulated crane's behaviour.
    pub fn engine(&self, change: impl FnOnce(&mut Engine)) {
        change(&mut self.memory.engine.lock().unwrap());
    }

    /// Reads the simulated crane's counters.
    pub fn engine_says<T>(&self, read: impl FnOnce(&Engine) -> T) -> T {
        read(&self.memory.engine.lock().unwrap())
    }

    /// Sets the hook called before the engine sees each write.
    pub fn on_write(&self, hook: Hook) {
        *self.memory.hook.lock().unwrap() = Some(hook);
    }

    /// Requests rackd made of the crane so far.
    pub fn requests_seen(&self) -> u64 {
        self.memory.requests.load(Ordering::Relaxed)
    }

    /// rackd's writes so far to D register `n` (as the first word written), with their
    /// instants.
    pub fn writes_to(&self, n: u32) -> Vec<(Instant, Vec<u16>)> {
        let writes = self.memory.writes.lock().unwrap();
        writes.iter().filter(|w| w.start == n).map(|w| (w.at, w.words.clone())).collect()
    }

    /// Queues a job for the crane (as the writer hands a committed job to the dispatcher).
    pub fn queue(&self, spec: JobSpec) -> i64 {
        self.port.queue(spec)
    }

    /// Pauses or resumes the device, as the dispatcher's control state does.
    pub fn set_paused(&self, paused: bool) {
        self.port.set_paused(paused);
    }

    /// Job `id` as the port holds it.
    pub fn job(&self, id: i64) -> Job {
        self.port.job_as_held(id)
    }

    /// The reports of job `id`, in order.
    pub fn reports(&self, id: i64) -> Vec<Reported> {
        self.port.reports_of(id)
    }

    /// Waits until the status satisfies `pred`, for at most `limit` of (virtual) time;
    /// returns the instant it first did. A change at the very instant the limit ends may be
    /// seen after the timeout fires: give exact bounds a millisecond more.
    pub async fn until(
        &mut self,
        what: &str,
        limit: Duration,
        pred: impl Fn(&DeviceStatus) -> bool,
    ) -> Instant {
        let deadline = Instant::now() + limit;
        loop {
            if pred(&self.status.borrow_and_update()) {
                return Instant::now();
            }
            match tokio::time::timeout_at(deadline, self.status.changed()).await {
                Ok(changed) => changed.expect("the device task runs"),
                Err(_) => panic!("the device never {what} within {limit:?}: {:?}", *self.status.borrow()),
            }
        }
    }

    /// Waits until job `id` is in `state`, for at most `limit`; returns the instant.
    pub async fn until_job(&self, id: i64, state: JobState, limit: Duration) -> Instant {
        eventually_every(Duration::from_millis(1), format!("job {id} {state}"), limit, async || {
            let job = self.job(id);
            if job.state == state { Ok(Instant::now()) } else { Err(job) }
        })
        .await
    }

    /// Waits until the device task has ended (a stop), for at most `limit`; returns the
    /// instant.
    pub async fn until_stopped(&mut self, limit: Duration) -> Instant {
        eventually_every(Duration::from_millis(1), "the device task to end", limit, async || {
            self.device.is_finished()
        })
        .await;
        Instant::now()
    }

    /// Waits until rackd has made `more` further requests of the crane (bounded by 60 s of
    /// virtual time): the positive sign that it went round its loop again.
    pub async fn polls(&self, more: u64) {
        let from = self.requests_seen();
        let what = format!("{more} more requests of the crane");
        eventually_every(Duration::from_millis(1), what, Duration::from_secs(60), async || {
            self.requests_seen() >= from + more
        })
        .await;
    }

    /// Stops the adapter (rackd gone); the crane keeps running.
    pub fn stop_rackd(&self) {
        self.device.abort();
    }
}

impl Drop for Rig {
    fn drop(&mut self) {
        self.device.abort();
        self.ticker.abort();
    }
}

/// A location in the crane aisle 2.
pub fn at(row: u16, bay: u16, level: u16, side: u16) -> Location {
    Location { aisle: 2, row, bay, level, position: side }
}

/// A travel job to `to`.
pub fn travel(to: Location) -> JobSpec {
    JobSpec::Travel { to }
}
