//! One subscription's deliverer: reads the log after its cursor, POSTs each event of its
//! types until the receiver answers 2xx, and records every try and the cursor through the
//! writer (the rules are the parent module's).

use std::sync::{Arc, Mutex};
use std::time::Duration;

use tokio::sync::mpsc;
use tokio::task::JoinHandle;

use super::{Action, ActionError, Command, Live, Parts, alarm_device, send};
use crate::config::WebhookConfig;
use crate::domain::AlarmKind;
use crate::domain::time::now_ms;
use crate::store::alarms::{AlarmFilter, NewAlarm};
use crate::store::events::{self, StoredEvent};
use crate::store::webhooks::{Delivery, PausedBy, Progress, Row};
use crate::store::writer::{Record, WriteError};

/// Events read from the log at a time.
const PAGE: u32 = 500;
/// The longest a cursor moved over other types' events stays unwritten.
const SKIPS_WRITTEN_AFTER: Duration = Duration::from_secs(1);

/// A subscription's deliverer.
pub(super) struct Deliverer {
    config: WebhookConfig,
    key: Vec<u8>,
    client: reqwest::Client,
    parts: Parts,
    live: Arc<Mutex<Live>>,
    commands: mpsc::Receiver<Command>,
    /// The row as it now stands.
    row: Row,
    /// Tries not yet handed to the writer.
    pending: Vec<Delivery>,
    /// Whether the row changed since it was last handed to the writer.
    dirty: bool,
    /// Since when the cursor has moved only over events of types this subscription does not
    /// take, unwritten: written with the next delivery, or after [`SKIPS_WRITTEN_AFTER`]
    /// (so a stream of other events does not cost the writer a command per commit).
    skipped_since: Option<tokio::time::Instant>,
    /// The write in flight.
    writing: Option<JoinHandle<Result<(), WriteError>>>,
    /// Since when deliveries have failed, on the monotonic clock, so that a step of the
    /// wall clock does not raise the failing alarm early (`failing_since`, stored, is for
    /// display and for a restart, which starts this from it).
    failing: Option<tokio::time::Instant>,
    /// Whether this deliverer raised the alarms of code 0 (failing), 1 (events lost), 2
    /// (paused by the receiver) and 3 (could not start).
    alarmed: [bool; 4],
    /// Set when the cursor moved by command: the events read are stale.
    moved: bool,
    /// The newest event when the deliverer was made (before rackd serves its API): where a
    /// subscription new to the store starts, so an event committed after rackd said it was
    /// ready is never skipped while the task reads its row.
    newest: i64,
}

/// Why the deliverer stops.
enum Stop {
    /// The writer is closed, or this node's writes are fenced: it no longer drives.
    Writer,
}

impl Deliverer {
    pub(super) fn new(
        config: WebhookConfig,
        key: Vec<u8>,
        client: reqwest::Client,
        parts: Parts,
        live: Arc<Mutex<Live>>,
        commands: mpsc::Receiver<Command>,
    ) -> Deliverer {
        let newest = parts.hub.published().get();
        Deliverer {
            newest,
            config,
            key,
            client,
            parts,
            live,
            commands,
            row: Row::default(),
            pending: Vec::new(),
            dirty: false,
            skipped_since: None,
            failing: None,
            writing: None,
            alarmed: [false; 4],
            moved: false,
        }
    }

    /// Runs until the writer closes or fences this node out: from the subscription's row in
    /// the store, read here (again each second while the store does not answer).
    pub(super) async fn run(mut self) {
        let name = self.config.name.clone();
        let stored = loop {
            match crate::store::webhooks::rows(&self.parts.pool).await {
                Ok(rows) => break rows.into_iter().find(|r| r.name == name),
                Err(e) => {
                    tracing::warn!(webhook = %name, error = %e, "reading the webhook's cursor");
                    tokio::time::sleep(Duration::from_secs(1)).await;
                }
            }
        };
        self.row = match stored {
            Some(row) => row,
            None => {
                // A new subscription starts from the newest event when it was made (see the
                // parent module).
                self.dirty = true;
                Row { name: name.clone(), cursor: self.newest, updated_at: now_ms(), ..Row::default() }
            }
        };
        // Alarms this subscription left active before a restart (or another node's
        // deliverer did) are its own to clear; the others are raised when due.
        let filter =
            AlarmFilter { active: Some(true), device: Some(alarm_device(&name)), before_id: None, limit: 10 };
        let active = crate::store::alarms::list(&self.parts.pool, &filter).await.unwrap_or_else(|e| {
            tracing::warn!(webhook = %name, error = %e, "reading the webhook's alarms");
            Vec::new()
        });
        self.alarmed =
            [0, 1, 2, 3].map(|code| active.iter().any(|a| a.kind == AlarmKind::Webhook && a.code == code));
        // It started: whatever kept it from starting before is over. A receiver's pause is
        // alarmed while the row says so (and only then).
        if self.alarmed[3] {
            self.alarm(3, None).await;
        }
        match (self.row.paused_by() == Some(PausedBy::Receiver), self.alarmed[2]) {
            (true, false) => {
                let text = format!(
                    "webhook {name:?} is paused by its receiver ({}); its events are held for it",
                    self.row.paused_reason.as_deref().unwrap_or("410 Gone")
                );
                self.alarm(2, Some(text)).await;
            }
            (false, true) => self.alarm(2, None).await,
            _ => {}
        }
        self.show(None);
        tracing::info!(webhook = %name, cursor = self.row.cursor, "webhook deliverer started");
        match self.work().await {
            Stop::Writer => tracing::info!(webhook = %name, "webhook deliverer stopped: no writer"),
        }
    }

    async fn work(&mut self) -> Stop {
        loop {
            if let Err(stop) = self.flush(true).await {
                return stop;
            }
            while let Ok(command) = self.commands.try_recv() {
                self.obey(command).await;
            }
            // Subscribed to the hub only while waiting for a commit: a subscriber that does
            // not read (this task, while a slow or dead receiver holds it in `deliver`) pins
            // the hub's last `events.buffer` commits in memory, and makes every commit
            // serialize its events for it. Subscribed before `published` is read, so that a
            // commit published after the read wakes it.
            let mut commits = self.parts.hub.subscribe();
            let published = self.parts.hub.published().get();
            if self.row.paused != 0 || self.row.cursor >= published {
                if self.row.cursor >= published && self.alarmed[1] {
                    self.alarm(1, None).await;
                }
                self.show(None);
                let skips_due = async {
                    match self.skipped_since {
                        Some(since) => tokio::time::sleep_until(since + SKIPS_WRITTEN_AFTER).await,
                        None => std::future::pending().await,
                    }
                };
                tokio::select! {
                    command = self.commands.recv() => match command {
                        Some(command) => self.obey(command).await,
                        None => std::future::pending().await,
                    },
                    // A commit, or a lag (commits were missed): either way, read the log.
                    _ = commits.recv() => {}
                    () = skips_due => self.dirty = true,
                }
                continue;
            }
            drop(commits);
            let page = match events::after(&self.parts.pool, self.row.cursor, PAGE).await {
                Ok(page) => page,
                Err(e) => {
                    tracing::warn!(webhook = %self.config.name, error = %e, "reading the event log");
                    tokio::time::sleep(Duration::from_secs(1)).await;
                    continue;
                }
            };
            self.moved = false;
            if let Some(first) = page.first()
                && first.seq > self.row.cursor + 1
            {
                let lost = format!(
                    "events {} to {} were pruned before they were delivered (events.webhook_hold_hours)",
                    self.row.cursor + 1,
                    first.seq - 1
                );
                tracing::error!(webhook = %self.config.name, "{lost}");
                self.alarm(1, Some(lost)).await;
            }
            for event in page.iter().filter(|e| e.seq <= published) {
                if !self.config.wants(&event.kind) {
                    self.row.cursor = event.seq;
                    self.skipped_since.get_or_insert_with(tokio::time::Instant::now);
                    continue;
                }
                if let Err(stop) = self.deliver(event).await {
                    return stop;
                }
                if self.moved || self.row.paused != 0 {
                    break;
                }
            }
        }
    }

    /// Delivers `event` until it is acknowledged, or the subscription is paused or moved.
    async fn deliver(&mut self, event: &StoredEvent) -> Result<(), Stop> {
        let body = bytes::Bytes::from(event.to_json());
        let id = format!("{}-{}", self.config.name, event.seq);
        let mut attempt = 1;
        loop {
            self.show(Some(event.at));
            while let Ok(command) = self.commands.try_recv() {
                self.obey(command).await;
            }
            if self.moved || self.row.paused != 0 {
                return Ok(());
            }
            if self.parts.gate.as_ref().is_some_and(|may| !may()) {
                // This node is losing its lease: it sends nothing more, and its writer is
                // about to be fenced out.
                tokio::time::sleep(Duration::from_millis(100)).await;
                self.flush(false).await?;
                continue;
            }
            let delivery =
                send::post(&self.client, &self.config, &self.key, (event.seq, &id, &body), attempt).await;
            if let Some(error) = &delivery.error {
                (self.row.last_error, self.row.last_error_at) = (Some(error.clone()), Some(delivery.at));
            }
            let outcome = delivery.outcome.clone();
            self.count(&delivery);
            self.pending.push(delivery);
            self.dirty = true;
            let now = now_ms();
            match outcome.as_str() {
                "delivered" => {
                    self.row.cursor = event.seq;
                    (self.row.last_ok_at, self.row.failing_since) = (Some(now), None);
                    self.failing = None;
                    self.flush(false).await?;
                    if self.alarmed[0] {
                        self.alarm(0, None).await;
                    }
                    return Ok(());
                }
                "gone" => {
                    self.row.paused = PausedBy::Receiver.stored();
                    let why = format!("the receiver answered 410 Gone to event {}", event.seq);
                    self.row.paused_reason = Some(why.clone());
                    tracing::warn!(webhook = %self.config.name, seq = event.seq,
                        "the receiver answered 410 Gone: paused, its events held");
                    self.flush(true).await?;
                    let text = format!(
                        "webhook {:?} is paused by its receiver: {why}; its events are held for it up to \
                         events.webhook_hold_hours",
                        self.config.name
                    );
                    self.alarm(2, Some(text)).await;
                    return Ok(());
                }
                _ => {
                    let since = *self.row.failing_since.get_or_insert(now);
                    let failing = *self.failing.get_or_insert_with(|| {
                        // Failing since before a restart: as long as the stored times say.
                        let before = Duration::from_millis((now - since).max(0) as u64);
                        let mono = tokio::time::Instant::now();
                        mono.checked_sub(before).unwrap_or(mono)
                    });
                    let failed_for = failing.elapsed();
                    let alarm_after = Duration::from_secs(self.config.alarm_after_secs);
                    if failed_for >= alarm_after && !self.alarmed[0] {
                        let error = self.row.last_error.clone().unwrap_or_default();
                        let text = format!(
                            "webhook {:?} has failed every delivery for {} s: {error}",
                            self.config.name,
                            failed_for.as_secs()
                        );
                        self.alarm(0, Some(text)).await;
                    }
                    self.flush(false).await?;
                    let wait = backoff(&self.config, attempt);
                    tokio::select! {
                        _ = tokio::time::sleep(wait) => {}
                        command = self.commands.recv() => if let Some(command) = command {
                            self.obey(command).await;
                        },
                    }
                    attempt += 1;
                }
            }
        }
    }

    /// Does what an operator asked, and answers with the row after it.
    async fn obey(&mut self, command: Command) {
        let Command { action, who, reason, reply } = command;
        let answer = self.apply(&action, who, reason).await;
        let _ = reply.send(answer);
    }

    async fn apply(
        &mut self,
        action: &Action,
        who: crate::domain::Who,
        reason: Option<String>,
    ) -> Result<Row, ActionError> {
        let before = self.row.clone();
        match action {
            Action::Pause => {
                self.row.paused = PausedBy::Admin.stored();
                self.row.paused_reason = Some(match &reason {
                    Some(why) => format!("paused by {}: {why}", who.name),
                    None => format!("paused by {}", who.name),
                });
            }
            Action::Resume => (self.row.paused, self.row.paused_reason) = (0, None),
            Action::Replay(from) => {
                let (first, last) = events::bounds(&self.parts.pool).await.map_err(ActionError::Read)?;
                if *from < first || *from > last {
                    return Err(ActionError::OutOfLog { first, last });
                }
                self.row.cursor = from - 1;
                self.moved = true;
            }
        }
        self.row.updated_at = now_ms();
        // The tries so far first, then the change with its audit entry, in one commit.
        if let Some(write) = self.writing.take() {
            let _ = write.await;
        }
        let progress = Progress { row: self.row.clone(), deliveries: std::mem::take(&mut self.pending) };
        let detail = match action {
            Action::Replay(from) => Some(match &reason {
                Some(why) => format!("from seq {from}: {why}"),
                None => format!("from seq {from}"),
            }),
            _ => reason,
        };
        let audit = Some((action.as_str().to_owned(), detail));
        let written = self.parts.writer.record_as(Record::Webhook { progress, audit }, who).await;
        if let Err(e) = written {
            self.row = before;
            self.moved = false;
            return Err(e.into());
        }
        (self.dirty, self.skipped_since) = (false, None);
        self.show(None);
        // Resumed, or paused by an administrator who has seen it: the receiver's pause is over.
        if self.alarmed[2] && self.row.paused_by() != Some(PausedBy::Receiver) {
            self.alarm(2, None).await;
        }
        Ok(self.row.clone())
    }

    /// Hands the row and the pending tries to the writer: waits for it with `wait`,
    /// otherwise only when no write is in flight (so a fast receiver's deliveries are
    /// committed in groups, one write at a time).
    async fn flush(&mut self, wait: bool) -> Result<(), Stop> {
        if let Some(write) = &self.writing {
            if !wait && !write.is_finished() {
                return Ok(());
            }
            let write = self.writing.take().expect("a write in flight");
            self.settle(write.await)?;
        }
        if self.skipped_since.is_some_and(|since| since.elapsed() >= SKIPS_WRITTEN_AFTER) {
            self.dirty = true;
        }
        if !self.dirty {
            return Ok(());
        }
        (self.dirty, self.skipped_since) = (false, None);
        self.row.updated_at = now_ms();
        let progress = Progress { row: self.row.clone(), deliveries: std::mem::take(&mut self.pending) };
        let writer = self.parts.writer.clone();
        let write =
            tokio::spawn(async move { writer.record(Record::Webhook { progress, audit: None }).await });
        if wait {
            self.settle(write.await)?;
        } else {
            self.writing = Some(write);
        }
        Ok(())
    }

    /// What came of a write: a writer that is gone or fences this node out stops the
    /// deliverer; another failure leaves the row to be written again with the next.
    fn settle(
        &mut self,
        written: Result<Result<(), WriteError>, tokio::task::JoinError>,
    ) -> Result<(), Stop> {
        match written {
            Ok(Ok(())) => {}
            Ok(Err(WriteError::Closed | WriteError::Fenced(_))) => return Err(Stop::Writer),
            Ok(Err(e)) => {
                tracing::warn!(webhook = %self.config.name, error = %e, "recording deliveries");
                self.dirty = true;
            }
            Err(_) => self.dirty = true,
        }
        Ok(())
    }

    /// Raises (`text`) or clears alarm `code` of this subscription.
    async fn alarm(&mut self, code: u16, text: Option<String>) {
        let raised = text.is_some();
        let record = alarm_record(&self.config.name, code, text);
        match self.parts.writer.record(record).await {
            Ok(()) => self.alarmed[usize::from(code)] = raised,
            Err(e) => tracing::warn!(webhook = %self.config.name, error = %e, "recording the webhook alarm"),
        }
    }

    fn count(&self, delivery: &Delivery) {
        let mut live = self.live.lock().unwrap_or_else(|p| p.into_inner());
        let outcome = match delivery.outcome.as_str() {
            "delivered" => "delivered",
            "gone" => "gone",
            _ => "failed",
        };
        *live.outcomes.entry(outcome).or_default() += 1;
        if delivery.attempt > 1 {
            live.retries += 1;
        }
    }

    /// Publishes the row and what is being delivered for the metrics and the API.
    fn show(&self, pending_at: Option<i64>) {
        let mut live = self.live.lock().unwrap_or_else(|p| p.into_inner());
        live.row = self.row.clone();
        live.oldest_pending_at = pending_at;
    }
}

/// The record that raises (`text`) or clears alarm `code` of subscription `name`.
fn alarm_record(name: &str, code: u16, text: Option<String>) -> Record {
    let device = alarm_device(name);
    let action = match code {
        2 => super::GONE_ACTION,
        3 => super::START_ACTION,
        _ => super::ACTION,
    };
    match text {
        Some(text) => Record::AlarmRaised(NewAlarm {
            device,
            kind: AlarmKind::Webhook,
            code,
            class: AlarmKind::Webhook.class(),
            text,
            detail: None,
            action: Some(action.replace("NAME", name)),
        }),
        None => Record::AlarmCleared { device, key: (AlarmKind::Webhook, code) },
    }
}

/// What runs instead of the deliverer of subscription `name`, which cannot start (`why`):
/// its `webhook` alarm with code 3, raised once (tried again each second while the store
/// refuses it).
pub(super) async fn unstarted(name: String, why: String, parts: Parts) {
    let text = format!(
        "webhook {name:?} cannot start: {why}; the machines are driven, its events are not delivered"
    );
    loop {
        match parts.writer.record(alarm_record(&name, 3, Some(text.clone()))).await {
            Ok(()) => return,
            Err(WriteError::Closed | WriteError::Fenced(_)) => return,
            Err(e) => {
                tracing::warn!(webhook = %name, error = %e, "recording the webhook alarm");
                tokio::time::sleep(Duration::from_secs(1)).await;
            }
        }
    }
}

/// How long to wait after the `attempt`th failed try of an event: `backoff_ms` doubled
/// per try, at most `max_backoff_ms`, then a uniform pick between half of it and all.
pub(super) fn backoff(config: &WebhookConfig, attempt: i64) -> Duration {
    let doublings = (attempt - 1).clamp(0, 40) as u32;
    let full = config.backoff_ms.saturating_mul(1u64 << doublings).min(config.max_backoff_ms).max(1);
    Duration::from_millis(rand::random_range(full.div_ceil(2)..=full))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn backoff_doubles_with_jitter_up_to_its_cap() {
        let mut config = WebhookConfig::new("w", "http://wms", &["*"], "");
        (config.backoff_ms, config.max_backoff_ms) = (100, 1000);
        for _ in 0..50 {
            let ms = |attempt| backoff(&config, attempt).as_millis() as u64;
            assert!((50..=100).contains(&ms(1)));
            assert!((100..=200).contains(&ms(2)));
            assert!((400..=800).contains(&ms(4)));
            assert!((500..=1000).contains(&ms(5)) && (500..=1000).contains(&ms(60)));
        }
    }
}
