//! What machines mean: device adapters that turn jobs into a machine's own commands and
//! follow them to their end, over any protocol (through [`crate::protocols::PlcMemory`]).
//!
//! Each configured device runs as one task that owns its PLC connection; the rest of rackd
//! talks to it through a [`DeviceHandle`]: a wake-up when new work arrives, requests
//! (cancel, pause, resume) answered by the device task, and a status snapshot.

pub mod config;
pub mod crane;
pub mod follow;
pub mod shelf;
pub mod status;
pub mod tags;

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};

use tokio::sync::{Notify, mpsc, oneshot};

pub use config::{DeviceConfig, DeviceKind};
pub use status::DeviceStatus;

/// What the rest of rackd may ask of a device task.
#[derive(Debug)]
pub enum DeviceRequest {
    /// Cancel a job of this device; answered with why not when it cannot be done safely.
    Cancel {
        /// The job.
        job: i64,
        /// Ok once cancelled and recorded; Err(reason) otherwise.
        reply: oneshot::Sender<Result<(), String>>,
    },
}

/// The handle to one running device.
#[derive(Clone)]
pub struct DeviceHandle {
    /// Wakes the device task when new work may be waiting.
    pub wake: Arc<Notify>,
    /// The latest status, kept up to date by the device task.
    pub status: Arc<Mutex<DeviceStatus>>,
    /// Requests to the device task.
    pub requests: mpsc::Sender<DeviceRequest>,
    /// Tag values and writes (tags devices only).
    pub tags: Option<tags::TagsHandle>,
}

impl DeviceHandle {
    /// A copy of the current status.
    pub fn status(&self) -> DeviceStatus {
        self.status.lock().unwrap_or_else(|p| p.into_inner()).clone()
    }

    /// Pauses or resumes the device (a paused device gets no new work; what it runs goes on).
    pub fn set_paused(&self, paused: bool) -> DeviceStatus {
        self.status.lock().unwrap_or_else(|p| p.into_inner()).paused = paused;
        self.wake.notify_one();
        self.status()
    }

    /// Asks the device task to cancel `job`.
    pub async fn cancel(&self, job: i64) -> Result<(), String> {
        let (reply, answer) = oneshot::channel();
        self.requests
            .send(DeviceRequest::Cancel { job, reply })
            .await
            .map_err(|_| "the device task has stopped".to_string())?;
        answer.await.map_err(|_| "the device task has stopped".to_string())?
    }
}

/// Every configured device, by id.
pub type Devices = Arc<BTreeMap<String, DeviceHandle>>;

/// A wake-up per configured device, made before the job writer so that the writer can wake
/// a device the moment a job for it is committed.
pub fn wakers(configs: &[DeviceConfig]) -> BTreeMap<String, Arc<Notify>> {
    configs.iter().map(|c| (c.id().to_owned(), Arc::new(Notify::new()))).collect()
}

/// The writer hook that wakes a job's device when queued work for it is committed.
pub fn wake_hook(wakers: BTreeMap<String, Arc<Notify>>) -> crate::store::writer::Wake {
    Arc::new(move |job: &crate::store::Job| {
        if job.state == crate::domain::JobState::Queued
            && let Some(n) = job.device.as_ref().and_then(|d| wakers.get(d))
        {
            n.notify_one();
        }
    })
}

/// Connects to every device and starts its task.
pub async fn start(
    configs: &[DeviceConfig],
    mut wakers: BTreeMap<String, Arc<Notify>>,
    writer: &crate::store::writer::Writer,
    pool: &sqlx::SqlitePool,
) -> anyhow::Result<(Devices, Vec<tokio::task::JoinHandle<()>>)> {
    use anyhow::Context;
    let mut devices = BTreeMap::new();
    let mut tasks = Vec::new();
    for c in configs {
        let id = c.id();
        let plc =
            crate::protocols::link::connect(c.link()).await.with_context(|| format!("device {id:?}"))?;
        let slots = match c {
            DeviceConfig::Shelf(s) => s.slots,
            DeviceConfig::Crane(_) => 1,
            DeviceConfig::Tags(_) => 0,
        };
        let link = c.link();
        let mut status = DeviceStatus::new(id, c.kind(), link.protocol.name(), &link.address, slots);
        status.aisles = c.aisles().to_vec();
        let status = Arc::new(Mutex::new(status));
        let (requests, inbox) = mpsc::channel(16);
        let wake = wakers.remove(id).unwrap_or_default();
        let context = || format!("device {id:?}");
        let mut tag_handle = None;
        let task = match c {
            DeviceConfig::Shelf(c) => {
                let shelf = shelf::Shelf::new(c.clone(), plc, writer.clone(), pool.clone(), status.clone())
                    .with_context(context)?;
                tokio::spawn(shelf.run(wake.clone(), inbox))
            }
            DeviceConfig::Crane(c) => {
                let crane = crane::Crane::new(c.clone(), plc, writer.clone(), pool.clone(), status.clone())
                    .with_context(context)?;
                tokio::spawn(crane.run(wake.clone(), inbox))
            }
            DeviceConfig::Tags(c) => {
                let (device, handle) = tags::TagDevice::new(c.clone(), plc, status.clone())
                    .map_err(anyhow::Error::msg)
                    .with_context(context)?;
                tag_handle = Some(handle);
                tokio::spawn(device.run(inbox))
            }
        };
        tasks.push(task);
        devices.insert(id.to_owned(), DeviceHandle { wake, status, requests, tags: tag_handle });
    }
    Ok((Arc::new(devices), tasks))
}
