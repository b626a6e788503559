//! The device monitor: turns each device's status and control state into events and
//! alarms.
//!
//! One task per device waits on the device's status watch and its control watch (pause),
//! and on each change records:
//! - `device.updated` with the device as the API shows it (status with its control state);
//!   the device's [`StatusCell`](crate::devices::StatusCell) wakes the watch at once for
//!   real changes and at most every `events.contact_refresh_ms` for a new last contact;
//! - alarms, raised and cleared: a crane's alarm code (D205), with the catalogue's text and
//!   class, and a `link` alarm (code 0) while a device does not answer. An alarm is judged
//!   only on what is known: while a device is offline its own alarms stay as they were.
//!
//! Alarms still active from before a restart are picked up from the database, so a
//! restart neither raises them twice nor forgets to clear them; those of devices no longer
//! configured are cleared at start.

use std::collections::{BTreeMap, BTreeSet, HashMap};

use sqlx::SqlitePool;
use tokio::sync::watch;

use super::dispatch::{Control, Queues};
use crate::devices::{DeviceHandle, DeviceStatus, Devices};
use crate::domain::AlarmClass;
use crate::store::alarms::{self, NewAlarm};
use crate::store::writer::{Record, WriteError, Writer};

/// The code of the alarm raised while a device does not answer.
pub const LINK_ALARM: u16 = 0;

/// A device as the API shows it: what it reports, with the control state set on it.
pub fn view(status: &DeviceStatus, control: Control) -> DeviceStatus {
    let mut view = status.clone();
    view.paused = control.paused;
    view
}

/// One device as the API shows it.
pub fn shown(id: &str, handle: &DeviceHandle, queues: &Queues) -> DeviceStatus {
    let control = queues.control(id).map(|c| *c.borrow()).unwrap_or_default();
    view(&handle.status.borrow(), control)
}

/// Every device as the API shows it, by id.
pub fn all_shown(devices: &Devices, queues: &Queues) -> Vec<DeviceStatus> {
    devices.iter().map(|(id, handle)| shown(id, handle, queues)).collect()
}

/// Starts watching every device; the tasks end when the writer stops.
pub async fn start(
    devices: &Devices,
    queues: &Queues,
    writer: Writer,
    pool: &SqlitePool,
) -> Vec<tokio::task::JoinHandle<()>> {
    let mut active: HashMap<String, BTreeSet<u16>> = HashMap::new();
    match alarms::active(pool).await {
        Ok(found) => {
            for alarm in found {
                if devices.contains_key(&alarm.device) {
                    active.entry(alarm.device).or_default().insert(alarm.code);
                } else {
                    let record = Record::AlarmCleared { device: alarm.device, code: alarm.code };
                    if let Err(e) = writer.record(record).await {
                        tracing::warn!(error = %e, "clearing an alarm of a device no longer configured");
                    }
                }
            }
        }
        Err(e) => tracing::error!(error = %e, "reading active alarms"),
    }
    let mut tasks = Vec::new();
    for (id, handle) in devices.iter() {
        let control = queues.control(id).unwrap_or_else(|| watch::Sender::default().subscribe());
        let alarms = active.remove(id).unwrap_or_default();
        tasks.push(tokio::spawn(watch_device(handle.clone(), control, alarms, writer.clone())));
    }
    tasks
}

/// Records every change of one device until its status or the writer goes away.
async fn watch_device(
    handle: DeviceHandle,
    mut control: watch::Receiver<Control>,
    mut alarms: BTreeSet<u16>,
    writer: Writer,
) {
    let mut status = handle.status;
    loop {
        let device = view(&status.borrow_and_update(), *control.borrow_and_update());
        match record(&device, &mut alarms, &writer).await {
            Ok(()) => {}
            Err(WriteError::Closed) => return,
            Err(e) => tracing::warn!(device = %device.id, error = %e, "recording device status"),
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
    active: &mut BTreeSet<u16>,
    writer: &Writer,
) -> Result<(), WriteError> {
    let (raise, clear) = alarm_changes(status, active);
    for code in clear {
        writer.record(Record::AlarmCleared { device: status.id.clone(), code }).await?;
        active.remove(&code);
    }
    for alarm in raise {
        let code = alarm.code;
        writer.record(Record::AlarmRaised(alarm)).await?;
        active.insert(code);
    }
    let json = serde_json::to_string(status).unwrap_or_default();
    writer.record(Record::Device { status: json }).await
}

/// The alarms to raise and the codes to clear, given the active codes.
fn alarm_changes(status: &DeviceStatus, active: &BTreeSet<u16>) -> (Vec<NewAlarm>, Vec<u16>) {
    let mut wanted: BTreeMap<u16, NewAlarm> = BTreeMap::new();
    let mut known: BTreeSet<u16> = BTreeSet::new();
    let alarm = |code: u16, class: AlarmClass, text: String| NewAlarm {
        device: status.id.clone(),
        code,
        class,
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
            let class = crane.alarm_class.unwrap_or(AlarmClass::Hardware);
            let text = crane.alarm_text.clone().unwrap_or_else(|| format!("alarm {code}"));
            wanted.insert(code, alarm(code, class, text));
        }
    } else if status.consecutive_failures > 0 {
        known.insert(LINK_ALARM);
        let why = status.last_error.as_deref().unwrap_or("no reply");
        wanted.insert(
            LINK_ALARM,
            alarm(LINK_ALARM, AlarmClass::Link, format!("the device does not answer: {why}")),
        );
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
            alarm_class: alarm.map(|_| AlarmClass::Hardware),
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
        assert_eq!(raise[0].class, AlarmClass::Link);
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
    fn the_view_carries_the_control_state() {
        let status = crane(true, 0, None);
        assert!(!view(&status, Control::default()).paused);
        assert!(view(&status, Control { paused: true }).paused);
    }
}
