//! `rackd plc`: read or write a PLC's memory by hand, for commissioning.
//!
//! ```text
//! rackd plc --protocol modbus-udp --address 10.0.0.5:502 read 4x4000 3
//! rackd plc --protocol modbus-rtu --address /dev/ttyUSB0 --serial 9600,8E1 --unit 2 write 4x4000 10000 10001
//! rackd plc --protocol mewtocol --address /dev/ttyUSB0 --unit 1 read DT100 2
//! rackd plc --protocol ppi-tcp --address 10.0.0.7:4001 read VW100 3
//! ```
//!
//! The flags make a [`LinkConfig`] and the PLC is opened by the same factory as the
//! devices' ([`crate::protocols::link::connect`]), so `rackd plc` reaches a PLC exactly as
//! a `[[devices]]` entry with the same settings would (MC monitoring timer included). The
//! command uses only the [`PlcMemory`] trait, apart from how addresses are printed.

use std::sync::Arc;
use std::time::Duration;

use anyhow::{Context, anyhow, bail};

use crate::protocols::link::{self, LinkConfig, LinkError};
use crate::protocols::mc3e::Device;
use crate::protocols::mewtocol;
use crate::protocols::modbus::address::{self as modbus_address, Table};
use crate::protocols::ppi;
use crate::protocols::protocol::Family;
use crate::protocols::serial::SerialSettings;
use crate::protocols::{Address, DeviceCode, PlcError, PlcMemory, Protocol, Quirk};

/// Arguments of `rackd plc`.
#[derive(Debug, clap::Args)]
pub struct PlcArgs {
    /// Protocol and transport.
    #[arg(long, value_enum)]
    pub protocol: Protocol,
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
    /// PPI: the PLC does not echo the PDU reference.
    #[arg(long)]
    pub no_pdu_ref: bool,
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

impl PlcArgs {
    /// The link these flags describe: unit and serial settings default by protocol, as a
    /// device's do; each quirk flag must suit the protocol.
    pub fn link(&self) -> LinkConfig {
        let flags = [
            (self.length0, Quirk::Length0),
            (self.ignore_transaction_id, Quirk::NoTransactionId),
            (self.no_bcc, Quirk::NoBcc),
            (self.long_frames, Quirk::LongFrames),
            (self.no_pdu_ref, Quirk::NoPduRef),
        ];
        let mut link = LinkConfig {
            unit: self.unit.unwrap_or(self.protocol.default_unit()),
            serial: self.serial,
            timeout: Duration::from_millis(self.timeout_ms),
            retries: self.retries,
            quirks: flags.into_iter().filter(|(on, _)| *on).map(|(_, q)| q).collect(),
            ..LinkConfig::new(self.protocol, self.address.clone())
        };
        // A one-off request has no round trips to learn from; the floor only has to fit.
        link.tuning.min_timeout = link.tuning.min_timeout.min(link.timeout);
        link
    }
}

/// Opens the PLC the arguments describe.
pub async fn connect(args: &PlcArgs) -> Result<Arc<dyn PlcMemory>, LinkError> {
    link::connect(&args.link()).await
}

/// Whether an address names a bit area, per protocol family.
fn is_bit_area(protocol: Protocol, address: &Address) -> bool {
    match protocol.family() {
        Family::Modbus => Table::from_area(&address.area).is_some_and(|t| !t.holds_words()),
        Family::Mc3e => Device::of_area(&address.area).is_ok_and(Device::is_bit),
        Family::Mewtocol => mewtocol::address::is_bit_area(address),
        Family::Ppi => ppi::address::is_bit_area(address),
    }
}

/// How far apart consecutive items are in `Address.index` (PPI words step 2 bytes).
fn step(protocol: Protocol, address: &Address) -> u32 {
    match protocol.family() {
        Family::Ppi => ppi::address::step(address),
        _ => 1,
    }
}

fn format_address(protocol: Protocol, address: &Address) -> String {
    match protocol.family() {
        Family::Modbus => modbus_address::format(address),
        Family::Mc3e => Device::of_area(&address.area)
            .map_or_else(|_| format!("{}{}", address.area, address.index), |d| d.format(address.index)),
        Family::Mewtocol => mewtocol::address::format(address),
        Family::Ppi => ppi::address::format(address),
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
        PlcError::Timeout { attempts, timeout, dropped } => {
            let note = dropped.map_or_else(String::new, |d| format!(" ({d})"));
            format!("timeout: no reply after {attempts} tries of {} ms{note}", timeout.as_millis())
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
    let plc = connect(&args).await.map_err(|e| match e {
        LinkError::Plc(e) => anyhow!(describe(&e)),
        other => anyhow!(other),
    })?;
    let target = format!("{} {}", args.protocol, args.address);
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
        super::say(serde_json::Value::Array(json));
    } else {
        for (address, value) in items {
            super::say(format!("{address} {value}"));
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
        let t = PlcError::Timeout { attempts: 3, timeout: Duration::from_millis(200), dropped: None };
        assert_eq!(describe(&t), "timeout: no reply after 3 tries of 200 ms");
        let dropped =
            Some(crate::protocols::Dropped { count: 2, reason: crate::protocols::DropReason::TransactionId });
        let t = PlcError::Timeout { attempts: 3, timeout: Duration::from_millis(200), dropped };
        assert_eq!(
            describe(&t),
            "timeout: no reply after 3 tries of 200 ms (2 replies arrived with another transaction id: \
             the `no-transaction-id` quirk would take them)"
        );
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
        assert_eq!(format_address(Protocol::Ppi, &vw.offset(step(Protocol::Ppi, &vw))), "VW102");
        assert!(is_bit_area(Protocol::PpiTcp, &ppi::address::parse("Q0.1").unwrap()));
        let y = mewtocol::address::parse("Y1A").unwrap();
        assert!(is_bit_area(Protocol::Mewtocol, &y));
        assert_eq!(format_address(Protocol::MewtocolTcp, &y.offset(6)), "Y20");
    }

    #[derive(clap::Parser)]
    struct Cli {
        #[command(flatten)]
        args: PlcArgs,
    }

    fn parse(args: &[&str]) -> Result<PlcArgs, clap::Error> {
        use clap::Parser;
        Cli::try_parse_from(["plc"].iter().chain(args)).map(|c| c.args)
    }

    #[test]
    fn flags_make_the_same_link_a_device_entry_would() {
        let args =
            parse(&["--protocol", "mc3e-udp", "--address", "10.0.0.1:8000", "--retries", "0", "read", "D0"]);
        let link = args.unwrap().link();
        assert_eq!((link.protocol, link.retries, link.unit), (Protocol::Mc3eUdp, 0, 1));
        assert_eq!((link.timeout, link.mc3e_monitor_timer()), (Duration::from_millis(1000), 3));
        let ppi = parse(&["--protocol", "ppi", "--address", "/dev/ttyS0", "--no-pdu-ref", "read", "VW0"]);
        let link = ppi.unwrap().link();
        assert_eq!((link.unit, link.quirks), (2, [Quirk::NoPduRef].into()));
        let modbus = parse(&["--protocol", "modbus-udp", "--address", "x:1", "--length0", "read", "4x1"]);
        assert_eq!(modbus.unwrap().link().quirks, [Quirk::Length0].into());
        assert!(parse(&["--protocol", "mc3e-tcp", "--address", "x:1", "read", "D0"]).is_ok());
        assert!(parse(&["--protocol", "mc9", "--address", "x:1", "read", "D0"]).is_err());
    }

    #[tokio::test]
    async fn a_quirk_of_another_protocol_is_refused_before_connecting() {
        let args = parse(&["--protocol", "mc3e", "--address", "127.0.0.1:9", "--length0", "read", "D0"]);
        let err = connect(&args.unwrap()).await.err().unwrap();
        assert!(matches!(err, LinkError::Quirk { quirk: Quirk::Length0, protocol: Protocol::Mc3e }), "{err}");
    }
}
