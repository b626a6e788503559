//! The devices this node drives, each with its task and its monitor, as a reload changes
//! them (issue 43): one device stopped, started or restarted while every other runs on
//! untouched, its link never reopened.
//!
//! Decisions:
//! - **Stopping** asks the device task to stop at its next safe point
//!   ([`DeviceRequest::Stop`](crate::devices::DeviceRequest::Stop): never between writing
//!   a task and its handshake's end; a crane finishes a hand-over under way first) and
//!   waits for the task, then for its monitor, which records the device's last status and
//!   ends with it. Only then does a restarted device's new task start: two tasks never
//!   talk to one machine at once, and the new monitor takes up the alarms the old one left.
//! - A device started again recovers from its own registers before it takes work, as
//!   after a restart: a shelf finds its tasks in their slots, a crane its task and any
//!   hand-over not over.
//! - A removed device's active alarms are cleared once it has stopped: nobody watches them
//!   any more (a restart clears them too).
//! - At shutdown every task is aborted between two requests, as before: the hand-over
//!   order and recovery make that the same as a crash.

use std::collections::{BTreeMap, BTreeSet};
use std::sync::{Arc, Mutex, RwLock};
use std::time::Duration;

use tokio::task::JoinHandle;

use super::dispatch::Queues;
use super::monitor;
use crate::config::devices::DeviceConfig;
use crate::devices::gate::MayDrive;
use crate::devices::{self, Devices, Prepared};
use crate::store::Pool;
use crate::store::writer::Writer;

/// What starting a device takes.
#[derive(Clone)]
pub struct Parts {
    /// The dispatcher's queues: each device's port.
    pub queues: Queues,
    /// What devices report through (fenced in a cluster).
    pub writer: Writer,
    /// The store, for the monitors' active alarms.
    pub pool: Pool,
    /// `events.contact_refresh_ms`.
    pub contact_refresh: Duration,
    /// The cluster's check before every request to a machine.
    pub gate: Option<MayDrive>,
    /// Where a device's last seconds go when it raises a `hardware` or `link` alarm.
    pub freeze: Option<super::captures::Freeze>,
}

/// The running devices.
#[derive(Clone)]
pub struct Fleet(Arc<Inner>);

struct Inner {
    devices: RwLock<Devices>,
    tasks: Mutex<BTreeMap<String, Tasks>>,
    parts: Parts,
}

/// A device's task and its monitor's.
struct Tasks {
    device: JoinHandle<()>,
    monitor: JoinHandle<()>,
}

impl Fleet {
    /// Starts every device of `configs`, after clearing the alarms of devices no longer
    /// configured. A `certificate` alarm is no device's: it is the alarm of the node that
    /// serves the certificate (device `tls:NODE`, raised before this node drives anything,
    /// maybe by a standby), which that node's watch clears itself; nor is a node's
    /// `config_reload` (a refused reload of its file, which the node clears itself, and
    /// which a takeover does not end).
    pub async fn start(configs: &[DeviceConfig], parts: Parts) -> anyhow::Result<Fleet> {
        let ids: BTreeSet<&str> = configs.iter().map(|c| c.id()).collect();
        let mut active = monitor::active(&parts.pool).await;
        for keys in active.values_mut() {
            keys.retain(|(kind, _)| *kind != crate::domain::AlarmKind::Certificate);
        }
        for (device, keys) in active.iter_mut().filter(|(device, _)| !ids.contains(device.as_str())) {
            keys.retain(|(kind, _)| *kind != crate::domain::AlarmKind::ConfigReload);
            monitor::clear(device, keys, &parts.writer).await;
        }
        let fleet = Fleet(Arc::new(Inner { devices: RwLock::default(), tasks: Mutex::default(), parts }));
        for c in configs {
            let prepared = fleet.prepare(c).await?;
            let alarms = active.remove(c.id()).unwrap_or_default();
            fleet.run(prepared, Some(alarms)).await;
        }
        Ok(fleet)
    }

    /// The running devices, by id.
    pub fn devices(&self) -> Devices {
        self.0.devices.read().unwrap_or_else(|p| p.into_inner()).clone()
    }

    /// Builds the device `c` describes without starting it ([`devices::prepare`]).
    pub async fn prepare(&self, c: &DeviceConfig) -> anyhow::Result<Prepared> {
        let p = &self.0.parts;
        let port = p.queues.port(c.id(), p.writer.clone());
        devices::prepare(c, port, p.contact_refresh, p.gate.clone()).await
    }

    /// Starts a prepared device, its monitor (taking up `alarms`, its active alarms; read
    /// from the store when `None`), and the dispatcher's watch on its status.
    pub async fn run(&self, prepared: Prepared, alarms: Option<BTreeSet<monitor::Key>>) {
        let p = &self.0.parts;
        let alarms = match alarms {
            Some(alarms) => alarms,
            None => monitor::active(&p.pool).await.remove(&prepared.id).unwrap_or_default(),
        };
        let (id, handle, device) = prepared.spawn();
        let monitor = monitor::watch(&id, &handle, &p.queues, p.writer.clone(), alarms, p.freeze.clone());
        p.queues.watch_device(&id, handle.status.clone());
        self.edit(|d| drop(d.insert(id.clone(), handle)));
        self.tasks().insert(id, Tasks { device, monitor });
    }

    /// Stops a device at its next safe point and waits for it and its monitor to end; with
    /// `removed`, clears its active alarms then.
    pub async fn stop(&self, id: &str, removed: bool) {
        let handle = self.devices().get(id).cloned();
        let tasks = self.tasks().remove(id);
        if let Some(handle) = &handle {
            handle.stop().await;
        }
        if let Some(Tasks { device, monitor }) = tasks {
            let _ = device.await;
            let _ = monitor.await;
        }
        let p = &self.0.parts;
        p.queues.unwatch_device(id);
        self.edit(|d| drop(d.remove(id)));
        if removed && let Some(keys) = monitor::active(&p.pool).await.get(id) {
            monitor::clear(id, keys, &p.writer).await;
        }
    }

    /// Aborts every task (shutdown) and waits for them to end.
    pub async fn abort(&self) {
        let all = std::mem::take(&mut *self.tasks());
        for t in all.values() {
            t.device.abort();
            t.monitor.abort();
        }
        for t in all.into_values() {
            let _ = t.device.await;
            let _ = t.monitor.await;
        }
    }

    fn tasks(&self) -> std::sync::MutexGuard<'_, BTreeMap<String, Tasks>> {
        self.0.tasks.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Changes the map of devices: readers keep the map they took.
    fn edit(&self, change: impl FnOnce(&mut BTreeMap<String, devices::DeviceHandle>)) {
        let mut devices = self.0.devices.write().unwrap_or_else(|p| p.into_inner());
        let mut map = (**devices).clone();
        change(&mut map);
        *devices = Arc::new(map);
    }
}
