//! Checks of a configuration that parsed: values that make no sense alone or together.

use std::collections::{BTreeMap, BTreeSet};

use super::{Config, EventsConfigError};
use crate::devices::config::DeviceConfigError;

/// A configuration that parses but cannot be run.
#[derive(Debug, thiserror::Error)]
pub enum Invalid {
    /// An aisle number that is 0 or appears twice.
    #[error("site.aisles: aisle {0} is zero or listed twice")]
    AisleNumber(u16),
    /// An aisle with no locations, or more than two rows.
    #[error("site.aisles: aisle {0} needs rows 1..=2 and at least one bay, level and position")]
    AisleSize(u16),
    /// No aisles at all.
    #[error("site.aisles: at least one aisle is needed")]
    NoAisles,
    /// A device entry.
    #[error(transparent)]
    Device(#[from] DeviceConfigError),
    /// Two devices with one id.
    #[error("devices: id {0:?} is used twice")]
    DeviceId(String),
    /// A device serving an aisle the site does not have.
    #[error("devices {device:?}: aisle {aisle} is not in site.aisles")]
    UnknownAisle {
        /// The device.
        device: String,
        /// The aisle.
        aisle: u16,
    },
    /// Two devices serving one aisle (jobs are routed by aisle).
    #[error("devices {device:?}: aisle {aisle} is already served by {other:?}")]
    AisleServedTwice {
        /// The device.
        device: String,
        /// The aisle.
        aisle: u16,
        /// The device that serves it already.
        other: String,
    },
    /// An intake bound of 0.
    #[error("intake.max_group and intake.queue must be at least 1")]
    Intake,
    /// `[events]`.
    #[error(transparent)]
    Events(#[from] EventsConfigError),
}

impl Config {
    /// Checks values that are valid TOML but make no sense.
    pub(super) fn check(&self) -> Result<(), Invalid> {
        let mut seen = BTreeSet::new();
        for a in &self.site.aisles {
            if a.aisle == 0 || !seen.insert(a.aisle) {
                return Err(Invalid::AisleNumber(a.aisle));
            }
            let l = a.layout();
            if !(1..=2).contains(&l.rows) || l.bays == 0 || l.levels == 0 || l.positions == 0 {
                return Err(Invalid::AisleSize(a.aisle));
            }
        }
        if self.site.aisles.is_empty() {
            return Err(Invalid::NoAisles);
        }
        let mut ids = BTreeSet::new();
        let mut served = BTreeMap::new();
        for d in &self.devices {
            d.check()?;
            let device = d.id();
            if !ids.insert(device) {
                return Err(Invalid::DeviceId(device.to_owned()));
            }
            for &aisle in d.aisles() {
                if !seen.contains(&aisle) {
                    return Err(Invalid::UnknownAisle { device: device.to_owned(), aisle });
                }
                if let Some(other) = served.insert(aisle, device) {
                    let (device, other) = (device.to_owned(), other.to_owned());
                    return Err(Invalid::AisleServedTwice { device, aisle, other });
                }
            }
        }
        if self.intake.max_group == 0 || self.intake.queue == 0 {
            return Err(Invalid::Intake);
        }
        Ok(self.events.check()?)
    }
}
