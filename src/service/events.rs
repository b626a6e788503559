//! Live events: the hub that hands each committed event to every subscriber.
//!
//! The writer calls [`Hub::publish`] after each commit with the events it appended,
//! in sequence order. Each event is serialized once, to the text subscribers receive, and
//! shared by all of them. The hub is a bounded broadcast ring of commits (one entry holds
//! all of a commit's events, so a batch of thousands of jobs is one entry, not a burst that
//! would overrun every subscriber at once): publishing never waits for a subscriber, and a
//! subscriber that falls more than the ring's size behind learns so on its next receive
//! (and is told to resync, see [`crate::api::ws`]) instead of slowing the writer or the
//! other subscribers.
//!
//! The hub also keeps the sequence number of the newest event published ([`Hub::published`]):
//! a replay from the log stops there. An event beyond it is committed but not yet told,
//! because on SQLite it may not be on disk yet (the writer publishes only after its sync, see
//! `store::writer::durable`). A subscriber is never sent what a power cut could take back.

use std::sync::Arc;
use std::sync::atomic::{AtomicI64, Ordering};

use bytes::Bytes;
use tokio::sync::broadcast;

use crate::store::events::StoredEvent;

/// What subscribers can filter on; an event's topic follows from its type's prefix.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Topic {
    /// `job.updated`
    Jobs,
    /// `device.updated`
    Devices,
    /// `alarm.raised`, `alarm.cleared`
    Alarms,
    /// `location.updated`
    Locations,
    /// `audit.recorded`: every audited change but a submission (whose jobs' `job.updated`
    /// tell of it); no snapshot part: the log is `GET /api/v1/audit`.
    Audit,
    /// `config.reloaded`: the configuration was reloaded; no snapshot part: the running
    /// one is `GET /api/v1/config`.
    Config,
}

impl Topic {
    /// Every topic.
    pub const ALL: [Topic; 6] =
        [Topic::Jobs, Topic::Devices, Topic::Alarms, Topic::Locations, Topic::Audit, Topic::Config];

    /// The topic of an event type.
    pub fn of(kind: &str) -> Option<Topic> {
        match kind.split('.').next()? {
            // A sequence is jobs in an order: its changes go with the jobs.
            "job" | "sequence" => Some(Topic::Jobs),
            "device" => Some(Topic::Devices),
            "alarm" => Some(Topic::Alarms),
            "location" => Some(Topic::Locations),
            "audit" => Some(Topic::Audit),
            "config" => Some(Topic::Config),
            _ => None,
        }
    }

    /// The topic's name in `?topics=`.
    pub fn as_str(self) -> &'static str {
        match self {
            Topic::Jobs => "jobs",
            Topic::Devices => "devices",
            Topic::Alarms => "alarms",
            Topic::Locations => "locations",
            Topic::Audit => "audit",
            Topic::Config => "config",
        }
    }

    /// A topic by its name.
    pub fn parse(name: &str) -> Option<Topic> {
        Topic::ALL.into_iter().find(|t| t.as_str() == name)
    }
}

/// One committed event, ready to send.
#[derive(Debug)]
pub struct Published {
    /// Its sequence number.
    pub seq: i64,
    /// Its topic (None for a type no topic covers: sent to everyone).
    pub topic: Option<Topic>,
    /// `{"seq", "time", "type", "data"}` as sent: UTF-8, serialized once and shared by
    /// every subscriber (a clone is a reference count).
    pub text: Bytes,
}

impl Published {
    /// A stored event, serialized for subscribers.
    pub fn new(event: &StoredEvent) -> Published {
        Published { seq: event.seq, topic: Topic::of(&event.kind), text: Bytes::from(event.to_json()) }
    }
}

/// The events of one commit, in sequence order.
pub type Commit = Arc<[Published]>;

/// The fan-out point between the writer and the WebSocket sessions.
#[derive(Clone)]
pub struct Hub {
    tx: broadcast::Sender<Commit>,
    published: PublishedSeq,
}

/// The sequence number of the newest event published: what a replay may go up to.
#[derive(Clone, Debug)]
pub struct PublishedSeq(Arc<AtomicI64>);

impl PublishedSeq {
    /// The number now.
    pub fn get(&self) -> i64 {
        self.0.load(Ordering::Acquire)
    }
}

impl Hub {
    /// A hub that lets a subscriber fall `capacity` commits behind before it must resync.
    /// `last` is the newest event in the log when rackd starts: it is on disk, so replays
    /// may go up to it.
    pub fn new(capacity: usize, last: i64) -> Hub {
        let published = PublishedSeq(Arc::new(AtomicI64::new(last)));
        Hub { tx: broadcast::channel(capacity.max(1)).0, published }
    }

    /// The newest event published, as it moves (a session holds it without holding the
    /// hub, whose sender would keep the stream open at shutdown).
    pub fn published(&self) -> PublishedSeq {
        self.published.clone()
    }

    /// Hands one commit's events, in sequence order, to every subscriber.
    pub fn publish(&self, events: Vec<StoredEvent>) {
        if let Some(last) = events.last() {
            self.published.0.fetch_max(last.seq, Ordering::AcqRel);
        }
        if self.tx.receiver_count() == 0 {
            // Nobody listens: the log keeps the events for later replays.
            return;
        }
        let _ = self.tx.send(events.iter().map(Published::new).collect());
    }

    /// A new subscription: every commit published from now on.
    pub fn subscribe(&self) -> broadcast::Receiver<Commit> {
        self.tx.subscribe()
    }

    /// How many subscribers there are.
    pub fn subscribers(&self) -> usize {
        self.tx.receiver_count()
    }

    /// The writer hook that publishes through this hub.
    pub fn hook(&self) -> crate::store::writer::Publish {
        let hub = self.clone();
        Arc::new(move |events| hub.publish(events))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stored(seq: i64, kind: &str) -> StoredEvent {
        StoredEvent { seq, at: 0, kind: kind.into(), data: "{}".into() }
    }

    #[test]
    fn topics_follow_the_type() {
        assert_eq!(Topic::of("job.updated"), Some(Topic::Jobs));
        assert_eq!(Topic::of("alarm.cleared"), Some(Topic::Alarms));
        assert_eq!(Topic::of("device.updated"), Some(Topic::Devices));
        assert_eq!(Topic::of("location.updated"), Some(Topic::Locations));
        assert_eq!(Topic::of("nothing"), None);
        assert!(Topic::ALL.iter().all(|t| Topic::parse(t.as_str()) == Some(*t)));
    }

    #[test]
    fn the_published_number_follows_every_commit_with_or_without_subscribers() {
        let hub = Hub::new(4, 7);
        let published = hub.published();
        assert_eq!(published.get(), 7, "the log's newest at start");
        hub.publish(vec![stored(8, "job.updated"), stored(9, "job.updated")]);
        assert_eq!(published.get(), 9, "no subscriber: published all the same");
        let _subscriber = hub.subscribe();
        hub.publish(vec![stored(10, "alarm.raised")]);
        hub.publish(Vec::new());
        assert_eq!(published.get(), 10);
    }

    #[tokio::test]
    async fn a_subscriber_that_falls_behind_is_told_so() {
        let hub = Hub::new(2, 0);
        let mut fast = hub.subscribe();
        let mut slow = hub.subscribe();
        hub.publish(vec![stored(1, "job.updated")]);
        assert_eq!(fast.recv().await.unwrap()[0].seq, 1);
        // A commit of many events is one entry: no lag for anyone.
        hub.publish((2..=100).map(|s| stored(s, "job.updated")).collect());
        let commit = fast.recv().await.unwrap();
        assert_eq!(commit.iter().map(|p| p.seq).collect::<Vec<_>>(), (2..=100).collect::<Vec<_>>());
        assert_eq!(commit[0].topic, Some(Topic::Jobs));
        hub.publish(vec![stored(101, "alarm.raised")]);
        assert_eq!(fast.recv().await.unwrap()[0].seq, 101);
        assert!(matches!(slow.recv().await, Err(broadcast::error::RecvError::Lagged(1))));
    }
}
