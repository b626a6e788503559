//! Webhooks: the event log pushed to a WMS over HTTP, signed, at least once and in order
//! (`[[webhooks]]`, [`crate::config::webhooks`]).
//!
//! The `events` table is the outbox: the writer appends each change's events in the commit
//! of the change, with a gapless `seq`. Each subscription has a cursor in the store (the
//! last `seq` it is done with) and one task on the node that drives the machines
//! ([`deliver`]), which reads the log after its cursor and POSTs each event of its types,
//! one at a time, in `seq` order, until the receiver answers 2xx.
//!
//! Decisions:
//! - **At least once.** The cursor moves in the same commit as the deliveries that moved
//!   it (the writer's [`Record::Webhook`](crate::store::writer::Record::Webhook)), after
//!   the receiver's 2xx, never before. A crash between the two, or a timeout after the
//!   receiver acted, sends the event again with the same `webhook-id` (`NAME-SEQ`), which a
//!   receiver de-duplicates on. Deliveries are committed in small groups (at most one
//!   write in flight per subscription), so a crash repeats at most the events of the
//!   groups not yet committed. A cursor that moved only over events of types the
//!   subscription does not take is written with its next delivery, or within a second:
//!   a site's stream of device events costs the writer nothing per commit.
//! - **Only what is on disk, in order.** A subscription reads no further than the hub's
//!   published seq: an event a power cut could take back is never sent. It wakes on each
//!   commit the hub publishes.
//! - **A new subscription starts from now**: the log's newest event when it is first seen.
//!   `POST /api/v1/webhooks/{name}/replay` sends older ones again (as far back as the log
//!   keeps them).
//! - **Retries** wait `backoff_ms`, doubling each time up to `max_backoff_ms`, with jitter
//!   (uniformly between half and all of the wait), for as long as it takes: an event is
//!   never skipped. Failures in a row for `alarm_after_secs` raise the `webhook` alarm
//!   (code 0) on device `webhook:NAME`; the next success clears it.
//! - **410 Gone pauses, loudly.** The receiver (or a proxy in front of it, which may say
//!   so for its own reasons) says it is not coming back: the subscription pauses, as
//!   paused by the receiver ([`PausedBy`], told apart
//!   from an administrator's pause in the API, the alarm and the row), raises the
//!   `webhook` alarm with code 2, and retention goes on holding its events as for a
//!   subscription that delivers, so the WMS can catch up once it is resumed. A resume
//!   clears the alarm; an administrator's pause of it makes it theirs (no alarm, nothing
//!   held). A 410 is not taken as the end of a subscription: that is the configuration's
//!   to say.
//! - **Retention waits** for the lowest cursor of the subscriptions that are configured
//!   and not paused by an administrator, up to `events.webhook_hold_hours` beyond the log's
//!   retention; past that, events go all the same, and the subscription that finds the gap
//!   raises the `webhook` alarm with code 1, saying which events it lost, until it catches
//!   up.
//! - **A subscription never stops the machines.** Its secret and CA file are read when
//!   the configuration is loaded ([`crate::config::webhooks`]); a subscription that cannot
//!   start all the same (a configuration built in code whose files are gone, a client that
//!   does not build) raises the `webhook` alarm with code 3 and stays stopped until rackd
//!   starts again or another node takes over, while everything else starts: the machines
//!   are driven. Its cursor, read by its own task, is not needed to start the rest.
//! - **Hot standby**: only the node that drives the machines delivers (its deliverers start
//!   and stop with the devices), every request first asks the lease's gate (as a device's
//!   request does), and its writes are fenced: a node that lost its lease sends nothing
//!   more and cannot move a cursor. The new active node starts from the stored cursor.
//! - **Never on the job path**: deliverers read the log through the pool and write through
//!   the writer's queue like any record; a slow or dead receiver holds only its own task.
//!   A deliverer listens to the hub's commits only while it waits for one, so one held by
//!   its receiver pins no commits in memory (`bench webhooks --neighbours`).

mod client;
mod deliver;
mod send;
pub mod sign;

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};

use tokio::sync::{mpsc, oneshot};
use tokio::task::JoinHandle;

use crate::config::WebhookConfig;
use crate::devices::gate::MayDrive;
use crate::domain::Who;
use crate::service::events::Hub;
use crate::store::Pool;
use crate::store::webhooks::{PausedBy, Row};
use crate::store::writer::{WriteError, Writer};

pub use client::BODY_LIMIT;

/// What a `webhook` alarm asks a person to do.
pub const ACTION: &str = "Check that the WMS's receiver is up and answers 2xx (its last error is on \
     GET /api/v1/webhooks and the dashboard); rackd keeps every event and retries by itself.";

/// What the `webhook` alarm with code 2 (paused by the receiver's 410 Gone) asks.
pub const GONE_ACTION: &str = "Ask whoever runs the WMS's receiver (or the proxy in front of it) why it \
     answered 410 Gone. Once it takes events again, resume the subscription (POST \
     /api/v1/webhooks/NAME/resume, or the dashboard): it goes on from the event it stopped at, and \
     rackd holds its events until then, up to events.webhook_hold_hours.";

/// What the `webhook` alarm with code 3 (the subscription cannot start) asks.
pub const START_ACTION: &str = "Fix what the alarm names (the subscription's secret_file or ca_file), \
     then restart rackd or let another node take over. The machines are driven meanwhile; the \
     subscription's cursor stays where it was.";

/// The device the `webhook` alarms of subscription `name` are raised on.
pub fn alarm_device(name: &str) -> String {
    format!("webhook:{name}")
}

/// What an operator asks of a subscription.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Action {
    /// Stop delivering (deliveries in flight end first).
    Pause,
    /// Deliver again.
    Resume,
    /// Deliver again from this seq on (the cursor goes to the seq before it).
    Replay(i64),
}

impl Action {
    /// The audit's name for it.
    pub fn as_str(&self) -> &'static str {
        match self {
            Action::Pause => "pause",
            Action::Resume => "resume",
            Action::Replay(_) => "replay",
        }
    }
}

/// Why an action was not taken.
#[derive(Debug, thiserror::Error)]
pub enum ActionError {
    /// No subscription of that name is configured.
    #[error("no webhook subscription is named {0:?}")]
    Unknown(String),
    /// A replay from before the oldest event the log keeps, or after the newest.
    #[error("the log holds events {first} to {last}: replay from one of them")]
    OutOfLog {
        /// The oldest kept.
        first: i64,
        /// The newest.
        last: i64,
    },
    /// The store refused or is gone.
    #[error(transparent)]
    Write(#[from] WriteError),
    /// The log could not be read.
    #[error("the event log could not be read")]
    Read(#[source] sqlx::Error),
    /// The deliverer stopped (the node is shutting down or lost its lease).
    #[error("the subscription's deliverer is not running")]
    Stopped,
    /// The subscription could not start on this node (its `webhook` alarm, code 3).
    #[error("the subscription could not start: {0}")]
    NotStarted(String),
}

/// A request to a deliverer.
struct Command {
    action: Action,
    who: Who,
    reason: Option<String>,
    reply: oneshot::Sender<Result<Row, ActionError>>,
}

/// The outcomes of a try, as [`Live::outcomes`] counts them (and the metrics list them,
/// each from zero).
pub const OUTCOMES: [&str; 3] = ["delivered", "failed", "gone"];

/// What a subscription's deliverer counts as it works (the metrics and the API's list).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Live {
    /// The row as the deliverer holds it (ahead of the store by the group being written).
    pub row: Row,
    /// The commit time (Unix ms) of the event being delivered, None when caught up.
    pub oldest_pending_at: Option<i64>,
    /// Tries by outcome (one of [`OUTCOMES`]).
    pub outcomes: BTreeMap<&'static str, u64>,
    /// Tries that were a retry of an event.
    pub retries: u64,
}

/// One running subscription.
struct Running {
    config: WebhookConfig,
    live: Arc<Mutex<Live>>,
    commands: mpsc::Sender<Command>,
}

/// The running deliverers of the node that drives the machines.
#[derive(Clone, Default)]
pub struct Webhooks {
    running: Arc<BTreeMap<String, Running>>,
    /// The subscriptions that could not start, and why.
    unstarted: Arc<BTreeMap<String, String>>,
}

/// What a subscription's deliverer needs besides its configuration.
#[derive(Clone)]
pub struct Parts {
    /// Where the log is read.
    pub pool: Pool,
    /// Where cursors and deliveries are written (fenced in a cluster).
    pub writer: Writer,
    /// The commits as they are published (and how far that is).
    pub hub: Hub,
    /// In a cluster, the lease's gate.
    pub gate: Option<MayDrive>,
}

impl Webhooks {
    /// Starts a deliverer per subscription; their tasks are the caller's to stop. One that
    /// cannot start (its secret or CA file unread and unreadable, a client that does not
    /// build) gets a task that raises its `webhook` alarm instead: it never fails the rest.
    pub fn start(configs: &[WebhookConfig], parts: Parts) -> (Webhooks, Vec<JoinHandle<()>>) {
        let mut running = BTreeMap::new();
        let mut unstarted = BTreeMap::new();
        let mut tasks = Vec::new();
        for config in configs {
            let built = config.material().map_err(|e| e.to_string()).and_then(|material| {
                let client = client::client(config, &material).map_err(|e| format!("{e:#}"))?;
                Ok((material.key, client))
            });
            let (key, client) = match built {
                Ok(built) => built,
                Err(why) => {
                    tracing::error!(webhook = %config.name, error = %why,
                        "the webhook subscription cannot start; the machines are driven without it");
                    tasks.push(tokio::spawn(deliver::unstarted(
                        config.name.clone(),
                        why.clone(),
                        parts.clone(),
                    )));
                    unstarted.insert(config.name.clone(), why);
                    continue;
                }
            };
            let live = Arc::new(Mutex::new(Live::default()));
            let (tx, rx) = mpsc::channel(16);
            let deliverer =
                deliver::Deliverer::new(config.clone(), key, client, parts.clone(), live.clone(), rx);
            tasks.push(tokio::spawn(deliverer.run()));
            running.insert(config.name.clone(), Running { config: config.clone(), live, commands: tx });
        }
        (Webhooks { running: Arc::new(running), unstarted: Arc::new(unstarted) }, tasks)
    }

    /// Asks subscription `name` to do `action`, as `who`; answers with its row after.
    pub async fn act(
        &self,
        name: &str,
        action: Action,
        who: Who,
        reason: Option<String>,
    ) -> Result<Row, ActionError> {
        if let Some(why) = self.unstarted.get(name) {
            return Err(ActionError::NotStarted(why.clone()));
        }
        let running = self.running.get(name).ok_or_else(|| ActionError::Unknown(name.to_owned()))?;
        let (reply, answer) = oneshot::channel();
        let command = Command { action, who, reason, reply };
        running.commands.send(command).await.map_err(|_| ActionError::Stopped)?;
        answer.await.map_err(|_| ActionError::Stopped)?
    }

    /// Why subscription `name` could not start on this node, if it could not.
    pub fn unstarted(&self, name: &str) -> Option<&str> {
        self.unstarted.get(name).map(String::as_str)
    }

    /// Each running subscription's configuration and figures, by name.
    pub fn live(&self) -> Vec<(WebhookConfig, Live)> {
        let lock = |l: &Mutex<Live>| l.lock().unwrap_or_else(|p| p.into_inner()).clone();
        self.running.values().map(|r| (r.config.clone(), lock(&r.live))).collect()
    }
}

/// What the log's retention may delete for the subscriptions: the lowest cursor of those
/// in `configs` that an administrator has not paused (`i64::MAX` when none holds
/// anything): one the receiver paused with a 410 still holds its events. A subscription
/// never seen (no row yet) starts from the newest event, which is always kept.
pub fn held_through(configs: &[WebhookConfig], rows: &[Row]) -> i64 {
    configs
        .iter()
        .filter_map(|c| rows.iter().find(|r| r.name == c.name))
        .filter(|r| r.paused_by() != Some(PausedBy::Admin))
        .map(|r| r.cursor)
        .min()
        .unwrap_or(i64::MAX)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn retention_waits_for_the_lowest_active_cursor() {
        let config = |name: &str| WebhookConfig::new(name, "http://wms", &["*"], "");
        let row = |name: &str, cursor, paused| Row { name: name.into(), cursor, paused, ..Row::default() };
        let configs = [config("a"), config("b"), config("c")];
        let rows = [row("a", 50, 0), row("b", 20, 1), row("c", 70, 0), row("gone", 1, 0)];
        assert_eq!(held_through(&configs, &rows), 50, "b is paused; `gone` is not configured");
        let by_receiver = [row("a", 50, 0), row("b", 20, PausedBy::Receiver.stored()), row("c", 70, 0)];
        assert_eq!(held_through(&configs, &by_receiver), 20, "a 410's pause holds what it needs");
        assert_eq!(held_through(&configs[1..2], &rows), i64::MAX);
        assert_eq!(held_through(&[], &rows), i64::MAX);
    }
}

#[cfg(test)]
mod gate_tests;

#[cfg(test)]
mod hold_tests;
