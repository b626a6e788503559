//! The crane's alarm catalogue (D205), from the spec: code → text and class.
//!
//! Business alarms are load-handling conflicts rackd resolves itself by cancelling the task;
//! hardware alarms need a person at the crane. A code missing from the catalogue is taken as
//! hardware: rackd cannot know that cancelling is safe, so it only stops giving new work.

pub use crate::domain::AlarmClass;

/// One alarm code as the catalogue describes it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Alarm {
    /// The code the crane writes to D205.
    pub code: u16,
    /// What it means.
    pub text: String,
    /// Who resolves it.
    pub class: AlarmClass,
}

use AlarmClass::{Business, Hardware};

/// Every alarm the spec names.
pub const CATALOGUE: &[(u16, AlarmClass, &str)] = &[
    (7069, Business, "left pick: no load on the platform after retracting"),
    (7070, Business, "right pick: no load on the platform after retracting"),
    (7072, Business, "left put: load still on the platform after retracting"),
    (7073, Business, "right put: load still on the platform after retracting"),
    (7079, Business, "load handling alarm 7079 (cancel the task)"),
    (7091, Business, "left: put near but near occupied"),
    (7092, Business, "left: put far but near occupied"),
    (7093, Business, "left: put far but far occupied"),
    (7094, Business, "left: pick far but near occupied"),
    (7095, Business, "right: put near but near occupied"),
    (7096, Business, "right: put far but near occupied"),
    (7097, Business, "right: put far but far occupied"),
    (7098, Business, "right: pick far but near occupied"),
    (7001, Hardware, "optical link emergency stop (X18)"),
    (7002, Hardware, "crane emergency stop button"),
    (7003, Hardware, "travel limit (X0E)"),
    (7004, Hardware, "lift limit (X0F)"),
    (7006, Hardware, "wire rope (X11E, X125)"),
    (7007, Hardware, "no laser data"),
    (7011, Hardware, "travel inverter fault"),
    (7012, Hardware, "lift inverter fault"),
    (7013, Hardware, "fork inverter fault"),
    (7014, Hardware, "high speed marker seen at high speed (X1E)"),
    (7020, Hardware, "heartbeat alarm"),
    (7054, Hardware, "fork low-speed timeout"),
    (7055, Hardware, "fork over-travel"),
    (7081, Hardware, "over-height 1"),
    (7082, Hardware, "over-width"),
    (7083, Hardware, "load sticks out left"),
    (7084, Hardware, "load sticks out right"),
    (7085, Hardware, "pallet sticks out"),
    (7086, Hardware, "over-height 2"),
    (7087, Hardware, "over-height 3"),
    (7101, Hardware, "ground cabinet emergency stop"),
    (7102, Hardware, "ground cabinet front safety door open"),
    (7104, Hardware, "ground cabinet rear safety door open"),
];

/// The alarm for a non-zero D205 code; unknown codes are hardware alarms.
pub fn lookup(code: u16) -> Alarm {
    match CATALOGUE.iter().find(|(c, _, _)| *c == code) {
        Some(&(code, class, text)) => Alarm { code, text: text.to_owned(), class },
        None => Alarm { code, text: format!("unknown alarm code {code}"), class: Hardware },
    }
}

/// The business alarm codes, in catalogue order.
pub fn business_codes() -> impl Iterator<Item = u16> {
    CATALOGUE.iter().filter(|(_, class, _)| *class == Business).map(|(c, _, _)| *c)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn catalogue_classifies_the_spec_codes() {
        assert_eq!(lookup(7069).class, Business);
        assert_eq!(lookup(7098).class, Business);
        assert_eq!(lookup(7079).class, Business);
        assert_eq!(lookup(7002).class, Hardware);
        assert_eq!(lookup(7104).class, Hardware);
        assert!(lookup(7083).text.contains("left"));
        assert_eq!(business_codes().count(), 13);
        assert_eq!(CATALOGUE.len(), 13 + 23);
    }

    #[test]
    fn unknown_codes_are_hardware() {
        let a = lookup(1234);
        assert_eq!(a.class, Hardware);
        assert!(a.text.contains("1234"));
    }

    #[test]
    fn codes_are_unique() {
        let mut codes: Vec<u16> = CATALOGUE.iter().map(|c| c.0).collect();
        codes.sort();
        codes.dedup();
        assert_eq!(codes.len(), CATALOGUE.len());
    }
}
