//! Reloading the configuration (issue 43): read it again from the sources the process
//! started with, check it as `rackd check-config` does, and say what would change.
//!
//! Decisions:
//! - One code path: [`Sources::load`] reads, merges and checks, for `serve`, for
//!   `check-config` and here; a file that `check-config` refuses is refused by a reload
//!   with the same `WHERE: KEY: MESSAGE`.
//! - The [`Sources`] are the ones the process started with (`--config`, `--listen`,
//!   `--database`, the `RACKD_` environment of its start), kept by the application: a
//!   reload reads the same file and the same environment, so a `--listen` given at the
//!   start is not taken for a change of the listen address.
//! - The demo site (no file), and an application built from a configuration in code,
//!   have no sources: there is nothing to read again, and a reload says so (409).
//! - A key that cannot change at run time ([`crate::config::diff::FIXED`]) refuses the
//!   whole reload, naming the key and where it is set: all or nothing.
//! - An aisle removed or shrunk while something uses one of the locations it loses is
//!   refused (409 naming what holds them): a box (`occupied`), a job's reservation, or an
//!   unfinished job the dispatcher holds that touches the location. A standby keeps no
//!   queues: it sees the boxes and reservations of the store alone.
//! - Applying is not done yet: only the dry run answers (see `api::config`), and SIGHUP
//!   ([`on_hangups`]) runs the same check and logs its outcome. A SIGHUP no longer ends
//!   the process (its default action), with or without a file.
//! - Each node of a cluster reads its own sources: a reload is not forwarded to the active
//!   node (`api::forward`), and a standby checks against its own running configuration.
//! - Reading runs on a blocking thread: the loader reads files (the configuration, keys,
//!   certificates) with the standard library.

use std::sync::{Arc, Mutex, OnceLock};

use crate::config::{Config, ConfigError, Difference, Origin, Sources};
use crate::domain::Location;
use crate::service::dispatch::Queues;
use crate::store::{Pool, locations};

/// At most this many holders are named in a refusal; the rest are counted.
const NAMED: usize = 5;

/// The running configuration and where it came from; cloned into the API's state.
#[derive(Clone)]
pub struct Reload {
    sources: Arc<OnceLock<Sources>>,
    running: Arc<Mutex<Config>>,
    pool: Pool,
    queues: Queues,
}

/// A configuration read again and checked, and what it changes.
#[derive(Debug)]
pub struct Plan {
    /// The new configuration.
    pub config: Config,
    /// What changes from the running one.
    pub difference: Difference,
}

/// Why a reload is refused.
#[derive(Debug, thiserror::Error)]
pub enum ReloadError {
    /// The process did not start from a file.
    #[error(
        "rackd was not started from a configuration file (the demo site, or built in code): nothing to reload"
    )]
    NoSources,
    /// The configuration does not load or does not check.
    #[error(transparent)]
    Invalid(#[from] ConfigError),
    /// Keys that cannot change while rackd runs.
    #[error("{}: cannot change while rackd runs (restart rackd to change them); nothing was applied", list(.0))]
    Fixed(Vec<(String, Origin)>),
    /// Locations an aisle would lose are in use.
    #[error("site.aisles: {}; nothing was applied", held(.0))]
    InUse(Vec<Held>),
    /// The store could not be read.
    #[error("reading the locations: {0}")]
    Store(#[from] sqlx::Error),
    /// The blocking read failed to run.
    #[error("reading the configuration did not finish: {0}")]
    Task(String),
}

/// What holds a location that a reload would remove.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Held {
    /// A box is there.
    Box(Location, Option<String>),
    /// A job reserved it, or an unfinished job touches it.
    Job(Location, i64),
}

impl std::fmt::Display for Held {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Held::Box(l, Some(barcode)) => write!(f, "box {barcode} at {l}"),
            Held::Box(l, None) => write!(f, "a box at {l}"),
            Held::Job(l, job) => write!(f, "job {job} at {l}"),
        }
    }
}

fn held(all: &[Held]) -> String {
    let aisles: std::collections::BTreeSet<u16> = all
        .iter()
        .map(|h| match h {
            Held::Box(l, _) | Held::Job(l, _) => l.aisle,
        })
        .collect();
    let aisles: Vec<String> = aisles.iter().map(|a| format!("aisle {a}")).collect();
    let named: Vec<String> = all.iter().take(NAMED).map(Held::to_string).collect();
    let more = match all.len().saturating_sub(NAMED) {
        0 => String::new(),
        n => format!(" and {n} more"),
    };
    format!("{} would lose locations in use: {}{more}", aisles.join(", "), named.join(", "))
}

fn list(keys: &[(String, Origin)]) -> String {
    let each: Vec<String> = keys.iter().map(|(key, origin)| format!("{key} ({origin})")).collect();
    each.join(", ")
}

impl Reload {
    /// `running`, with no sources yet ([`Reload::read_from`]); `pool` and `queues` say
    /// which locations are in use.
    pub fn new(running: Config, pool: Pool, queues: Queues) -> Reload {
        Reload { sources: Arc::new(OnceLock::new()), running: Arc::new(Mutex::new(running)), pool, queues }
    }

    /// Reload from `sources` (those the running configuration was loaded from); set once.
    pub fn read_from(&self, sources: Sources) {
        let _ = self.sources.set(sources);
    }

    /// The running configuration.
    pub fn running(&self) -> Config {
        self.running.lock().unwrap_or_else(|p| p.into_inner()).clone()
    }

    /// Reads the sources again, checks the configuration, and says what changes; refused
    /// whole if a fixed key changes.
    pub async fn check(&self) -> Result<Plan, ReloadError> {
        let sources = self.sources.get().cloned().ok_or(ReloadError::NoSources)?;
        let loaded = tokio::task::spawn_blocking(move || sources.load())
            .await
            .map_err(|e| ReloadError::Task(e.to_string()))??;
        let difference = self.running().difference(&loaded.config);
        if !difference.fixed.is_empty() {
            let keys = difference.fixed.iter().map(|k| (k.clone(), loaded.locate(k))).collect();
            return Err(ReloadError::Fixed(keys));
        }
        let in_use = self.in_use(&difference, &loaded.config).await?;
        if !in_use.is_empty() {
            return Err(ReloadError::InUse(in_use));
        }
        Ok(Plan { config: loaded.config, difference })
    }

    /// What holds the locations that the aisles removed or changed would lose: boxes and
    /// reservations first (by place), then the dispatcher's unfinished jobs.
    async fn in_use(&self, difference: &Difference, new: &Config) -> Result<Vec<Held>, ReloadError> {
        let layout = new.layout();
        let exists = |l: &Location| layout.check(l).is_ok();
        let aisles = difference
            .aisles
            .removed
            .iter()
            .copied()
            .chain(difference.aisles.changed.iter().map(|c| c.aisle));
        let mut held = Vec::new();
        for aisle in aisles {
            for l in locations::list(&self.pool, Some(aisle)).await? {
                let place = l.location();
                if exists(&place) {
                    continue;
                }
                if l.occupied {
                    held.push(Held::Box(place, l.barcode.clone()));
                }
                if let Some(job) = l.reserved_by {
                    held.push(Held::Job(place, job));
                }
            }
        }
        for (job, place) in self.queues.touching_outside(exists) {
            if !held.contains(&Held::Job(place, job)) {
                held.push(Held::Job(place, job));
            }
        }
        Ok(held)
    }
}

/// On each SIGHUP, the check of `POST /config/reload?dry_run=true`, its outcome logged:
/// the difference, or why the configuration is refused.
#[cfg(unix)]
pub async fn on_hangups(reload: Reload, mut hangups: tokio::signal::unix::Signal) {
    while hangups.recv().await.is_some() {
        match reload.check().await {
            Ok(plan) => {
                let difference = serde_json::to_string(&plan.difference).unwrap_or_default();
                tracing::info!(%difference, "SIGHUP: the configuration was read again and checks; not applied (dry run only so far)");
            }
            Err(e) => {
                tracing::warn!(error = %e, "SIGHUP: the configuration was read again and is refused; nothing was applied")
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(aisle: u16, bay: u16) -> Location {
        Location { aisle, row: 1, bay, level: 1, position: 1 }
    }

    #[test]
    fn a_refusal_names_the_aisles_and_the_first_holders_and_counts_the_rest() {
        let mut all = vec![Held::Box(at(2, 1), Some("BOX-1".into())), Held::Box(at(2, 2), None)];
        all.extend((3..8).map(|bay| Held::Job(at(1, bay), i64::from(bay))));
        assert_eq!(
            ReloadError::InUse(all).to_string(),
            "site.aisles: aisle 1, aisle 2 would lose locations in use: box BOX-1 at 2-1-1-1-1, a box at 2-1-2-1-1, \
             job 3 at 1-1-3-1-1, job 4 at 1-1-4-1-1, job 5 at 1-1-5-1-1 and 2 more; nothing was applied"
        );
    }
}
