//! A device's status as the API shows it, and the watch it travels through.
//!
//! Each device task owns a [`StatusCell`], the sending side of a `tokio::sync::watch`:
//! the API reads the latest status from its receiver and the service's monitor wakes on
//! each change. What changes on every poll (last contact, failures in a row) is contact
//! bookkeeping: it is always current for readers, but wakes watchers at most every
//! `refresh`, so a fleet of devices polled twice a second does not publish twice a second.
//!
//! The link's health ([`LinkStats`], from the protocol client) is copied in with each
//! contact. Its counters, round trip and timeout are bookkeeping too; `degraded` flipping
//! is told at once (the service raises a warning alarm on it). A link error in
//! `last_error` clears on the next successful request, so a device that recovered does not
//! keep showing an old failure (an error an adapter sets while the link answers, such as a
//! crane's handshake timeout, stays until the adapter clears it); `last_error_at` keeps
//! when the last error was set, whoever set it ([`StatusCell`] stamps it).

use std::time::Duration;

use serde::Serialize;
use time::OffsetDateTime;
use tokio::sync::watch;
use tokio::time::Instant;
use utoipa::ToSchema;

use crate::config::devices::DeviceKind;
use crate::protocols::transport::LinkStats;

/// What rackd knows of a device right now.
#[derive(Clone, Debug, PartialEq, Serialize, ToSchema)]
#[schema(example = json!({"id": "shelf1", "kind": "shelf", "protocol": "modbus-udp", "address": "127.0.0.1:1502",
    "aisles": [1], "online": true, "paused": false, "last_contact": "2026-11-21T08:00:00.000Z", "slots_total": 60,
    "slots_in_use": 3, "consecutive_failures": 0, "last_error": null, "last_error_at": "2026-11-21T07:58:12.000Z",
    "link": {"degraded": false, "requests": 1200, "retries": 3, "timeouts": 3, "stale": 0, "foreign": 0,
    "malformed": 0, "srtt_ms": 0.41, "timeout_ms": 20.0}}))]
pub struct DeviceStatus {
    /// The device's id from the configuration.
    pub id: String,
    /// What kind of machine it is.
    pub kind: DeviceKind,
    /// How rackd talks to it.
    pub protocol: String,
    /// Where it is.
    pub address: String,
    /// The aisles whose locations it serves (from the configuration).
    pub aisles: Vec<u16>,
    /// It answered recently (fewer than the configured number of consecutive failures).
    pub online: bool,
    /// Paused by an operator: gets no new work (the device is paused, or every aisle it
    /// serves is). Control state, kept by the service's dispatcher and shown here; a device
    /// task never sets it.
    pub paused: bool,
    /// Who paused the device, when and why; null while it is not paused itself.
    pub pause: Option<crate::domain::Pause>,
    /// The aisles it serves that are paused: jobs there wait.
    pub paused_aisles: Vec<u16>,
    /// When it last answered.
    #[serde(with = "time::serde::rfc3339::option")]
    #[schema(value_type = Option<String>, format = DateTime)]
    pub last_contact: Option<OffsetDateTime>,
    /// Task slots (shelf PLC) or task places it has.
    pub slots_total: u16,
    /// Slots holding rackd's work.
    pub slots_in_use: u16,
    /// Requests in a row that failed.
    pub consecutive_failures: u32,
    /// The last error, while it lasts: cleared by the next successful request.
    pub last_error: Option<String>,
    /// When the last error happened (kept after it cleared).
    #[serde(with = "time::serde::rfc3339::option")]
    #[schema(value_type = Option<String>, format = DateTime)]
    pub last_error_at: Option<OffsetDateTime>,
    /// The link's health: adaptive timeout, degraded flag and counters.
    pub link: LinkStats,
    /// When a shelf PLC answered with every slot empty where rackd had tasks (it lost its
    /// memory: a power cycle?); null again once it takes new work.
    #[serde(with = "time::serde::rfc3339::option")]
    #[schema(value_type = Option<String>, format = DateTime)]
    pub memory_lost_at: Option<OffsetDateTime>,
    /// What a stacker crane reports (cranes only; absent for other kinds).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub crane: Option<CraneStatus>,
    /// Each tag's latest value, by name (tags devices only; absent for other kinds).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tags: Option<std::collections::BTreeMap<String, crate::wire::tags::TagStatus>>,
}

/// A stacker crane's own registers, as last read.
#[derive(Clone, Debug, Default, PartialEq, Serialize, ToSchema)]
pub struct CraneStatus {
    /// The registers below have been read since rackd started (until then they are zeros,
    /// not the crane's word).
    pub known: bool,
    /// The crane's heartbeat moves (false once it stalled for the configured time).
    pub heartbeat_ok: bool,
    /// While the heartbeat counts as lost: when the crane's D200 last changed (or, if it
    /// has not changed since rackd started watching, that start). Null while it moves.
    #[serde(with = "time::serde::rfc3339::option")]
    #[schema(value_type = Option<String>, format = DateTime)]
    pub heartbeat_stalled_since: Option<OffsetDateTime>,
    /// Current action state (D203): 0 idle, 1..18 motion, 20/30/40 awaiting acknowledgement,
    /// 100 homing.
    pub action_state: u16,
    /// The action state in words.
    pub action: String,
    /// Travel axis position (D220).
    pub travel_position: u16,
    /// Lift axis position (D221).
    pub lift_position: u16,
    /// Load on the platform (D206; 0 = empty).
    pub load: u16,
    /// Task number the crane holds (D208; 0 = none).
    pub task: u16,
    /// Active alarm code (D205), if any.
    pub alarm_code: Option<u16>,
    /// The alarm in words, from the catalogue.
    pub alarm_text: Option<String>,
    /// `business` (rackd resolves it) or `hardware` (needs a person at the crane).
    pub alarm_class: Option<crate::domain::AlarmClass>,
}

impl DeviceStatus {
    /// Records the outcome of one request to the device (time of contact, failures in a
    /// row, last error, the link's health as `link` says after it) and returns whether the
    /// link is up now, given whether it was: an answer brings it up and, after failures,
    /// clears the last error; it goes down after `offline_after` failures in a row.
    pub fn record_contact(
        &mut self,
        result: Result<(), &crate::protocols::PlcError>,
        offline_after: u32,
        was_up: bool,
        link: LinkStats,
    ) -> bool {
        self.link = link;
        let now = || crate::domain::time::from_ms(crate::domain::time::now_ms());
        match result {
            Ok(()) => {
                // The link recovered: its error goes. An error the adapter set itself while
                // the link answered (a crane's handshake timeout) is the adapter's to clear.
                if self.consecutive_failures > 0 {
                    self.last_error = None;
                }
                self.consecutive_failures = 0;
                self.last_contact = Some(now());
                true
            }
            Err(e) => {
                self.consecutive_failures += 1;
                self.last_error = Some(e.to_string());
                self.last_error_at = Some(now());
                was_up && self.consecutive_failures < offline_after
            }
        }
    }

    /// The status of a device not yet heard from.
    pub fn new(id: &str, kind: DeviceKind, protocol: &str, address: &str, slots_total: u16) -> Self {
        DeviceStatus {
            id: id.to_owned(),
            kind,
            protocol: protocol.to_owned(),
            address: address.to_owned(),
            aisles: Vec::new(),
            online: false,
            paused: false,
            pause: None,
            paused_aisles: Vec::new(),
            last_contact: None,
            slots_total,
            slots_in_use: 0,
            consecutive_failures: 0,
            last_error: None,
            last_error_at: None,
            link: LinkStats::default(),
            memory_lost_at: None,
            crane: (kind == DeviceKind::Crane).then(CraneStatus::default),
            tags: None,
        }
    }
}

/// What watchers must hear of at once: everything but the contact bookkeeping (last
/// contact, failures in a row, the link's counters) and the tags (whose changes the tags
/// device reports itself).
#[derive(PartialEq)]
struct Shape {
    online: bool,
    degraded: bool,
    slots_in_use: u16,
    last_error: Option<String>,
    memory_lost_at: Option<OffsetDateTime>,
    crane: Option<CraneStatus>,
}

impl Shape {
    fn of(s: &DeviceStatus) -> Shape {
        Shape {
            online: s.online,
            degraded: s.link.degraded,
            slots_in_use: s.slots_in_use,
            last_error: s.last_error.clone(),
            memory_lost_at: s.memory_lost_at,
            crane: s.crane.clone(),
        }
    }
}

/// The sending side of a device's status (see the module doc).
pub struct StatusCell {
    tx: watch::Sender<DeviceStatus>,
    refresh: Duration,
    told: Instant,
}

impl StatusCell {
    /// A cell holding `status`; contact bookkeeping wakes watchers at most every `refresh`.
    pub fn new(status: DeviceStatus, refresh: Duration) -> StatusCell {
        StatusCell { tx: watch::Sender::new(status), refresh, told: Instant::now() }
    }

    /// A receiver of the status.
    pub fn subscribe(&self) -> watch::Receiver<DeviceStatus> {
        self.tx.subscribe()
    }

    /// The status now.
    pub fn get(&self) -> watch::Ref<'_, DeviceStatus> {
        self.tx.borrow()
    }

    /// Changes the status.
    pub fn update(&mut self, f: impl FnOnce(&mut DeviceStatus)) {
        self.update_marked(|s| {
            f(s);
            false
        })
    }

    /// Changes the status; `f` answers whether it changed a tag (which [`StatusCell::update`]
    /// does not look at).
    pub fn update_marked(&mut self, f: impl FnOnce(&mut DeviceStatus) -> bool) {
        let stale = self.told.elapsed() >= self.refresh;
        let mut told = false;
        self.tx.send_if_modified(|s| {
            let (before, contact) = (Shape::of(s), s.last_contact);
            let tags_changed = f(s);
            if s.last_error.is_some() && s.last_error != before.last_error {
                s.last_error_at = Some(crate::domain::time::from_ms(crate::domain::time::now_ms()));
            }
            told = tags_changed || Shape::of(s) != before || (stale && s.last_contact != contact);
            told
        });
        if told {
            self.told = Instant::now();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test(start_paused = true)]
    async fn contact_bookkeeping_reaches_watchers_at_most_every_refresh() {
        let status = DeviceStatus::new("shelf1", DeviceKind::Shelf, "modbus-udp", "127.0.0.1:1", 60);
        let mut cell = StatusCell::new(status, Duration::from_secs(5));
        let mut seen = cell.subscribe();
        seen.mark_unchanged();
        cell.update(|s| {
            s.record_contact(Ok(()), 3, false, LinkStats::default());
        });
        assert!(!seen.has_changed().unwrap(), "a first contact within the refresh is bookkeeping");
        assert!(cell.get().last_contact.is_some(), "readers see it all the same");
        cell.update(|s| s.online = true);
        assert!(seen.has_changed().unwrap(), "online is a change");
        seen.mark_unchanged();
        tokio::time::advance(Duration::from_secs(6)).await;
        cell.update(|s| s.last_contact = Some(OffsetDateTime::UNIX_EPOCH));
        assert!(seen.has_changed().unwrap(), "a new contact after the refresh is told");
        seen.mark_unchanged();
        cell.update(|s| s.last_contact = None);
        assert!(!seen.has_changed().unwrap(), "and then not again before the next refresh");
        cell.update_marked(|_| true);
        assert!(seen.has_changed().unwrap(), "a tag change is told at once");
    }

    #[tokio::test(start_paused = true)]
    async fn link_counters_are_bookkeeping_but_degraded_is_told_at_once() {
        let status = DeviceStatus::new("shelf1", DeviceKind::Shelf, "modbus-udp", "127.0.0.1:1", 60);
        let mut cell = StatusCell::new(status, Duration::from_secs(5));
        let mut seen = cell.subscribe();
        seen.mark_unchanged();
        let busy = LinkStats { requests: 10, retries: 2, timeouts: 2, ..LinkStats::default() };
        cell.update(|s| {
            s.record_contact(Ok(()), 3, true, busy.clone());
        });
        assert!(!seen.has_changed().unwrap(), "counters are bookkeeping");
        assert_eq!(cell.get().link, busy, "readers see them all the same");
        let degraded = LinkStats { degraded: true, ..busy };
        cell.update(|s| {
            s.record_contact(Ok(()), 3, true, degraded);
        });
        assert!(seen.has_changed().unwrap(), "degraded is told at once");
    }

    #[test]
    fn the_last_error_clears_on_recovery_and_its_time_stays() {
        let mut s = DeviceStatus::new("shelf1", DeviceKind::Shelf, "modbus-udp", "127.0.0.1:1", 60);
        let e = crate::protocols::PlcError::Malformed("bad");
        assert!(s.record_contact(Err(&e), 3, true, LinkStats::default()));
        assert_eq!(s.last_error.as_deref(), Some("malformed reply: bad"));
        let at = s.last_error_at;
        assert!(at.is_some());
        assert!(s.record_contact(Ok(()), 3, true, LinkStats::default()));
        assert_eq!((s.last_error.as_deref(), s.last_error_at), (None, at), "cleared; its time kept");
        s.last_error = Some("handshake timed out".into());
        s.record_contact(Ok(()), 3, true, LinkStats::default());
        assert!(s.last_error.is_some(), "not a link error: the adapter's to clear");
    }

    #[test]
    fn the_cell_stamps_every_new_error() {
        let status = DeviceStatus::new("crane1", DeviceKind::Crane, "mc3e", "127.0.0.1:1", 1);
        let mut cell = StatusCell::new(status, Duration::from_secs(5));
        cell.update(|s| s.last_error = Some("heartbeat stopped".into()));
        assert!(cell.get().last_error_at.is_some());
    }
}
