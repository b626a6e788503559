//! Alarm classes: who resolves an alarm.

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

/// Who resolves an alarm.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum AlarmClass {
    /// A load-handling conflict rackd resolves itself by cancelling the task (a crane's
    /// business alarm).
    Business,
    /// A person must fix the machine; it gets no new work until the alarm clears.
    Hardware,
    /// The device does not answer.
    Link,
}

impl AlarmClass {
    /// Every class.
    pub const ALL: [AlarmClass; 3] = [AlarmClass::Business, AlarmClass::Hardware, AlarmClass::Link];

    /// The class's name as the API writes it.
    pub fn as_str(self) -> &'static str {
        match self {
            AlarmClass::Business => "business",
            AlarmClass::Hardware => "hardware",
            AlarmClass::Link => "link",
        }
    }

    /// The class with this name.
    pub fn parse(text: &str) -> Option<AlarmClass> {
        AlarmClass::ALL.into_iter().find(|c| c.as_str() == text)
    }
}

impl std::fmt::Display for AlarmClass {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// What raised an alarm: one of the device's own codes, or rackd about the device.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum AlarmKind {
    /// The device's own alarm code (a crane's D205), with the catalogue's text.
    Device,
    /// The device does not answer.
    Link,
    /// The crane's heartbeat (D200) stopped moving.
    Heartbeat,
    /// The link works but loses or retries more than the configured share of requests.
    Degraded,
    /// A shelf PLC answered again with every slot empty where rackd had tasks.
    MemoryLost,
    /// Another node of the cluster took over driving the machines (device `cluster`);
    /// cleared once a standby is back.
    Takeover,
    /// The retention could not archive ended jobs (device `store`: a full disk, a folder
    /// that went read-only); nothing was deleted. Cleared by the next archive that works.
    Archive,
    /// The store cannot commit (device `store`, `store:NODE` in a cluster): its disk is
    /// full (code 0), it takes no writes (1), its disk fails (2) or the database does not
    /// answer (3); see [`crate::store::fault`]. Cleared once a commit succeeds again.
    Store,
    /// A webhook subscription's receiver has failed every delivery for longer than its
    /// `alarm_after_secs` (code 0), events were pruned before it got them (code 1), its
    /// receiver paused it with a 410 Gone (code 2), or it could not start (code 3); device
    /// `webhook:NAME`. Cleared by the next success (code 0), once it has caught up (code
    /// 1), when it is resumed or an administrator pauses it (code 2), when it starts (code
    /// 3).
    Webhook,
    /// Nodes of the cluster run different `[site]` or `[[devices]]` (device `cluster`, a
    /// warning raised by the active node): a takeover would change the site. Cleared once
    /// every node seen runs the active node's.
    ConfigDrift,
    /// The certificate served over HTTPS expires within 14 days or has expired (code 0), or
    /// its files changed but do not load and the previous one is still served (code 1);
    /// device `tls` (`tls:NODE` in a cluster). Cleared once a certificate that is good for
    /// longer is served (code 0), or the files load (code 1).
    Certificate,
    /// A reload on SIGHUP was refused (device `config`, or `config:NODE` in a cluster): the
    /// file changed and what runs is not what it says (a revoked key may still be valid).
    /// Cleared by the next reload that is applied (SIGHUP or the API), or a restart.
    ConfigReload,
}

impl AlarmKind {
    /// Every kind.
    pub const ALL: [AlarmKind; 12] = [
        AlarmKind::Device,
        AlarmKind::Link,
        AlarmKind::Heartbeat,
        AlarmKind::Degraded,
        AlarmKind::MemoryLost,
        AlarmKind::Takeover,
        AlarmKind::Archive,
        AlarmKind::Store,
        AlarmKind::Webhook,
        AlarmKind::ConfigDrift,
        AlarmKind::Certificate,
        AlarmKind::ConfigReload,
    ];

    /// The kind's name as the API writes it.
    pub fn as_str(self) -> &'static str {
        match self {
            AlarmKind::Device => "device",
            AlarmKind::Link => "link",
            AlarmKind::Heartbeat => "heartbeat",
            AlarmKind::Degraded => "degraded",
            AlarmKind::MemoryLost => "memory_lost",
            AlarmKind::Takeover => "takeover",
            AlarmKind::Archive => "archive",
            AlarmKind::Store => "store",
            AlarmKind::Webhook => "webhook",
            AlarmKind::ConfigDrift => "config_drift",
            AlarmKind::Certificate => "certificate",
            AlarmKind::ConfigReload => "config_reload",
        }
    }

    /// The kind with this name.
    pub fn parse(text: &str) -> Option<AlarmKind> {
        AlarmKind::ALL.into_iter().find(|k| k.as_str() == text)
    }

    /// Who resolves an alarm of this kind that is not the device's own code.
    pub fn class(self) -> AlarmClass {
        match self {
            AlarmKind::Link
            | AlarmKind::Degraded
            | AlarmKind::Takeover
            | AlarmKind::Webhook
            | AlarmKind::ConfigDrift
            | AlarmKind::Certificate
            | AlarmKind::ConfigReload => AlarmClass::Link,
            AlarmKind::Device
            | AlarmKind::Heartbeat
            | AlarmKind::MemoryLost
            | AlarmKind::Archive
            | AlarmKind::Store => AlarmClass::Hardware,
        }
    }
}

impl std::fmt::Display for AlarmKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}
