//! Opening a PLC connection from configuration: protocol name, address and the protocol's
//! settings, to a [`PlcMemory`] that device adapters use without knowing the protocol.

use std::sync::Arc;
use std::time::Duration;

use super::mc3e::{Mc3eClient, Mc3eConfig, TransportKind};
use super::modbus::{ModbusClient, ModbusConfig, Quirks, Transport};
use super::{PlcError, PlcMemory};

/// The protocols a device can be reached with.
pub const PROTOCOLS: &[&str] =
    &["modbus-udp", "modbus-tcp", "modbus-rtu", "modbus-rtu-tcp", "mc3e", "mc3e-udp"];

/// How to reach one PLC.
#[derive(Clone, Debug, PartialEq)]
pub struct LinkConfig {
    /// One of [`PROTOCOLS`].
    pub protocol: String,
    /// `HOST:PORT`, or a serial device path for serial protocols.
    pub address: String,
    /// Unit / station number.
    pub unit: u8,
    /// Serial settings (`9600,8E1`) for serial protocols.
    pub serial: Option<String>,
    /// Reply timeout per attempt.
    pub timeout: Duration,
    /// Resends after a timeout or bad reply.
    pub retries: u32,
    /// Protocol quirks by name (`length0`, `no-transaction-id`).
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
        match self.mc3e() {
            Some(_) if !self.quirks.is_empty() => Err(LinkError::Setting("mc3e links have no quirks".into())),
            Some(_) => Ok(()),
            None => self.modbus().map(|_| ()),
        }
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
    Ok(Arc::new(ModbusClient::connect(config.modbus()?).await?))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn link(protocol: &str) -> LinkConfig {
        LinkConfig {
            protocol: protocol.into(),
            address: "127.0.0.1:5000".into(),
            unit: 1,
            serial: None,
            timeout: Duration::from_millis(1000),
            retries: 2,
            quirks: vec![],
        }
    }

    #[tokio::test]
    async fn mc3e_links_over_tcp_and_udp() {
        for p in ["mc3e", "mc3e-udp"] {
            assert!(PROTOCOLS.contains(&p));
            link(p).check().unwrap();
            let plc = connect(&link(p)).await.unwrap();
            assert_eq!(plc.parse_address("D200").unwrap().index, 200);
        }
        let mut quirky = link("mc3e");
        quirky.quirks = vec!["length0".into()];
        assert!(quirky.check().is_err());
        assert!(matches!(link("mc9").check(), Err(LinkError::UnknownProtocol(_))));
        let timer = link("mc3e-udp").mc3e().unwrap().monitor_timer;
        assert_eq!(timer, 4, "1 s timeout = 4 x 250 ms");
    }
}
