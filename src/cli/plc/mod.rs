//! `rackd plc`: read or write a PLC's memory by hand, for commissioning, once or in a
//! poll loop, with the display formats of the tags.
//!
//! ```text
//! rackd plc --protocol modbus-tcp --address 10.0.0.5 read 40001 10 --interval 500
//! rackd plc --protocol modbus-rtu --address /dev/ttyUSB0 --serial 9600,8E1 --unit 2 write 4x4000 -f f32 3.14
//! rackd plc --protocol mc3e --address 10.0.0.6:5000 read D200 4 -f i32
//! rackd plc --protocol mewtocol --address /dev/ttyUSB0 --unit EE read DT100 2
//! rackd plc --protocol ppi-tcp --address 10.0.0.7:4001 read VD4
//! ```
//!
//! The flags make a [`LinkConfig`] and the PLC is opened by the same factory as the
//! devices' ([`crate::protocols::link::connect`]), so `rackd plc` reaches a PLC exactly as
//! a `[[devices]]` entry with the same settings would (MC monitoring timer included). The
//! command uses only the [`PlcMemory`] trait. The parts: [`flags`] (unit, default ports),
//! [`format`](mod@format) (display formats and word orders), [`item`] (addresses, items and their
//! labels), [`poll`] (output and the poll loop), [`hints`] (errors that say what to try).
//!
//! Every option is global (accepted before or after `read ADDR`), except `--protocol` and
//! `--address`, which clap cannot make both required and global. A new operation (say
//! `identify`) is one more [`PlcOp`] variant and one more arm in [`run`].

pub mod capture;
pub mod extra;
pub mod flags;
pub mod format;
pub mod hints;
pub mod identify;
pub mod item;
pub mod poll;

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use anyhow::{Context, anyhow, bail};

use self::capture::Capture;
use self::format::{Format, Order};
use self::item::Target;
use self::poll::Output;
use crate::protocols::link::{self, LinkConfig, LinkError};
use crate::protocols::serial::SerialSettings;
use crate::protocols::transport::LinkTuning;
use crate::protocols::{PlcMemory, Protocol, Quirk};
use crate::wire::tags::spec::native_order;

/// Examples per protocol family and the notations, shown by `rackd plc --help`.
const EXAMPLES: &str = "\
Examples:
  rackd plc --protocol modbus-tcp --address 10.0.0.5 read 40001 10 --interval 500
  rackd plc --protocol modbus-rtu --address /dev/ttyUSB0 --serial 19200,8E1 --unit 2 write 4x100 -f f32 3.14
  rackd plc --protocol mc3e --address 10.0.0.6:5000 read D200 4 -f i32
  rackd plc --protocol mewtocol --address /dev/ttyUSB0 --unit EE read DT100 2
  rackd plc --protocol ppi-tcp --address 10.0.0.7:4001 read VD4
  rackd plc --protocol modbus-tcp --address 10.0.0.5 --unit 255 identify

Notations:
  Modbus    4x100 = holding register at PDU address 100 = 40101 (Modicon, 1-based) = %MW100 = MW100;
            3x input registers, 1x discrete inputs, 0x coils: 0x10 is coil ten in the Modicon area
            notation, not hex sixteen (the number is always decimal); 30001, 10001, 00001; %M10 coil 10
  MC 3E/4E  D200, W1F (hex), R, ZR, SD, SW words; M100, X1A, Y1A, B, L, SM, F, V bits (X, Y, B, W
            numbered in hex); K4M100 = M100..M115 as one word; TN/CN current values, TS/TC, CS/CC bits
  MEWTOCOL  DT100 words; WX, WY, WR, WL contact words; X, Y, R, L, T, C bits (last digit hex: R1F)
  S7 PPI    VW100 (words step 2 bytes), VB0 bytes, VD4 32-bit double words, V10.3, Q0.1, I0.0 bits,
            MW4, SMB0, AIW0, T37, C5

Formats (-f): u16 (default), i16, hex, bin, u32, i32, f32 (two words each, --word-order abcd|cdab|badc|dcba,
default abcd for Modbus and S7, cdab for MC and MEWTOCOL), ascii (COUNT words as one text, high byte first).
Write values take the same format: write 4x100 -f f32 3.14; write D0 -f ascii HELLO.";

/// Arguments of `rackd plc`.
#[derive(Debug, clap::Args)]
#[command(after_help = EXAMPLES)]
pub struct PlcArgs {
    /// Protocol and transport.
    #[arg(long, value_enum)]
    pub protocol: Protocol,
    /// HOST:PORT (HOST alone takes port 502 for Modbus TCP/UDP), or a serial device such as
    /// /dev/ttyUSB0.
    #[arg(long)]
    pub address: String,
    /// Serial settings: baud,data bits parity stop bits [default: 9600,8E1; 9600,8O1 for
    /// MEWTOCOL].
    #[arg(long, global = true)]
    pub serial: Option<SerialSettings>,
    /// Station (unit) number, 0..255 as the protocol allows; EE is MEWTOCOL's global station
    /// (238); 0 broadcasts a Modbus RTU write [default: 1; 2 for PPI, the S7-200's default
    /// address].
    #[arg(long, global = true, value_parser = flags::unit)]
    pub unit: Option<u8>,
    /// Reply timeout of each try, in milliseconds [default: 1000].
    #[arg(long, global = true)]
    pub timeout_ms: Option<u64>,
    /// Tries after the first one before giving up [default: 2].
    #[arg(long, global = true)]
    pub retries: Option<u32>,
    /// Modbus: the device answers with MBAP length 0 (the shelf PLC).
    #[arg(long, global = true)]
    pub length0: bool,
    /// Modbus: the device does not echo the transaction id.
    #[arg(long, global = true)]
    pub ignore_transaction_id: bool,
    /// MEWTOCOL: send `**` instead of a BCC (PLC set up without the check).
    #[arg(long, global = true)]
    pub no_bcc: bool,
    /// MEWTOCOL: use `<` long frames.
    #[arg(long, global = true)]
    pub long_frames: bool,
    /// PPI: the PLC does not echo the PDU reference.
    #[arg(long, global = true)]
    pub no_pdu_ref: bool,
    /// Print JSON instead of `ADDRESS VALUE` lines (one object per line when polling).
    #[arg(long, global = true)]
    pub json: bool,
    /// How to show words and read values to write [default: u16].
    #[arg(long, short = 'f', global = true, value_enum)]
    pub format: Option<Format>,
    /// Word order of 32-bit values (abcd = big = high-first, cdab = little = low-first; badc
    /// and dcba also swap the bytes of each word) [default: abcd; cdab for MC and MEWTOCOL].
    #[arg(long, global = true, value_enum)]
    pub word_order: Option<Order>,
    /// Repeat the read every MS milliseconds until --count polls or Ctrl-C.
    #[arg(long, global = true, value_name = "MS")]
    pub interval: Option<u64>,
    /// Stop after N polls [default: forever with --interval; --interval defaults to 1000].
    #[arg(long = "count", global = true, value_name = "N")]
    pub polls: Option<u64>,
    /// Write every frame sent and received to FILE (pcapng, for Wireshark) when the command
    /// ends, also after an error or Ctrl-C.
    #[arg(long, global = true, value_name = "FILE")]
    pub capture: Option<PathBuf>,
    /// What to do.
    #[command(subcommand)]
    pub op: PlcOp,
}

/// What to do with the PLC.
#[derive(Debug, clap::Subcommand)]
pub enum PlcOp {
    /// Read COUNT items from ADDRESS (e.g. 4x4000, 40001, D200, DT100, VD4).
    Read {
        /// First address, in the protocol's notation.
        address: String,
        /// How many items (an item is one value of the format; with -f ascii, one word).
        #[arg(default_value_t = 1)]
        count: u16,
        /// Modbus: send the count as asked, 0 or past the limits (125 words, 2000 bits)
        /// included, to see how the device answers; items are shown as plain numbers.
        #[arg(long)]
        unchecked: bool,
    },
    /// Write values from ADDRESS on, each in the format (-f); bits: 0/1.
    Write {
        /// First address, in the protocol's notation.
        address: String,
        /// The values.
        #[arg(required = true, allow_negative_numbers = true)]
        values: Vec<String>,
    },
    /// Ask the PLC what it is: Modbus device identification (43/14), MC CPU model name (0101).
    Identify {
        /// Modbus: which objects.
        #[arg(long, value_enum, default_value_t = identify::Category::Regular)]
        category: identify::Category,
        /// Modbus: one object by its id (0..255) instead of a category.
        #[arg(long)]
        object: Option<u8>,
    },
    /// MC: read words at scattered addresses in one request (random read, 0403).
    Random {
        /// Word addresses (D100 W1F K4M100 TN5).
        addresses: Vec<String>,
        /// Double-word addresses, read as 32-bit values.
        #[arg(long = "dword")]
        dwords: Vec<String>,
    },
    /// MC: read several blocks in one request (multi-block read, 0406), each ADDRESS:COUNT
    /// (D100:10; bit devices as 16-point words: K4M100:2).
    Blocks {
        /// The blocks.
        #[arg(required = true)]
        blocks: Vec<String>,
    },
    /// Modbus: Read FIFO Queue (function 24) at its pointer register (4x100).
    Fifo {
        /// The FIFO pointer register.
        address: String,
    },
    /// Modbus: a Diagnostics (function 8) counter or register by sub-function, in hex (000B
    /// bus messages, 000C CRC errors, 000D exceptions, 000E server messages, 0002 register).
    Diag {
        /// The sub-function.
        sub_function: String,
    },
}

impl PlcArgs {
    /// The link these flags describe: unit and serial settings default by protocol, as a
    /// device's do; each quirk flag must suit the protocol; a network address without a
    /// port gets the protocol's standard port, if it has one.
    pub fn link(&self) -> anyhow::Result<LinkConfig> {
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
            timeout: Duration::from_millis(self.timeout_ms.unwrap_or(1000)),
            retries: self.retries.unwrap_or(2),
            quirks: flags.into_iter().filter(|(on, _)| *on).map(|(_, q)| q).collect(),
            ..LinkConfig::new(self.protocol, flags::address(self.protocol, &self.address)?)
        };
        // The floor follows the quirks (a PLC without transaction ids gets the longer one);
        // a one-off request has no round trips to learn from, so it only has to fit.
        link.tuning = LinkTuning::for_replies(link.replies());
        link.tuning.min_timeout = link.tuning.min_timeout.min(link.timeout);
        if self.capture.is_some() {
            link.capture = Capture::limits();
        }
        Ok(link)
    }

    /// The poll period and the number of polls, if the read repeats.
    fn polling(&self) -> Option<(Duration, Option<u64>)> {
        match (self.interval, self.polls) {
            (None, None) => None,
            (every, polls) => Some((Duration::from_millis(every.unwrap_or(1000)), polls)),
        }
    }
}

/// Opens the PLC the arguments describe; with `capture`, its recorder is handed to it.
pub async fn connect(args: &PlcArgs, capture: Option<&Capture>) -> anyhow::Result<Arc<dyn PlcMemory>> {
    let link = args.link()?;
    let plc = link::connect(&link).await.map_err(|e| match e {
        LinkError::Plc(e) => anyhow!(hints::explain(&e, args.protocol)),
        other => anyhow!(other),
    })?;
    if let Some(c) = capture {
        c.keep(plc.recorder());
    }
    Ok(plc)
}

/// Runs `rackd plc`: prints one `ADDRESS VALUE` line per item (or JSON), once or per
/// poll, and fails with a message that says what to check otherwise. With `--capture`,
/// the frames go to the file when the command ends, however it ends.
pub async fn run(args: PlcArgs) -> anyhow::Result<()> {
    let Some(path) = &args.capture else { return run_op(&args, None).await };
    let capture = Capture::create(path)?;
    let result = if args.polling().is_some() {
        // The poll loop stops on Ctrl-C itself, and reports its polls.
        run_op(&args, Some(&capture)).await
    } else {
        tokio::select! {
            result = run_op(&args, Some(&capture)) => result,
            _ = tokio::signal::ctrl_c() => Err(anyhow!("interrupted (Ctrl-C)")),
        }
    };
    match (result, capture.finish()) {
        (Ok(()), written) => written.map(|_| ()),
        (Err(e), Ok(_)) => Err(e),
        (Err(e), Err(unwritten)) => {
            eprintln!("error: {unwritten:#}");
            Err(e)
        }
    }
}

/// The operation the arguments ask for.
async fn run_op(args: &PlcArgs, capture: Option<&Capture>) -> anyhow::Result<()> {
    let order = args.word_order.unwrap_or_else(|| Order::of(native_order(args.protocol)));
    let out = Output::new(args.json);
    let at = flags::address(args.protocol, &args.address).unwrap_or_else(|_| args.address.clone());
    let peer = format!("{} {at}", args.protocol);
    match &args.op {
        PlcOp::Read { address, count, unchecked: true } => {
            extra::once(args.polling().is_some(), "an unchecked read")?;
            let request = extra::Extra::Unchecked { address, count: *count };
            let pairs =
                extra::run(&args.link()?, request, capture).await.with_context(|| format!("on {peer}"))?;
            extra::say(args.json, pairs, false);
        }
        PlcOp::Read { address, count, .. } => {
            let target = Target::new(args.protocol, address, args.format, order)?;
            let plc = connect(args, capture).await?;
            match args.polling() {
                None => {
                    let items = target
                        .read(&*plc, *count)
                        .await
                        .with_context(|| format!("read {address} x{count} from {peer}"))?;
                    out.once(&items);
                }
                Some((every, polls)) => poll::run(&*plc, &target, *count, every, polls, out).await?,
            }
        }
        PlcOp::Write { address, values } => {
            if args.polling().is_some() {
                bail!("--interval and --count repeat reads; a write is done once");
            }
            let target = Target::new(args.protocol, address, args.format, order)?;
            let plc = connect(args, capture).await?;
            let items =
                target.write(&*plc, values).await.with_context(|| format!("write {address} on {peer}"))?;
            out.once(&items);
        }
        PlcOp::Identify { category, object } => {
            extra::once(args.polling().is_some(), "identify")?;
            let pairs = identify::identify(&args.link()?, *category, *object, capture)
                .await
                .with_context(|| format!("identify {peer}"))?;
            extra::say(args.json, pairs, true);
        }
        op => {
            let request = match op {
                PlcOp::Random { addresses, dwords } => extra::Extra::Random { words: addresses, dwords },
                PlcOp::Blocks { blocks } => extra::Extra::Blocks(blocks),
                PlcOp::Fifo { address } => extra::Extra::Fifo(address),
                PlcOp::Diag { sub_function } => extra::Extra::Diagnostics(sub_function),
                _ => unreachable!("read, write and identify are handled above"),
            };
            extra::once(args.polling().is_some(), "this request")?;
            let pairs =
                extra::run(&args.link()?, request, capture).await.with_context(|| format!("on {peer}"))?;
            extra::say(args.json, pairs, false);
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

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
        let link = args.unwrap().link().unwrap();
        assert_eq!((link.protocol, link.retries, link.unit), (Protocol::Mc3eUdp, 0, 1));
        assert_eq!((link.timeout, link.mc3e_monitor_timer()), (Duration::from_millis(1000), 3));
        let ppi = parse(&["--protocol", "ppi", "--address", "/dev/ttyS0", "--no-pdu-ref", "read", "VW0"]);
        let link = ppi.unwrap().link().unwrap();
        assert_eq!((link.unit, link.quirks), (2, [Quirk::NoPduRef].into()));
        let modbus = parse(&["--protocol", "modbus-udp", "--address", "x:1", "--length0", "read", "4x1"]);
        assert_eq!(modbus.unwrap().link().unwrap().quirks, [Quirk::Length0].into());
        assert!(parse(&["--protocol", "mc3e-tcp", "--address", "x:1", "read", "D0"]).is_ok());
        assert!(parse(&["--protocol", "mc9", "--address", "x:1", "read", "D0"]).is_err());
    }

    #[tokio::test]
    async fn a_quirk_of_another_protocol_is_refused_before_connecting() {
        let args = parse(&["--protocol", "mc3e", "--address", "127.0.0.1:9", "--length0", "read", "D0"]);
        let err = connect(&args.unwrap(), None).await.err().unwrap();
        let quirk = err.downcast_ref::<LinkError>();
        assert!(
            matches!(quirk, Some(LinkError::Quirk { quirk: Quirk::Length0, protocol: Protocol::Mc3e })),
            "{err}"
        );
    }

    #[test]
    fn options_are_taken_anywhere_on_the_line() {
        let args = parse(&[
            "--protocol",
            "modbus-tcp",
            "--address",
            "10.0.0.5",
            "read",
            "40001",
            "4",
            "--json",
            "-f",
            "f32",
            "--word-order",
            "little",
            "--interval",
            "50",
            "--count",
            "3",
            "--unit",
            "255",
        ])
        .unwrap();
        assert!(args.json);
        assert_eq!((args.format, args.word_order), (Some(Format::F32), Some(Order::Cdab)));
        assert_eq!(args.polling(), Some((Duration::from_millis(50), Some(3))));
        let link = args.link().unwrap();
        assert_eq!((link.address.as_str(), link.unit), ("10.0.0.5:502", 255));
        let ee = parse(&["--protocol", "mewtocol-tcp", "--address", "h:9094", "read", "DT0", "--unit", "EE"]);
        assert_eq!(ee.unwrap().link().unwrap().unit, 238);
        let once = parse(&["--protocol", "ppi-tcp", "--address", "h:1", "read", "VD4"]).unwrap();
        assert_eq!(once.polling(), None);
        let counted =
            parse(&["--protocol", "ppi-tcp", "--address", "h:1", "--count", "2", "read", "VD4"]).unwrap();
        assert_eq!(counted.polling(), Some((Duration::from_millis(1000), Some(2))));
    }
}
