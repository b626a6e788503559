//! Operators' actions on many jobs or locations at once: unlock the locations one cause
//! locked, retry failed jobs, cancel queued ones.
//!
//! Each action first selects its items (from a filter, or as listed), then hands them to the
//! writer as one [`Bulk`]: every item is checked in the commit and either all of them are
//! done in it, or none ([`BulkError::Refused`], naming each refused item and why). A dry run
//! goes through the same selection and the same check and writes nothing, so it answers
//! exactly what the action would do at that moment.
//!
//! Decisions:
//! - **Unlock and retry is one action.** After a memory loss each lost job locked its
//!   locations, and later jobs on them wait behind the lock. Unlocking first would let a
//!   device take those later jobs before the lost ones are queued again, out of the order
//!   the WMS sent them in. So a retry can lift, in its own commit, the locks its jobs'
//!   failures set (`unlock`); the dispatcher is handed the retried jobs before the unlocks
//!   (`store::writer::durable`), so each retried job is back in its queue, ahead of the
//!   later jobs on its locations, before any of them can go. Retried jobs keep their ids,
//!   and jobs on one location run in id order ([`super::order`]): in the order they were
//!   first accepted. A lock set by anything else (a person, another job) stays, and the
//!   retried job waits on it. A retry without `unlock` keeps the order too (the jobs wait
//!   on their own locks until they are unlocked); an unlock before the retry does not.
//! - **What the operator checked is what is done.** An unlock by cause names, for each
//!   location, the job whose failure locked it; a location unlocked meanwhile, or locked
//!   again by another cause, refuses the action. The dashboard sends the items of the dry
//!   run it showed as a list (`jobs`, `locations`), so that a failure after the operator
//!   looked is not swept in unchecked.
//! - **A cancel never races a hand-over.** The selected jobs are withheld from their
//!   devices first (no device takes them from then on), then each device is asked which of
//!   them it holds ([`crate::devices::DeviceRequest::Holding`], answered between two of its
//!   rounds, so a hand-over begun before is recorded by then). A job a device holds, or one
//!   the writer finds no longer queued, refuses the action: a bulk cancel only cancels
//!   queued jobs (one on a machine is cancelled on its own, `POST /api/v1/jobs/{id}/cancel`).
//!   A dry run does not ask the devices. The hold is the action's own
//!   ([`super::withhold`]), let go when it ends however it ends (answered, refused, failed,
//!   or dropped with its request): another cancel of the same jobs under way keeps them
//!   withheld until it ends too.
//! - **Bounded.** At most [`MAX_BULK`] items an action; a selection of more is refused
//!   ([`BulkError::TooMany`]) rather than cut, since a partial action is not what was asked.
//!   The failed jobs are read on the state index (`store::jobs::failed`): the failed jobs
//!   the store keeps, not the whole history; locks by cause from the locked locations (the
//!   site, not the history); queued jobs a page at a time on the state index.

use std::collections::{BTreeMap, BTreeSet};

use super::Dispatcher;
use super::control::Actor;
use crate::devices::Devices;
use crate::domain::time::to_ms;
use crate::domain::{FailureKind, JobState, Location};
use crate::store::jobs::{self, JobFilter};
use crate::store::locations;
use crate::store::writer::{Bulk, BulkAction, Bulked, Refusal, WriteError};

/// The most items one bulk action takes.
pub const MAX_BULK: usize = 10_000;

/// Failed jobs to act on: those of a device, of a failure kind, failed at or after a time,
/// each filter if given.
#[derive(Clone, Debug, Default)]
pub struct FailedJobs {
    /// Only jobs of this device.
    pub device: Option<String>,
    /// Only jobs that failed this way.
    pub kind: Option<FailureKind>,
    /// Only jobs that failed at or after this time.
    pub since: Option<time::OffsetDateTime>,
}

impl FailedJobs {
    /// Whether `job` is one of them (compared in milliseconds, as the store keeps times,
    /// so that both ways of selecting agree: `store::jobs::failed` and this).
    fn passes(&self, job: &jobs::Job) -> bool {
        job.state == JobState::Failed
            && self.device.as_ref().is_none_or(|d| job.device.as_ref() == Some(d))
            && self.kind.is_none_or(|k| job.failure.as_ref().is_some_and(|f| f.kind == k))
            && self.since.is_none_or(|t| to_ms(job.updated_at) >= to_ms(t))
    }
}

/// Queued jobs to act on: those of a device, touching an aisle, each filter if given.
#[derive(Clone, Debug, Default)]
pub struct QueuedJobs {
    /// Only jobs of this device.
    pub device: Option<String>,
    /// Only jobs with a location in this aisle.
    pub aisle: Option<u16>,
}

/// Why a bulk action was not done; nothing of it was.
#[derive(Debug, thiserror::Error)]
pub enum BulkError {
    /// The selection holds more items than one action takes.
    #[error("the selection holds more than {MAX_BULK} {what}; narrow it")]
    TooMany {
        /// `jobs` or `locations`.
        what: &'static str,
    },
    /// Items cannot be done as asked.
    #[error("{}", crate::store::writer::describe(.0))]
    Refused(Vec<Refusal>),
    /// A device that may hold some of the jobs does not answer.
    #[error("device {device:?} is not available; try again")]
    Unavailable {
        /// The device.
        device: String,
    },
    /// The store failed.
    #[error(transparent)]
    Store(WriteError),
}

impl From<WriteError> for BulkError {
    fn from(e: WriteError) -> Self {
        match e {
            WriteError::Refused(refusals) => BulkError::Refused(refusals),
            other => BulkError::Store(other),
        }
    }
}

impl From<sqlx::Error> for BulkError {
    fn from(e: sqlx::Error) -> Self {
        BulkError::Store(WriteError::Database(std::sync::Arc::new(e)))
    }
}

/// How many queued jobs a selection reads at a time.
const PAGE: u32 = 1000;

impl Dispatcher {
    /// The failed jobs `filter` selects, in id order.
    pub async fn failed_jobs(&self, filter: &FailedJobs) -> Result<Vec<i64>, BulkError> {
        let since = filter.since.map(to_ms);
        let limit = MAX_BULK as u32 + 1;
        let ids = jobs::failed(&self.pool, filter.device.as_deref(), filter.kind, since, limit).await?;
        bounded(ids, "jobs")
    }

    /// The locations locked by the failures of the jobs `filter` selects, each with its
    /// job, in location order.
    pub async fn locked_by(&self, filter: &FailedJobs) -> Result<Vec<(Location, i64)>, BulkError> {
        let locked: Vec<(Location, i64)> = locations::locked(&self.pool)
            .await?
            .into_iter()
            .filter_map(|(l, lock)| Some((l, lock.job?)))
            .collect();
        let ids: Vec<i64> = locked.iter().map(|(_, job)| *job).collect::<BTreeSet<_>>().into_iter().collect();
        let mut selected = BTreeSet::new();
        for chunk in ids.chunks(PAGE as usize) {
            let found = jobs::many(&self.pool, chunk).await?;
            selected.extend(found.iter().filter(|j| filter.passes(j)).map(|j| j.id));
        }
        let mut chosen: Vec<(Location, i64)> =
            locked.into_iter().filter(|(_, job)| selected.contains(job)).collect();
        chosen.sort();
        bounded(chosen, "locations")
    }

    /// The queued jobs `filter` selects, in id order.
    pub async fn queued_jobs(&self, filter: &QueuedJobs) -> Result<Vec<i64>, BulkError> {
        let mut page = JobFilter {
            state: Some(JobState::Queued),
            device: filter.device.clone(),
            limit: PAGE,
            ..JobFilter::default()
        };
        let mut ids = Vec::new();
        loop {
            let batch = jobs::list(&self.pool, &page).await?;
            let read = batch.len();
            for job in batch {
                page.after_id = Some(job.id);
                let places = job.spec().map(|s| s.locations()).unwrap_or_default();
                if filter.aisle.is_none_or(|a| places.iter().any(|l| l.aisle == a)) {
                    ids.push(job.id);
                }
            }
            if read < PAGE as usize || ids.len() > MAX_BULK {
                return bounded(ids, "jobs");
            }
        }
    }

    /// Unlocks `locations` all or nothing (each locked by the job named, or at all).
    pub async fn bulk_unlock(
        &self,
        locations: Vec<(Location, Option<i64>)>,
        dry_run: bool,
        actor: &Actor,
    ) -> Result<Bulked, BulkError> {
        self.bulk(BulkAction::Unlock(locations), dry_run, actor).await
    }

    /// Puts failed `jobs` back in the queue all or nothing, in id order; with `unlock`,
    /// lifting the locks their failures set in the same commit.
    pub async fn bulk_retry(
        &self,
        jobs: Vec<i64>,
        unlock: bool,
        dry_run: bool,
        actor: &Actor,
    ) -> Result<Bulked, BulkError> {
        self.bulk(BulkAction::Retry { jobs, unlock }, dry_run, actor).await
    }

    /// Cancels queued `jobs` all or nothing: withheld from their devices, each device
    /// asked which it holds, then cancelled in one commit if none is held or moved on.
    pub async fn bulk_cancel(
        &self,
        jobs: Vec<i64>,
        devices: &Devices,
        dry_run: bool,
        actor: &Actor,
    ) -> Result<Bulked, BulkError> {
        if dry_run || jobs.is_empty() {
            return self.bulk(BulkAction::Cancel(jobs), dry_run, actor).await;
        }
        // Jobs past queued are not asked about: the writer refuses them, by their state.
        let mut by_device: BTreeMap<String, Vec<i64>> = BTreeMap::new();
        for id in &jobs {
            let queued = self.queues.find(*id).filter(|j| j.state == JobState::Queued);
            if let Some(device) = queued.and_then(|j| j.device) {
                by_device.entry(device).or_default().push(*id);
            }
        }
        let pairs = by_device.iter().flat_map(|(d, ids)| ids.iter().map(|id| (d.clone(), *id)));
        let _withheld = self.queues.withhold(pairs.collect());
        let mut held = Vec::new();
        for (device, ids) in &by_device {
            let Some(handle) = devices.get(device) else { continue };
            let holding = handle
                .holding(ids.clone())
                .await
                .ok_or_else(|| BulkError::Unavailable { device: device.clone() })?;
            held.extend(holding.into_iter().map(|id| Refusal::Held { id, device: device.clone() }));
        }
        if !held.is_empty() {
            // The whole answer: what the writer would refuse as well.
            if let Err(BulkError::Refused(more)) = self.bulk(BulkAction::Cancel(jobs), true, actor).await {
                let named: BTreeSet<String> = held.iter().map(Refusal::item).collect();
                held.extend(more.into_iter().filter(|r| !named.contains(&r.item())));
            }
            return Err(BulkError::Refused(held));
        }
        self.bulk(BulkAction::Cancel(jobs), false, actor).await
    }

    async fn bulk(&self, action: BulkAction, dry_run: bool, actor: &Actor) -> Result<Bulked, BulkError> {
        if action.is_empty() {
            return Ok(Bulked { applied: !dry_run, ..Bulked::default() });
        }
        let bulk = Bulk { action, dry_run, by: actor.by.clone(), reason: actor.reason.clone() };
        Ok(self.writer.bulk(bulk, actor.who()).await?)
    }
}

/// At most [`MAX_BULK`] items, or [`BulkError::TooMany`].
fn bounded<T>(items: Vec<T>, what: &'static str) -> Result<Vec<T>, BulkError> {
    if items.len() > MAX_BULK {
        return Err(BulkError::TooMany { what });
    }
    Ok(items)
}
