//! `[[devices]]`: one entry per machine, with its protocol link and its kind's settings.

use std::time::Duration;

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use crate::protocols::link::LinkConfig;

/// The kinds of machine rackd drives.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum DeviceKind {
    /// A shelf storage PLC with task slots (shelf-plc.md).
    Shelf,
}

impl DeviceKind {
    /// The job kinds this kind of machine runs.
    pub fn job_kinds(self) -> &'static [crate::domain::JobKind] {
        use crate::domain::JobKind::*;
        match self {
            DeviceKind::Shelf => &[Store, Retrieve, Move, Clear, Light],
        }
    }

    /// The kind's name as the configuration writes it.
    pub fn as_str(self) -> &'static str {
        match self {
            DeviceKind::Shelf => "shelf",
        }
    }
}

/// One `[[devices]]` entry. Every key but `id`, `kind`, `address` and `aisles` has a default.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DeviceConfig {
    /// The device's id, used in the API and in jobs' `device`.
    pub id: String,
    /// What kind of machine.
    pub kind: DeviceKind,
    /// The aisles whose locations this device serves (jobs are routed by location).
    pub aisles: Vec<u16>,
    /// One of [`crate::protocols::link::PROTOCOLS`] (`modbus-udp`, `modbus-tcp`, `modbus-rtu`, `modbus-rtu-tcp`, `mewtocol`, `mewtocol-tcp`, `ppi`, `ppi-tcp`).
    #[serde(default = "default_protocol")]
    pub protocol: String,
    /// `HOST:PORT`, or a serial device path.
    pub address: String,
    /// Modbus unit (station).
    #[serde(default = "one")]
    pub unit: u8,
    /// Serial settings such as `9600,8E1` (serial protocols only).
    pub serial: Option<String>,
    /// Reply timeout per attempt, in milliseconds.
    #[serde(default = "default_timeout_ms")]
    pub timeout_ms: u64,
    /// Resends after a timeout.
    #[serde(default = "default_retries")]
    pub retries: u32,
    /// Protocol quirks: `length0` (replies with MBAP length 0), `no-transaction-id`.
    #[serde(default)]
    pub quirks: Vec<String>,
    /// How often running work is polled, in milliseconds.
    #[serde(default = "default_poll_ms")]
    pub poll_ms: u64,
    /// Consecutive failed requests after which the device is offline (no new work).
    #[serde(default = "default_offline_after")]
    pub offline_after: u32,
    /// Shelf: number of task slots.
    #[serde(default = "default_slots")]
    pub slots: u16,
    /// Shelf: address of slot 1's task id, in the protocol's notation.
    #[serde(default = "default_base")]
    pub base: String,
    /// Shelf: words from one slot to the next.
    #[serde(default = "default_stride")]
    pub stride: u16,
    /// Shelf: after recording a finished or failed task, set the slot's task id to 0.
    #[serde(default = "yes")]
    pub clear_finished: bool,
    /// Shelf: allow cancelling a task the PLC has not started by clearing its slot.
    #[serde(default = "yes")]
    pub withdraw: bool,
}

fn default_protocol() -> String {
    "modbus-udp".into()
}
fn one() -> u8 {
    1
}
fn default_timeout_ms() -> u64 {
    300
}
fn default_retries() -> u32 {
    2
}
fn default_poll_ms() -> u64 {
    200
}
fn default_offline_after() -> u32 {
    3
}
fn default_slots() -> u16 {
    60
}
fn default_base() -> String {
    "4x4000".into()
}
fn default_stride() -> u16 {
    100
}
fn yes() -> bool {
    true
}

impl DeviceConfig {
    /// A shelf PLC on the given address with every default (as in the seed).
    pub fn shelf(id: &str, address: &str, aisles: Vec<u16>) -> Self {
        let text = format!(
            "id = {id:?}\nkind = \"shelf\"\naddress = {address:?}\naisles = {aisles:?}\nquirks = [\"length0\"]\n"
        );
        toml::from_str(&text).expect("a valid shelf entry")
    }

    /// The protocol link.
    pub fn link(&self) -> LinkConfig {
        LinkConfig {
            protocol: self.protocol.clone(),
            address: self.address.clone(),
            unit: self.unit,
            serial: self.serial.clone(),
            timeout: Duration::from_millis(self.timeout_ms),
            retries: self.retries,
            quirks: self.quirks.clone(),
        }
    }

    /// Poll period.
    pub fn poll(&self) -> Duration {
        Duration::from_millis(self.poll_ms.max(1))
    }

    /// Checks values that are valid TOML but make no sense.
    pub fn check(&self) -> Result<(), String> {
        let fail = |m: String| Err(format!("devices {:?}: {m}", self.id));
        if self.id.is_empty() || !self.id.chars().all(|c| c.is_ascii_alphanumeric() || "-_.".contains(c)) {
            return fail("id must be letters, digits, '-', '_' or '.'".into());
        }
        if self.slots == 0 || self.stride < crate::devices::shelf::slot::SLOT_WORDS as u16 {
            return fail("slots must be at least 1 and stride at least 35".into());
        }
        if self.offline_after == 0 {
            return fail("offline_after must be at least 1".into());
        }
        self.link().check().or_else(|e| fail(e.to_string()))
    }
}
