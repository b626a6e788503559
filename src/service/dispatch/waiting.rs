//! Why a queued job is not moving: the `waiting` reason every job carries.
//!
//! The reason is computed beside the dispatcher's decisions, never instead of them: the
//! devices still ask [`Port::next`](crate::devices::port::Port::next) and take what it
//! offers; nothing here holds a job back or lets one go. A queued job's reason is the first
//! of, in this order (an operator's decision first, then what the machine says, then what
//! other work says):
//!
//! 1. `no_device`: the job has no device (no configured device runs jobs when it was
//!    accepted) or its device is no longer configured;
//! 2. `device_paused`: an operator paused its device;
//! 3. `device_offline`: its device does not answer (or has not answered yet);
//! 4. `device_alarm`: its device (a crane) reports an alarm code;
//! 5. `location_locked`, then `aisle_paused`: as the dispatcher holds such jobs back;
//! 6. `behind_job`: an older unfinished job on the same device touches one of its
//!    locations (the job named is the nearest one ahead, the one it waits for directly);
//!    then `dependency` (a job its `after` names has not completed) and `sequence` (an
//!    earlier member of its sequence goes first), as [`super::gate`] holds such jobs back;
//! 7. what the crane planner's last decision left it waiting for: `behind_job` (the job that
//!    takes the box in front of its far location, or fills the far place behind its near
//!    one, first) or `no_place` (no free location for it or for the box in its way);
//! 8. `slots_busy`: every slot of its device (the crane) is taken by rackd's other jobs or
//!    shows busy.
//!
//! Otherwise the job is about to be handed out and `waiting` is null, as it is for every job
//! that is not queued. "About to" includes a job a device with free slots has not taken yet
//! because better jobs came first: the next round takes it.
//!
//! Telling clients: each `job.updated` event the writer commits carries the reason as of
//! that commit ([`Queues::tell_hook`]), and the reasons told are remembered. A change of
//! reason alone (a device goes offline, a crane raises an alarm, a slot frees up) wakes
//! [`watch`](fn@watch), which recomputes the reasons of each device's oldest `dispatch_window` queued
//! jobs (the ones the dispatcher weighs) at most every [`SETTLE`], and asks the writer to
//! tell again those whose reason changed ([`Record::Retell`]); the writer re-reads each job
//! and writes a `job.updated` only while it is still queued, with its reason as of then,
//! so a late retell never shows a job older than it is. Jobs further back in a long
//! backlog show their reason when read and in their own events, and are told of changes
//! once they reach the window: a hundred thousand queued jobs cost a change no more than a
//! thousand events.

use std::collections::HashMap;
use std::time::Duration;

use tokio::sync::watch;

use super::queues::{Holds, Queue, Queues, Watched, because, slashed};
use crate::devices::DeviceStatus;
use crate::domain::{Job, JobState, Waiting, WaitingReason};
use crate::service::planner::Wait;
use crate::store::writer::{Record, Tell, WriteError, Writer};

/// How long the watcher lets a burst of changes settle before it recomputes.
pub const SETTLE: Duration = Duration::from_millis(50);

impl Queues {
    /// Gives the dispatcher what a device reports, once it runs (at start, or when a reload
    /// starts it again), so reasons can say it is offline, in alarm or busy; each change of
    /// its status wakes the [`watch`](fn@watch)er.
    pub fn watch_device(&self, device: &str, status: watch::Receiver<DeviceStatus>) {
        let queues = self.clone();
        let mut changes = status.clone();
        let forwarder = tokio::spawn(async move {
            while changes.changed().await.is_ok() {
                queues.0.changed.notify_one();
            }
        });
        let watched = Watched { status, forwarder };
        self.statuses().insert(device.to_owned(), watched);
        self.0.changed.notify_one();
    }

    /// Forgets what a device reports (a reload stopped it).
    pub fn unwatch_device(&self, device: &str) {
        self.statuses().remove(device);
    }

    fn statuses(&self) -> std::sync::MutexGuard<'_, HashMap<String, Watched>> {
        self.0.statuses.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Why `job` is not moving now; None while it moves or is about to be handed out.
    pub fn waiting(&self, job: &Job) -> Option<Waiting> {
        if job.state != JobState::Queued || !self.drives() {
            return None;
        }
        let status = job.device.as_deref().and_then(|d| self.status(d));
        let queues = self.lock();
        let queue = job.device.as_deref().and_then(|d| queues.get(d));
        let holds = self.holds();
        self.reason(job, queue, &holds, status.as_ref())
    }

    /// Fills in what a job read from the store shows as of now: why it waits, how late it
    /// is.
    pub fn show(&self, job: &mut Job) {
        job.waiting = self.waiting(job);
        job.late_by_s = job.late_at(crate::domain::time::now_ms());
    }

    fn status(&self, device: &str) -> Option<DeviceStatus> {
        self.statuses().get(device).map(|w| w.status.borrow().clone())
    }

    /// The reason, given the job's queue, the holds and its device's status (the module doc
    /// says in which order reasons are weighed).
    fn reason(
        &self,
        job: &Job,
        queue: Option<&Queue>,
        holds: &Holds,
        status: Option<&DeviceStatus>,
    ) -> Option<Waiting> {
        let Some(device) = job.device.as_deref() else {
            let mut aisles: Vec<u16> =
                job.spec().map(|s| s.locations()).unwrap_or_default().iter().map(|l| l.aisle).collect();
            aisles.dedup();
            let aisles: Vec<String> = aisles.iter().map(u16::to_string).collect();
            let text = format!("no configured device runs jobs on aisle {}", aisles.join(", "));
            return Some(Waiting::new(WaitingReason::NoDevice, text));
        };
        let Some(queue) = queue.filter(|_| self.has(device)) else {
            let text = format!("device {device} is not configured");
            return Some(Waiting::new(WaitingReason::NoDevice, text).on(device));
        };
        if let Some(pause) = self.pause_of(device) {
            let text = format!("device {device} is paused{}", because(&pause));
            let mut w = Waiting::new(WaitingReason::DevicePaused, text).on(device);
            w.by = Some(pause.by);
            return Some(w);
        }
        if let Some(s) = status {
            if !s.online {
                let text = match s.last_contact {
                    None => format!("{device} has not answered yet"),
                    Some(_) => format!("{device} does not answer"),
                };
                return Some(Waiting::new(WaitingReason::DeviceOffline, text).on(device));
            }
            if let Some(crane) = &s.crane
                && let Some(code) = crane.alarm_code
            {
                let what = crane.alarm_text.as_deref().unwrap_or("see its alarm");
                let mut w = Waiting::new(
                    WaitingReason::DeviceAlarm,
                    format!("{device} reports alarm {code}: {what}"),
                )
                .on(device);
                w.code = Some(code);
                return Some(w);
            }
        }
        if let Some(w) = holds.why(job) {
            return Some(w);
        }
        let locations = job.spec().map(|s| s.locations()).unwrap_or_default();
        let ahead = locations
            .iter()
            .filter_map(|l| Some((*queue.on.get(l)?.range(..job.id).next_back()?, l)))
            .max_by_key(|(id, _)| *id);
        if let Some((id, l)) = ahead {
            let text = format!("behind job {id} on location {}", slashed(l));
            let mut w = Waiting::new(WaitingReason::BehindJob, text).on(device);
            w.job = Some(id);
            return Some(w);
        }
        if (job.sequence.is_some() || !job.after.is_empty())
            && let Some(w) = self.book().why(job, crate::domain::time::now_ms())
        {
            return Some(w.on(device));
        }
        if let Some(w) = self.planned(job, device) {
            return Some(w);
        }
        let total = status.map_or(0, |s| usize::from(s.slots_total));
        let in_use = status.map_or(0, |s| usize::from(s.slots_in_use)).max(queue.active.len());
        if total > 0 && in_use >= total {
            let text = match total {
                1 => format!("{device} is busy with another job"),
                _ => format!("every slot of {device} is busy with other jobs"),
            };
            return Some(Waiting::new(WaitingReason::SlotsBusy, text).on(device));
        }
        None
    }

    /// What the crane planner's last decision left `job` waiting for, if anything.
    fn planned(&self, job: &Job, device: &str) -> Option<Waiting> {
        let planner = self.planner(device)?;
        Some(match planner.wait_of(job.id)? {
            Wait::Behind(id) => {
                let text = format!("behind job {id}, which must go first in the double-deep rack");
                let mut w = Waiting::new(WaitingReason::BehindJob, text).on(device);
                w.job = Some(id);
                w
            }
            Wait::NoPlace => {
                let text = "no free location: its zones are full, or a box in its way has nowhere to go";
                Waiting::new(WaitingReason::NoPlace, text).on(device)
            }
        })
    }

    /// The writer hook: fills in each job's reason before its event is written, and
    /// remembers it as told.
    pub fn tell_hook(&self) -> Tell {
        let queues = self.clone();
        std::sync::Arc::new(move |job: &mut Job| {
            if !queues.drives() {
                return;
            }
            job.waiting = queues.waiting(job);
            let mut told = queues.0.told.lock().unwrap_or_else(|p| p.into_inner());
            match job.state == JobState::Queued && job.device.as_deref().is_some_and(|d| queues.has(d)) {
                true => drop(told.insert(job.id, job.waiting.clone())),
                false => drop(told.remove(&job.id)),
            }
        })
    }

    /// The queued jobs (of each device's dispatch window) whose reason is not the one last
    /// told; a job never told counts as told "not waiting".
    fn untold(&self) -> Vec<i64> {
        let statuses: HashMap<String, DeviceStatus> =
            self.statuses().iter().map(|(id, w)| (id.clone(), w.status.borrow().clone())).collect();
        let windows = self.windows();
        let queues = self.lock();
        let holds = self.holds();
        let told = self.0.told.lock().unwrap_or_else(|p| p.into_inner());
        let mut changed = Vec::new();
        for (device, queue) in queues.iter() {
            let window = windows.get(device).copied().unwrap_or(usize::MAX);
            for job in queue.queued.values().take(window) {
                let now = self.reason(job, Some(queue), &holds, statuses.get(device));
                if told.get(&job.id).unwrap_or(&None) != &now {
                    changed.push(job.id);
                }
            }
        }
        changed
    }
}

/// Tells clients of every change of reason alone (see the module doc) until the writer
/// stops. Device status changes wake it as well as the dispatcher's own.
pub async fn watch(queues: Queues, writer: Writer) {
    loop {
        queues.0.changed.notified().await;
        tokio::time::sleep(SETTLE).await;
        let jobs = queues.untold();
        if jobs.is_empty() {
            continue;
        }
        match writer.record(Record::Retell { jobs }).await {
            Ok(()) => {}
            Err(WriteError::Closed) => return,
            Err(e) => tracing::warn!(error = %e, "telling why jobs wait"),
        }
    }
}
