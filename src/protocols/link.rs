//! Opening a PLC connection from configuration: protocol name, address and the protocol's
//! settings, to a [`PlcMemory`] that device adapters use without knowing the protocol.

use std::sync::Arc;
use std::time::Duration;

use super::mc3e::{Mc3eClient, Mc3eConfig, TransportKind};
use super::mewtocol::{MewtocolClient, MewtocolConfig, MewtocolTransport};
use super::modbus::{ModbusClient, ModbusConfig, Quirks, Transport};
use super::ppi::{PpiClient, PpiConfig, PpiTransport};
use super::serial::SerialSettings;
use super::{PlcError, PlcMemory};

/// The protocols a device can be reached with.
pub const PROTOCOLS: &[&str] = &[
    "modbus-udp",
    "modbus-tcp",
    "modbus-rtu",
    "modbus-rtu-tcp",
    "mc3e",
    "mc3e-udp",
    "mewtocol",
    "mewtocol-tcp",
    "ppi",
    "ppi-tcp",
];

/// The unit / station a protocol's PLC answers by default: 2 on PPI (an S7-200's factory
/// address), 1 elsewhere.
pub fn default_unit(protocol: &str) -> u8 {
    if protocol.starts_with("ppi") { 2 } else { 1 }
}

/// How to reach one PLC.
#[derive(Clone, Debug, PartialEq)]
pub struct LinkConfig {
    /// One of [`PROTOCOLS`].
    pub protocol: String,
    /// `HOST:PORT`, or a serial device path for serial protocols.
    pub address: String,
    /// Unit / station number (Modbus unit, MEWTOCOL station, PPI address of the PLC).
    pub unit: u8,
    /// Serial settings (`9600,8E1`) for serial protocols.
    pub serial: Option<String>,
    /// Reply timeout per attempt.
    pub timeout: Duration,
    /// Resends after a timeout or bad reply.
    pub retries: u32,
    /// Protocol quirks by name: Modbus `length0`, `no-transaction-id`; MEWTOCOL `no-bcc`,
    /// `long-frames`; PPI `no-pdu-ref`.
    pub quirks: Vec<String>,
}

/// Why a link configuration cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    /// The protocol name is not known.
    #[error("unknown protocol {0:?} (known: {known})", known = PROTOCOLS.join(", "))]
    UnknownProtocol(String),
    /// A setting is wrong for the protocol.
    #[error("{0}")]
    Setting(String),
    /// The connection could not be set up.
    #[error(transparent)]
    Plc(#[from] PlcError),
}

impl LinkConfig {
    /// Checks the settings without connecting (for `rackd check-config`).
    pub fn check(&self) -> Result<(), LinkError> {
        match self.protocol.as_str() {
            "mc3e" | "mc3e-tcp" | "mc3e-udp" if !self.quirks.is_empty() => {
                Err(LinkError::Setting("mc3e links have no quirks".into()))
            }
            "mc3e" | "mc3e-tcp" | "mc3e-udp" => Ok(()),
            "mewtocol" | "mewtocol-tcp" => self.mewtocol().map(|_| ()),
            "ppi" | "ppi-tcp" => self.ppi().map(|_| ()),
            _ => self.modbus().map(|_| ()),
        }
    }

    fn serial_or(&self, default: SerialSettings) -> Result<SerialSettings, LinkError> {
        match &self.serial {
            Some(text) => text
                .parse()
                .map_err(|e: super::serial::SerialSettingsError| LinkError::Setting(e.to_string())),
            None => Ok(default),
        }
    }

    fn quirks_of(&self, known: &[&str]) -> Result<(), LinkError> {
        match self.quirks.iter().find(|q| !known.contains(&q.as_str())) {
            Some(q) => Err(LinkError::Setting(format!("unknown quirk {q:?} (known: {})", known.join(", ")))),
            None => Ok(()),
        }
    }

    fn mewtocol(&self) -> Result<MewtocolConfig, LinkError> {
        let transport =
            if self.protocol == "mewtocol" { MewtocolTransport::Serial } else { MewtocolTransport::Tcp };
        let mut config = MewtocolConfig::new(transport, self.address.clone());
        self.quirks_of(&["no-bcc", "long-frames"])?;
        config.serial = self.serial_or(config.serial)?;
        config.station = self.unit;
        config.timeout = self.timeout;
        config.retries = self.retries;
        config.bcc = !self.quirks.iter().any(|q| q == "no-bcc");
        config.long_frames = self.quirks.iter().any(|q| q == "long-frames");
        if !(1..=99).contains(&config.station) {
            return Err(LinkError::Setting("a MEWTOCOL station (unit) is 1..=99".into()));
        }
        Ok(config)
    }

    fn ppi(&self) -> Result<PpiConfig, LinkError> {
        let transport = if self.protocol == "ppi" { PpiTransport::Serial } else { PpiTransport::Tcp };
        let mut config = PpiConfig::new(transport, self.address.clone());
        self.quirks_of(&["no-pdu-ref"])?;
        config.serial = self.serial_or(config.serial)?;
        config.plc = self.unit;
        config.timeout = self.timeout;
        config.retries = self.retries;
        config.match_pdu_ref = !self.quirks.iter().any(|q| q == "no-pdu-ref");
        if config.plc == config.master || config.plc > 126 {
            return Err(LinkError::Setting("a PPI PLC address (unit) is 1..=126".into()));
        }
        Ok(config)
    }

    /// The MC 3E settings, when the protocol is `mc3e` (TCP) or `mc3e-udp`.
    fn mc3e(&self) -> Option<Mc3eConfig> {
        let transport = match self.protocol.as_str() {
            "mc3e" | "mc3e-tcp" => TransportKind::Tcp,
            "mc3e-udp" => TransportKind::Udp,
            _ => return None,
        };
        let mut config = Mc3eConfig::new(self.address.clone(), transport);
        config.link.timeout = self.timeout;
        config.link.retries = self.retries;
        // The PLC's own monitoring timer must give up before rackd does (250 ms units).
        config.monitor_timer = ((self.timeout.as_millis() / 250) as u16).clamp(1, 40);
        Some(config)
    }

    fn modbus(&self) -> Result<ModbusConfig, LinkError> {
        let transport = match self.protocol.as_str() {
            "modbus-udp" => Transport::Udp,
            "modbus-tcp" => Transport::Tcp,
            "modbus-rtu" => Transport::RtuSerial,
            "modbus-rtu-tcp" => Transport::RtuOverTcp,
            other => return Err(LinkError::UnknownProtocol(other.to_owned())),
        };
        let mut config = ModbusConfig::new(transport, self.address.clone());
        config.unit = self.unit;
        config.timeout = self.timeout;
        config.retries = self.retries;
        if let Some(serial) = &self.serial {
            config.serial = serial
                .parse()
                .map_err(|e: super::serial::SerialSettingsError| LinkError::Setting(e.to_string()))?;
        }
        let mut quirks = Quirks::default();
        for q in &self.quirks {
            match q.as_str() {
                "length0" => quirks.length0 = true,
                "no-transaction-id" => quirks.ignore_transaction_id = true,
                other => {
                    return Err(LinkError::Setting(format!(
                        "unknown quirk {other:?} (known: length0, no-transaction-id)"
                    )));
                }
            }
        }
        config.quirks = quirks;
        Ok(config)
    }
}

/// Opens the PLC connection a configuration describes. Connection-oriented transports
/// connect lazily, so a PLC that is down at start does not stop rackd.
pub async fn connect(config: &LinkConfig) -> Result<Arc<dyn PlcMemory>, LinkError> {
    if let Some(mc3e) = config.mc3e() {
        config.check()?;
        return Ok(Arc::new(Mc3eClient::new(mc3e)));
    }
    match config.protocol.as_str() {
        "mewtocol" | "mewtocol-tcp" => Ok(Arc::new(MewtocolClient::new(config.mewtocol()?)?)),
        "ppi" | "ppi-tcp" => Ok(Arc::new(PpiClient::new(config.ppi()?)?)),
        _ => Ok(Arc::new(ModbusClient::connect(config.modbus()?).await?)),
    }
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use super::*;

    fn link(protocol: &str, unit: u8, quirks: &[&str]) -> LinkConfig {
        LinkConfig {
            protocol: protocol.into(),
            address: "127.0.0.1:9".into(),
            unit,
            serial: None,
            timeout: Duration::from_millis(100),
            retries: 0,
            quirks: quirks.iter().map(|q| q.to_string()).collect(),
        }
    }

    #[test]
    fn mewtocol_and_ppi_settings() {
        let m = link("mewtocol-tcp", 3, &["no-bcc", "long-frames"]).mewtocol().unwrap();
        assert_eq!((m.station, m.bcc, m.long_frames, m.transport), (3, false, true, MewtocolTransport::Tcp));
        assert_eq!(m.serial.parity, tokio_serial::Parity::Odd);
        let p = link("ppi", 2, &["no-pdu-ref"]).ppi().unwrap();
        assert_eq!((p.plc, p.match_pdu_ref, p.transport), (2, false, PpiTransport::Serial));
        assert!(link("mewtocol", 0, &[]).check().is_err());
        assert!(link("ppi", 0, &[]).check().is_err());
        assert!(link("ppi-tcp", 2, &["length0"]).check().is_err());
        assert!(link("mewtocol", 1, &[]).check().is_ok());
        let mut serial = link("ppi", 2, &[]);
        serial.serial = Some("187500,8E1".into());
        assert_eq!(serial.ppi().unwrap().serial.baud, 187_500);
    }

    #[tokio::test]
    async fn mc3e_links_over_tcp_and_udp() {
        for p in ["mc3e", "mc3e-udp"] {
            assert!(PROTOCOLS.contains(&p));
            link(p, 1, &[]).check().unwrap();
            let plc = connect(&link(p, 1, &[])).await.unwrap();
            assert_eq!(plc.parse_address("D200").unwrap().index, 200);
        }
        assert!(link("mc3e", 1, &["length0"]).check().is_err());
        assert!(matches!(link("mc9", 1, &[]).check(), Err(LinkError::UnknownProtocol(_))));
        let mut one_second = link("mc3e-udp", 1, &[]);
        one_second.timeout = Duration::from_millis(1000);
        let timer = one_second.mc3e().unwrap().monitor_timer;
        assert_eq!(timer, 4, "1 s timeout = 4 x 250 ms");
    }
}
