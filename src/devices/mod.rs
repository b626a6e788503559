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

/// Connects to every device and starts its task; `port` gives each device that runs jobs
/// its port to the dispatcher; contact bookkeeping reaches status watchers at most every
/// `contact_refresh`. With `gate` (the active node of a cluster), every request to a
/// machine asks it first ([`gate::Gated`]).
pub async fn start(
    configs: &[DeviceConfig],
    port: impl Fn(&str) -> Arc<dyn port::Port>,
    contact_refresh: Duration,
    gate: Option<gate::MayDrive>,
) -> anyhow::Result<(Devices, Vec<tokio::task::JoinHandle<()>>)> {
    use anyhow::Context;
    let mut devices = BTreeMap::new();
    let mut tasks = Vec::new();
    for c in configs {
        let id = c.id();
        let plc =
            crate::protocols::link::connect(c.link()).await.with_context(|| format!("device {id:?}"))?;
        let plc = match &gate {
            Some(may) => Arc::new(gate::Gated::new(plc, may.clone())),
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
        let mut tag_handle = None;
        // Everything the device task logs carries the device's id from this span.
        let span = tracing::info_span!("device", device = %id);
        let task = match c {
            DeviceConfig::Shelf(c) => {
                let shelf = shelf::Shelf::new(c.clone(), plc, port(id), status).with_context(context)?;
                tokio::spawn(shelf.run(inbox).instrument(span))
            }
            DeviceConfig::Crane(c) => {
                let crane = crane::Crane::new(c.clone(), plc, port(id), status).with_context(context)?;
                tokio::spawn(crane.run(inbox).instrument(span))
            }
            DeviceConfig::Tags(c) => {
                let (device, handle) = tags::TagDevice::new(c.clone(), plc, status).with_context(context)?;
                tag_handle = Some(handle);
                tokio::spawn(device.run(inbox).instrument(span))
            }
        };
        tasks.push(task);
        devices.insert(id.to_owned(), DeviceHandle { status: receiver, requests, tags: tag_handle });
    }
    Ok((Arc::new(devices), tasks))
}
