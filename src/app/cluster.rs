//! A cluster node's wiring (`[cluster]`, see `service::cluster`): the leadership loop, the
//! node's row, the event log followed into the hub (and, on the active node, into the
//! queues: jobs the standbys took in; on every node, into the counts of jobs and alarms
//! `/metrics` shows, read again after each batch), and the takeover: driving starts when
//! the lease is won, exactly as at a restart (under the reload's lock: a reload waits, so
//! the node drives the configuration whose hash it reports), and stops the instant it is
//! lost; the process then ends ([`Clustered::lost`]) so that its supervisor starts it again
//! as a standby, with nothing of the old term left in memory.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::Duration;

use tokio::sync::{Notify, mpsc, watch};
use tokio::task::JoinHandle;

use super::drive;
use crate::api::metrics::Metrics;
use crate::config::{ClusterConfig, Config};
use crate::domain::time::now_ms;
use crate::domain::{AlarmClass, AlarmKind};
use crate::service::cluster::DRIFT_ACTION;
use crate::service::cluster::lease::Timing;
use crate::service::cluster::{Leadership, Node, Role, TAKEOVER_ACTION, follow, node};
use crate::service::dispatch::Dispatcher;
use crate::service::events::Hub;
use crate::service::reload::Reload;
use crate::service::webhooks::Webhooks;
use crate::store::alarms::NewAlarm;
use crate::store::writer::{Record, WriteError, Writer};
use crate::store::{Pool, events};

/// The device of the `takeover` alarm.
pub const CLUSTER_DEVICE: &str = "cluster";

/// A running cluster node.
pub(super) struct Clustered {
    /// The node, for the API.
    pub node: Node,
    /// Its leadership loop.
    pub leadership: Leadership,
    /// Set when this node must stop: its lease was lost, or it could not drive.
    pub lost: watch::Receiver<Option<String>>,
    /// The follower, the node's row, the adopter and the takeover.
    pub background: Vec<JoinHandle<()>>,
}

/// What the wiring needs of the rest of the application.
pub(super) struct Parts {
    pub config: Config,
    /// The address the API is bound to (its port, when configured as 0).
    pub listen: std::net::SocketAddr,
    pub pool: Pool,
    pub pg: sqlx::PgPool,
    /// The schema this node knows (`store::schema::Known::latest`).
    pub schema: i64,
    pub dispatcher: Dispatcher,
    pub writer: Writer,
    pub hub: Hub,
    pub metrics: Arc<Metrics>,
    pub commits: Arc<AtomicU64>,
    /// The running configuration (a standby may have reloaded it) and, once driving,
    /// the devices.
    pub reload: Reload,
    pub webhooks: Arc<OnceLock<Webhooks>>,
    pub tasks: drive::Tasks,
}

/// Starts the leadership loop (before the writer: its gate fences the writer's handle).
pub(super) fn lead(pg: &sqlx::PgPool, c: &ClusterConfig) -> (Leadership, Timing) {
    let (lease, margin) = c.lease();
    let timing = Timing { lease, margin };
    (Leadership::start(pg.clone(), c.node.clone(), timing), timing)
}

/// Starts the rest of the node around `leadership`.
pub(super) async fn start(
    c: &ClusterConfig,
    leadership: Leadership,
    timing: Timing,
    parts: Parts,
) -> anyhow::Result<Clustered> {
    let node = Node {
        name: c.node.clone(),
        url: c.url(parts.listen, parts.config.server.tls.is_some()),
        role: leadership.role.clone(),
        gate: leadership.gate.clone(),
        pool: parts.pg.clone(),
        timing,
        takeovers: Arc::new(AtomicU64::new(0)),
        started_at: now_ms(),
        config: parts.reload.watch_loaded(),
        schema: parts.schema,
    };
    let (_, from) = events::bounds(&parts.pool).await?;
    let (adopt, wanted) = mpsc::unbounded_channel();
    let recount = Arc::new(Notify::new());
    // Once at start: what committed between the counts' first read and `from` is counted.
    recount.notify_one();
    let seen: follow::Seen = {
        let (hub, commits, recount) = (parts.hub.clone(), parts.commits.clone(), recount.clone());
        let queues = parts.dispatcher.queues().clone();
        Arc::new(move |batch| {
            if queues.drives() {
                let ids: Vec<i64> = follow::unfinished_jobs(&batch)
                    .into_iter()
                    .filter(|id| queues.find(*id).is_none())
                    .collect();
                if !ids.is_empty() {
                    let _ = adopt.send(ids);
                }
            }
            commits.fetch_add(1, Ordering::Release);
            recount.notify_one();
            hub.publish(batch);
        })
    };
    let (lost_tx, lost) = watch::channel(None);
    let background = vec![
        tokio::spawn(follow::run(parts.pg.clone(), from, timing.poll_every(), seen)),
        tokio::spawn(node::tell(node.clone())),
        tokio::spawn(adopter(parts.writer.clone(), wanted)),
        tokio::spawn(refresh_counts(parts.pool.clone(), parts.metrics.clone(), recount)),
        tokio::spawn(takeover(node.clone(), parts, lost_tx)),
    ];
    Ok(Clustered { node, leadership, lost, background })
}

/// Hands the jobs other nodes took in to this node's queues, through its writer (so they
/// come in its commit order; see `Writer::adopt`).
///
/// A batch the writer could not read (the database failing over, say, or the writer's
/// queue full) is tried again, with a pause, until it is read, and before any later batch:
/// the follower has moved past its events and never hands them on again. It was once dropped with an error logged, and a job
/// a standby took in just before a database failover then waited in the store, unseen by the
/// active node's queues, until the next takeover, while the jobs after it ran
/// (`tests/it/standby/database_failover.rs` found it: a retrieve ran before the store it
/// depended on, and failed). Reading a job again is harmless: the queues take each job as
/// it stands.
async fn adopter(writer: Writer, mut wanted: mpsc::UnboundedReceiver<Vec<i64>>) {
    while let Some(ids) = wanted.recv().await {
        let mut pause = ADOPT_PAUSE.0;
        loop {
            match writer.adopt(ids.clone()).await {
                Ok(_) => break,
                Err(WriteError::Closed) => return,
                // Not the store's trouble: trying again would give the same answer.
                Err(e) if !matches!(e, WriteError::Database(_) | WriteError::Overloaded) => {
                    tracing::error!(error = %e, jobs = ids.len(), "cluster: jobs of another node could not be taken in");
                    break;
                }
                Err(e) => {
                    tracing::warn!(error = %e, jobs = ids.len(), "cluster: jobs of another node could not be taken in yet");
                    tokio::time::sleep(pause).await;
                    pause = (pause * 2).min(ADOPT_PAUSE.1);
                }
            }
        }
    }
}

/// The adopter's first and longest pause between two tries.
const ADOPT_PAUSE: (Duration, Duration) = (Duration::from_millis(50), Duration::from_secs(1));

/// Reads the counts of jobs and alarms again each time the follower hands on a batch (every
/// node commits, so this node's writer alone would miss some; see `store::counts`): one
/// read at a time, and batches followed meanwhile take one more read between them.
async fn refresh_counts(pool: Pool, metrics: Arc<Metrics>, recount: Arc<Notify>) {
    loop {
        recount.notified().await;
        match crate::store::counts::load(&pool).await {
            Ok(counts) => metrics.set_counts(counts),
            Err(e) => {
                tracing::warn!(error = %e, "cluster: the counts of jobs and alarms cannot be read");
                // Tried again at the next batch, or after a pause if none comes.
                tokio::time::sleep(std::time::Duration::from_secs(1)).await;
                recount.notify_one();
            }
        }
    }
}

/// Waits to become active, then drives until the lease is lost.
async fn takeover(node: Node, parts: Parts, lost: watch::Sender<Option<String>>) {
    let mut role = node.role.clone();
    let Ok(won) = role.wait_for(|r| matches!(r, Role::Active { .. })).await.map(|r| *r) else { return };
    let Role::Active { epoch } = won else { return };
    node.takeovers.fetch_add(1, Ordering::Relaxed);
    parts.dispatcher.queues().set_drives(true);
    let fenced = parts.writer.fenced(node.gate.epoch());
    let may = Some(node.gate.may());
    // No reload between reading the configuration and driving it (`service::reload`): the
    // node reports the hash of what it drives.
    let takeover = parts.reload.take_over().await;
    let config = takeover.config();
    match drive::start(config, &parts.pool, &parts.dispatcher, fenced.clone(), &parts.hub, may).await {
        Ok(d) => {
            takeover.drive(d.fleet);
            let _ = parts.webhooks.set(d.webhooks);
            parts.tasks.lock().unwrap_or_else(|p| p.into_inner()).extend(d.tasks);
        }
        Err(e) => {
            tracing::error!(error = %format!("{e:#}"), "cluster: this node won the lease but cannot drive");
            lost.send_replace(Some(format!("this node won the lease but cannot drive the machines: {e:#}")));
            return;
        }
    }
    tracing::info!(node = node.name, epoch, "cluster: this node drives the machines");
    let drift = tokio::spawn(watch_drift(node.clone(), fenced.clone()));
    parts.tasks.lock().unwrap_or_else(|p| p.into_inner()).push(drift);
    if epoch > 1 {
        let alarms = tokio::spawn(tell_takeover(node.clone(), fenced, epoch));
        parts.tasks.lock().unwrap_or_else(|p| p.into_inner()).push(alarms);
    }
    let _ = role.wait_for(|r| *r == Role::Standby).await;
    let tasks = std::mem::take(&mut *parts.tasks.lock().unwrap_or_else(|p| p.into_inner()));
    drive::stop(tasks).await;
    if let Some(fleet) = parts.reload.fleet() {
        fleet.abort().await;
    }
    lost.send_replace(Some("this node lost the cluster's lease; it stopped driving the machines".into()));
}

/// While this node drives: raises `config_drift` while a node seen runs another
/// configuration than this one's, and clears it once none does (checked three times a
/// lease; the nodes tell their hash as often).
async fn watch_drift(node: Node, writer: Writer) {
    let mut raised: Option<Vec<(String, String)>> = None;
    loop {
        if let Ok(view) = node.view().await {
            let drift = node.drift(&view);
            let record = match (&raised, drift.is_empty()) {
                (Some(was), false) if *was == drift => None,
                (_, false) => {
                    let own = node.config.borrow().hash.clone();
                    let others: Vec<String> = drift
                        .iter()
                        .map(|(name, hash)| format!("node {name:?} runs {}", short(hash)))
                        .collect();
                    let text = format!(
                        "the cluster's nodes run different sites: node {:?} (active) runs {}, {}",
                        node.name,
                        short(&own),
                        others.join(", ")
                    );
                    // A new text for a drift that changed: cleared, then raised again.
                    if raised.is_some() {
                        let key = (AlarmKind::ConfigDrift, 0);
                        let _ =
                            writer.record(Record::AlarmCleared { device: CLUSTER_DEVICE.into(), key }).await;
                    }
                    Some(Record::AlarmRaised(NewAlarm {
                        device: CLUSTER_DEVICE.into(),
                        kind: AlarmKind::ConfigDrift,
                        code: 0,
                        class: AlarmKind::ConfigDrift.class(),
                        text,
                        detail: Some("the hash of [site] and [[devices]] (GET /api/v1/cluster)".into()),
                        action: Some(DRIFT_ACTION.into()),
                    }))
                }
                (Some(_), true) => Some(Record::AlarmCleared {
                    device: CLUSTER_DEVICE.into(),
                    key: (AlarmKind::ConfigDrift, 0),
                }),
                (None, true) => None,
            };
            if let Some(record) = record {
                match writer.record(record).await {
                    Ok(()) => raised = (!drift.is_empty()).then_some(drift),
                    Err(e) => {
                        tracing::warn!(error = %e, "cluster: the config_drift alarm could not be recorded")
                    }
                }
            }
        }
        tokio::time::sleep(node.timing.renew_every()).await;
    }
}

/// The first characters of a configuration's hash, as people compare them.
fn short(hash: &str) -> &str {
    &hash[..hash.len().min(8)]
}

/// Raises the `takeover` alarm, and clears it once another node stands by again.
async fn tell_takeover(node: Node, writer: Writer, epoch: i64) {
    let alarm = NewAlarm {
        device: CLUSTER_DEVICE.into(),
        kind: AlarmKind::Takeover,
        code: 0,
        class: AlarmClass::Link,
        text: format!("node {:?} took over driving the machines (epoch {epoch})", node.name),
        detail: None,
        action: Some(TAKEOVER_ACTION.into()),
    };
    if let Err(e) = writer.record(Record::AlarmRaised(alarm)).await {
        tracing::warn!(error = %e, "cluster: the takeover alarm could not be raised");
    }
    loop {
        tokio::time::sleep(node.timing.renew_every()).await;
        let Ok(view) = node.view().await else { continue };
        let fresh = (node.timing.lease * 2).as_millis() as i64;
        let back = view
            .nodes
            .iter()
            .any(|n| n.name != node.name && n.role == "standby" && view.now - n.seen_at < fresh);
        if back {
            let key = (AlarmKind::Takeover, 0);
            match writer.record(Record::AlarmCleared { device: CLUSTER_DEVICE.into(), key }).await {
                Ok(()) => return,
                Err(e) => tracing::warn!(error = %e, "cluster: the takeover alarm could not be cleared"),
            }
        }
    }
}
