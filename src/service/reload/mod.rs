//! Reloading the configuration (issue 43): read it again from the sources the process
//! started with, check it as `rackd check-config` does, and apply the difference to the
//! running site ([`apply`]): devices started, stopped or restarted one by one, aisles and
//! locations added or removed, every other device untouched.
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
//! - Only `[[devices]]`, `[site]` and `[auth]` change at run time; any other key that
//!   changed refuses the whole reload, naming the key and where it is set: all or nothing.
//! - `[auth]` (the keys, `keys_file`'s too, and the failed-key limit) is one [`KeyRing`],
//!   swapped whole once the rest of the reload is applied: a key removed from the file is
//!   refused from the next request on, on every node (a standby serves the API too: its
//!   keys change at once, not at its takeover), and a WebSocket opened with it is closed
//!   (`api::ws`). The audit entry and the event name the keys added, removed or changed,
//!   by name; never a key or its hash.
//! - A reload may not remove every key nor add the first (409 `fixed_key`): keyless mode
//!   (no key: every request allowed, loopback only unless `--insecure`) is decided at
//!   start, and emptying the file must not open the API to everyone.
//! - An aisle removed or shrunk while something uses one of the locations it loses is
//!   refused (409 naming what holds them): a box (`occupied`), a job's reservation, or an
//!   unfinished job the dispatcher holds that touches the location. A standby keeps no
//!   queues: it sees the boxes and reservations of the store alone.
//! - A device removed while it holds jobs on the machine (handed over, not ended) is
//!   refused the same way (409 naming them): nobody would follow them. Its queued jobs do
//!   not hold it: they stay queued and wait as `no_device` until a device with its id is
//!   configured again.
//! - One reload at a time: a second waits for the first to end, then reads the file again.
//! - SIGHUP ([`on_hangups`]) applies as the API does, audited as `rackd`; its outcome is
//!   logged. It no longer ends the process (its default action), with or without a file.
//!   A refusal raises the `config_reload` alarm ([`hangups`]), which nobody would see in
//!   a log: the file says one thing and another runs (a key removed from it still valid).
//! - A takeover holds the reload's lock ([`Reload::take_over`]) from reading the running
//!   configuration until the node drives it: a reload on a standby that ran in between
//!   would change the configuration the node reports (its hash) and not the devices it
//!   starts, so drift detection would stay quiet and every later reload find no change.
//!   A reload asked for meanwhile waits, then changes the devices the node drives.
//! - Each node of a cluster reads its own sources: a reload is not forwarded to the active
//!   node (`api::forward`). A standby checks against its own running configuration and
//!   keeps the new one for when it takes over (it runs no device to change).
//! - Reading runs on a blocking thread: the loader reads files (the configuration, keys,
//!   certificates) with the standard library.

mod apply;
mod hangups;

use std::sync::atomic::AtomicU64;
use std::sync::{Arc, Mutex, OnceLock, RwLock};

use crate::auth::KeyRing;
pub use crate::config::RunningConfig;
use crate::config::{Change, Config, ConfigError, Difference, Origin, Sources};
use crate::domain::Location;
use crate::service::dispatch::Dispatcher;
use crate::service::fleet::Fleet;
use crate::service::intake::Rules;
use crate::store::writer::Writer;
use crate::store::{Pool, locations};

pub use apply::Applied;
#[cfg(unix)]
pub use hangups::on_hangups;

/// At most this many holders are named in a refusal; the rest are counted.
const NAMED: usize = 5;

/// The running configuration and where it came from, and what a reload changes; cloned
/// into the API's state.
#[derive(Clone)]
pub struct Reload(Arc<Inner>);

struct Inner {
    sources: OnceLock<Sources>,
    running: Mutex<Config>,
    /// Which configuration runs, for whoever tells it (a cluster node's row).
    loaded: tokio::sync::watch::Sender<RunningConfig>,
    rules: RwLock<Arc<Rules>>,
    /// `[auth]` as it runs, for the API's key check and the sessions opened with a key.
    keys: tokio::sync::watch::Sender<Arc<KeyRing>>,
    fleet: OnceLock<Fleet>,
    parts: Parts,
    /// One reload at a time.
    one: tokio::sync::Mutex<()>,
    /// The words of the `config_reload` alarm this process raised, while it is raised.
    refused: Mutex<Option<String>>,
}

/// What a reload needs of the rest of rackd.
pub struct Parts {
    /// The store: locations in use, locations to add, the queued jobs of an added device.
    pub pool: Pool,
    /// The dispatcher: its queues change with the devices.
    pub dispatcher: Dispatcher,
    /// This node's writer (not fenced: the audit entry is this node's own).
    pub writer: Writer,
    /// The writer's commits, for the cranes' planners.
    pub commits: Arc<AtomicU64>,
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
    /// The reload would remove every API key (true), or add the first (false).
    #[error("auth.keys: {}: keyless mode is decided at start (restart rackd for that); nothing was applied",
        if *.0 { "a reload cannot remove every key (rackd would then allow every request)" }
        else { "a reload cannot add the first key to a rackd started without any" })]
    Keyless(bool),
    /// Locations an aisle would lose are in use.
    #[error("site.aisles: {}; nothing was applied", held(.0))]
    InUse(Vec<Held>),
    /// Devices removed while they hold jobs on the machine: (device, jobs).
    #[error("{}; nothing was applied", busy(.0))]
    Busy(Vec<(String, Vec<i64>)>),
    /// A device could not be built (its link's settings).
    #[error("device {0:?}: {1}; nothing was applied")]
    Device(String, String),
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

fn busy(all: &[(String, Vec<i64>)]) -> String {
    let each: Vec<String> = all
        .iter()
        .map(|(device, jobs)| {
            let jobs: Vec<String> = jobs.iter().take(NAMED).map(i64::to_string).collect();
            format!("devices: {device} is removed but holds jobs on the machine ({})", jobs.join(", "))
        })
        .collect();
    each.join("; ")
}

fn list(keys: &[(String, Origin)]) -> String {
    let each: Vec<String> = keys.iter().map(|(key, origin)| format!("{key} ({origin})")).collect();
    each.join(", ")
}

impl Reload {
    /// `running`, with no sources yet ([`Reload::read_from`]) and no devices running yet
    /// ([`Reload::drive`]).
    pub fn new(running: Config, parts: Parts) -> Reload {
        let loaded = RunningConfig::now(&running);
        let rules = RwLock::new(Arc::new(Rules::of(&running)));
        let keys = tokio::sync::watch::Sender::new(Arc::new(KeyRing::new(&running.auth)));
        Reload(Arc::new(Inner {
            sources: OnceLock::new(),
            loaded: tokio::sync::watch::Sender::new(loaded),
            running: Mutex::new(running),
            rules,
            keys,
            fleet: OnceLock::new(),
            parts,
            one: tokio::sync::Mutex::new(()),
            refused: Mutex::new(None),
        }))
    }

    /// Reload from `sources` (those the running configuration was loaded from); set once.
    pub fn read_from(&self, sources: Sources) {
        let _ = self.0.sources.set(sources);
    }

    /// This node drives `fleet` from now on (at start, or when it takes over).
    pub fn drive(&self, fleet: Fleet) {
        let _ = self.0.fleet.set(fleet);
    }

    /// The devices this node drives, if it drives any.
    pub fn fleet(&self) -> Option<&Fleet> {
        self.0.fleet.get()
    }

    /// The running devices (none on a standby node).
    pub fn devices(&self) -> crate::devices::Devices {
        self.fleet().map(Fleet::devices).unwrap_or_default()
    }

    /// The dispatcher (its queues follow the devices a reload changes).
    pub fn dispatcher(&self) -> &crate::service::dispatch::Dispatcher {
        &self.0.parts.dispatcher
    }

    /// The running configuration.
    pub fn running(&self) -> Config {
        self.0.running.lock().unwrap_or_else(|p| p.into_inner()).clone()
    }

    /// Which configuration runs, and since when.
    pub fn loaded(&self) -> RunningConfig {
        self.0.loaded.borrow().clone()
    }

    /// Which configuration runs, as reloads change it.
    pub fn watch_loaded(&self) -> tokio::sync::watch::Receiver<RunningConfig> {
        self.0.loaded.subscribe()
    }

    /// What job requests are checked against and routed by, as the running configuration
    /// sets them.
    pub fn rules(&self) -> Arc<Rules> {
        self.0.rules.read().unwrap_or_else(|p| p.into_inner()).clone()
    }

    /// The API keys and the failed-key limit, as the running configuration sets them.
    pub fn keys(&self) -> Arc<KeyRing> {
        self.0.keys.borrow().clone()
    }

    /// The key ring, as reloads change it.
    pub fn watch_keys(&self) -> tokio::sync::watch::Receiver<Arc<KeyRing>> {
        self.0.keys.subscribe()
    }

    /// Begins a takeover: waits for a reload under way to end, then holds the reload's lock
    /// until [`Takeover::drive`] (or until the takeover is dropped), with the running
    /// configuration set in the dispatcher's queues.
    pub async fn take_over(&self) -> Takeover<'_> {
        let one = self.0.one.lock().await;
        let config = self.for_takeover();
        Takeover { reload: self, config, _one: one }
    }

    /// The running configuration for a node that takes over: the dispatcher's devices set
    /// as it says (a standby may have reloaded since it started).
    fn for_takeover(&self) -> Config {
        let config = self.running();
        let queues = self.0.parts.dispatcher.queues();
        let deep = &self.rules().deep;
        for d in &config.devices {
            let p = &self.0.parts;
            queues.set_device(crate::service::dispatch::Setup::of(d, deep, &p.pool, &p.commits));
        }
        for id in queues.devices() {
            if !config.devices.iter().any(|d| d.id() == id) {
                queues.remove_device(&id);
            }
        }
        config
    }

    /// Reads the sources again, checks the configuration, and says what changes; refused
    /// whole if a fixed key changes, or if what it removes is in use.
    pub async fn check(&self) -> Result<Plan, ReloadError> {
        let _one = self.0.one.lock().await;
        self.plan().await
    }

    async fn plan(&self) -> Result<Plan, ReloadError> {
        let sources = self.0.sources.get().cloned().ok_or(ReloadError::NoSources)?;
        let loaded = tokio::task::spawn_blocking(move || sources.load())
            .await
            .map_err(|e| ReloadError::Task(e.to_string()))??;
        let running = self.running();
        let difference = running.difference(&loaded.config);
        if !difference.fixed.is_empty() {
            let keys = difference.fixed.iter().map(|k| (k.clone(), loaded.locate(k))).collect();
            return Err(ReloadError::Fixed(keys));
        }
        let keyless = loaded.config.auth.keys.is_empty();
        if running.auth.keys.is_empty() != keyless {
            return Err(ReloadError::Keyless(keyless));
        }
        let in_use = self.in_use(&difference, &loaded.config).await?;
        if !in_use.is_empty() {
            return Err(ReloadError::InUse(in_use));
        }
        let queues = self.0.parts.dispatcher.queues();
        let busy: Vec<(String, Vec<i64>)> = removed(&difference)
            .map(|id| (id.to_owned(), queues.active_on(id)))
            .filter(|(_, jobs)| !jobs.is_empty())
            .collect();
        if !busy.is_empty() {
            return Err(ReloadError::Busy(busy));
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
            for l in locations::list(&self.0.parts.pool, Some(aisle)).await? {
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
        for (job, place) in self.0.parts.dispatcher.queues().touching_outside(exists) {
            if !held.contains(&Held::Job(place, job)) {
                held.push(Held::Job(place, job));
            }
        }
        Ok(held)
    }
}

/// The ids of the devices a difference removes.
fn removed(difference: &Difference) -> impl Iterator<Item = &str> {
    difference.devices.iter().filter(|d| d.change == Change::Removed).map(|d| d.id.as_str())
}

/// A takeover under way ([`Reload::take_over`]): no reload runs until it drives what it
/// read, or gives up.
pub struct Takeover<'a> {
    reload: &'a Reload,
    config: Config,
    _one: tokio::sync::MutexGuard<'a, ()>,
}

impl Takeover<'_> {
    /// The configuration to drive: the running one, which no reload changes meanwhile.
    pub fn config(&self) -> &Config {
        &self.config
    }

    /// The node drives `fleet`, started from [`Takeover::config`]; reloads may run again.
    pub fn drive(self, fleet: Fleet) {
        self.reload.drive(fleet);
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
