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
