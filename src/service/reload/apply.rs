//! Applying a reload to the running site, all or nothing, in an order that never loses a
//! job or talks to a machine from two tasks at once:
//!
//! 1. Everything that can fail comes first, before anything changes: the configuration is
//!    read and checked, each device to start is built (its link opened lazily, nothing
//!    sent: [`Fleet::prepare`]), the unfinished jobs of each added device are read, the
//!    new locations are added to the store (rows for locations that exist nowhere yet
//!    change nothing if the rest fails).
//! 2. Devices to remove get no new work, and each answers once what it holds (a round of
//!    its task, so a hand-over begun before is recorded by then); one that holds a job on
//!    the machine refuses the reload, and the devices are given their work back.
//! 3. The dispatcher's queues take the added devices (with their unfinished jobs) and the
//!    changed ones' settings (window, aisles, a crane's planner); cranes get new planners
//!    when the double-deep aisles change. The intake's rules change next, so a job routed
//!    to an added device finds its queue.
//!    The locations that removed or shrunk aisles lose go from the store (nothing uses
//!    them: the check said so, and no job can name them now).
//! 4. Removed and changed devices stop, all at once, each at its own safe point
//!    ([`Fleet::stop`]); removed ones leave the queues, and their queued jobs are told
//!    again: they wait as `no_device`.
//! 5. Changed and added devices start; each recovers from its registers before it takes
//!    work.
//! 6. The new configuration runs, its API keys last (`[auth]`: the key ring swapped whole),
//!    then an audit entry (who, the hash, the difference, keys by name) and a
//!    `config.reloaded` event, in one commit; a `config_reload` alarm clears.
//!
//! A device whose keys did not change is not touched: its task, its link and its monitor
//! run on.

use serde::Serialize;
use utoipa::ToSchema;

use super::{Reload, ReloadError, RunningConfig, removed};
use crate::auth::KeyRing;
use crate::config::devices::DeviceConfig;
use crate::config::{Change, Config, Difference};
use crate::domain::Who;
use crate::domain::time::now_ms;
use crate::service::dispatch::Setup;
use crate::service::fleet::Fleet;
use crate::service::intake::Rules;
use crate::store::writer::Record;
use crate::store::{jobs, locations};

/// What a reload did: the data of its `config.reloaded` event.
#[derive(Clone, Debug, Serialize, ToSchema)]
pub struct Applied {
    /// The API key's name (`rackd` for a SIGHUP).
    pub by: String,
    /// The configuration now running.
    #[serde(flatten)]
    pub loaded: RunningConfig,
    /// What changed.
    #[serde(flatten)]
    pub difference: Difference,
    /// A standby runs no device: it keeps the configuration for when it takes over.
    pub kept_for_takeover: bool,
}

impl Reload {
    /// Reads the configuration again, checks it, and applies the difference (see the
    /// module doc), audited as `who` with `reason`.
    pub async fn apply(&self, who: Who, reason: Option<String>) -> Result<Applied, ReloadError> {
        let _one = self.0.one.lock().await;
        self.apply_held(who, reason).await
    }

    /// [`Reload::apply`], its caller holding the reload's lock.
    pub(super) async fn apply_held(&self, who: Who, reason: Option<String>) -> Result<Applied, ReloadError> {
        let plan = self.plan().await?;
        let (new, difference) = (plan.config, plan.difference);
        let p = &self.0.parts;
        let kept_for_takeover = match self.fleet() {
            Some(fleet) => {
                self.change(fleet, &new, &difference).await?;
                false
            }
            None => {
                locations::seed(&p.pool, &new.layout(), now_ms()).await?;
                *self.0.rules.write().unwrap_or_else(|e| e.into_inner()) =
                    std::sync::Arc::new(Rules::of(&new));
                true
            }
        };
        let loaded = RunningConfig::now(&new);
        let keys = (!difference.auth.is_empty()).then(|| KeyRing::new(&new.auth));
        *self.0.running.lock().unwrap_or_else(|e| e.into_inner()) = new;
        self.0.loaded.send_replace(loaded.clone());
        // Last: everything else is applied, and no request is checked against a ring that
        // a failed reload left.
        if let Some(keys) = keys {
            self.0.keys.send_replace(std::sync::Arc::new(keys));
        }
        let applied = Applied { by: who.name.clone(), loaded, difference, kept_for_takeover };
        let summary = match &reason {
            Some(r) => format!("{} ({r})", summary(&applied)),
            None => summary(&applied),
        };
        let data = serde_json::to_string(&applied).unwrap_or_default();
        if let Err(e) = p.writer.record_as(Record::Reloaded { data, reason: summary }, who).await {
            tracing::warn!(error = %e, "the reload was applied but could not be audited");
        }
        self.clear_alarm(false).await;
        Ok(applied)
    }

    /// Changes the running devices, queues and rules from the running configuration to
    /// `new` (steps 1 to 5 of the module doc).
    async fn change(&self, fleet: &Fleet, new: &Config, difference: &Difference) -> Result<(), ReloadError> {
        let p = &self.0.parts;
        let queues = p.dispatcher.queues();
        let old = self.running();
        let find = |c: &Config, id: &str| c.devices.iter().find(|d| d.id() == id).cloned();
        let mut starting = Vec::new();
        for change in difference.devices.iter().filter(|c| c.change != Change::Removed) {
            let Some(c) = find(new, &change.id) else { continue };
            let prepared = fleet
                .prepare(&c)
                .await
                .map_err(|e| ReloadError::Device(change.id.clone(), format!("{e:#}")))?;
            let unfinished = match change.change {
                Change::Added => jobs::unfinished(&p.pool, &change.id).await?,
                _ => Vec::new(),
            };
            starting.push((c, prepared, unfinished));
        }
        locations::seed(&p.pool, &new.layout(), now_ms()).await?;

        let rules = Rules::of(new);
        let setup = |d: &DeviceConfig| Setup::of(d, &rules.deep, &p.pool, &p.commits);
        let gone: Vec<String> = removed(difference).map(str::to_owned).collect();
        for id in &gone {
            let aisles = find(&old, id).map(|d| d.aisles().to_vec()).unwrap_or_default();
            queues.set_device(Setup { id: id.clone(), window: 0, aisles, planner: None });
        }
        let running = fleet.devices();
        for id in &gone {
            if let Some(device) = running.get(id) {
                device.holding(Vec::new()).await;
            }
        }
        let busy: Vec<(String, Vec<i64>)> = gone
            .iter()
            .map(|id| (id.clone(), queues.active_on(id)))
            .filter(|(_, jobs)| !jobs.is_empty())
            .collect();
        if !busy.is_empty() {
            let deep = self.rules().deep.clone();
            for d in gone.iter().filter_map(|id| find(&old, id)) {
                queues.set_device(Setup::of(&d, &deep, &p.pool, &p.commits));
            }
            return Err(ReloadError::Busy(busy));
        }

        let deep_changed = rules.deep != self.rules().deep;
        for d in &new.devices {
            let changed = starting.iter().any(|(c, _, _)| c.id() == d.id());
            if changed || (deep_changed && matches!(d, DeviceConfig::Crane(_))) {
                queues.set_device(setup(d));
            }
        }
        for (c, _, unfinished) in &mut starting {
            if !unfinished.is_empty() {
                queues.load(c.id(), std::mem::take(unfinished));
            }
        }
        queues.set_stations(&new.site.stations);
        let layout = rules.layout.clone();
        *self.0.rules.write().unwrap_or_else(|e| e.into_inner()) = std::sync::Arc::new(rules);
        // Nothing uses them (checked), and no job can name them any more.
        let shrunk = difference.aisles.changed.iter().map(|c| c.aisle);
        for aisle in difference.aisles.removed.iter().copied().chain(shrunk) {
            if let Err(e) = locations::drop_outside(&p.pool, &layout, aisle).await {
                tracing::warn!(aisle, error = %e, "the locations a reload removed could not be deleted");
            }
        }

        let stopping = difference.devices.iter().filter(|c| c.change != Change::Added);
        futures::future::join_all(stopping.map(|c| fleet.stop(&c.id, c.change == Change::Removed))).await;
        let mut waiting = Vec::new();
        for id in &gone {
            waiting.extend(queues.remove_device(id));
        }
        for (_, prepared, _) in starting {
            fleet.run(prepared, None).await;
        }
        if !waiting.is_empty()
            && let Err(e) = p.writer.record(Record::Retell { jobs: waiting }).await
        {
            tracing::warn!(error = %e, "telling the jobs of removed devices why they wait");
        }
        Ok(())
    }
}

/// The audit entry's words: the hash and what changed.
fn summary(applied: &Applied) -> String {
    let d = &applied.difference;
    let mut parts: Vec<String> = d
        .devices
        .iter()
        .map(|c| match c.change {
            Change::Added => format!("device {} added", c.id),
            Change::Removed => format!("device {} removed", c.id),
            Change::Changed => format!("device {} changed ({})", c.id, c.keys.join(", ")),
        })
        .collect();
    let aisles = |what: &str, list: &[u16]| {
        let list: Vec<String> = list.iter().map(u16::to_string).collect();
        format!("aisle {} {what}", list.join(", "))
    };
    if !d.aisles.added.is_empty() {
        parts.push(aisles("added", &d.aisles.added));
    }
    if !d.aisles.removed.is_empty() {
        parts.push(aisles("removed", &d.aisles.removed));
    }
    for c in &d.aisles.changed {
        parts.push(format!("aisle {} changed ({})", c.aisle, c.keys.join(", ")));
    }
    // By name only: never a key, nor its hash.
    for k in &d.auth.keys {
        parts.push(match k.change {
            Change::Added => format!("key {} added", k.name),
            Change::Removed => format!("key {} removed", k.name),
            Change::Changed => format!("key {} changed ({})", k.name, k.fields.join(", ")),
        });
    }
    for setting in &d.auth.settings {
        parts.push(format!("{setting} changed"));
    }
    if parts.is_empty() {
        parts.push("no change".into());
    }
    let kept = if applied.kept_for_takeover { "; kept for when this standby takes over" } else { "" };
    format!("configuration {}: {}{kept}", applied.loaded.hash, parts.join("; "))
}
