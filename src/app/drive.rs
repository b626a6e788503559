//! What the node that drives the machines runs: the queues filled from the store, the
//! pauses and locks restored, the devices connected (each reconciling with its own
//! registers before it hands anything over, as after any restart) with their monitors,
//! the waiting-reason watcher and the log's retention. A node of its own starts it at
//! once; a cluster node when it becomes the active one (a takeover is a restart).

use std::sync::Arc;
use std::time::Duration;

use anyhow::Context;
use tokio::task::JoinHandle;

use crate::config::{ARCHIVE_ACTION, Config, RetentionConfig};
use crate::devices::gate::MayDrive;
use crate::domain::AlarmKind;
use crate::domain::time::now_ms;
use crate::service::captures::{self, Freeze};
use crate::service::dispatch::{Dispatcher, Queues};
use crate::service::events::Hub;
use crate::service::fleet::{self, Fleet};
use crate::service::webhooks::{self, Webhooks};
use crate::store::alarms::NewAlarm;
use crate::store::writer::{Record, Writer};
use crate::store::{self, Pool};

/// The driving part, running.
pub(super) struct Drive {
    /// The devices.
    pub fleet: Fleet,
    /// The webhook subscriptions' deliverers.
    pub webhooks: Webhooks,
    /// Their tasks and the rest: stopped before the writer drains.
    pub tasks: Vec<JoinHandle<()>>,
}

/// Starts driving: `writer` is the handle every device-side write goes through (fenced
/// in a cluster), `gate` the check before every request to a machine (in a cluster).
pub(super) async fn start(
    config: &Config,
    pool: &Pool,
    dispatcher: &Dispatcher,
    writer: Writer,
    hub: &Hub,
    gate: Option<MayDrive>,
) -> anyhow::Result<Drive> {
    let queues: &Queues = dispatcher.queues();
    let ids: Vec<String> = config.devices.iter().map(|d| d.id().to_owned()).collect();
    queues.set_stations(&config.site.stations);
    dispatcher.load(ids.iter().map(String::as_str)).await.context("loading the queues")?;
    dispatcher.restore().await.context("restoring pauses and location locks")?;
    let parts = fleet::Parts {
        queues: queues.clone(),
        writer: writer.clone(),
        pool: pool.clone(),
        contact_refresh: Duration::from_millis(config.events.contact_refresh_ms),
        gate: gate.clone(),
        freeze: Some(Freeze::new(
            config.retention.captures(&config.database.path),
            &config.retention,
            pool.clone(),
            Duration::from_secs(config.events.retention_hours.saturating_mul(3600)),
        )),
    };
    let fleet = Fleet::start(&config.devices, parts).await?;
    let parts = webhooks::Parts { pool: pool.clone(), writer: writer.clone(), hub: hub.clone(), gate };
    let (webhooks, mut tasks) = Webhooks::start(&config.webhooks, parts);
    tasks.push(tokio::spawn(crate::service::dispatch::waiting::watch(queues.clone(), writer.clone())));
    tasks.push(tokio::spawn(crate::service::dispatch::release::watch(
        queues.clone(),
        pool.clone(),
        writer.clone(),
    )));
    tasks.push(tokio::spawn(retention(pool.clone(), writer.clone(), config.clone())));
    let folder = config.retention.folder(&config.database.path);
    tasks.push(tokio::spawn(archive(pool.clone(), writer, config.retention.clone(), folder)));
    Ok(Drive { fleet, webhooks, tasks })
}

/// Deletes events older than the retention from the log, at start and then every tenth of
/// the retention (at most hourly); those a webhook subscription not paused by an
/// administrator has not delivered yet stay up to `events.webhook_hold_hours` longer
/// (`service::webhooks`).
async fn retention(pool: Pool, writer: Writer, config: Config) {
    let hours = |h: u64| Duration::from_secs(h.saturating_mul(3600));
    let keep = hours(config.events.retention_hours);
    let hold = hours(config.events.webhook_hold_hours);
    let mut tick = tokio::time::interval((keep / 10).min(Duration::from_secs(3600)));
    loop {
        tick.tick().await;
        let before_ms = now_ms().saturating_sub(keep.as_millis() as i64);
        let hard_ms = before_ms.saturating_sub(hold.as_millis() as i64);
        let through = match store::webhooks::rows(&pool).await {
            Ok(rows) => webhooks::held_through(&config.webhooks, &rows),
            Err(e) => {
                tracing::warn!(error = %e, "reading the webhooks' cursors: the log is not pruned this time");
                continue;
            }
        };
        let folder = config.retention.captures(&config.database.path);
        let max_bytes = config.retention.captures_max_bytes;
        match tokio::task::spawn_blocking(move || captures::prune(&folder, keep, max_bytes)).await {
            Ok(Ok(pruned)) => pruned.log(),
            Ok(Err(e)) => tracing::warn!(error = %e, "retention: the alarm captures could not be pruned"),
            Err(e) => tracing::warn!(error = %e, "retention: pruning the alarm captures did not finish"),
        }
        match writer.record(Record::Prune { before_ms, through, hard_ms }).await {
            Ok(()) => {}
            Err(store::writer::WriteError::Closed) => return,
            Err(e) => tracing::warn!(error = %e, "pruning the event log"),
        }
    }
}

/// Moves the jobs that ended before midnight UTC `jobs_days` days ago to the archive in
/// `folder` (`store::archive`), at start and then every hour. A run that fails deleted
/// nothing: it raises the `archive` alarm, which the next run that works clears.
async fn archive(pool: Pool, writer: Writer, retention: RetentionConfig, folder: std::path::PathBuf) {
    let days = retention.jobs_days;
    let mut tick = tokio::time::interval(retention.every);
    loop {
        tick.tick().await;
        let today = crate::domain::time::now().date();
        let before = today.saturating_sub(time::Duration::days(days.min(36_500) as i64));
        let how = store::archive::Delete::Writer(&writer);
        let record = match store::archive::archive(&pool, before, &folder, how).await {
            Ok(done) => {
                if done.jobs > 0 {
                    tracing::info!(jobs = done.jobs, files = done.files.len(), kept = done.kept, before = %before,
                        "retention: ended jobs archived");
                }
                Record::AlarmCleared { device: ARCHIVE_DEVICE.into(), key: (AlarmKind::Archive, 0) }
            }
            Err(e) => {
                tracing::error!(error = %e, "retention: archiving ended jobs failed; nothing was deleted");
                Record::AlarmRaised(NewAlarm {
                    device: ARCHIVE_DEVICE.into(),
                    kind: AlarmKind::Archive,
                    code: 0,
                    class: AlarmKind::Archive.class(),
                    text: format!("ended jobs could not be archived: {e}"),
                    detail: None,
                    action: Some(ARCHIVE_ACTION.into()),
                })
            }
        };
        match writer.record(record).await {
            Ok(()) => {}
            Err(store::writer::WriteError::Closed) => return,
            Err(e) => tracing::warn!(error = %e, "retention: the archive alarm could not be recorded"),
        }
    }
}

/// The device an `archive` alarm is raised on.
pub const ARCHIVE_DEVICE: &str = "store";

/// Stops the tasks and waits for them to end.
pub(super) async fn stop(tasks: Vec<JoinHandle<()>>) {
    for task in &tasks {
        task.abort();
    }
    for task in tasks {
        let _ = task.await;
    }
}

/// A shared list of the driving tasks, filled when driving starts.
pub(super) type Tasks = Arc<std::sync::Mutex<Vec<JoinHandle<()>>>>;
