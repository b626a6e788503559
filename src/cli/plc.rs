//! `rackd plc`: read or write a PLC's memory by hand, for commissioning.
//!
//! ```text
//! rackd plc --protocol modbus-udp --address 10.0.0.5:502 read 4x4000 3
//! rackd plc --protocol modbus-rtu --address /dev/ttyUSB0 --serial 9600,8E1 --unit 2 write 4x4000 10000 10001
//! ```
//!
//! The command builds a `Box<dyn PlcMemory>` from `--protocol` and uses only the trait, so
//! another protocol is one more [`PlcProtocol`] value and one arm in [`connect`].

use std::time::Duration;

use anyhow::{Context, anyhow, bail};

use crate::protocols::mc3e::Device;
use crate::protocols::modbus::address::{self as modbus_address, Table};
use crate::protocols::modbus::{ModbusClient, ModbusConfig, Quirks, Transport};
use crate::protocols::serial::SerialSettings;
use crate::protocols::{Address, PlcError, PlcMemory};

/// The protocols `rackd plc` speaks.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum PlcProtocol {
    /// Modbus TCP (MBAP over TCP).
    ModbusTcp,
    /// Modbus UDP (MBAP in datagrams).
    ModbusUdp,
    /// Modbus RTU on a serial port.
    ModbusRtu,
    /// Modbus RTU frames over raw TCP (serial-to-Ethernet gateway).
    ModbusRtuTcp,
    /// Mitsubishi MC protocol 3E binary over TCP.
    Mc3e,
    /// Mitsubishi MC protocol 3E binary over UDP.
    Mc3eUdp,
}

/// Arguments of `rackd plc`.
#[derive(Debug, clap::Args)]
pub struct PlcArgs {
    /// Protocol and transport.
    #[arg(long, value_enum)]
    pub protocol: PlcProtocol,
    /// HOST:PORT, or a serial device such as /dev/ttyUSB0.
    #[arg(long)]
    pub address: String,
    /// Serial settings: baud,data bits parity stop bits.
    #[arg(long, default_value = "9600,8E1")]
    pub serial: SerialSettings,
    /// Station (unit) number; 0 broadcasts a write.
    #[arg(long, default_value_t = 1)]
    pub unit: u8,
    /// Reply timeout of each try, in milliseconds.
    #[arg(long, default_value_t = 1000)]
    pub timeout_ms: u64,
    /// Tries after the first one before giving up.
    #[arg(long, default_value_t = 2)]
    pub retries: u32,
    /// The device answers with MBAP length 0 (the shelf PLC).
    #[arg(long)]
    pub length0: bool,
    /// The device does not echo the transaction id.
    #[arg(long)]
    pub ignore_transaction_id: bool,
    /// Print JSON instead of `ADDRESS VALUE` lines.
    #[arg(long)]
    pub json: bool,
    /// What to do.
    #[command(subcommand)]
    pub op: PlcOp,
}

/// `read` or `write`.
#[derive(Debug, clap::Subcommand)]
pub enum PlcOp {
    /// Read COUNT items from ADDRESS (e.g. 4x4000).
    Read {
        /// First address, in the protocol's notation.
        address: String,
        /// How many consecutive items.
        #[arg(default_value_t = 1)]
        count: u16,
    },
    /// Write consecutive items from ADDRESS (words: 0..65535 or -32768..-1; bits: 0/1).
    Write {
        /// First address, in the protocol's notation.
        address: String,
        /// The values.
        #[arg(required = true, allow_negative_numbers = true)]
        values: Vec<String>,
    },
}

/// Builds the PLC memory for the arguments.
pub async fn connect(args: &PlcArgs) -> Result<Box<dyn PlcMemory>, PlcError> {
    let timeout = Duration::from_millis(args.timeout_ms);
    let transport = match args.protocol {
        PlcProtocol::ModbusTcp => Transport::Tcp,
        PlcProtocol::ModbusUdp => Transport::Udp,
        PlcProtocol::ModbusRtu => Transport::RtuSerial,
        PlcProtocol::ModbusRtuTcp => Transport::RtuOverTcp,
        PlcProtocol::Mc3e | PlcProtocol::Mc3eUdp => {
            let name = if args.protocol == PlcProtocol::Mc3e { "mc3e" } else { "mc3e-udp" };
            // The PLC's own monitoring timer (units of 250 ms) stays below our timeout so
            // the module gives up first and answers with an end code.
            let monitor = (args.timeout_ms / 250).saturating_sub(1).clamp(1, u16::MAX as u64) as u16;
            return super::plc_mc3e::build_client(name, &args.address, timeout, args.retries, monitor)
                .map_err(|_| PlcError::BadAddress {
                    text: args.address.clone(),
                    reason: "not an MC 3E protocol",
                });
        }
    };
    let mut config = ModbusConfig::new(transport, args.address.clone());
    config.serial = args.serial;
    config.unit = args.unit;
    config.timeout = timeout;
    config.retries = args.retries;
    config.quirks = Quirks { length0: args.length0, ignore_transaction_id: args.ignore_transaction_id };
    Ok(Box::new(ModbusClient::connect(config).await?))
}

/// Whether an address names a bit area, and how to print an address, per protocol.
fn is_bit_area(protocol: PlcProtocol, address: &Address) -> bool {
    match protocol {
        PlcProtocol::ModbusTcp
        | PlcProtocol::ModbusUdp
        | PlcProtocol::ModbusRtu
        | PlcProtocol::ModbusRtuTcp => Table::from_area(&address.area).is_some_and(|t| !t.holds_words()),
        PlcProtocol::Mc3e | PlcProtocol::Mc3eUdp => Device::of_area(&address.area).is_ok_and(Device::is_bit),
    }
}

fn format_address(protocol: PlcProtocol, address: &Address) -> String {
    match protocol {
        PlcProtocol::ModbusTcp
        | PlcProtocol::ModbusUdp
        | PlcProtocol::ModbusRtu
        | PlcProtocol::ModbusRtuTcp => modbus_address::format(address),
        PlcProtocol::Mc3e | PlcProtocol::Mc3eUdp => Device::of_area(&address.area)
            .map_or_else(|_| format!("{}{}", address.area, address.index), |d| d.format(address.index)),
    }
}

/// A failure in words an operator understands.
pub fn describe(error: &PlcError) -> String {
    match error {
        PlcError::Device { protocol: "modbus", code, meaning } => {
            format!("exception {code:02X} \"{meaning}\"")
        }
        PlcError::Device { protocol: "mc3e", code, meaning } => format!("end code {code:04X} \"{meaning}\""),
        PlcError::Timeout { attempts, timeout } => {
            format!("timeout: no reply after {attempts} tries of {} ms", timeout.as_millis())
        }
        other => other.to_string(),
    }
}

fn parse_word(text: &str) -> anyhow::Result<u16> {
    match text.parse::<i32>() {
        Ok(v @ 0..=65535) => Ok(v as u16),
        Ok(v @ -32768..=-1) => Ok(v as i16 as u16),
        _ => bail!("bad word value {text:?}: expected 0..65535 or -32768..-1"),
    }
}

fn parse_bit(text: &str) -> anyhow::Result<bool> {
    match text.to_ascii_lowercase().as_str() {
        "1" | "true" | "on" => Ok(true),
        "0" | "false" | "off" => Ok(false),
        _ => bail!("bad bit value {text:?}: expected 0 or 1"),
    }
}

/// Runs `rackd plc`: prints one `ADDRESS VALUE` line per item (or JSON), fails with a
/// clear message otherwise.
pub async fn run(args: PlcArgs) -> anyhow::Result<()> {
    let plc = connect(&args).await.map_err(|e| anyhow!(describe(&e)))?;
    let name = clap::ValueEnum::to_possible_value(&args.protocol)
        .map(|v| v.get_name().to_string())
        .unwrap_or_default();
    let target = format!("{name} {}", args.address);
    let (start, values): (Address, Vec<u32>) = match &args.op {
        PlcOp::Read { address, count } => {
            let start = plc.parse_address(address).map_err(|e| anyhow!(describe(&e)))?;
            let values = if is_bit_area(args.protocol, &start) {
                plc.read_bits(&start, *count).await.map(|b| b.into_iter().map(u32::from).collect())
            } else {
                plc.read_words(&start, *count).await.map(|w| w.into_iter().map(u32::from).collect())
            };
            let values = values
                .map_err(|e| anyhow!(describe(&e)))
                .with_context(|| format!("read {address} x{count} from {target}"))?;
            (start, values)
        }
        PlcOp::Write { address, values } => {
            let start = plc.parse_address(address).map_err(|e| anyhow!(describe(&e)))?;
            let written: Vec<u32> = if is_bit_area(args.protocol, &start) {
                let bits = values.iter().map(|v| parse_bit(v)).collect::<anyhow::Result<Vec<_>>>()?;
                plc.write_bits(&start, &bits)
                    .await
                    .map_err(|e| anyhow!(describe(&e)))
                    .with_context(|| format!("write {address} on {target}"))?;
                bits.into_iter().map(u32::from).collect()
            } else {
                let words = values.iter().map(|v| parse_word(v)).collect::<anyhow::Result<Vec<_>>>()?;
                plc.write_words(&start, &words)
                    .await
                    .map_err(|e| anyhow!(describe(&e)))
                    .with_context(|| format!("write {address} on {target}"))?;
                words.into_iter().map(u32::from).collect()
            };
            (start, written)
        }
    };
    let items: Vec<(String, u32)> = values
        .iter()
        .enumerate()
        .map(|(i, v)| (format_address(args.protocol, &start.offset(i as u32)), *v))
        .collect();
    if args.json {
        let json: Vec<_> =
            items.iter().map(|(a, v)| serde_json::json!({ "address": a, "value": v })).collect();
        println!("{}", serde_json::Value::Array(json));
    } else {
        for (address, value) in items {
            println!("{address} {value}");
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_parse() {
        assert_eq!(parse_word("10000").unwrap(), 10000);
        assert_eq!(parse_word("-1").unwrap(), 0xFFFF);
        assert!(parse_word("65536").is_err());
        assert!(parse_word("x").is_err());
        assert!(parse_bit("1").unwrap() && !parse_bit("off").unwrap());
        assert!(parse_bit("2").is_err());
    }

    #[test]
    fn errors_read_like_the_device_manual() {
        let e: PlcError = crate::protocols::modbus::Exception(2).into();
        assert_eq!(describe(&e), "exception 02 \"illegal data address\"");
        let t = PlcError::Timeout { attempts: 3, timeout: Duration::from_millis(200) };
        assert_eq!(describe(&t), "timeout: no reply after 3 tries of 200 ms");
    }
}
