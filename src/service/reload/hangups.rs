//! Reloads on SIGHUP, and the `config_reload` alarm a refused one raises.
//!
//! Decisions:
//! - A SIGHUP has nobody to answer, so a refusal is an alarm as well as a log line: the
//!   file then says one thing and rackd runs another (a key removed from the file is still
//!   valid), and a log line is read by nobody until it matters. A refusal through the API
//!   answers its caller, who knows; it raises nothing.
//! - The alarm is this node's: device `config`, or `config:NODE` in a cluster (each node
//!   reads its own file), so one node's reload never clears another's.
//! - It clears when a reload is applied (SIGHUP or the API: the file and what runs agree
//!   again), and at start (rackd read the file then, and it loaded). A refusal for another
//!   reason than the active alarm's clears it and raises it again with the new words, as
//!   `config_drift` does.
//! - Its words are the refusal's, as the API and `check-config` give them: keys by name
//!   and place, never a value (a secret in a printed URL is redacted).

use super::Reload;
use crate::config::RELOAD_ACTION;
use crate::domain::{AlarmKind, Who};
use crate::store::alarms::NewAlarm;
use crate::store::writer::Record;

/// The alarm's kind; its code is always 0.
const KEY: (AlarmKind, u16) = (AlarmKind::ConfigReload, 0);

impl Reload {
    /// The device the `config_reload` alarm is raised on: `config`, or `config:NODE`.
    pub fn alarm_device(&self) -> String {
        match &self.running().cluster {
            Some(c) => format!("config:{}", c.node),
            None => "config".to_owned(),
        }
    }

    fn refused(&self) -> std::sync::MutexGuard<'_, Option<String>> {
        self.0.refused.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Clears this node's `config_reload` alarm if this process raised it (`always`: in any
    /// case, as at start).
    pub(super) async fn clear_alarm(&self, always: bool) {
        if !always && self.refused().is_none() {
            return;
        }
        let record = Record::AlarmCleared { device: self.alarm_device(), key: KEY };
        match self.0.parts.writer.record(record).await {
            Ok(()) => *self.refused() = None,
            Err(e) => tracing::warn!(error = %e, "the config_reload alarm could not be cleared"),
        }
    }

    /// Raises this node's `config_reload` alarm for a SIGHUP refused with `why` (cleared
    /// first if it is raised with other words).
    #[cfg(unix)]
    async fn raise_alarm(&self, why: String) {
        let raised = self.refused().clone();
        if raised.as_ref() == Some(&why) {
            return;
        }
        if raised.is_some() {
            self.clear_alarm(false).await;
        }
        let alarm = NewAlarm {
            device: self.alarm_device(),
            kind: AlarmKind::ConfigReload,
            code: 0,
            class: AlarmKind::ConfigReload.class(),
            text: "the configuration file was read again on SIGHUP and refused: rackd runs on with the \
                   configuration it ran before"
                .to_owned(),
            detail: Some(why.clone()),
            action: Some(RELOAD_ACTION.to_owned()),
        };
        match self.0.parts.writer.record(Record::AlarmRaised(alarm)).await {
            Ok(()) => *self.refused() = Some(why),
            Err(e) => tracing::warn!(error = %e, "the config_reload alarm could not be raised"),
        }
    }
}

impl Reload {
    /// A SIGHUP's reload, audited as `rackd`; a refusal raises the alarm before another
    /// reload may run (one applied meanwhile would otherwise be followed by a stale alarm).
    #[cfg(unix)]
    async fn on_hangup(&self) -> Result<super::Applied, super::ReloadError> {
        let _one = self.0.one.lock().await;
        let who = Who { name: "rackd".into(), client: None };
        let applied = self.apply_held(who, Some("SIGHUP".into())).await;
        if let Err(e) = &applied {
            self.raise_alarm(e.to_string()).await;
        }
        applied
    }
}

/// On each SIGHUP, the reload of `POST /config/reload`, audited as `rackd`; its outcome
/// logged: what changed, or why the configuration is refused (and the alarm raised).
#[cfg(unix)]
pub async fn on_hangups(reload: Reload, mut hangups: tokio::signal::unix::Signal) {
    // The file loaded at start: whatever an earlier run's alarm said is over.
    reload.clear_alarm(true).await;
    while hangups.recv().await.is_some() {
        match reload.on_hangup().await {
            // `apply` cleared the alarm.
            Ok(applied) => {
                let difference = serde_json::to_string(&applied.difference).unwrap_or_default();
                tracing::info!(%difference, hash = %applied.loaded.hash, "SIGHUP: the configuration was reloaded");
            }
            Err(e) => {
                tracing::warn!(error = %e, "SIGHUP: the configuration was read again and is refused; nothing was applied")
            }
        }
    }
}
