//! The device monitor: turns each device's status and control state into events and
//! alarms.
//!
//! One task per device waits on the device's status watch and its control watch (pause),
//! and on each change records:
//! - `device.updated` with the device as the API shows it (status with its control state);
//!   the device's [`StatusCell`](crate::devices::StatusCell) wakes the watch at once for
//!   real changes and at most every `events.contact_refresh_ms` for a new last contact;
//! - alarms, raised and cleared, one per kind and code: a crane's own code (D205, kind
//!   `device`) with the catalogue's text and class, whenever its block is read (a crane
//!   whose heartbeat stalled still answers, so its 7020 is listed); `link` while a device
//!   does not answer, in plain words ("no answer from 10.0.0.5:5000 for 3 polls") with the
//!   protocol's error in `detail`; `heartbeat` while the crane's D200 stands still (the
//!   seconds since it last moved); `degraded` while the link works but too many of its
//!   recent requests need a retry (a warning: the device keeps working; cleared with the
//!   link's hysteresis); `memory_lost` when a shelf PLC came back without its tasks, until
//!   it takes new work. An alarm is judged only on what is known: while a
//!   device does not answer, its own alarms and its heartbeat stay as they were.
//!
//! Alarms still active from before a restart (or a reload that restarted the device) are
//! picked up from the database, so a restart neither raises them twice nor forgets to clear
//! them; those of devices no longer configured are cleared at start, and those of a device
//! a reload removes when it stops.

use std::collections::{BTreeMap, BTreeSet, HashMap};

use crate::store::Pool;
use tokio::sync::watch;
use tracing::Instrument;

use std::sync::Arc;

use super::captures::Freeze;
use super::dispatch::{Control, Queues};
use crate::capture::Recorder;
use crate::devices::{DeviceHandle, DeviceStatus, Devices};
use crate::domain::{AlarmClass, AlarmKind};
use crate::store::alarms::{self, NewAlarm};
use crate::store::writer::{Record, WriteError, Writer};

/// The code of the alarms rackd raises about a device (all but kind `device`).
pub const LINK_ALARM: u16 = 0;

/// A device as the API shows it: what it reports, with the control state set on it. It
/// counts as paused when it is, or when every aisle it serves is.
pub fn view(status: &DeviceStatus, control: &Control) -> DeviceStatus {
    let mut view = status.clone();
    let every_aisle =
        !status.aisles.is_empty() && status.aisles.iter().all(|a| control.paused_aisles.contains(a));
    view.paused = control.pause.is_some() || every_aisle;
    view.pause = control.pause.clone();
    view.paused_aisles = control.paused_aisles.clone();
    view
}

/// One device as the API shows it.
pub fn shown(id: &str, handle: &DeviceHandle, queues: &Queues) -> DeviceStatus {
    let control = queues.control(id).map(|c| c.borrow().clone()).unwrap_or_default();
    view(&handle.status.borrow(), &control)
}

/// Every device as the API shows it, by id.
pub fn all_shown(devices: &Devices, queues: &Queues) -> Vec<DeviceStatus> {
    devices.iter().map(|(id, handle)| shown(id, handle, queues)).collect()
}

/// The active alarms in the store, by device (none if the store cannot be read: logged).
pub async fn active(pool: &Pool) -> HashMap<String, BTreeSet<Key>> {
    let mut by_device: HashMap<String, BTreeSet<Key>> = HashMap::new();
    match alarms::active(pool).await {
        Ok(found) => {
            for a in found {
                by_device.entry(a.device).or_default().insert((a.kind, a.code));
            }
        }
        Err(e) => tracing::error!(error = %e, "reading active alarms"),
    }
    by_device
}

/// Clears `keys`, active alarms of `device`, which is no longer configured (at start, or a
/// reload removed it).
pub async fn clear(device: &str, keys: &BTreeSet<Key>, writer: &Writer) {
    for key in keys {
        let record = Record::AlarmCleared { device: device.to_owned(), key: *key };
        if let Err(e) = writer.record(record).await {
            tracing::warn!(error = %e, "clearing an alarm of a device no longer configured");
        }
    }
}

/// Starts watching one device, taking up `alarms`, those it has active; the task ends when
/// the device's task ends (its status goes away) or the writer stops.
pub fn watch(
    id: &str,
    handle: &DeviceHandle,
    queues: &Queues,
    writer: Writer,
    alarms: BTreeSet<Key>,
    freeze: Option<Freeze>,
) -> tokio::task::JoinHandle<()> {
    let control = queues.control(id).unwrap_or_else(|| watch::Sender::default().subscribe());
    let span = tracing::info_span!("device", device = %id);
    tokio::spawn(watch_device(handle.clone(), control, alarms, writer, freeze).instrument(span))
}

/// Records every change of one device until its status or the writer goes away.
async fn watch_device(
    handle: DeviceHandle,
    mut control: watch::Receiver<Control>,
    mut alarms: BTreeSet<Key>,
    writer: Writer,
    freeze: Option<Freeze>,
) {
    let mut status = handle.status;
    let kept = freeze.zip(handle.recorder);
    loop {
        let device = view(&status.borrow_and_update(), &control.borrow_and_update());
        match record(&device, &mut alarms, &writer, kept.as_ref()).await {
            Ok(()) => {}
            Err(WriteError::Closed) => return,
            Err(e) => tracing::warn!(error = %e, "recording device status"),
        }
        tokio::select! {
            changed = status.changed() => if changed.is_err() { return },
            changed = control.changed() => if changed.is_err() { return },
        }
    }
}

/// Records the device's status and the alarms it raises or clears, given those active.
async fn record(
    status: &DeviceStatus,
    active: &mut BTreeSet<Key>,
    writer: &Writer,
    kept: Option<&(Freeze, Arc<Recorder>)>,
) -> Result<(), WriteError> {
    let (raise, clear) = alarm_changes(status, active);
    for key in clear {
        writer.record(Record::AlarmCleared { device: status.id.clone(), key }).await?;
        active.remove(&key);
    }
    for alarm in raise {
        let key = alarm.key();
        // The moment before the fault, taken before the ring moves on.
        let frozen = kept
            .filter(|(freeze, _)| freeze.admit(&status.id, key, alarm.class))
            .map(|(freeze, recorder)| (freeze, recorder.reader(Some(freeze.span()))));
        writer.record(Record::AlarmRaised(alarm)).await?;
        active.insert(key);
        if let Some((freeze, frames)) = frozen {
            freeze.keep(&status.id, key, frames).await;
        }
    }
    let json = serde_json::to_string(status).unwrap_or_default();
    writer.record(Record::Device { status: json }).await
}

/// What an operator should do about an alarm, in plain words (a crane's own codes: the
/// catalogue's word).
fn action(device: &str, kind: AlarmKind, code: u16) -> String {
    match kind {
        AlarmKind::Device => crate::wire::alarms::action(code).to_owned(),
        AlarmKind::Link => format!(
            "Check that {device} is powered and its network or serial cable is connected; rackd reconnects \
             by itself and gives it no work meanwhile."
        ),
        AlarmKind::Heartbeat => {
            "Check that the crane's PLC is running; rackd gives the crane no new work until its heartbeat \
             moves again."
                .to_owned()
        }
        AlarmKind::Degraded => {
            "Nothing now: the device keeps working. If it lasts, check the network (cable, switch, \
             interference)."
                .to_owned()
        }
        AlarmKind::Takeover => crate::service::cluster::TAKEOVER_ACTION.to_owned(),
        AlarmKind::Archive => crate::config::ARCHIVE_ACTION.to_owned(),
        AlarmKind::Store => crate::service::store_alarm::ACTION.to_owned(),
        AlarmKind::Webhook => match code {
            2 => crate::service::webhooks::GONE_ACTION
                .replace("NAME", device.strip_prefix("webhook:").unwrap_or(device)),
            3 => crate::service::webhooks::START_ACTION.to_owned(),
            _ => crate::service::webhooks::ACTION.to_owned(),
        },
        AlarmKind::ConfigDrift => crate::service::cluster::DRIFT_ACTION.to_owned(),
        AlarmKind::Certificate => match code {
            1 => crate::config::tls::REFUSED_ACTION.to_owned(),
            _ => crate::config::tls::EXPIRING_ACTION.to_owned(),
        },
        AlarmKind::ConfigReload => crate::config::RELOAD_ACTION.to_owned(),
        AlarmKind::MemoryLost => {
            "Check the locked locations of the lost tasks, correct the inventory, unlock them and retry \
             the failed jobs."
                .to_owned()
        }
    }
}

/// An active alarm's identity on its device.
pub type Key = (AlarmKind, u16);

/// The alarms to raise and the keys to clear, given those active.
///
/// A device's own codes are judged only while its registers are read (the link answers
/// and, for a crane, its block was read since the start): a crane whose heartbeat stalled
/// still answers, so its 7020 reaches the list. What rackd raises about a device is judged
/// on what it knows: the link alarm while requests fail, the heartbeat alarm while the
/// crane's D200 stands still, the memory alarm until the PLC takes new work.
fn alarm_changes(status: &DeviceStatus, active: &BTreeSet<Key>) -> (Vec<NewAlarm>, Vec<Key>) {
    let mut wanted: BTreeMap<Key, NewAlarm> = BTreeMap::new();
    let mut known: BTreeSet<Key> = BTreeSet::new();
    let mut want = |kind: AlarmKind, code: u16, class: AlarmClass, text: String, detail: Option<String>| {
        let action = Some(action(&status.id, kind, code).to_owned());
        let alarm = NewAlarm { device: status.id.clone(), kind, code, class, text, detail, action };
        wanted.insert(alarm.key(), alarm);
    };
    let answers = status.consecutive_failures == 0 && status.last_contact.is_some();
    if answers {
        known.insert((AlarmKind::Link, LINK_ALARM));
        if status.crane.as_ref().is_none_or(|c| c.known) {
            known.extend(active.iter().copied().filter(|(kind, _)| *kind == AlarmKind::Device));
        }
        if let Some(crane) = &status.crane
            && let Some(code) = crane.alarm_code
        {
            let class = crane.alarm_class.unwrap_or(AlarmClass::Hardware);
            let what = crane.alarm_text.clone().unwrap_or_else(|| format!("alarm {code}"));
            let text = format!("{} reports alarm {code}: {what}", status.id);
            let detail = format!("D205 = {code} ({} alarm in the crane's catalogue)", class.as_str());
            want(AlarmKind::Device, code, class, text, Some(detail));
        }
    } else if status.consecutive_failures > 0 && !status.online {
        known.insert((AlarmKind::Link, LINK_ALARM));
        let n = status.consecutive_failures;
        let text = format!("no answer from {} for {n} poll{}", status.address, if n == 1 { "" } else { "s" });
        want(AlarmKind::Link, LINK_ALARM, AlarmClass::Link, text, status.last_error.clone());
    }
    if let Some(crane) = status.crane.as_ref().filter(|c| c.known && answers) {
        known.insert((AlarmKind::Heartbeat, 0));
        if let Some(since) = crane.heartbeat_stalled_since {
            let seconds = (crate::domain::time::now() - since).as_seconds_f64().max(0.0);
            let text = format!("the crane's heartbeat (D200) has not changed for {seconds:.1} s");
            want(AlarmKind::Heartbeat, 0, AlarmKind::Heartbeat.class(), text, None);
        }
    }
    if answers && status.online {
        known.insert((AlarmKind::Degraded, 0));
        if status.link.degraded {
            let l = &status.link;
            let text = format!(
                "the link to {} is degraded: too many recent requests needed a retry; the device keeps working",
                status.address
            );
            let round_trip = l.srtt_ms.map_or("not measured".to_owned(), |ms| format!("{ms:.2} ms"));
            let detail = format!(
                "{} requests, {} retries, {} timeouts; dropped replies: {} stale, {} foreign, {} malformed; \
                 smoothed round trip {round_trip}, timeout {:.1} ms",
                l.requests, l.retries, l.timeouts, l.stale, l.foreign, l.malformed, l.timeout_ms
            );
            want(AlarmKind::Degraded, 0, AlarmKind::Degraded.class(), text, Some(detail));
        }
    }
    known.insert((AlarmKind::MemoryLost, 0));
    if status.memory_lost_at.is_some() {
        let text = "the PLC lost its task memory: power cycle? Its tasks failed as lost and their locations \
                    are locked for a person to check"
            .to_owned();
        want(AlarmKind::MemoryLost, 0, AlarmKind::MemoryLost.class(), text, None);
    }
    let clear =
        active.iter().copied().filter(|key| known.contains(key) && !wanted.contains_key(key)).collect();
    let raise = wanted.into_iter().filter(|(key, _)| !active.contains(key)).map(|(_, a)| a).collect();
    (raise, clear)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::devices::DeviceKind;
    use crate::devices::status::CraneStatus;

    const LINK: Key = (AlarmKind::Link, LINK_ALARM);
    const HEARTBEAT: Key = (AlarmKind::Heartbeat, 0);

    fn own(code: u16) -> Key {
        (AlarmKind::Device, code)
    }

    fn crane(online: bool, failures: u32, alarm: Option<u16>) -> DeviceStatus {
        let mut s = DeviceStatus::new("crane1", DeviceKind::Crane, "mc3e", "10.0.0.5:5000", 1);
        s.online = online;
        s.consecutive_failures = failures;
        s.last_contact = Some(time::OffsetDateTime::UNIX_EPOCH);
        s.crane = Some(CraneStatus {
            known: true,
            alarm_code: alarm,
            alarm_text: alarm.map(|c| format!("text {c}")),
            alarm_class: alarm.map(|_| AlarmClass::Hardware),
            ..CraneStatus::default()
        });
        s
    }

    fn keys(raise: &[NewAlarm]) -> Vec<Key> {
        raise.iter().map(NewAlarm::key).collect()
    }

    #[test]
    fn a_crane_alarm_is_raised_then_cleared() {
        let (raise, clear) = alarm_changes(&crane(true, 0, Some(41)), &BTreeSet::new());
        assert_eq!((keys(&raise), clear), (vec![own(41)], vec![]));
        assert_eq!(raise[0].text, "crane1 reports alarm 41: text 41");
        assert_eq!(raise[0].detail.as_deref(), Some("D205 = 41 (hardware alarm in the crane's catalogue)"));
        assert!(raise[0].action.as_deref().is_some_and(|a| a.starts_with("A person must")), "{raise:?}");
        let (raise, clear) = alarm_changes(&crane(true, 0, Some(41)), &BTreeSet::from([own(41)]));
        assert_eq!((keys(&raise), clear), (vec![], vec![]));
        let (raise, clear) = alarm_changes(&crane(true, 0, None), &BTreeSet::from([own(41)]));
        assert_eq!((keys(&raise), clear), (vec![], vec![own(41)]));
    }

    #[test]
    fn while_it_does_not_answer_only_the_link_alarm_changes() {
        let (raise, clear) = alarm_changes(&crane(true, 1, None), &BTreeSet::from([own(41)]));
        assert!(raise.is_empty() && clear.is_empty(), "one lost reply is no lost link, and judges nothing");
        let (raise, clear) = alarm_changes(&crane(false, 3, None), &BTreeSet::from([own(41), HEARTBEAT]));
        assert_eq!((keys(&raise), clear), (vec![LINK], vec![]));
        assert_eq!(raise[0].class, AlarmClass::Link);
        assert_eq!(raise[0].text, "no answer from 10.0.0.5:5000 for 3 polls");
        let (raise, clear) = alarm_changes(&crane(true, 0, None), &BTreeSet::from([LINK, own(41)]));
        assert_eq!((keys(&raise), clear), (vec![], vec![own(41), LINK]));
    }

    #[test]
    fn the_link_alarm_keeps_the_protocol_words_apart() {
        let mut status = crane(false, 1, None);
        status.last_error = Some("MC 3E: no reply after 3 attempts".into());
        let (raise, _) = alarm_changes(&status, &BTreeSet::new());
        assert_eq!(raise[0].text, "no answer from 10.0.0.5:5000 for 1 poll");
        assert_eq!(raise[0].detail.as_deref(), Some("MC 3E: no reply after 3 attempts"));
    }

    #[test]
    fn a_crane_whose_heartbeat_stalled_still_reports_its_own_codes() {
        let mut status = crane(false, 0, Some(7020));
        let stalled = time::OffsetDateTime::now_utc() - time::Duration::seconds(12);
        status.crane.as_mut().unwrap().heartbeat_stalled_since = Some(stalled);
        let (raise, clear) = alarm_changes(&status, &BTreeSet::new());
        assert_eq!((keys(&raise), clear), (vec![own(7020), HEARTBEAT], vec![]));
        assert!(
            raise[1].text.starts_with("the crane's heartbeat (D200) has not changed for 12."),
            "{}",
            raise[1].text
        );
        assert_eq!(raise[1].class, AlarmClass::Hardware);
        let (raise, clear) = alarm_changes(&crane(true, 0, None), &BTreeSet::from([own(7020), HEARTBEAT]));
        assert_eq!((keys(&raise), clear), (vec![], vec![own(7020), HEARTBEAT]));
    }

    #[test]
    fn a_crane_answering_but_not_yet_read_clears_only_the_link() {
        let mut status = crane(true, 0, None);
        status.crane.as_mut().unwrap().known = false;
        let (raise, clear) = alarm_changes(&status, &BTreeSet::from([own(41), LINK, HEARTBEAT]));
        assert!(raise.is_empty());
        assert_eq!(clear, vec![LINK]);
    }

    #[test]
    fn a_device_not_yet_tried_changes_nothing() {
        let mut status = crane(false, 0, None);
        status.last_contact = None;
        let (raise, clear) = alarm_changes(&status, &BTreeSet::from([own(41), LINK]));
        assert!(raise.is_empty() && clear.is_empty());
    }

    #[test]
    fn a_plc_that_lost_its_memory_raises_one_alarm_until_it_works_again() {
        let mut status = DeviceStatus::new("shelf1", DeviceKind::Shelf, "modbus-udp", "10.0.0.6:502", 60);
        status.last_contact = Some(time::OffsetDateTime::UNIX_EPOCH);
        status.memory_lost_at = Some(time::OffsetDateTime::UNIX_EPOCH);
        let lost = (AlarmKind::MemoryLost, 0);
        let (raise, clear) = alarm_changes(&status, &BTreeSet::new());
        assert_eq!((keys(&raise), clear), (vec![lost], vec![]));
        assert!(raise[0].text.starts_with("the PLC lost its task memory: power cycle?"));
        status.memory_lost_at = None;
        let (raise, clear) = alarm_changes(&status, &BTreeSet::from([lost]));
        assert_eq!((keys(&raise), clear), (vec![], vec![lost]));
    }

    #[test]
    fn a_degraded_link_is_a_warning_alarm_until_it_recovers() {
        let degraded = (AlarmKind::Degraded, 0);
        let mut status = crane(true, 0, None);
        status.link.degraded = true;
        status.link.retries = 12;
        let (raise, clear) = alarm_changes(&status, &BTreeSet::new());
        assert_eq!((keys(&raise), clear), (vec![degraded], vec![]));
        assert_eq!(raise[0].class, AlarmClass::Link);
        assert!(raise[0].text.starts_with("the link to 10.0.0.5:5000 is degraded"), "{}", raise[0].text);
        assert!(raise[0].detail.as_deref().is_some_and(|d| d.contains("12 retries")));
        let (raise, clear) = alarm_changes(&crane(false, 3, None), &BTreeSet::from([degraded]));
        assert_eq!((keys(&raise), clear), (vec![LINK], vec![]), "offline: unknown, kept");
        let (raise, clear) = alarm_changes(&crane(true, 0, None), &BTreeSet::from([degraded]));
        assert_eq!((keys(&raise), clear), (vec![], vec![degraded]));
    }

    #[test]
    fn the_view_carries_the_control_state() {
        let mut status = crane(true, 0, None);
        status.aisles = vec![1, 2];
        assert!(!view(&status, &Control::default()).paused);
        let pause = crate::domain::Pause {
            by: "ops".into(),
            reason: Some("inspection".into()),
            at: time::OffsetDateTime::UNIX_EPOCH,
        };
        let shown = view(&status, &Control { pause: Some(pause.clone()), paused_aisles: vec![] });
        assert!(shown.paused);
        assert_eq!(shown.pause, Some(pause));
        let one = view(&status, &Control { pause: None, paused_aisles: vec![2] });
        assert!(!one.paused, "aisle 1 still works");
        assert_eq!(one.paused_aisles, vec![2]);
        assert!(view(&status, &Control { pause: None, paused_aisles: vec![1, 2] }).paused);
    }
}
