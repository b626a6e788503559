//! The one place that turns a link description into a PLC client: [`connect`] opens the
//! [`PlcMemory`] a [`LinkConfig`] describes, for the device adapters (from `[[devices]]`)
//! and for `rackd plc` (from its flags) alike, so both reach a PLC with the same settings.
//!
//! Decisions the protocol documents leave open:
//! - **MC monitoring timer**: the PLC's own wait (units of 250 ms) is set one unit below
//!   rackd's reply timeout (at least 1), so that a CPU that cannot answer makes the module
//!   reply with an end code before rackd gives up and resends; equal or longer, the end
//!   code would arrive as a late reply to be thrown away. It follows the configured
//!   timeout, not the adaptive one: a CPU that was fast so far and is slow now makes rackd
//!   give up first, and the end code lands on the closed exclusive connection, harmless.
//! - **Quirks** are checked against the protocol ([`Quirk::applies_to`]): a quirk another
//!   protocol's client knows is refused rather than silently ignored.
//! - **Adaptive timeouts**: `timeout` is the ceiling of each client's RFC 6298 timer and
//!   `tuning.min_timeout` its floor (see the transport's `health.rs`). A floor at or above
//!   the ceiling is allowed and means a fixed timeout (the way to turn adaptation off; a
//!   device with `timeout_ms` below the default floor simply gets a fixed timeout).
//!   Shares outside 0..=1, a `degraded_below` above `degraded_above` or an empty window
//!   are refused by [`LinkConfig::check`].
//! - **Unit** ranges are the protocols' own: MEWTOCOL stations 1..=99, or 238 (0xEE) for
//!   the global station `EE` that the one PLC on a line answers whatever its number; PPI addresses
//!   1..=126 (0 is rackd's own master address). Modbus RTU (serial or over TCP) units
//!   0..=247: 0 broadcasts a write (no reply; `rackd plc` allows it), 248..=255 are
//!   reserved. Modbus TCP and UDP units 0..=255: the unit id addresses the device itself
//!   (or a station behind a gateway), many TCP devices expect 255 (0xFF, the Modbus
//!   Messaging on TCP/IP Implementation Guide's value) or 0, and unit 0 is answered like
//!   any other, never a broadcast. Checked before connecting, so `rackd check-config`
//!   reports them.
//! - **Capture**: every link has a flight recorder ([`crate::capture::Recorder`]) unless
//!   `capture.bytes` is 0; at most [`MAX_CAPTURE_BYTES`] (256 MiB, a bound on what one
//!   device may hold in memory) and [`MAX_CAPTURE_SECONDS`] (a day), at least a second.

use std::collections::BTreeSet;
use std::sync::Arc;
use std::time::Duration;

use super::mc3e::{FrameKind, Mc3eClient, Mc3eConfig, TransportKind};
use super::mewtocol::frame::GLOBAL_STATION;
use super::mewtocol::{MewtocolClient, MewtocolConfig, MewtocolTransport};
use super::modbus::{ModbusClient, ModbusConfig, Quirks, Transport};
use super::ppi::{PpiClient, PpiConfig, PpiTransport};
use super::protocol::{Family, Protocol, Quirk, Replies, names};
use super::serial::SerialSettings;
use super::transport::{Dial, LinkTuning};
use super::{PlcError, PlcMemory};
use crate::capture::Limits;

/// Reply timeout per attempt when none is configured.
pub const DEFAULT_TIMEOUT: Duration = Duration::from_millis(300);
/// Resends after a timeout when none is configured.
pub const DEFAULT_RETRIES: u32 = 2;

/// The most bytes a link's flight recorder may keep.
pub const MAX_CAPTURE_BYTES: usize = 256 * 1024 * 1024;
/// The most seconds a link's flight recorder may keep.
pub const MAX_CAPTURE_SECONDS: u64 = 86_400;

/// How to reach one PLC.
#[derive(Clone, Debug, PartialEq)]
pub struct LinkConfig {
    /// Protocol and transport.
    pub protocol: Protocol,
    /// `HOST:PORT`, or a serial device path for serial protocols.
    pub address: String,
    /// Unit / station number (Modbus unit, MEWTOCOL station, PPI address of the PLC).
    pub unit: u8,
    /// Serial settings (`9600,8E1`); `None` takes the protocol's default (8O1 for
    /// MEWTOCOL, 8E1 otherwise). Modbus RTU over TCP uses the baud rate for its frame gaps.
    pub serial: Option<SerialSettings>,
    /// Reply timeout per attempt.
    pub timeout: Duration,
    /// Resends after a timeout or bad reply.
    pub retries: u32,
    /// Habits of the PLC the client must put up with; each must apply to `protocol`.
    pub quirks: BTreeSet<Quirk>,
    /// The adaptive timeout's floor (`timeout` is its ceiling) and when the link counts as
    /// degraded.
    pub tuning: LinkTuning,
    /// The flight recorder's bounds (`capture_bytes`, `capture_seconds`); 0 bytes turns it
    /// off.
    pub capture: Limits,
}

/// Why a link configuration cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    /// A quirk of another protocol.
    #[error("quirk {quirk} is not one of {protocol}'s (its quirks: {known})", known = known_quirks(*.protocol))]
    Quirk {
        /// The quirk.
        quirk: Quirk,
        /// The link's protocol.
        protocol: Protocol,
    },
    /// A unit number the protocol cannot address.
    #[error("unit {unit} is not a {protocol} station: {range}")]
    Unit {
        /// The unit as configured.
        unit: u8,
        /// The link's protocol.
        protocol: Protocol,
        /// The valid range, in words.
        range: &'static str,
    },
    /// Adaptive timeout or degraded settings that make no sense.
    #[error("{0}")]
    Tuning(&'static str),
    /// Flight recorder bounds out of range.
    #[error("{key} must be {range}")]
    Capture {
        /// The key (`capture_bytes`, `capture_seconds`).
        key: &'static str,
        /// The valid range, in words.
        range: &'static str,
    },
    /// A protocol of another family than the request needs.
    #[error("{protocol} is not {wanted}")]
    Family {
        /// The link's protocol.
        protocol: Protocol,
        /// The family the request needs.
        wanted: &'static str,
    },
    /// The client could not be set up.
    #[error(transparent)]
    Plc(#[from] PlcError),
}

fn known_quirks(protocol: Protocol) -> String {
    match Quirk::of(protocol) {
        q if q.is_empty() => "none".into(),
        q => names(&q),
    }
}

impl LinkConfig {
    /// A link to `address` with the protocol's default unit, [`DEFAULT_TIMEOUT`],
    /// [`DEFAULT_RETRIES`], the protocol's serial settings, no quirks and the flight
    /// recorder's default bounds (4 MiB, 10 minutes).
    pub fn new(protocol: Protocol, address: impl Into<String>) -> LinkConfig {
        LinkConfig {
            protocol,
            address: address.into(),
            unit: protocol.default_unit(),
            serial: None,
            timeout: DEFAULT_TIMEOUT,
            retries: DEFAULT_RETRIES,
            quirks: BTreeSet::new(),
            tuning: LinkTuning::for_replies(protocol.replies(&BTreeSet::new())),
            capture: Limits::default(),
        }
    }

    /// The flight recorder's bounds, or `None` when capture is off.
    pub fn capture_limits(&self) -> Option<Limits> {
        (self.capture.bytes > 0).then_some(self.capture)
    }

    /// Whether the link's replies name their request ([`Protocol::replies`]).
    pub fn replies(&self) -> Replies {
        self.protocol.replies(&self.quirks)
    }

    /// Whether the link has `quirk`.
    pub fn has(&self, quirk: Quirk) -> bool {
        self.quirks.contains(&quirk)
    }

    /// Checks the settings without connecting (for `rackd check-config`).
    pub fn check(&self) -> Result<(), LinkError> {
        if let Some(&quirk) = self.quirks.iter().find(|q| !q.applies_to(self.protocol)) {
            return Err(LinkError::Quirk { quirk, protocol: self.protocol });
        }
        let t = &self.tuning;
        if !(0.0..=1.0).contains(&t.degraded_above) || !(0.0..=1.0).contains(&t.degraded_below) {
            return Err(LinkError::Tuning("degraded_above and degraded_below are shares between 0 and 1"));
        }
        if t.degraded_below > t.degraded_above {
            return Err(LinkError::Tuning("degraded_below must not exceed degraded_above"));
        }
        if t.degraded_window == 0 {
            return Err(LinkError::Tuning("degraded_window must be at least 1"));
        }
        if self.capture.bytes > MAX_CAPTURE_BYTES {
            return Err(LinkError::Capture { key: "capture_bytes", range: "0 (off) to 268435456 (256 MiB)" });
        }
        if !(1..=MAX_CAPTURE_SECONDS).contains(&self.capture.seconds) {
            return Err(LinkError::Capture { key: "capture_seconds", range: "1 to 86400 (a day)" });
        }
        let unit = |range| Err(LinkError::Unit { unit: self.unit, protocol: self.protocol, range });
        match self.protocol.family() {
            Family::Mewtocol if !(1..=99).contains(&self.unit) && self.unit != GLOBAL_STATION => {
                unit("1..=99, or 238 for EE, the global station")
            }
            Family::Ppi if !(1..=126).contains(&self.unit) => unit("1..=126 (0 is rackd's own address)"),
            Family::Modbus if self.modbus().transport.check_unit(self.unit).is_err() => {
                unit("1..=247, or 0 to broadcast a write (248..=255 are reserved on RTU)")
            }
            _ => Ok(()),
        }
    }

    /// The PLC's monitoring timer for MC requests (units of 250 ms): one unit below the
    /// timeout, at least 1 (see the module documentation).
    pub fn mc3e_monitor_timer(&self) -> u16 {
        let units = (self.timeout.as_millis() / 250).saturating_sub(1);
        units.clamp(1, u16::MAX as u128) as u16
    }

    fn mc3e(&self) -> Mc3eConfig {
        let transport = match self.protocol {
            Protocol::Mc3eUdp | Protocol::Mc4eUdp => TransportKind::Udp,
            _ => TransportKind::Tcp,
        };
        let mut config = Mc3eConfig::new(self.address.clone(), transport);
        config.frame = match self.protocol {
            Protocol::Mc4e | Protocol::Mc4eUdp => FrameKind::E4,
            _ => FrameKind::E3,
        };
        config.link.timeout = self.timeout;
        config.link.retries = self.retries;
        config.link.tuning = self.tuning;
        config.link.capture = self.capture_limits();
        config.monitor_timer = self.mc3e_monitor_timer();
        config
    }

    fn mewtocol(&self) -> MewtocolConfig {
        let transport =
            if self.protocol.is_serial() { MewtocolTransport::Serial } else { MewtocolTransport::Tcp };
        let mut config = MewtocolConfig::new(transport, self.address.clone());
        config.serial = self.serial.unwrap_or(config.serial);
        config.station = self.unit;
        config.timeout = self.timeout;
        config.retries = self.retries;
        config.tuning = self.tuning;
        config.capture = self.capture_limits();
        config.bcc = !self.has(Quirk::NoBcc);
        config.long_frames = self.has(Quirk::LongFrames);
        config
    }

    fn ppi(&self) -> PpiConfig {
        let transport = if self.protocol.is_serial() { PpiTransport::Serial } else { PpiTransport::Tcp };
        let mut config = PpiConfig::new(transport, self.address.clone());
        config.serial = self.serial.unwrap_or(config.serial);
        config.plc = self.unit;
        config.timeout = self.timeout;
        config.retries = self.retries;
        config.tuning = self.tuning;
        config.capture = self.capture_limits();
        config.match_pdu_ref = !self.has(Quirk::NoPduRef);
        config
    }

    fn modbus(&self) -> ModbusConfig {
        let transport = match self.protocol {
            Protocol::ModbusTcp => Transport::Tcp,
            Protocol::ModbusRtu => Transport::RtuSerial,
            Protocol::ModbusRtuTcp => Transport::RtuOverTcp,
            _ => Transport::Udp,
        };
        let mut config = ModbusConfig::new(transport, self.address.clone());
        config.unit = self.unit;
        config.timeout = self.timeout;
        config.retries = self.retries;
        config.tuning = self.tuning;
        config.serial = self.serial.unwrap_or(config.serial);
        config.capture = self.capture_limits();
        config.quirks = Quirks {
            length0: self.has(Quirk::Length0),
            ignore_transaction_id: self.has(Quirk::NoTransactionId),
        };
        config
    }
}

/// Opens the PLC connection a configuration describes, after [`LinkConfig::check`].
/// Connection-oriented transports connect lazily, so a PLC that is down at start does not
/// stop rackd.
pub async fn connect(config: &LinkConfig) -> Result<Arc<dyn PlcMemory>, LinkError> {
    config.check()?;
    Ok(match config.protocol.family() {
        Family::Mc3e => Arc::new(Mc3eClient::new(config.mc3e())),
        Family::Mewtocol => Arc::new(MewtocolClient::new(config.mewtocol())?),
        Family::Ppi => Arc::new(PpiClient::new(config.ppi())?),
        Family::Modbus => Arc::new(ModbusClient::connect(config.modbus()).await?),
    })
}

/// The client a configuration describes, over carriers the caller dials instead of the
/// address (the simulated wire of the tests, `protocols::simwire`), after
/// [`LinkConfig::check`]: the same settings a device gets, on another carrier.
pub fn connect_over(config: &LinkConfig, dial: Arc<dyn Dial>) -> Result<Arc<dyn PlcMemory>, LinkError> {
    config.check()?;
    Ok(match config.protocol.family() {
        Family::Mc3e => Arc::new(Mc3eClient::over(config.mc3e(), dial)),
        Family::Mewtocol => Arc::new(MewtocolClient::over(config.mewtocol(), dial)?),
        Family::Ppi => Arc::new(PpiClient::over(config.ppi(), dial)?),
        Family::Modbus => Arc::new(ModbusClient::over(config.modbus(), dial)?),
    })
}

/// A Modbus client for the link, for the requests beyond memory reads and writes (device
/// identification, diagnostics), after [`LinkConfig::check`].
pub async fn connect_modbus(config: &LinkConfig) -> Result<ModbusClient, LinkError> {
    config.check()?;
    match config.protocol.family() {
        Family::Modbus => Ok(ModbusClient::connect(config.modbus()).await?),
        _ => Err(LinkError::Family { protocol: config.protocol, wanted: "Modbus" }),
    }
}

/// An MC client for the link, for the requests beyond memory reads and writes (CPU model
/// name, random and block reads), after [`LinkConfig::check`].
pub fn connect_mc3e(config: &LinkConfig) -> Result<Mc3eClient, LinkError> {
    config.check()?;
    match config.protocol.family() {
        Family::Mc3e => Ok(Mc3eClient::new(config.mc3e())),
        _ => Err(LinkError::Family { protocol: config.protocol, wanted: "MC protocol" }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn link(protocol: Protocol, unit: u8, quirks: &[Quirk]) -> LinkConfig {
        LinkConfig {
            unit,
            timeout: Duration::from_millis(100),
            retries: 0,
            quirks: quirks.iter().copied().collect(),
            ..LinkConfig::new(protocol, "127.0.0.1:9")
        }
    }

    #[test]
    fn mewtocol_and_ppi_settings() {
        let m = link(Protocol::MewtocolTcp, 3, &[Quirk::NoBcc, Quirk::LongFrames]).mewtocol();
        assert_eq!((m.station, m.bcc, m.long_frames, m.transport), (3, false, true, MewtocolTransport::Tcp));
        assert_eq!(m.serial.parity, tokio_serial::Parity::Odd);
        let p = link(Protocol::Ppi, 2, &[Quirk::NoPduRef]).ppi();
        assert_eq!((p.plc, p.match_pdu_ref, p.transport), (2, false, PpiTransport::Serial));
        assert!(matches!(link(Protocol::Mewtocol, 0, &[]).check(), Err(LinkError::Unit { .. })));
        assert!(matches!(link(Protocol::Ppi, 0, &[]).check(), Err(LinkError::Unit { .. })));
        let err = link(Protocol::PpiTcp, 2, &[Quirk::Length0]).check().unwrap_err();
        assert!(matches!(err, LinkError::Quirk { quirk: Quirk::Length0, protocol: Protocol::PpiTcp }));
        assert!(err.to_string().contains("no-pdu-ref"), "{err}");
        assert!(link(Protocol::Mewtocol, 1, &[]).check().is_ok());
        assert!(link(Protocol::MewtocolTcp, 238, &[]).check().is_ok(), "EE, the global station");
        assert!(link(Protocol::Mewtocol, 100, &[]).check().is_err());
        let mut serial = link(Protocol::Ppi, 2, &[]);
        serial.serial = Some("187500,8E1".parse().unwrap());
        assert_eq!(serial.ppi().serial.baud, 187_500);
    }

    #[test]
    fn tuning_is_checked_and_a_floor_above_the_timeout_fixes_it() {
        let mut l = link(Protocol::ModbusUdp, 1, &[]);
        l.tuning.min_timeout = Duration::from_secs(5);
        assert!(l.check().is_ok(), "a fixed timeout");
        l.tuning.degraded_below = 0.5;
        assert!(matches!(l.check(), Err(LinkError::Tuning(_))), "below above `above`");
        l.tuning.degraded_below = 0.0;
        l.tuning.degraded_above = 1.5;
        assert!(matches!(l.check(), Err(LinkError::Tuning(_))));
        l.tuning.degraded_above = 0.1;
        l.tuning.degraded_window = 0;
        assert!(matches!(l.check(), Err(LinkError::Tuning(_))));
    }

    #[test]
    fn modbus_settings_and_quirks() {
        let m = link(Protocol::ModbusUdp, 7, &[Quirk::Length0, Quirk::NoTransactionId]).modbus();
        assert_eq!((m.unit, m.transport), (7, Transport::Udp));
        assert_eq!(m.quirks, Quirks { length0: true, ignore_transaction_id: true });
        assert!(link(Protocol::ModbusRtu, 1, &[Quirk::Length0]).check().is_err(), "RTU has no MBAP");
        assert_eq!(link(Protocol::ModbusRtuTcp, 0, &[]).modbus().transport, Transport::RtuOverTcp);
        for unit in [0, 248, 255] {
            for p in [Protocol::ModbusTcp, Protocol::ModbusUdp] {
                assert!(link(p, unit, &[]).check().is_ok(), "{p} unit {unit} addresses the device");
            }
        }
        assert!(link(Protocol::ModbusRtu, 0, &[]).check().is_ok(), "unit 0 broadcasts on RTU");
        for p in [Protocol::ModbusRtu, Protocol::ModbusRtuTcp] {
            let err = link(p, 248, &[]).check().unwrap_err();
            assert!(matches!(err, LinkError::Unit { unit: 248, .. }), "{err:?}");
            assert!(err.to_string().contains("248..=255 are reserved"), "{err}");
        }
    }

    #[tokio::test]
    async fn mc3e_links_over_tcp_and_udp() {
        for p in [Protocol::Mc3e, Protocol::Mc3eUdp] {
            link(p, 1, &[]).check().unwrap();
            let plc = connect(&link(p, 1, &[])).await.unwrap();
            assert_eq!(plc.parse_address("D200").unwrap().index, 200);
        }
        assert_eq!(link(Protocol::Mc3eUdp, 1, &[]).mc3e().link.transport, TransportKind::Udp);
        let four = link(Protocol::Mc4eUdp, 1, &[]).mc3e();
        assert_eq!((four.link.transport, four.frame), (TransportKind::Udp, FrameKind::E4));
        let four = link(Protocol::Mc4e, 1, &[]).mc3e();
        assert_eq!((four.link.transport, four.frame), (TransportKind::Tcp, FrameKind::E4));
        assert_eq!(link(Protocol::Mc3e, 1, &[]).mc3e().frame, FrameKind::E3);
        assert!(link(Protocol::Mc3e, 1, &[Quirk::Length0]).check().is_err());
        assert!(connect(&link(Protocol::Mc3e, 1, &[Quirk::NoBcc])).await.is_err());
        let mut one_second = link(Protocol::Mc3eUdp, 1, &[]);
        one_second.timeout = Duration::from_millis(1000);
        assert_eq!(one_second.mc3e().monitor_timer, 3, "750 ms: below the 1 s timeout");
        one_second.timeout = Duration::from_millis(300);
        assert_eq!(one_second.mc3e().monitor_timer, 1, "never 0, which waits forever");
    }
}
