//! What machines mean: device adapters that turn jobs into a machine's own commands and
//! follow them to their end, over any protocol (through [`crate::protocols::PlcMemory`]).
//!
//! Each configured device runs as one task that owns its PLC connection. It gets its work
//! from the dispatcher and reports what became of it through a narrow [`port::Port`]; it
//! publishes its status through a `watch` ([`status::StatusCell`]); the rest of rackd
//! reaches it through a [`DeviceHandle`]: the status receiver and requests (cancel)
//! answered by the device task, which alone hands work to the machine.

pub mod cancel;
pub mod crane;
pub mod gate;
pub mod port;
pub mod repeats;
pub mod shelf;
pub mod status;
pub mod tags;

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Duration;

use tokio::sync::{mpsc, oneshot, watch};
use tracing::Instrument;

use crate::config::devices::DeviceConfig;

pub use cancel::{CancelRefusal, Withdrawal};
pub use status::{DeviceStatus, StatusCell};

/// What the rest of rackd may ask of a device task.
#[derive(Debug)]
pub enum DeviceRequest {
    /// Cancel a job of this device, or say that the device does not hold it.
    Cancel {
        /// The job.
        job: i64,
        /// What the device did, or why it cannot.
        reply: oneshot::Sender<Result<Withdrawal, CancelRefusal>>,
    },
    /// Which of these jobs the device holds (written into a slot, or being handed to the
    /// machine). Asked between two rounds of the device task, so whatever hand-over began
    /// before is recorded by the time it answers.
    Holding {
        /// The jobs.
        jobs: Vec<i64>,
        /// Those of them it holds.
        reply: oneshot::Sender<Vec<i64>>,
    },
    /// End the task at its next safe point (a reload stops or restarts the device): never
    /// between writing a task and the end of its handshake. A shelf stops between two
    /// rounds; a crane first finishes a hand-over under way (see [`crane`]); a tags device
    /// at once. Whoever asks waits for the task's end.
    Stop,
}

/// The handle to one running device.
#[derive(Clone)]
pub struct DeviceHandle {
    /// The latest status, as the device task publishes it.
    pub status: watch::Receiver<DeviceStatus>,
    /// Requests to the device task.
    pub requests: mpsc::Sender<DeviceRequest>,
    /// Tag values and writes (tags devices only).
    pub tags: Option<tags::TagsHandle>,
    /// The flight recorder of its link (none when `capture_bytes` is 0).
    pub recorder: Option<Arc<crate::capture::Recorder>>,
}

impl DeviceHandle {
    /// A copy of the current status.
    pub fn status(&self) -> DeviceStatus {
        self.status.borrow().clone()
    }

    /// Asks the device task about cancelling `job`; `None` if the task has stopped.
    pub async fn cancel(&self, job: i64) -> Option<Result<Withdrawal, CancelRefusal>> {
        let (reply, answer) = oneshot::channel();
        self.requests.send(DeviceRequest::Cancel { job, reply }).await.ok()?;
        answer.await.ok()
    }

    /// Asks the device task to end at its next safe point ([`DeviceRequest::Stop`]); false
    /// if it has already stopped.
    pub async fn stop(&self) -> bool {
        self.requests.send(DeviceRequest::Stop).await.is_ok()
    }

    /// Which of `jobs` the device holds (see [`DeviceRequest::Holding`]); `None` if its
    /// task has stopped.
    pub async fn holding(&self, jobs: Vec<i64>) -> Option<Vec<i64>> {
        let (reply, answer) = oneshot::channel();
        self.requests.send(DeviceRequest::Holding { jobs, reply }).await.ok()?;
        answer.await.ok()
    }
}

/// Every configured device, by id.
pub type Devices = Arc<BTreeMap<String, DeviceHandle>>;

/// A device ready to run: its link opened (lazily: nothing is sent yet) and its adapter
/// built, its task not yet started. Building it is what can fail (a bad address, a serial
/// port that cannot be set up), so a reload builds every device it starts before it stops
/// any ([`prepare`]).
pub struct Prepared {
    /// The device's id.
    pub id: String,
    /// Its handle, valid once it runs.
    pub handle: DeviceHandle,
    run: std::pin::Pin<Box<dyn std::future::Future<Output = ()> + Send>>,
}

impl Prepared {
    /// Starts the device's task.
    pub fn spawn(self) -> (String, DeviceHandle, tokio::task::JoinHandle<()>) {
        (self.id, self.handle, tokio::spawn(self.run))
    }
}

/// Opens the link of the device `c` describes and builds its adapter; `port` is its port
/// to the dispatcher; contact bookkeeping reaches status watchers at most every
/// `contact_refresh`. With `gate` (the active node of a cluster), every request to the
/// machine asks it first ([`gate::Gated`]).
pub async fn prepare(
    c: &DeviceConfig,
    port: Arc<dyn port::Port>,
    contact_refresh: Duration,
    gate: Option<gate::MayDrive>,
) -> anyhow::Result<Prepared> {
    use anyhow::Context;
    let id = c.id();
    let plc = crate::protocols::link::connect(c.link()).await.with_context(|| format!("device {id:?}"))?;
    let recorder = plc.recorder();
    let plc = match gate {
        Some(may) => Arc::new(gate::Gated::new(plc, may)),
        None => plc,
    };
    let slots = match c {
        DeviceConfig::Shelf(s) => s.slots,
        DeviceConfig::Crane(_) => 1,
        DeviceConfig::Tags(_) => 0,
    };
    let link = c.link();
    let mut status = DeviceStatus::new(id, c.kind(), link.protocol.name(), &link.address, slots);
    status.aisles = c.aisles().to_vec();
    let status = StatusCell::new(status, contact_refresh);
    let receiver = status.subscribe();
    let (requests, inbox) = mpsc::channel(16);
    let context = || format!("device {id:?}");
    let mut tags = None;
    // Everything the device task logs carries the device's id from this span.
    let span = tracing::info_span!("device", device = %id);
    let run: std::pin::Pin<Box<dyn std::future::Future<Output = ()> + Send>> = match c {
        DeviceConfig::Shelf(c) => {
            let shelf = shelf::Shelf::new(c.clone(), plc, port, status).with_context(context)?;
            Box::pin(shelf.run(inbox).instrument(span))
        }
        DeviceConfig::Crane(c) => {
            let crane = crane::Crane::new(c.clone(), plc, port, status).with_context(context)?;
            Box::pin(crane.run(inbox).instrument(span))
        }
        DeviceConfig::Tags(c) => {
            let (device, handle) = tags::TagDevice::new(c.clone(), plc, status).with_context(context)?;
            tags = Some(handle);
            Box::pin(device.run(inbox).instrument(span))
        }
    };
    let handle = DeviceHandle { status: receiver, requests, tags, recorder };
    Ok(Prepared { id: id.to_owned(), handle, run })
}

/// Waits `period` while a device task cannot answer requests yet (its recovery failed and
/// is tried again after the wait): true as soon as a [`DeviceRequest::Stop`] comes (the
/// task ends: it has sent nothing it must finish). [`DeviceRequest::Holding`] is answered
/// at once, with none: the task has handed nothing over since it started, and what the
/// machine holds from before, its recovery reconciles as the jobs' state says. Cancels are
/// kept in `later`, to be answered once the device knows what it holds.
pub(crate) async fn wait_recovering(
    period: Duration,
    requests: &mut mpsc::Receiver<DeviceRequest>,
    later: &mut Vec<DeviceRequest>,
) -> bool {
    let until = tokio::time::Instant::now() + period;
    loop {
        tokio::select! {
            _ = tokio::time::sleep_until(until) => return false,
            Some(request) = requests.recv() => match request {
                DeviceRequest::Stop => return true,
                DeviceRequest::Holding { reply, .. } => drop(reply.send(Vec::new())),
                other => later.push(other),
            },
        }
    }
}
