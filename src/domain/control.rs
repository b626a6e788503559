//! What operators set apart from the jobs: pauses (of a device or a whole aisle) and
//! location locks, each with who set it, when and why.

use serde::{Deserialize, Serialize};
use time::OffsetDateTime;
use utoipa::ToSchema;

/// Who paused a device or an aisle, when and why.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
pub struct Pause {
    /// The API key's name that paused it (`anonymous` when no keys are configured).
    pub by: String,
    /// Why, as the operator gave it.
    pub reason: Option<String>,
    /// When.
    #[serde(with = "time::serde::rfc3339")]
    #[schema(value_type = String, format = DateTime)]
    pub at: OffsetDateTime,
}

/// Who asks for a change through the API, as the audit log names them.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Who {
    /// The API key's name (`anonymous` when no keys are configured).
    pub name: String,
    /// The client's address (the TCP peer's IP address), when known.
    pub client: Option<std::net::IpAddr>,
}

/// Why a location is locked: no job touching it is handed out until a person unlocks it.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
pub struct LocationLock {
    /// `rackd` when a failed job locked it, else the API key's name.
    pub by: String,
    /// Why.
    pub reason: String,
    /// The failed job that locked it, if one did.
    pub job: Option<i64>,
    /// When.
    #[serde(with = "time::serde::rfc3339")]
    #[schema(value_type = String, format = DateTime)]
    pub at: OffsetDateTime,
}

/// What a pause applies to.
#[derive(Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Target {
    /// One device.
    Device(String),
    /// Every location of an aisle, whichever device serves it.
    Aisle(u16),
}

impl Target {
    /// The target as stored and audited: `device:ID` or `aisle:N`.
    pub fn key(&self) -> String {
        match self {
            Target::Device(id) => format!("device:{id}"),
            Target::Aisle(n) => format!("aisle:{n}"),
        }
    }

    /// The target with this key.
    pub fn parse(key: &str) -> Option<Target> {
        match key.split_once(':')? {
            ("device", id) if !id.is_empty() => Some(Target::Device(id.to_owned())),
            ("aisle", n) => n.parse().ok().map(Target::Aisle),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn targets_round_trip() {
        for t in [Target::Device("crane1".into()), Target::Aisle(2)] {
            assert_eq!(Target::parse(&t.key()), Some(t));
        }
        assert_eq!(Target::parse("aisle:x"), None);
        assert_eq!(Target::parse("device:"), None);
        assert_eq!(Target::parse("shelf1"), None);
    }
}
