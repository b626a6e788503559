//! Building an MC 3E client from command-line values, for `rackd plc --protocol mc3e|mc3e-udp`.
//!
//! ```text
//! rackd plc --protocol mc3e-udp --address 192.168.60.45:8000 --timeout-ms 1000 read D200 40
//! ```

use std::time::Duration;

use anyhow::bail;

use crate::protocols::PlcMemory;
use crate::protocols::mc3e::{Mc3eClient, Mc3eConfig, Route, TransportKind};

/// The MC 3E connection options.
#[derive(clap::Args, Clone, Debug)]
pub struct PlcMc3eArgs {
    /// The PLC's Ethernet module, HOST:PORT.
    #[arg(long)]
    pub address: String,
    /// Use UDP instead of TCP.
    #[arg(long)]
    pub udp: bool,
    /// Time allowed for one attempt, in milliseconds.
    #[arg(long, default_value_t = 1500)]
    pub timeout_ms: u64,
    /// Further attempts after a timeout, lost connection or malformed reply.
    #[arg(long, default_value_t = 2)]
    pub retries: u32,
    /// CPU monitoring timer sent in each request, in units of 250 ms.
    #[arg(long, default_value_t = 4)]
    pub monitor_timer: u16,
    /// Network number (hexadecimal).
    #[arg(long, default_value = "00", value_parser = hex_u8)]
    pub network: u8,
    /// PC number (hexadecimal).
    #[arg(long, default_value = "FF", value_parser = hex_u8)]
    pub pc: u8,
    /// Request destination module I/O number (hexadecimal).
    #[arg(long, default_value = "03FF", value_parser = hex_u16)]
    pub module_io: u16,
    /// Request destination module station number (hexadecimal).
    #[arg(long, default_value = "00", value_parser = hex_u8)]
    pub station: u8,
}

impl PlcMc3eArgs {
    /// The client configuration these options describe.
    pub fn config(&self) -> Mc3eConfig {
        let transport = if self.udp { TransportKind::Udp } else { TransportKind::Tcp };
        let mut config = Mc3eConfig::new(self.address.clone(), transport);
        config.link.timeout = Duration::from_millis(self.timeout_ms);
        config.link.retries = self.retries;
        config.monitor_timer = self.monitor_timer;
        config.route =
            Route { network: self.network, pc: self.pc, module_io: self.module_io, station: self.station };
        config
    }

    /// The client these options describe (it connects on its first request).
    pub fn build(&self) -> Box<dyn PlcMemory> {
        Box::new(Mc3eClient::new(self.config()))
    }
}

/// A client for `protocol` (`mc3e` over TCP, `mc3e-udp` over UDP) with the default route
/// 00/FF/03FF/00: what `rackd plc --protocol ... --address ...` needs.
pub fn build_client(
    protocol: &str,
    address: &str,
    timeout: Duration,
    retries: u32,
    monitor_timer: u16,
) -> anyhow::Result<Box<dyn PlcMemory>> {
    let transport = match protocol {
        "mc3e" => TransportKind::Tcp,
        "mc3e-udp" => TransportKind::Udp,
        other => bail!("not an MC 3E protocol: {other:?} (expected mc3e or mc3e-udp)"),
    };
    let mut config = Mc3eConfig::new(address, transport);
    config.link.timeout = timeout;
    config.link.retries = retries;
    config.monitor_timer = monitor_timer;
    Ok(Box::new(Mc3eClient::new(config)))
}

fn hex_u8(text: &str) -> Result<u8, String> {
    u8::from_str_radix(text.trim_start_matches("0x"), 16).map_err(|e| format!("{text:?}: {e} (hexadecimal)"))
}

fn hex_u16(text: &str) -> Result<u16, String> {
    u16::from_str_radix(text.trim_start_matches("0x"), 16).map_err(|e| format!("{text:?}: {e} (hexadecimal)"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        args: PlcMc3eArgs,
    }

    #[test]
    fn parses_options_into_config() {
        let cli = Cli::parse_from([
            "x",
            "--address",
            "10.0.0.1:8000",
            "--udp",
            "--retries",
            "0",
            "--module-io",
            "03E0",
        ]);
        let config = cli.args.config();
        assert_eq!(config.link.transport, TransportKind::Udp);
        assert_eq!(config.link.retries, 0);
        assert_eq!(config.route, Route { module_io: 0x03E0, ..Route::default() });
        assert_eq!(config.monitor_timer, 4);
        assert!(build_client("modbus", "x:1", Duration::from_secs(1), 0, 4).is_err());
        assert!(build_client("mc3e-udp", "x:1", Duration::from_secs(1), 0, 4).is_ok());
    }
}
