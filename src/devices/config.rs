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
    /// A stacker crane with the MC 3E register interface (crane-mc3e.md).
    Crane,
    /// Named tags mapped to PLC addresses (light towers, stations, conveyors), polled and
    /// written through the API; runs no jobs.
    Tags,
}

impl DeviceKind {
    /// The job kinds this kind of machine runs.
    pub fn job_kinds(self) -> &'static [crate::domain::JobKind] {
        use crate::domain::JobKind::*;
        match self {
            DeviceKind::Shelf => &[Store, Retrieve, Move, Clear, Light],
            DeviceKind::Crane => &[Store, Retrieve, Move, Travel],
            DeviceKind::Tags => &[],
        }
    }

    /// The kind's name as the configuration writes it.
    pub fn as_str(self) -> &'static str {
        match self {
            DeviceKind::Shelf => "shelf",
            DeviceKind::Crane => "crane",
            DeviceKind::Tags => "tags",
        }
    }
}

/// One `[[devices]]` entry. Every key but `id`, `kind` and `address` has a default.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DeviceConfig {
    /// The device's id, used in the API and in jobs' `device`.
    pub id: String,
    /// What kind of machine.
    pub kind: DeviceKind,
    /// The aisles whose locations this device serves (jobs are routed by location); none
    /// by default, and none for a tags device.
    #[serde(default)]
    pub aisles: Vec<u16>,
    /// One of [`crate::protocols::link::PROTOCOLS`] (`modbus-udp`, `modbus-tcp`, `modbus-rtu`,
    /// `modbus-rtu-tcp`, `mc3e`, `mc3e-udp`, `mewtocol`, `mewtocol-tcp`, `ppi`, `ppi-tcp`).
    #[serde(default = "default_protocol")]
    pub protocol: String,
    /// `HOST:PORT`, or a serial device path.
    pub address: String,
    /// Unit / station: Modbus unit, MEWTOCOL station, PPI address of the PLC. Default 1, or
    /// 2 on PPI (an S7-200's factory address); see [`DeviceConfig::unit`].
    #[serde(default)]
    pub unit: Option<u8>,
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
    /// Shelf: address of slot 1's task id, in the protocol's notation; the default depends
    /// on the protocol (see [`crate::devices::shelf::default_layout`]).
    #[serde(default)]
    pub base: Option<String>,
    /// Shelf: 16-bit words from one slot to the next, whatever the protocol's address step
    /// (on PPI, `VW` addresses count bytes: a stride of 50 is 100 byte addresses); the
    /// default depends on the protocol.
    #[serde(default)]
    pub stride: Option<u16>,
    /// Shelf: after recording a finished or failed task, set the slot's task id to 0.
    #[serde(default = "yes")]
    pub clear_finished: bool,
    /// Shelf: allow cancelling a task the PLC has not started by clearing its slot.
    #[serde(default = "yes")]
    pub withdraw: bool,
    /// How many of the oldest queued jobs the dispatcher weighs at a time: priorities order
    /// jobs within this window, so a very urgent job behind a longer backlog waits until it
    /// enters the window. Bounds the work of each dispatch round.
    #[serde(default = "default_window")]
    pub dispatch_window: u32,
    /// Crane: first word the WCS writes (D0..D39), in the protocol's notation.
    #[serde(default = "default_wcs_base")]
    pub wcs_base: String,
    /// Crane: first word the crane writes (D200..D239), in the protocol's notation.
    #[serde(default = "default_crane_base")]
    pub crane_base: String,
    /// Crane: where an inbound transfer (a store) picks: row, bay, level, side.
    #[serde(default = "default_inbound")]
    pub inbound_station: [u16; 4],
    /// Crane: where an outbound transfer (a retrieve) puts: row, bay, level, side.
    #[serde(default = "default_outbound")]
    pub outbound_station: [u16; 4],
    /// Crane: least time between two of rackd's heartbeat steps, in milliseconds.
    #[serde(default = "default_heartbeat_ms")]
    pub heartbeat_ms: u64,
    /// Crane: the crane is lost when its heartbeat stays unchanged this long (ms).
    #[serde(default = "default_heartbeat_timeout_ms")]
    pub heartbeat_timeout_ms: u64,
    /// Crane: longest wait for each step of the STB/ACK hand-over, in milliseconds.
    #[serde(default = "default_handshake_timeout_ms")]
    pub handshake_timeout_ms: u64,
    /// Crane: a business alarm sends the cancel (mode 3) by itself.
    #[serde(default = "yes")]
    pub auto_cancel: bool,
    /// Crane: how completion is acknowledged (see `devices::crane::ack`): `handshake`
    /// (D22 := 1, wait for D223 = 0, D22 := 0) or `echo` (D22 := the value of D223).
    #[serde(default = "default_ack")]
    pub ack: String,
    /// Tags: `[devices.tags]`, tag name -> address or `{ address, type, word_order, min,
    /// max, writable }` (see [`crate::devices::tags`]).
    #[serde(default)]
    pub tags: crate::devices::tags::TagTable,
}

fn default_protocol() -> String {
    "modbus-udp".into()
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
fn default_window() -> u32 {
    1000
}
fn default_wcs_base() -> String {
    "D0".into()
}
fn default_crane_base() -> String {
    "D200".into()
}
fn default_inbound() -> [u16; 4] {
    [2, 0, 1, 1]
}
fn default_outbound() -> [u16; 4] {
    [1, 0, 1, 1]
}
fn default_heartbeat_ms() -> u64 {
    500
}
fn default_heartbeat_timeout_ms() -> u64 {
    10_000
}
fn default_handshake_timeout_ms() -> u64 {
    3_000
}
fn default_ack() -> String {
    "handshake".into()
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

    /// A stacker crane over MC 3E TCP on the given address with every default.
    pub fn crane(id: &str, address: &str, aisles: Vec<u16>) -> Self {
        let text = format!(
            "id = {id:?}\nkind = \"crane\"\nprotocol = \"mc3e\"\naddress = {address:?}\naisles = {aisles:?}\ntimeout_ms = 1500\n"
        );
        toml::from_str(&text).expect("a valid crane entry")
    }

    /// The unit / station, or the protocol's default.
    pub fn unit(&self) -> u8 {
        self.unit.unwrap_or_else(|| crate::protocols::link::default_unit(&self.protocol))
    }

    /// Shelf: slot 1's task id, or the protocol's default.
    pub fn slot_base(&self) -> &str {
        self.base.as_deref().unwrap_or_else(|| crate::devices::shelf::default_layout(&self.protocol).0)
    }

    /// Shelf: words from one slot to the next, or the protocol's default.
    pub fn slot_stride(&self) -> u16 {
        self.stride.unwrap_or_else(|| crate::devices::shelf::default_layout(&self.protocol).1)
    }

    /// The protocol link.
    pub fn link(&self) -> LinkConfig {
        LinkConfig {
            protocol: self.protocol.clone(),
            address: self.address.clone(),
            unit: self.unit(),
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
        if self.kind == DeviceKind::Crane {
            if crate::devices::crane::ack::AckReading::parse(&self.ack).is_none() {
                return fail(format!("ack must be \"handshake\" or \"echo\", got {:?}", self.ack));
            }
            if self.heartbeat_timeout_ms == 0 || self.handshake_timeout_ms == 0 {
                return fail("heartbeat_timeout_ms and handshake_timeout_ms must be above 0".into());
            }
        }
        if self.slots == 0 || self.slot_stride() < crate::wire::slot::SLOT_WORDS as u16 {
            return fail("slots must be at least 1 and stride at least 35".into());
        }
        if self.offline_after == 0 {
            return fail("offline_after must be at least 1".into());
        }
        self.link().check().or_else(|e| fail(e.to_string()))?;
        match self.kind {
            DeviceKind::Shelf => crate::devices::shelf::check_layout(self).or_else(fail)?,
            DeviceKind::Crane => {
                // rackd writes its own block and only reads the crane's.
                let words = crate::wire::registers::BLOCK_WORDS;
                check_words(&self.protocol, "wcs_base", &self.wcs_base, words, true).or_else(fail)?;
                check_words(&self.protocol, "crane_base", &self.crane_base, words, false).or_else(fail)?;
            }
            DeviceKind::Tags => {}
        }
        match self.kind {
            DeviceKind::Tags => crate::devices::tags::check(self).or_else(fail),
            _ if !self.tags.0.is_empty() => fail("[devices.tags] is only for kind = \"tags\"".into()),
            _ => Ok(()),
        }
    }
}

/// Checks, without a connection, that `count` words (`writable` ones when rackd writes
/// them) of the protocol start at `text` (the value of `key`).
pub fn check_words(protocol: &str, key: &str, text: &str, count: u16, writable: bool) -> Result<(), String> {
    use crate::protocols::notation::{Items, shape};
    let area = shape(protocol, text).map_err(|e| format!("{key} {text:?}: {e}"))?;
    if area.items != Items::Words {
        return Err(format!("{key} {text:?} must be a word address of {protocol}"));
    }
    if writable && !area.writable {
        return Err(format!("{key} {text:?} must be a writable word address of {protocol}"));
    }
    if !area.fits(count as u32) {
        return Err(format!("{key} {text:?}: {count} words from there run past the end of the memory area"));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shelf_over(protocol: &str, extra: &str) -> DeviceConfig {
        let text = format!(
            "id = \"s\"\nkind = \"shelf\"\nprotocol = {protocol:?}\naddress = \"/dev/ttyS0\"\n{extra}"
        );
        toml::from_str(&text).unwrap()
    }

    #[test]
    fn shelf_slots_and_unit_default_by_protocol() {
        let ppi = shelf_over("ppi", "");
        assert_eq!((ppi.slot_base(), ppi.slot_stride(), ppi.unit()), ("VW1000", 50, 2));
        assert!(ppi.check().is_ok(), "{:?}", ppi.check());
        let rtu = shelf_over("modbus-rtu", "");
        assert_eq!((rtu.slot_base(), rtu.slot_stride(), rtu.unit()), ("4x0", 100, 1));
        let mew = shelf_over("mewtocol", "unit = 5\nstride = 40\n");
        assert_eq!((mew.slot_base(), mew.slot_stride(), mew.unit()), ("DT4000", 40, 5));
        assert!(mew.check().is_ok(), "{:?}", mew.check());
    }

    #[test]
    fn crane_blocks_are_checked_against_the_protocol() {
        let mut c = DeviceConfig::crane("crane1", "127.0.0.1:1", vec![2]);
        assert!(c.check().is_ok());
        c.protocol = "ppi-tcp".into();
        let err = c.check().unwrap_err();
        assert!(err.contains("wcs_base"), "{err}");
        c.wcs_base = "VW0".into();
        c.crane_base = "VW400".into();
        assert!(c.check().is_ok(), "{:?}", c.check());
    }

    #[test]
    fn a_shelf_base_the_protocol_cannot_write_is_refused_before_connecting() {
        let err = shelf_over("ppi", "base = \"4x4000\"\n").check().unwrap_err();
        assert!(err.contains("base"), "{err}");
        let err = shelf_over("modbus-rtu", "base = \"3x0\"\n").check().unwrap_err();
        assert!(err.contains("writable word address"), "{err}");
        let err = shelf_over("modbus-rtu", "base = \"4x60000\"\n").check().unwrap_err();
        assert!(err.contains("run past the end"), "{err}");
    }

    #[test]
    fn a_crane_entry_has_the_spec_defaults() {
        let c = DeviceConfig::crane("crane1", "192.168.60.45:8000", vec![2]);
        assert_eq!(c.kind.job_kinds().len(), 4);
        assert!(!c.kind.job_kinds().contains(&crate::domain::JobKind::Clear));
        assert_eq!((c.inbound_station, c.outbound_station), ([2, 0, 1, 1], [1, 0, 1, 1]));
        assert_eq!(
            (c.heartbeat_timeout_ms, c.wcs_base.as_str(), c.crane_base.as_str()),
            (10_000, "D0", "D200")
        );
        assert!(c.auto_cancel);
        assert_eq!(c.ack, "handshake");
        c.check().unwrap();
        let mut bad = c.clone();
        bad.ack = "maybe".into();
        assert!(bad.check().unwrap_err().contains("ack"));
        let mut bad = c;
        bad.handshake_timeout_ms = 0;
        assert!(bad.check().is_err());
    }

    fn tags_entry(extra: &str) -> Result<DeviceConfig, String> {
        let text = format!(
            "id = \"tower1\"\nkind = \"tags\"\nprotocol = \"modbus-tcp\"\naddress = \"127.0.0.1:502\"\n{extra}"
        );
        let c: DeviceConfig = toml::from_str(&text).map_err(|e| e.to_string())?;
        c.check().map(|_| c)
    }

    #[test]
    fn a_tags_entry_is_checked_without_a_connection() {
        let c = tags_entry(
            "[tags]\n\"beacon.red\" = \"0x1\"\nconveyor.speed = { address = \"4x100\", type = \"f32\" }\n",
        )
        .unwrap();
        assert_eq!((c.kind.as_str(), c.kind.job_kinds(), c.tags.0.len()), ("tags", &[][..], 2));
        assert!(c.aisles.is_empty());
        let err = tags_entry("aisles = [1]\n[tags]\nx = \"0x1\"\n").unwrap_err();
        assert!(err.contains("tower1") && err.contains("aisles"), "{err}");
        let err = tags_entry("").unwrap_err();
        assert!(err.contains("at least one tag"), "{err}");
        let err = tags_entry("[tags]\nbeacon.red = \"Q0.1\"\n").unwrap_err();
        assert!(err.contains("beacon.red") && err.contains("Q0.1"), "{err}");
        let err = tags_entry("[tags]\n\"9lives\" = \"0x1\"\n").unwrap_err();
        assert!(err.contains("9lives"), "{err}");
        let err = tags_entry("[tags]\nx = { address = \"4x1\", typo = 1 }\n").unwrap_err();
        assert!(err.contains("typo"), "{err}");
        let mut shelf = DeviceConfig::shelf("shelf1", "127.0.0.1:502", vec![1]);
        shelf.tags.0.insert("x".into(), crate::devices::tags::TagDef::at("0x1"));
        assert!(shelf.check().unwrap_err().contains("only for kind"));
    }
}
