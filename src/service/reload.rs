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
//! - Applying is not done yet: only the dry run answers (see `api::config`), and SIGHUP
//!   ([`on_hangups`]) runs the same check and logs its outcome. A SIGHUP no longer ends
//!   the process (its default action), with or without a file.
//! - Reading runs on a blocking thread: the loader reads files (the configuration, keys,
//!   certificates) with the standard library.

use std::sync::{Arc, Mutex, OnceLock};

use crate::config::{Config, ConfigError, Difference, Origin, Sources};

/// The running configuration and where it came from; cloned into the API's state.
#[derive(Clone)]
pub struct Reload {
    sources: Arc<OnceLock<Sources>>,
    running: Arc<Mutex<Config>>,
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
    /// The blocking read failed to run.
    #[error("reading the configuration did not finish: {0}")]
    Task(String),
}

fn list(keys: &[(String, Origin)]) -> String {
    let each: Vec<String> = keys.iter().map(|(key, origin)| format!("{key} ({origin})")).collect();
    each.join(", ")
}

impl Reload {
    /// `running`, with no sources yet ([`Reload::read_from`]).
    pub fn new(running: Config) -> Reload {
        Reload { sources: Arc::new(OnceLock::new()), running: Arc::new(Mutex::new(running)) }
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
        Ok(Plan { config: loaded.config, difference })
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
