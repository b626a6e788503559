//! What machines mean: device adapters that turn jobs into a machine's own commands and
//! follow them to their end, over any protocol (through [`crate::protocols::PlcMemory`]).
//!
//! Each configured device runs as one task that owns its PLC connection; the rest of rackd
//! talks to it through a [`DeviceHandle`]: a wake-up when new work arrives, requests
//! (cancel, pause, resume) answered by the device task, and a status snapshot.

pub mod config;
pub mod follow;
pub mod shelf;
pub mod status;

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
