//! The records of a group: what it changes besides jobs (a device's state, pauses, location
//! locks and inventory, alarms), applied in memory like the rest of the group.

use super::{Group, location_key};
use crate::domain::{JobState, Who};
use crate::store::alarms::{self, Alarm};
use crate::store::writer::{Record, WriteError};

impl Group {
    /// Records a change that is not a job's; an error refuses it. Sent by `who`, its audit
    /// entries carry their address.
    pub(super) fn record(&mut self, record: &Record, who: Option<&Who>) -> Result<(), WriteError> {
        let now = self.now;
        let client = who.and_then(|w| w.client);
        match record {
            Record::Device { status } => self.append("device.updated", status.clone()),
            Record::Pause { target, paused, by } => {
                self.controls.insert(target.key(), paused.then(|| by.clone()));
                let action = if *paused { "pause" } else { "resume" };
                self.audit(&by.by, client, action, &target.key(), by.reason.as_deref());
            }
            Record::Lock { location, lock } => {
                self.audit(&lock.by, client, "lock", &location_key(*location), Some(&lock.reason));
                if self.lock(*location, lock) {
                    self.out.locks.push((*location, Some(lock.clone())));
                    self.location_events(&[*location]);
                }
            }
            Record::Unlock { location, by, reason } => {
                self.audit(by, client, "unlock", &location_key(*location), reason.as_deref());
                self.unlock(*location);
            }
            Record::AlarmRaised(new) => {
                let active = |a: &&alarms::Row| {
                    a.cleared_at.is_none()
                        && a.device == new.device
                        && a.kind == new.kind.as_str()
                        && a.code == new.code as i64
                };
                if self.alarms.values().find(active).is_none() {
                    let row = alarms::Row {
                        id: self.next.alarm,
                        device: new.device.clone(),
                        kind: new.kind.as_str().to_owned(),
                        code: new.code as i64,
                        class: new.class.as_str().to_owned(),
                        text: new.text.clone(),
                        detail: new.detail.clone(),
                        action: new.action.clone(),
                        acknowledged_by: None,
                        acknowledged_at: None,
                        raised_at: now,
                        cleared_at: None,
                    };
                    self.next.alarm += 1;
                    self.raised.insert(row.id);
                    self.alarms.insert(row.id, row.clone());
                    self.event("alarm.raised", &Alarm::from(row));
                }
            }
            Record::AlarmCleared { device, key: (kind, code) } => {
                let found = self.alarms.values_mut().find(|a| {
                    a.cleared_at.is_none()
                        && a.device == *device
                        && a.kind == kind.as_str()
                        && a.code == *code as i64
                });
                if let Some(row) = found {
                    row.cleared_at = Some(now);
                    let row = row.clone();
                    self.alarm_changed(row.id);
                    self.event("alarm.cleared", &Alarm::from(row));
                }
            }
            Record::Inventory { entries, by, reason } => {
                let held = entries.iter().find_map(|e| {
                    let row = self.locations.get(&e.location)?;
                    row.reserved_by.map(|job| (e.location, job))
                });
                if let Some((location, job)) = held {
                    return Err(WriteError::Reserved { location, job });
                }
                let mut changed = Vec::new();
                for e in entries {
                    let same = self.locations.get(&e.location).map(|r| (r.occupied, r.barcode.as_deref()))
                        == Some((e.occupied, e.barcode.as_deref()));
                    if !same && self.locations.contains_key(&e.location) {
                        self.set_box(e.location, e.occupied, e.barcode.clone());
                        let what = match (&e.occupied, &e.barcode) {
                            (true, Some(b)) => format!("inventory: a box, {b}"),
                            (true, None) => "inventory: a box".to_owned(),
                            (false, _) => "inventory: empty".to_owned(),
                        };
                        let why = reason.as_deref().map_or(what.clone(), |r| format!("{what} ({r})"));
                        self.audit(by, client, "inventory", &location_key(e.location), Some(&why));
                        changed.push(e.location);
                    }
                }
                self.location_events(&changed);
            }
            Record::Acknowledge { alarm, by, note } => {
                let Some(row) = self.alarms.get_mut(alarm) else {
                    return Err(WriteError::AlarmNotFound(*alarm));
                };
                if let Some(first) = &row.acknowledged_by {
                    return Err(WriteError::AlreadyAcknowledged { id: *alarm, by: first.clone() });
                }
                (row.acknowledged_by, row.acknowledged_at) = (Some(by.clone()), Some(now));
                let row = row.clone();
                self.alarm_changed(row.id);
                self.audit(by, client, "acknowledge", &format!("alarm:{alarm}"), note.as_deref());
                self.event("alarm.updated", &Alarm::from(row));
            }
            Record::Retell { jobs } => {
                for id in jobs {
                    // A job that moved on meanwhile was told by its own commit.
                    if let Some(mut job) = self.jobs.get(id).filter(|j| j.state == JobState::Queued).cloned()
                    {
                        self.tell(&mut job);
                        self.event("job.updated", &job);
                    }
                }
            }
            Record::Audit { action, target, reason } => {
                let by = who.map_or("rackd", |w| w.name.as_str());
                self.audit(by, client, action, target, reason.as_deref());
            }
            Record::Reloaded { data, reason } => {
                let by = who.map_or("rackd", |w| w.name.as_str());
                self.audit(by, client, "reload", "config", Some(reason));
                self.append("config.reloaded", data.clone());
            }
            Record::Prune { before_ms, through, hard_ms } => {
                self.prune = Some((*before_ms, *through, *hard_ms))
            }
            Record::Webhook { progress, audit } => {
                if let Some((action, reason)) = audit {
                    let by = who.map_or("rackd", |w| w.name.as_str());
                    let target = format!("webhook:{}", progress.row.name);
                    self.audit(by, client, action, &target, reason.as_deref());
                }
                self.webhooks.push(progress.clone());
            }
            Record::Sequence { name, cancel } => self.sequence(name, *cancel, who)?,
            Record::Late { jobs } => {
                for id in jobs {
                    if let Some(mut job) = self.jobs.get(id).filter(|j| !j.state.is_terminal()).cloned() {
                        self.tell(&mut job);
                        self.event("job.late", &job);
                    }
                }
            }
            Record::Archived { jobs } => {
                for id in jobs {
                    if self.jobs.get(id).is_some_and(|j| j.state.is_terminal())
                        && let Some(job) = self.jobs.remove(id)
                    {
                        self.archived.push((job.id, job.device, job.state));
                    }
                }
            }
        }
        Ok(())
    }

    /// Notes that a stored alarm changed (one this group raised is written as it ends up).
    fn alarm_changed(&mut self, id: i64) {
        if !self.raised.contains(&id) {
            self.alarms_changed.insert(id);
        }
    }
}
