//! One subscriber's connection: start (snapshot or replay), then the live stream, with
//! pings, a send timeout and resync for a subscriber that falls behind; closed (1008) when
//! a reload removes the key it was opened with.

use std::sync::Arc;
use std::time::Duration;

use crate::store::Pool;
use axum::extract::ws::{CloseFrame, Message, Utf8Bytes, WebSocket};
use futures::stream::SplitSink;
use futures::{SinkExt, StreamExt};
use tokio::sync::broadcast::{Receiver, error::RecvError};
use tokio::sync::watch;

use crate::api::state::AppState;
use crate::auth::{KeyHash, KeyRing};
use crate::devices::Devices;
use crate::service::dispatch::Queues;
use crate::service::events::{Commit, PublishedSeq, Topic};
use crate::store::events;

/// Close code sent with `resync`: the client fell behind and should reconnect with `since`.
pub const CLOSE_RESYNC: u16 = 4000;

/// Close code sent when a reload removed the key the session was opened with (1008, policy
/// violation): a revoked key reads nothing more, on a socket opened before as on a request.
pub const CLOSE_REVOKED: u16 = 1008;

/// Events read from the log per query during a replay.
const REPLAY_PAGE: u32 = 1000;

/// Why a session ended early.
#[derive(Debug, thiserror::Error)]
enum End {
    #[error("the client went away or a send failed: {0}")]
    Socket(#[from] axum::Error),
    #[error("a send took longer than {0:?}")]
    Stalled(Duration),
    #[error("reading the database: {0}")]
    Database(#[from] sqlx::Error),
}

/// Everything a session needs, taken from the app state before the upgrade (a session must
/// not hold the job writer, or shutdown would wait for subscribers).
pub struct Session {
    pool: Pool,
    devices: Devices,
    queues: Queues,
    events: Receiver<Commit>,
    published: PublishedSeq,
    topics: Vec<Topic>,
    since: Option<i64>,
    ping: Duration,
    send_timeout: Duration,
    snapshot_jobs: u32,
    metrics: std::sync::Arc<crate::api::metrics::Metrics>,
    /// The hash of the key the session was opened with (none in keyless mode), and the key
    /// ring as reloads change it.
    key: Option<KeyHash>,
    keys: watch::Receiver<Arc<KeyRing>>,
    /// Whether the store commits (`store::fault`).
    store: watch::Receiver<Option<crate::store::fault::Fault>>,
}

type Sink = SplitSink<WebSocket, Message>;

impl Session {
    /// Subscribes to the hub now, so the session misses nothing committed from here on;
    /// `key` is the hash of the key it was opened with.
    pub fn new(app: &AppState, topics: Vec<Topic>, since: Option<i64>, key: Option<KeyHash>) -> Session {
        let options = &app.events;
        Session {
            pool: app.pool.clone(),
            devices: app.devices(),
            queues: app.dispatcher.queues().clone(),
            events: app.hub.subscribe(),
            published: app.hub.published(),
            topics,
            since,
            ping: Duration::from_secs(options.ping_secs),
            send_timeout: Duration::from_secs(options.send_timeout_secs),
            snapshot_jobs: options.snapshot_jobs,
            metrics: app.metrics.clone(),
            key,
            keys: app.reload.watch_keys(),
            store: app.store_fault.subscribe(),
        }
    }

    /// Whether a reload removed the session's key (seen now, so a ring swapped between
    /// the request's check and here counts too).
    fn revoked(&mut self) -> bool {
        let keys = self.keys.borrow_and_update();
        self.key.as_ref().is_some_and(|k| !keys.holds(k))
    }

    /// Runs the session until the client leaves, falls behind or the server stops.
    pub async fn run(mut self, socket: WebSocket) {
        let (mut sink, mut stream) = socket.split();
        let result = async {
            if self.revoked() {
                return self.close(&mut sink, CLOSE_REVOKED, "the API key was revoked").await;
            }
            // The store's state is told after the start, then as it changes; a fault under way
            // is told at once.
            let faulted = self.store.borrow_and_update().is_some();
            let mut last = self.start(&mut sink).await?;
            if faulted || self.store.has_changed().unwrap_or(false) {
                self.tell_store(&mut sink).await?;
            }
            let mut store_watching = true;
            let mut ping = tokio::time::interval_at(tokio::time::Instant::now() + self.ping, self.ping);
            let mut heard = true;
            // Until the ring's sender goes (the server stopping), in sessions opened with a key.
            let mut watching = self.key.is_some();
            loop {
                tokio::select! {
                    changed = self.keys.changed(), if watching => match changed {
                        Ok(()) if self.revoked() => {
                            return self.close(&mut sink, CLOSE_REVOKED, "the API key was revoked").await;
                        }
                        Ok(()) => {}
                        Err(_) => watching = false,
                    },
                    changed = self.store.changed(), if store_watching => match changed {
                        Ok(()) => self.tell_store(&mut sink).await?,
                        Err(_) => store_watching = false,
                    },
                    commit = self.events.recv() => match commit {
                        Ok(commit) => {
                            // Queue the commit's events, then write them out together.
                            let from = last;
                            let mut queued = false;
                            for event in commit.iter().filter(|e| e.seq > from) {
                                last = event.seq;
                                if self.wants(event.topic) {
                                    self.feed(&mut sink, Message::Text(text_of(&event.text))).await?;
                                    queued = true;
                                }
                            }
                            if queued {
                                self.flush(&mut sink).await?;
                            }
                        }
                        Err(RecvError::Lagged(missed)) => {
                            let reason = format!("fell {missed} commits behind; reconnect with since={last}");
                            let resync = super::Resync { kind: "resync", seq: last, reason };
                            let text = serde_json::to_string(&resync).unwrap_or_default();
                            self.metrics.count_resync();
                            self.send(&mut sink, Message::Text(text.into())).await?;
                            return self.close(&mut sink, CLOSE_RESYNC, "resync").await;
                        }
                        Err(RecvError::Closed) => return self.close(&mut sink, 1001, "server stopping").await,
                    },
                    message = stream.next() => match message {
                        Some(Ok(Message::Close(_))) | None | Some(Err(_)) => return Ok(()),
                        Some(Ok(_)) => heard = true,
                    },
                    _ = ping.tick() => {
                        if !heard {
                            return self.close(&mut sink, 1001, "no answer to ping").await;
                        }
                        heard = false;
                        self.send(&mut sink, Message::Ping(Default::default())).await?;
                    }
                }
            }
        }
        .await;
        if let Err(e) = result {
            tracing::debug!(error = %e, "websocket session ended");
        }
    }

    /// Sends the store's state as it is now.
    async fn tell_store(&mut self, sink: &mut Sink) -> Result<(), End> {
        let state = super::StoreState::of(*self.store.borrow_and_update());
        let text = serde_json::to_string(&state).unwrap_or_default();
        self.send(sink, Message::Text(text.into())).await
    }

    fn wants(&self, topic: Option<Topic>) -> bool {
        topic.is_none_or(|t| self.topics.contains(&t))
    }

    /// Sends the replay after `since` when the log still holds it, else a snapshot; returns
    /// the last sequence number covered. The log is read up to the newest event published
    /// (read after subscribing, so what comes after it comes live): what is committed beyond
    /// it is not on disk yet on SQLite (see [`crate::service::events`]).
    async fn start(&mut self, sink: &mut Sink) -> Result<i64, End> {
        let published = self.published.get();
        let (first, end) = events::bounds(&self.pool).await?;
        let end = end.min(published);
        let reason = match self.since {
            None => "requested",
            Some(since) if since > end => "since_unknown",
            Some(since) if since + 1 < first => "since_expired",
            Some(since) => return self.replay(sink, since, end).await,
        };
        let snapshot = super::snapshot::read(
            &self.pool,
            (&self.devices, &self.queues),
            &self.topics,
            self.snapshot_jobs,
            reason,
        )
        .await?;
        let text = serde_json::to_string(&snapshot).unwrap_or_default();
        self.send(sink, Message::Text(text.into())).await?;
        self.metrics.count_snapshot(reason);
        Ok(snapshot.seq)
    }

    /// Sends every event after `since` and up to `end` from the log, page by page.
    async fn replay(&self, sink: &mut Sink, since: i64, end: i64) -> Result<i64, End> {
        let mut last = since;
        loop {
            let page = events::after(&self.pool, last, REPLAY_PAGE).await?;
            for event in &page {
                if event.seq > end {
                    return Ok(last);
                }
                last = event.seq;
                if self.wants(Topic::of(&event.kind)) {
                    self.send(sink, Message::Text(Utf8Bytes::from(event.to_json()))).await?;
                }
            }
            if page.len() < REPLAY_PAGE as usize {
                return Ok(last);
            }
        }
    }

    async fn send(&self, sink: &mut Sink, message: Message) -> Result<(), End> {
        self.bounded(sink.send(message)).await
    }

    async fn feed(&self, sink: &mut Sink, message: Message) -> Result<(), End> {
        self.bounded(sink.feed(message)).await
    }

    async fn flush(&self, sink: &mut Sink) -> Result<(), End> {
        self.bounded(sink.flush()).await
    }

    /// A socket operation that may take at most `send_timeout` (a stalled client is dropped).
    async fn bounded(&self, op: impl Future<Output = Result<(), axum::Error>>) -> Result<(), End> {
        match tokio::time::timeout(self.send_timeout, op).await {
            Ok(result) => Ok(result?),
            Err(_) => Err(End::Stalled(self.send_timeout)),
        }
    }

    async fn close(&self, sink: &mut Sink, code: u16, reason: &'static str) -> Result<(), End> {
        let frame = CloseFrame { code, reason: Utf8Bytes::from_static(reason) };
        self.send(sink, Message::Close(Some(frame))).await
    }
}

/// An event's text as a WebSocket text frame, sharing its bytes (they are the UTF-8 of a
/// `String`, so the check never fails).
fn text_of(bytes: &bytes::Bytes) -> Utf8Bytes {
    Utf8Bytes::try_from(bytes.clone()).unwrap_or_default()
}
