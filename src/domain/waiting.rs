//! Why a queued job is not moving: one reason, in a closed set, with plain words.
//!
//! The dispatcher computes it (see `service::dispatch::waiting`); it lives here, with the
//! job it describes, so the API, the event log and the store share one type.

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

/// The kind of thing that holds a queued job back.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum WaitingReason {
    /// Its device does not answer.
    DeviceOffline,
    /// An operator paused its device.
    DevicePaused,
    /// An operator paused an aisle it touches.
    AislePaused,
    /// Its device (a crane) reports an alarm (`code`).
    DeviceAlarm,
    /// One of its locations is locked, by a failed job (`job`) or a person (`by`).
    LocationLocked,
    /// An older unfinished job (`job`) touches one of its locations: jobs on one location
    /// run in the order they were accepted.
    BehindJob,
    /// Every slot of its device (the crane) is busy with other jobs.
    SlotsBusy,
    /// No configured device runs it.
    NoDevice,
    /// Its crane's planner finds no free location for it: a store left to rackd whose
    /// zones are full, or a relocation it needs with nowhere to go.
    NoPlace,
    /// A job its `after` names has not completed (`job`).
    Dependency,
    /// An earlier member of its sequence goes first (`job`, when posted), or its box would
    /// reach the station before the one ahead of it.
    Sequence,
}

impl WaitingReason {
    /// Every reason.
    pub const ALL: [WaitingReason; 11] = [
        WaitingReason::DeviceOffline,
        WaitingReason::DevicePaused,
        WaitingReason::AislePaused,
        WaitingReason::DeviceAlarm,
        WaitingReason::LocationLocked,
        WaitingReason::BehindJob,
        WaitingReason::SlotsBusy,
        WaitingReason::NoDevice,
        WaitingReason::NoPlace,
        WaitingReason::Dependency,
        WaitingReason::Sequence,
    ];

    /// The reason's name as the API writes it.
    pub fn as_str(self) -> &'static str {
        match self {
            WaitingReason::DeviceOffline => "device_offline",
            WaitingReason::DevicePaused => "device_paused",
            WaitingReason::AislePaused => "aisle_paused",
            WaitingReason::DeviceAlarm => "device_alarm",
            WaitingReason::LocationLocked => "location_locked",
            WaitingReason::BehindJob => "behind_job",
            WaitingReason::SlotsBusy => "slots_busy",
            WaitingReason::NoDevice => "no_device",
            WaitingReason::NoPlace => "no_place",
            WaitingReason::Dependency => "dependency",
            WaitingReason::Sequence => "sequence",
        }
    }

    /// The reason with this name.
    pub fn parse(text: &str) -> Option<WaitingReason> {
        WaitingReason::ALL.into_iter().find(|r| r.as_str() == text)
    }
}

/// Why a queued job is not handed out now.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[schema(example = json!({"reason": "device_alarm", "text": "crane1 reports alarm 7002 (crane emergency stop button)",
    "device": "crane1", "code": 7002, "job": null, "by": null}))]
pub struct Waiting {
    /// What holds it back.
    pub reason: WaitingReason,
    /// The same in plain words, for an operator.
    pub text: String,
    /// The device concerned, if one is.
    pub device: Option<String>,
    /// The device's alarm code (`device_alarm`).
    pub code: Option<u16>,
    /// The failed job that locked the location (`location_locked`) or the job ahead on the
    /// same location (`behind_job`).
    pub job: Option<i64>,
    /// Who paused or locked (`device_paused`, `aisle_paused`, `location_locked` by hand).
    pub by: Option<String>,
}

impl Waiting {
    /// A reason with its words and nothing else.
    pub fn new(reason: WaitingReason, text: impl Into<String>) -> Waiting {
        Waiting { reason, text: text.into(), device: None, code: None, job: None, by: None }
    }

    /// The same, naming `device`.
    pub fn on(mut self, device: &str) -> Waiting {
        self.device = Some(device.to_owned());
        self
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reasons_round_trip_by_name() {
        for r in WaitingReason::ALL {
            assert_eq!(WaitingReason::parse(r.as_str()), Some(r));
            assert_eq!(serde_json::to_value(r).unwrap(), r.as_str());
        }
        assert_eq!(WaitingReason::parse("any"), None);
    }
}
