//! `kind = "shelf"`: a shelf storage PLC with task slots (shelf-plc.md).

use std::collections::BTreeSet;
use std::time::Duration;

use super::defaults::{OFFLINE_AFTER, POLL_MS};
use super::words::{WordsError, check_words};
use crate::protocols::link::LinkConfig;
use crate::protocols::{Protocol, Quirk};
use crate::wire::slot::SLOT_WORDS;
use crate::wire::slot::default_layout;

/// Task slots when `slots` is not set (shelf-plc.md: 60).
pub const DEFAULT_SLOTS: u16 = 60;
/// Oldest queued jobs weighed per dispatch round when `dispatch_window` is not set.
pub const DEFAULT_DISPATCH_WINDOW: u32 = 1000;

/// A shelf PLC's settings, every default filled in.
#[derive(Clone, Debug, PartialEq)]
pub struct ShelfConfig {
    /// The device's id.
    pub id: String,
    /// The aisles whose locations it serves (jobs are routed by location).
    pub aisles: Vec<u16>,
    /// How to reach the PLC.
    pub link: LinkConfig,
    /// How often running work is polled, in milliseconds.
    pub poll_ms: u64,
    /// Consecutive failed requests after which the device is offline (no new work).
    pub offline_after: u32,
    /// How many of the oldest queued jobs the dispatcher weighs at a time: priorities order
    /// jobs within this window, so a very urgent job behind a longer backlog waits until it
    /// enters the window. Bounds the work of each dispatch round.
    pub dispatch_window: u32,
    /// Number of task slots.
    pub slots: u16,
    /// Address of slot 1's task id, in the protocol's notation.
    pub base: String,
    /// 16-bit words from one slot to the next, whatever the protocol's address step (on
    /// PPI, `VW` addresses count bytes: a stride of 50 is 100 byte addresses).
    pub stride: u16,
    /// After recording a finished or failed task, set the slot's task id to 0.
    pub clear_finished: bool,
    /// Allow cancelling a task the PLC has not started by clearing its slot.
    pub withdraw: bool,
}

/// A shelf setting that cannot work.
#[derive(Debug, thiserror::Error)]
pub enum ShelfConfigError {
    /// No slots.
    #[error("slots must be at least 1")]
    NoSlots,
    /// Slots would overlap: a slot uses [`SLOT_WORDS`] words.
    #[error("stride {0} is below the {SLOT_WORDS} words a slot uses")]
    Stride(u16),
    /// The slot area does not suit the protocol.
    #[error(transparent)]
    Area(#[from] WordsError),
}

/// The quirks a shelf has unless `quirks` is set: over Modbus UDP `length0` and
/// `no-transaction-id`, the seed's PLC's habits (it answers MBAP length 0 and transaction id
/// 0 whatever it was sent; see the module documentation of [`super`]), none elsewhere. A
/// PLC that does echo transaction ids works under them too (its replies are then matched
/// as if it did not, which costs a new port after a lost reply); setting `quirks =
/// ["length0"]` for it lets the ids do the work.
pub fn default_shelf_quirks(protocol: Protocol) -> BTreeSet<Quirk> {
    match protocol {
        Protocol::ModbusUdp => BTreeSet::from([Quirk::Length0, Quirk::NoTransactionId]),
        _ => BTreeSet::new(),
    }
}

impl ShelfConfig {
    /// The seed's shelf PLC at `address` (Modbus UDP) with every default.
    pub fn new(id: &str, address: &str, aisles: Vec<u16>) -> ShelfConfig {
        let mut link = LinkConfig::new(Protocol::ModbusUdp, address);
        link.quirks = default_shelf_quirks(Protocol::ModbusUdp);
        link.tuning = crate::protocols::transport::LinkTuning::for_replies(link.replies());
        ShelfConfig::on(id, link, aisles)
    }

    /// A shelf PLC over `link` (taken as it is) with the protocol's slot layout and every
    /// other default.
    pub fn on(id: &str, link: LinkConfig, aisles: Vec<u16>) -> ShelfConfig {
        let (base, stride) = default_layout(link.protocol);
        ShelfConfig {
            id: id.to_owned(),
            aisles,
            link,
            poll_ms: POLL_MS,
            offline_after: OFFLINE_AFTER,
            dispatch_window: DEFAULT_DISPATCH_WINDOW,
            slots: DEFAULT_SLOTS,
            base: base.to_owned(),
            stride,
            clear_finished: true,
            withdraw: true,
        }
    }

    /// Slot 1's task id.
    pub fn slot_base(&self) -> &str {
        &self.base
    }

    /// Words from one slot to the next.
    pub fn slot_stride(&self) -> u16 {
        self.stride
    }

    /// Poll period.
    pub fn poll(&self) -> Duration {
        Duration::from_millis(self.poll_ms.max(1))
    }

    /// Checks, without a connection, that the slots fit: at least one, none overlapping,
    /// in writable words of the protocol, inside its memory area.
    pub fn check(&self) -> Result<(), ShelfConfigError> {
        if self.slots == 0 {
            return Err(ShelfConfigError::NoSlots);
        }
        if (self.stride as usize) < SLOT_WORDS {
            return Err(ShelfConfigError::Stride(self.stride));
        }
        check_layout(self)?;
        Ok(())
    }
}

/// Checks, without a connection, that the slot area is writable words of the protocol and
/// that every slot fits inside its memory area.
pub fn check_layout(config: &ShelfConfig) -> Result<(), WordsError> {
    let words = config.slots as u32 * config.slot_stride() as u32;
    check_words(config.link.protocol, "base", config.slot_base(), words, true)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::devices::DeviceConfig;

    fn shelf_over(protocol: &str, extra: &str) -> ShelfConfig {
        let text = format!(
            "id = \"s\"\nkind = \"shelf\"\nprotocol = {protocol:?}\naddress = \"/dev/ttyS0\"\n{extra}"
        );
        match toml::from_str(&text).unwrap() {
            DeviceConfig::Shelf(s) => s,
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn slots_unit_and_quirks_default_by_protocol() {
        let ppi = shelf_over("ppi", "");
        assert_eq!((ppi.slot_base(), ppi.slot_stride(), ppi.link.unit), ("VW1000", 50, 2));
        assert!(ppi.check().is_ok(), "{:?}", ppi.check());
        let rtu = shelf_over("modbus-rtu", "");
        assert_eq!((rtu.slot_base(), rtu.slot_stride(), rtu.link.unit), ("4x0", 100, 1));
        assert!(rtu.link.quirks.is_empty());
        let mew = shelf_over("mewtocol", "unit = 5\nstride = 40\n");
        assert_eq!((mew.slot_base(), mew.slot_stride(), mew.link.unit), ("DT4000", 40, 5));
        assert!(mew.check().is_ok(), "{:?}", mew.check());
        let udp = shelf_over("modbus-udp", "");
        assert_eq!(udp, ShelfConfig::new("s", "/dev/ttyS0", vec![]), "the seed's PLC");
        assert_eq!(udp.link.quirks, BTreeSet::from([Quirk::Length0, Quirk::NoTransactionId]));
        assert!(shelf_over("modbus-udp", "quirks = []\n").link.quirks.is_empty());
    }

    #[test]
    fn the_seed_shelf_has_the_spec_defaults() {
        let s = ShelfConfig::new("shelf1", "10.0.0.5:502", vec![1]);
        assert_eq!((s.slots, s.base.as_str(), s.stride), (60, "4x4000", 100));
        assert_eq!((s.link.timeout, s.link.retries, s.link.unit), (Duration::from_millis(300), 2, 1));
        assert_eq!((s.poll_ms, s.offline_after, s.dispatch_window), (200, 3, 1000));
        assert!(s.clear_finished && s.withdraw);
        s.check().unwrap();
    }

    #[test]
    fn a_slot_area_that_cannot_work_is_refused_before_connecting() {
        let err = shelf_over("ppi", "base = \"4x4000\"\n").check().unwrap_err().to_string();
        assert!(err.contains("base"), "{err}");
        let err = shelf_over("modbus-rtu", "base = \"3x0\"\n").check().unwrap_err().to_string();
        assert!(err.contains("writable word address"), "{err}");
        let err = shelf_over("modbus-rtu", "base = \"4x60000\"\n").check().unwrap_err().to_string();
        assert!(err.contains("run past the end"), "{err}");
        assert!(matches!(shelf_over("ppi", "stride = 34\n").check(), Err(ShelfConfigError::Stride(34))));
        assert!(matches!(shelf_over("ppi", "slots = 0\n").check(), Err(ShelfConfigError::NoSlots)));
    }
}
