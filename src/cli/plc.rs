//! `rackd plc`: read or write a PLC's memory by hand, for commissioning.
//!
//! ```text
//! rackd plc --protocol modbus-udp --address 10.0.0.5:502 read 4x4000 3
//! rackd plc --protocol modbus-rtu --address /dev/ttyUSB0 --serial 9600,8E1 --unit 2 write 4x4000 10000 10001
//! rackd plc --protocol mewtocol --address /dev/ttyUSB0 --unit 1 read DT100 2
//! rackd plc --protocol ppi-tcp --address 10.0.0.7:4001 read VW100 3
//! ```
//!
//! The command builds a `Box<dyn PlcMemory>` from `--protocol` and uses only the trait, so
//! another protocol is one more [`PlcProtocol`] value and one arm in [`connect`].

use std::time::Duration;

use anyhow::{Context, anyhow, bail};

use crate::protocols::mc3e::Device;
use crate::protocols::mewtocol::{self, MewtocolClient, MewtocolConfig, MewtocolTransport};
use crate::protocols::modbus::address::{self as modbus_address, Table};
use crate::protocols::modbus::{ModbusClient, ModbusConfig, Quirks, Transport};
use crate::protocols::ppi::{self, PpiClient, PpiConfig, PpiTransport};
use crate::protocols::serial::SerialSettings;
use crate::protocols::{Address, DeviceCode, PlcError, PlcMemory};

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
    /// Panasonic MEWTOCOL-COM on a serial port (addresses DT100, WR1, R1F, Y1A).
    Mewtocol,
    /// Panasonic MEWTOCOL-COM over raw TCP (serial-to-Ethernet gateway).
    MewtocolTcp,
    /// Siemens S7-200 PPI on a serial port (addresses VW100, VB0, V10.3, Q0.1, T37).
    Ppi,
    /// Siemens S7-200 PPI over raw TCP (serial-to-Ethernet gateway).
    PpiTcp,
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
    /// Serial settings: baud,data bits parity stop bits [default: 9600,8E1; 9600,8O1 for
    /// MEWTOCOL].
    #[arg(long)]
    pub serial: Option<SerialSettings>,
    /// Station (unit) number; 0 broadcasts a Modbus write [default: 1; 2 for PPI, the
    /// S7-200's default address].
    #[arg(long)]
    pub unit: Option<u8>,
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
    /// MEWTOCOL: send `**` instead of a BCC (PLC set up without the check).
    #[arg(long)]
    pub no_bcc: bool,
    /// MEWTOCOL: use `<` long frames.
    #[arg(long)]
    pub long_frames: bool,
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
        PlcProtocol::Mewtocol | PlcProtocol::MewtocolTcp => {
            let transport = if args.protocol == PlcProtocol::Mewtocol {
                MewtocolTransport::Serial
            } else {
                MewtocolTransport::Tcp
            };
            let mut config = MewtocolConfig::new(transport, args.address.clone());
            config.serial = args.serial.unwrap_or(config.serial);
            config.station = args.unit.unwrap_or(1);
            config.timeout = timeout;
            config.retries = args.retries;
            config.bcc = !args.no_bcc;
            config.long_frames = args.long_frames;
            return Ok(Box::new(MewtocolClient::new(config)?));
        }
        PlcProtocol::Ppi | PlcProtocol::PpiTcp => {
            let transport =
                if args.protocol == PlcProtocol::Ppi { PpiTransport::Serial } else { PpiTransport::Tcp };
            let mut config = PpiConfig::new(transport, args.address.clone());
            config.serial = args.serial.unwrap_or(config.serial);
            config.plc = args.unit.unwrap_or(2);
            config.timeout = timeout;
            config.retries = args.retries;
            return Ok(Box::new(PpiClient::new(config)?));
        }
    };
    let mut config = ModbusConfig::new(transport, args.address.clone());
    config.serial = args.serial.unwrap_or_default();
    config.unit = args.unit.unwrap_or(1);
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
        PlcProtocol::Mewtocol | PlcProtocol::MewtocolTcp => mewtocol::address::is_bit_area(address),
        PlcProtocol::Ppi | PlcProtocol::PpiTcp => ppi::address::is_bit_area(address),
    }
}

/// How far apart consecutive items are in `Address.index` (PPI words step 2 bytes).
fn step(protocol: PlcProtocol, address: &Address) -> u32 {
    match protocol {
        PlcProtocol::Ppi | PlcProtocol::PpiTcp => ppi::address::step(address),
        _ => 1,
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
        PlcProtocol::Mewtocol | PlcProtocol::MewtocolTcp => mewtocol::address::format(address),
        PlcProtocol::Ppi | PlcProtocol::PpiTcp => ppi::address::format(address),
    }
}

/// A failure in words an operator understands.
pub fn describe(error: &PlcError) -> String {
    match error {
        PlcError::Device(code) => match code {
            DeviceCode::Modbus(e) => format!("exception {:02X} \"{}\"", e.0, e.meaning()),
            DeviceCode::Mc3e(c) => format!("end code {:04X} \"{}\"", c.0, c.meaning()),
            DeviceCode::Mewtocol(c) => format!("error {:02} \"{}\"", c.0, c.meaning()),
            DeviceCode::Ppi(c @ ppi::ReturnCode::Refused { class, code }) => {
                format!("request refused, error class {class:02X} code {code:02X} \"{}\"", c.meaning())
            }
            DeviceCode::Ppi(c @ ppi::ReturnCode::Item(code)) => {
                format!("item return code {code:02X} \"{}\"", c.meaning())
            }
        },
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
        .map(|(i, v)| {
            let at = start.offset(i as u32 * step(args.protocol, &start));
            (format_address(args.protocol, &at), *v)
        })
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
        assert_eq!(describe(&mewtocol::error_code::device_error(63)), "error 63 \"PLC mode error\"");
        assert_eq!(
            describe(&ppi::return_code::item_error(0x0A)),
            "item return code 0A \"object does not exist\""
        );
        assert_eq!(
            describe(&ppi::return_code::refused(0x85, 0)),
            "request refused, error class 85 code 00 \"error on supplies (request refused)\""
        );
    }

    #[test]
    fn mewtocol_and_ppi_notation() {
        let vw = ppi::address::parse("VW100").unwrap();
        assert_eq!(format_address(PlcProtocol::Ppi, &vw.offset(step(PlcProtocol::Ppi, &vw))), "VW102");
        assert!(is_bit_area(PlcProtocol::PpiTcp, &ppi::address::parse("Q0.1").unwrap()));
        let y = mewtocol::address::parse("Y1A").unwrap();
        assert!(is_bit_area(PlcProtocol::Mewtocol, &y));
        assert_eq!(format_address(PlcProtocol::MewtocolTcp, &y.offset(6)), "Y20");
    }
}
