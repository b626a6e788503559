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

/// What an operator should do about a crane alarm, in plain words. Business alarms need no
/// one at the crane (rackd cancels the task; the job fails and its locations lock until a
/// person checks them); every hardware alarm, and an unknown code, needs a person at the
/// crane, as the spec's catalogue says.
pub fn action(code: u16) -> &'static str {
    match code {
        _ if lookup(code).class == Business => {
            "No one needs to go to the crane: rackd cancels the task and fails the job. Check the job's \
             locations, unlock them, then retry the job."
        }
        7001 | 7002 | 7101 => {
            "A person must go to the crane: find out why the emergency stop was pressed, make the area \
             safe, release the stop and reset the crane."
        }
        7102 | 7104 => "A person must close the ground cabinet's safety door and reset the crane.",
        7003 | 7004 => {
            "A person must go to the crane: it reached a limit switch; move it back in manual mode and \
             reset it."
        }
        7006 => "Do not run the crane: a person must inspect the lift's wire rope before resetting it.",
        7007 => "A person must check the crane's distance laser (dirt, alignment), then reset the crane.",
        7011..=7013 => "A person must check the drive and its inverter on the crane, then reset the fault.",
        7014 => "A person must check the crane's travel position markers, then reset the crane.",
        7020 => {
            "Check that rackd reaches the crane's PLC (the heartbeat stopped); reset the crane once the \
             link works again."
        }
        7054 | 7055 => {
            "A person must check the forks (obstruction, sensors), bring them home in manual mode, then \
             reset the crane."
        }
        7081..=7087 => {
            "A person must take the load off the crane at the station, fix its size or pallet, then reset \
             the crane."
        }
        _ => "A person must check the crane's panel: this code is not in rackd's catalogue.",
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
    fn every_code_says_what_to_do_and_whether_a_person_must_go() {
        for &(code, class, _) in CATALOGUE {
            let action = action(code);
            assert_eq!(action.contains("No one needs to go"), class == Business, "{code}: {action}");
        }
        assert!(action(1234).contains("not in rackd's catalogue"));
    }

    #[test]
    fn codes_are_unique() {
        let mut codes: Vec<u16> = CATALOGUE.iter().map(|c| c.0).collect();
        codes.sort();
        codes.dedup();
        assert_eq!(codes.len(), CATALOGUE.len());
    }
}
