//! `kind = "crane"`: a stacker crane with the MC 3E register interface (crane-mc3e.md).

use std::time::Duration;

use serde::{Deserialize, Serialize};

use super::defaults::{OFFLINE_AFTER, POLL_MS};
use super::words::{WordsError, check_words};
use crate::protocols::Protocol;
use crate::protocols::link::LinkConfig;
use crate::wire::motion::Motion;
use crate::wire::registers::BLOCK_WORDS;

/// A crane's reply timeout when `timeout_ms` is not set (see [`super`] for why it is
/// longer than a shelf's).
pub const DEFAULT_TIMEOUT: Duration = Duration::from_millis(1500);

/// How completion is acknowledged (see `devices::crane::ack`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Ack {
    /// D22 := 1 while D223 != 0; D22 := 0 once D223 = 0.
    #[default]
    Handshake,
    /// D22 := the value of D223.
    Echo,
}

/// How the crane's next job is chosen (see `service::planner`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Planner {
    /// Priority, then age (deadlines not weighed).
    Fifo,
    /// Priority, then the least empty travel from where the crane stands, with aging,
    /// unless a deadline is at risk.
    #[default]
    Travel,
}

/// A station (pick-and-drop point) of the crane, written `[row, bay, level, side]`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, Serialize)]
#[serde(from = "[u16; 4]", into = "[u16; 4]")]
pub struct Station {
    /// Row (1 = A, 2 = B).
    pub row: u16,
    /// Bay (0 is the aisle's station bay).
    pub bay: u16,
    /// Level.
    pub level: u16,
    /// Side (depth) the crane's fork reaches.
    pub side: u16,
}

impl From<[u16; 4]> for Station {
    fn from([row, bay, level, side]: [u16; 4]) -> Self {
        Station { row, bay, level, side }
    }
}

impl From<Station> for [u16; 4] {
    fn from(s: Station) -> Self {
        s.words()
    }
}

impl Station {
    /// The words the crane's task block takes: row, bay, level, side.
    pub fn words(self) -> [u16; 4] {
        [self.row, self.bay, self.level, self.side]
    }
}

/// A crane's settings, every default filled in.
#[derive(Clone, Debug, PartialEq)]
pub struct CraneConfig {
    /// The device's id.
    pub id: String,
    /// The aisles whose locations it serves.
    pub aisles: Vec<u16>,
    /// How to reach the crane's PLC.
    pub link: LinkConfig,
    /// How often the crane's block is read, in milliseconds.
    pub poll_ms: u64,
    /// Consecutive failed requests after which the crane is offline (no new work).
    pub offline_after: u32,
    /// First word the WCS writes (D0..D39), in the protocol's notation.
    pub wcs_base: String,
    /// First word the crane writes (D200..D239), in the protocol's notation.
    pub crane_base: String,
    /// Where an inbound transfer (a store) picks.
    pub inbound_station: Station,
    /// Where an outbound transfer (a retrieve) puts.
    pub outbound_station: Station,
    /// Least time between two of rackd's heartbeat steps, in milliseconds.
    pub heartbeat_ms: u64,
    /// The crane is lost when its heartbeat stays unchanged this long (ms).
    pub heartbeat_timeout_ms: u64,
    /// Longest wait for each step of the STB/ACK hand-over, in milliseconds.
    pub handshake_timeout_ms: u64,
    /// A business alarm sends the cancel (mode 3) by itself.
    pub auto_cancel: bool,
    /// How completion is acknowledged.
    pub ack: Ack,
    /// How the next job is chosen.
    pub planner: Planner,
    /// Times a queued job may be passed over by younger ones of its priority (travel
    /// planner) before it goes next.
    pub max_overtaken: u32,
    /// Seconds before its deadline by which the travel planner wants a job ended (0: by the
    /// deadline itself); a job that would end later goes before the travel choice.
    pub deadline_margin_s: u32,
    /// How the crane moves: what the travel planner weighs and putaway ranks by.
    pub motion: Motion,
}

/// A crane setting that cannot work.
#[derive(Debug, thiserror::Error)]
pub enum CraneConfigError {
    /// A timeout of 0 would declare the crane lost, or a hand-over failed, at once; a
    /// `max_overtaken` of 0 would be no travel planning at all.
    #[error("{0} must be above 0")]
    Zero(&'static str),
    /// A figure of the motion model is zero, negative or not a number.
    #[error("every figure of motion must be above 0")]
    Motion,
    /// A register block does not suit the protocol.
    #[error(transparent)]
    Block(#[from] WordsError),
}

impl CraneConfig {
    /// A crane over MC 3E TCP at `address` with every default (crane-mc3e.md).
    pub fn new(id: &str, address: &str, aisles: Vec<u16>) -> CraneConfig {
        let link = LinkConfig { timeout: DEFAULT_TIMEOUT, ..LinkConfig::new(Protocol::Mc3e, address) };
        CraneConfig {
            id: id.to_owned(),
            aisles,
            link,
            poll_ms: POLL_MS,
            offline_after: OFFLINE_AFTER,
            wcs_base: "D0".into(),
            crane_base: "D200".into(),
            inbound_station: Station::from([2, 0, 1, 1]),
            outbound_station: Station::from([1, 0, 1, 1]),
            heartbeat_ms: 500,
            heartbeat_timeout_ms: 10_000,
            handshake_timeout_ms: 3_000,
            auto_cancel: true,
            ack: Ack::Handshake,
            planner: Planner::Travel,
            max_overtaken: 30,
            deadline_margin_s: 30,
            motion: Motion::default(),
        }
    }

    /// Poll period.
    pub fn poll(&self) -> Duration {
        Duration::from_millis(self.poll_ms.max(1))
    }

    /// Checks the timeouts, and that the register blocks are words of the protocol (rackd
    /// writes its own block and only reads the crane's). `deadline_margin_s` takes any
    /// value: 0 weighs a deadline itself, and a large margin only puts deadlines first sooner.
    pub fn check(&self) -> Result<(), CraneConfigError> {
        if self.heartbeat_timeout_ms == 0 {
            return Err(CraneConfigError::Zero("heartbeat_timeout_ms"));
        }
        if self.handshake_timeout_ms == 0 {
            return Err(CraneConfigError::Zero("handshake_timeout_ms"));
        }
        if self.max_overtaken == 0 {
            return Err(CraneConfigError::Zero("max_overtaken"));
        }
        if !self.motion.is_valid() {
            return Err(CraneConfigError::Motion);
        }
        let (protocol, words) = (self.link.protocol, BLOCK_WORDS as u32);
        check_words(protocol, "wcs_base", &self.wcs_base, words, true)?;
        check_words(protocol, "crane_base", &self.crane_base, words, false)?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::devices::DeviceConfig;

    #[test]
    fn a_crane_entry_has_the_spec_defaults() {
        let c = CraneConfig::new("crane1", "192.168.60.45:8000", vec![2]);
        let entry = "id = \"crane1\"\nkind = \"crane\"\naddress = \"192.168.60.45:8000\"\naisles = [2]\n";
        assert_eq!(toml::from_str::<DeviceConfig>(entry).unwrap(), DeviceConfig::Crane(c.clone()));
        let kinds = DeviceConfig::Crane(c.clone()).kind().job_kinds();
        assert_eq!(kinds.len(), 4);
        assert!(!kinds.contains(&crate::domain::JobKind::Clear));
        assert_eq!((c.inbound_station.words(), c.outbound_station.words()), ([2, 0, 1, 1], [1, 0, 1, 1]));
        assert_eq!(
            (c.heartbeat_timeout_ms, c.wcs_base.as_str(), c.crane_base.as_str()),
            (10_000, "D0", "D200")
        );
        assert_eq!((c.link.protocol, c.link.timeout), (Protocol::Mc3e, Duration::from_millis(1500)));
        assert!(c.auto_cancel);
        assert_eq!(c.ack, Ack::Handshake);
        assert_eq!((c.max_overtaken, c.deadline_margin_s), (30, 30));
        c.check().unwrap();
        let mut bad = c;
        bad.handshake_timeout_ms = 0;
        assert!(matches!(bad.check(), Err(CraneConfigError::Zero("handshake_timeout_ms"))));
    }

    #[test]
    fn crane_blocks_are_checked_against_the_protocol() {
        let mut c = CraneConfig::new("crane1", "127.0.0.1:1", vec![2]);
        c.link.protocol = Protocol::PpiTcp;
        let err = c.check().unwrap_err().to_string();
        assert!(err.contains("wcs_base"), "{err}");
        c.wcs_base = "VW0".into();
        c.crane_base = "VW400".into();
        assert!(c.check().is_ok(), "{:?}", c.check());
    }
}
