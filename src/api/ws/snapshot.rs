//! The state a new subscriber starts from, consistent with one event sequence number.

use crate::store::Pool;
use serde::Serialize;
use utoipa::ToSchema;

use crate::devices::{DeviceStatus, Devices};
use crate::service::dispatch::Queues;
use crate::service::events::Topic;
use crate::service::monitor::all_shown;
use crate::store::alarms::{self, Alarm};
use crate::store::locations::{self, LocationState};
use crate::store::{Job, events, jobs};

/// The first message of a subscription without a usable `since`.
#[derive(Debug, Serialize, ToSchema)]
pub struct Snapshot {
    /// Always `snapshot`.
    #[serde(rename = "type")]
    #[schema(rename = "type")]
    pub kind: &'static str,
    /// The state is as of this event; live events follow from the next one.
    pub seq: i64,
    /// Why a snapshot: `requested`, `since_expired` (the log no longer reaches back that
    /// far) or `since_unknown` (beyond the log's end).
    pub reason: &'static str,
    /// The requested topics' state.
    pub data: SnapshotData,
}

/// What a snapshot holds; only the requested topics are present.
#[derive(Debug, Default, Serialize, ToSchema)]
pub struct SnapshotData {
    /// Jobs not yet ended, newest first (at most `events.snapshot_jobs`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub jobs: Option<Vec<Job>>,
    /// More jobs are active than the snapshot holds.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub jobs_truncated: Option<bool>,
    /// Every device.
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schema(value_type = Option<Vec<DeviceStatus>>)]
    pub devices: Option<Vec<Shown>>,
    /// Active alarms.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub alarms: Option<Vec<Alarm>>,
    /// Every location.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub locations: Option<Vec<LocationState>>,
}

/// A device's status: as its task publishes it, or as the log last told it.
#[derive(Debug, Serialize)]
#[serde(untagged)]
pub enum Shown {
    /// From the device task (this node drives the machines).
    Live(Box<DeviceStatus>),
    /// From the last `device.updated` event (a standby node of a cluster).
    Told(serde_json::Value),
}

/// The newest `device.updated` events a standby's snapshot looks through for each
/// device's last status (a device tells at least every `contact_refresh_ms`).
const TOLD_DEVICES: u32 = 2000;

/// Reads the snapshot in one read transaction, so jobs, alarms and locations are all as of
/// the same `seq`. Device statuses come from memory and may be a little newer, which is
/// harmless: a `device.updated` event carries the whole status and replaces it. A node
/// that runs no devices (a standby of a cluster) shows each device as its last
/// `device.updated` event in the log tells it, as of the same `seq`.
pub async fn read(
    pool: &Pool,
    devices: (&Devices, &Queues),
    topics: &[Topic],
    job_limit: u32,
    reason: &'static str,
) -> Result<Snapshot, sqlx::Error> {
    let mut tx = pool.read_tx().await?;
    let (_, seq) = events::bounds(tx.reader()).await?;
    let mut data = SnapshotData::default();
    if topics.contains(&Topic::Jobs) {
        let mut active = jobs::active(tx.reader(), job_limit.saturating_add(1)).await?;
        data.jobs_truncated = Some(active.len() > job_limit as usize);
        active.truncate(job_limit as usize);
        for job in &mut active {
            devices.1.show(job);
        }
        data.jobs = Some(active);
    }
    if topics.contains(&Topic::Alarms) {
        data.alarms = Some(alarms::active(tx.reader()).await?);
    }
    if topics.contains(&Topic::Locations) {
        data.locations = Some(locations::list(tx.reader(), None).await?);
    }
    if topics.contains(&Topic::Devices) && devices.0.is_empty() {
        data.devices = Some(told(events::latest(tx.reader(), "device.updated", TOLD_DEVICES).await?));
    }
    tx.finish().await?;
    if topics.contains(&Topic::Devices) && !devices.0.is_empty() {
        data.devices =
            Some(all_shown(devices.0, devices.1).into_iter().map(|d| Shown::Live(Box::new(d))).collect());
    }
    Ok(Snapshot { kind: "snapshot", seq, reason, data })
}

/// Each device's newest status among `events` (newest first), by id.
fn told(events: Vec<events::StoredEvent>) -> Vec<Shown> {
    #[derive(serde::Deserialize)]
    struct Id {
        id: String,
    }
    let mut seen = std::collections::BTreeMap::new();
    for e in events {
        if let Ok(Id { id }) = serde_json::from_str(&e.data) {
            seen.entry(id).or_insert(e.data);
        }
    }
    seen.into_values().filter_map(|data| serde_json::from_str(&data).ok()).map(Shown::Told).collect()
}
