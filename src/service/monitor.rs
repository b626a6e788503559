//! The device monitor: turns what the device tasks keep in their status into events and
//! alarms.
//!
//! Device tasks update their [`DeviceStatus`] in many places (every poll, every hand-over);
//! rather than have each place publish, one task looks at every status each `period` and
//! records:
//! - `device.updated` when anything but the contact bookkeeping changed (online, paused,
//!   slots, last error, crane registers, tags), and otherwise at most every
//!   `contact_refresh` while the device answers, so dashboards see "last contact" move
//!   without an event per poll;
//! - alarms, raised and cleared: a crane's alarm code (D205), with the catalogue's text and
//!   class, and a `link` alarm (code 0) while a device does not answer. An alarm is judged
//!   only on what is known: while a device is offline its own alarms stay as they were.
//!
//! Alarms still active from before a restart are picked up from the database, so a
//! restart neither raises them twice nor forgets to clear them; those of devices no longer
//! configured are cleared at start.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::time::{Duration, Instant};

use sqlx::SqlitePool;

use crate::devices::{DeviceStatus, Devices};
use crate::store::alarms::{self, NewAlarm};
use crate::store::writer::{Record, WriteError, Writer};

/// The code of the alarm raised while a device does not answer.
pub const LINK_ALARM: u16 = 0;

/// How the monitor looks.
#[derive(Clone, Copy, Debug)]
pub struct MonitorOptions {
    /// How often every status is looked at.
    pub period: Duration,
    /// Longest time a device's new last contact goes unpublished.
    pub contact_refresh: Duration,
}

/// What was last recorded of one device.
#[derive(Default)]
struct Seen {
    /// The status without its contact bookkeeping, as last published.
    shape: String,
    /// Last contact as last published.
    contact: Option<time::OffsetDateTime>,
    /// When it was last published.
    at: Option<Instant>,
    /// Active alarm codes.
    alarms: BTreeSet<u16>,
}

/// Runs until the writer stops.
pub async fn run(devices: Devices, writer: Writer, pool: SqlitePool, options: MonitorOptions) {
    let mut seen: HashMap<String, Seen> = devices.keys().map(|id| (id.clone(), Seen::default())).collect();
    match alarms::active(&pool).await {
        Ok(active) => {
            for alarm in active {
                match seen.get_mut(&alarm.device) {
                    Some(s) => drop(s.alarms.insert(alarm.code)),
                    None => {
                        let record = Record::AlarmCleared { device: alarm.device, code: alarm.code };
                        if let Err(WriteError::Closed) = writer.record(record).await {
                            return;
                        }
                    }
                }
            }
        }
        Err(e) => tracing::error!(error = %e, "reading active alarms"),
    }
    let mut tick = tokio::time::interval(options.period);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        tick.tick().await;
        for (id, handle) in devices.iter() {
            let status = handle.status();
            let seen = seen.entry(id.clone()).or_default();
            if let Err(e) = look(&status, seen, &writer, options).await {
                if matches!(e, WriteError::Closed) {
                    return;
                }
                tracing::warn!(device = %id, error = %e, "recording device status");
            }
        }
    }
}

/// Records what changed in one device's status since `seen`.
async fn look(
    status: &DeviceStatus,
    seen: &mut Seen,
    writer: &Writer,
    options: MonitorOptions,
) -> Result<(), WriteError> {
    let (raise, clear) = alarm_changes(status, &seen.alarms);
    for code in clear {
        writer.record(Record::AlarmCleared { device: status.id.clone(), code }).await?;
        seen.alarms.remove(&code);
    }
    for alarm in raise {
        let code = alarm.code;
        writer.record(Record::AlarmRaised(alarm)).await?;
        seen.alarms.insert(code);
    }
    let shape = shape(status);
    let stale = status.last_contact != seen.contact
        && seen.at.is_none_or(|at| at.elapsed() >= options.contact_refresh);
    if shape != seen.shape || stale {
        let json = serde_json::to_string(status).unwrap_or_default();
        writer.record(Record::Device { status: json }).await?;
        seen.shape = shape;
        seen.contact = status.last_contact;
        seen.at = Some(Instant::now());
    }
    Ok(())
}

/// The status without what changes on every poll.
fn shape(status: &DeviceStatus) -> String {
    let mut s = status.clone();
    s.last_contact = None;
    s.consecutive_failures = 0;
    serde_json::to_string(&s).unwrap_or_default()
}

/// The alarms to raise and the codes to clear, given the active codes.
fn alarm_changes(status: &DeviceStatus, active: &BTreeSet<u16>) -> (Vec<NewAlarm>, Vec<u16>) {
    let mut wanted: BTreeMap<u16, NewAlarm> = BTreeMap::new();
    let mut known: BTreeSet<u16> = BTreeSet::new();
    let alarm = |code: u16, class: &str, text: String| NewAlarm {
        device: status.id.clone(),
        code,
        class: class.to_owned(),
        text,
    };
    if status.online {
        known.insert(LINK_ALARM);
        // Online and its alarm register read (a crane's just after a start may not be yet):
        // every code is known.
        if status.crane.as_ref().is_none_or(|c| c.known) {
            known.extend(active.iter().copied());
        }
        if let Some(crane) = &status.crane
            && let Some(code) = crane.alarm_code
        {
            let class = crane.alarm_class.as_deref().unwrap_or("hardware");
            let text = crane.alarm_text.clone().unwrap_or_else(|| format!("alarm {code}"));
            wanted.insert(code, alarm(code, class, text));
        }
    } else if status.consecutive_failures > 0 {
        known.insert(LINK_ALARM);
        let why = status.last_error.as_deref().unwrap_or("no reply");
        wanted.insert(LINK_ALARM, alarm(LINK_ALARM, "link", format!("the device does not answer: {why}")));
    }
    let clear =
        active.iter().copied().filter(|code| known.contains(code) && !wanted.contains_key(code)).collect();
    let raise = wanted.into_iter().filter(|(code, _)| !active.contains(code)).map(|(_, a)| a).collect();
    (raise, clear)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::devices::DeviceKind;
    use crate::devices::status::CraneStatus;

    fn crane(online: bool, failures: u32, alarm: Option<u16>) -> DeviceStatus {
        let mut s = DeviceStatus::new("crane1", DeviceKind::Crane, "mc3e", "127.0.0.1:1", 1);
        s.online = online;
        s.consecutive_failures = failures;
        s.crane = Some(CraneStatus {
            known: true,
            alarm_code: alarm,
            alarm_text: alarm.map(|c| format!("text {c}")),
            alarm_class: alarm.map(|_| "hardware".into()),
            ..CraneStatus::default()
        });
        s
    }

    fn codes(raise: &[NewAlarm]) -> Vec<u16> {
        raise.iter().map(|a| a.code).collect()
    }

    #[test]
    fn a_crane_alarm_is_raised_then_cleared() {
        let (raise, clear) = alarm_changes(&crane(true, 0, Some(41)), &BTreeSet::new());
        assert_eq!((codes(&raise), clear), (vec![41], vec![]));
        assert_eq!(raise[0].text, "text 41");
        let (raise, clear) = alarm_changes(&crane(true, 0, Some(41)), &BTreeSet::from([41]));
        assert_eq!((codes(&raise), clear), (vec![], vec![]));
        let (raise, clear) = alarm_changes(&crane(true, 0, None), &BTreeSet::from([41]));
        assert_eq!((codes(&raise), clear), (vec![], vec![41]));
    }

    #[test]
    fn while_offline_only_the_link_alarm_changes() {
        let (raise, clear) = alarm_changes(&crane(false, 3, None), &BTreeSet::from([41]));
        assert_eq!((codes(&raise), clear), (vec![LINK_ALARM], vec![]));
        assert_eq!(raise[0].class, "link");
        let (raise, clear) = alarm_changes(&crane(true, 0, None), &BTreeSet::from([LINK_ALARM, 41]));
        assert_eq!((codes(&raise), clear), (vec![], vec![LINK_ALARM, 41]));
    }

    #[test]
    fn a_crane_online_but_not_yet_read_clears_nothing() {
        let mut status = crane(true, 0, None);
        status.crane.as_mut().unwrap().known = false;
        let (raise, clear) = alarm_changes(&status, &BTreeSet::from([41, LINK_ALARM]));
        assert!(raise.is_empty());
        assert_eq!(clear, vec![LINK_ALARM]);
    }

    #[test]
    fn a_device_not_yet_tried_changes_nothing() {
        let (raise, clear) = alarm_changes(&crane(false, 0, None), &BTreeSet::from([41, LINK_ALARM]));
        assert!(raise.is_empty() && clear.is_empty());
    }

    #[test]
    fn contact_bookkeeping_is_not_a_change() {
        let a = crane(true, 0, None);
        let mut b = a.clone();
        b.last_contact = Some(time::OffsetDateTime::now_utc());
        b.consecutive_failures = 1;
        assert_eq!(shape(&a), shape(&b));
        b.paused = true;
        assert_ne!(shape(&a), shape(&b));
    }
}
