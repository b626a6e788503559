//! `rackd sim <machine>`: the arguments of each simulator, and what they mean to it (its
//! options); the simulators themselves, and running them alone, are
//! [`crate::sim::standalone`]'s.
//!
//! Every simulator takes the same fault flags ([`FaultArgs`], flattened into each
//! subcommand) with the same meanings, from [`crate::protocols::faults`]; only the notation
//! of `--device-error` follows each protocol's manual (hexadecimal MC end codes, decimal
//! MEWTOCOL codes). The memory simulators take `--preset` and `--control` too
//! ([`bench::PresetArgs`]).

pub mod bench;
pub mod crane;
pub mod faults;
pub mod line;
pub mod mc3e;
pub mod modbus;
pub mod replay;

use std::time::Duration;

use crate::protocols::serial::SerialSettings;
use crate::protocols::{DeviceCode, Protocol};
use crate::sim::shelf::{ShelfProtocol, ShelfSimOptions};
use crate::sim::standalone;
use faults::FaultArgs;

/// The simulators.
#[derive(clap::Subcommand, Debug)]
pub enum SimCommand {
    /// A Modbus server with a full register bank (all four tables, 0..65535).
    Modbus(modbus::SimModbusArgs),
    /// The shelf storage PLC: task slots over Modbus UDP (answering with MBAP length 0),
    /// Modbus TCP, Modbus RTU as an S7-1200 (serial or over TCP), PPI or MEWTOCOL.
    Shelf(SimShelfArgs),
    /// A Mitsubishi MC protocol 3E (binary) server over the whole device range.
    Mc3e(mc3e::SimMc3eArgs),
    /// A stacker crane with the MC 3E register interface (D0..D39 / D200..D239). Reads
    /// commands on stdin: `alarm CODE`, `clear`, `heartbeat on|off`, `handshake on|off`, `force`, `drop`,
    /// `link on|off`, `status`.
    Crane(crane::SimCraneArgs),
    /// A Panasonic PLC answering MEWTOCOL-COM (DT, X, Y, R, L, T, C) on TCP or a serial port.
    Mewtocol(line::SimLineArgs),
    /// A Siemens S7-200 answering PPI (V, I, Q, M, SM, S, AI, AQ, T, C) on TCP or a serial port.
    Ppi(line::SimLineArgs),
    /// The device side of a capture (pcapng, UDP or TCP) played back to a live rackd: each
    /// request answered with the recorded reply, divergence reported.
    Replay(replay::SimReplayArgs),
}

/// Options of `rackd sim shelf`.
#[derive(clap::Args, Debug)]
pub struct SimShelfArgs {
    /// Protocol served: modbus-udp, modbus-tcp, modbus-rtu, modbus-rtu-tcp, ppi, ppi-tcp,
    /// mewtocol or mewtocol-tcp.
    #[arg(long, value_enum, default_value_t = Protocol::ModbusUdp)]
    pub protocol: Protocol,
    /// Address to answer on (UDP / TCP), or the serial device to open (modbus-rtu, ppi,
    /// mewtocol) [default: 127.0.0.1:1502 for network protocols].
    #[arg(long)]
    pub listen: Option<String>,
    /// Number of task slots.
    #[arg(long, default_value_t = 60)]
    pub slots: u16,
    /// Slot 1's task id in the protocol's notation (a bare number is a Modbus holding
    /// register) [default: 4x4000 Modbus UDP/TCP, 4x0 Modbus RTU (S7-1200), VW1000 PPI,
    /// DT4000 MEWTOCOL].
    #[arg(long)]
    pub base: Option<String>,
    /// Words from one slot to the next [default: 50 for PPI, else 100].
    #[arg(long)]
    pub stride: Option<u16>,
    /// Modbus unit, PPI address or MEWTOCOL station [default: 2 for PPI, else 1].
    #[arg(long)]
    pub unit: Option<u8>,
    /// Serial settings when opening a serial device [default: 9600,8E1; 9600,8O1 for
    /// MEWTOCOL].
    #[arg(long)]
    pub serial: Option<SerialSettings>,
    /// Milliseconds each task takes.
    #[arg(long, default_value_t = 500)]
    pub task_ms: u64,
    /// Fraction (0..1) of tasks failing with kind 1 (PLC fault).
    #[arg(long, default_value_t = 0.0)]
    pub fail: f64,
    /// Modbus UDP/TCP: answer with transaction id 0 whatever the request carried, as the
    /// seed's PLC does (a device entry for it needs the `no-transaction-id` quirk).
    #[arg(long)]
    pub no_transaction_id: bool,
    /// Link faults.
    #[command(flatten)]
    pub faults: FaultArgs,
}

impl SimShelfArgs {
    /// The simulator options these arguments select.
    pub fn options(&self) -> anyhow::Result<ShelfSimOptions> {
        anyhow::ensure!(
            (0.0..=1.0).contains(&self.fail),
            "--fail must be between 0 and 1, got {}",
            self.fail
        );
        let faults = self.faults.faults_with(|text| DeviceCode::parse(self.protocol, text))?;
        anyhow::ensure!(
            !self.no_transaction_id || matches!(self.protocol, Protocol::ModbusUdp | Protocol::ModbusTcp),
            "--no-transaction-id is for modbus-udp and modbus-tcp (other frames carry no transaction id)"
        );
        Ok(ShelfSimOptions {
            protocol: ShelfProtocol::try_from(self.protocol)?,
            slots: self.slots,
            base: self.base.clone(),
            stride: self.stride,
            unit: self.unit,
            serial: self.serial,
            task_time: Duration::from_millis(self.task_ms),
            fail_rate: self.fail,
            faults,
            no_transaction_id: self.no_transaction_id,
        })
    }

    /// Where to serve: `--listen`, or for network protocols 127.0.0.1:1502.
    pub fn listen(&self) -> anyhow::Result<String> {
        match (&self.listen, self.protocol.is_serial()) {
            (Some(at), _) => Ok(at.clone()),
            (None, false) => Ok("127.0.0.1:1502".into()),
            (None, true) => {
                anyhow::bail!("{} needs --listen with a serial device, e.g. /dev/ttyUSB0", self.protocol)
            }
        }
    }
}

/// Runs a simulator until Ctrl-C.
pub async fn run(cmd: SimCommand) -> anyhow::Result<()> {
    match cmd {
        SimCommand::Modbus(args) => standalone::modbus::run(args.options()?).await,
        SimCommand::Mc3e(args) => standalone::mc3e::run(args.options()?).await,
        SimCommand::Crane(args) => standalone::crane::run(args.options()?).await,
        SimCommand::Mewtocol(args) => {
            let running = line::start_mewtocol(&args).await?;
            standalone::line::run(running, "MEWTOCOL", &args.listen).await
        }
        SimCommand::Ppi(args) => {
            let running = line::start_ppi(&args).await?;
            standalone::line::run(running, "PPI", &args.listen).await
        }
        SimCommand::Shelf(args) => standalone::shelf::run(&args.listen()?, args.options()?).await,
        SimCommand::Replay(args) => standalone::replay::run(args.options()).await.map(drop),
    }
}

#[cfg(test)]
mod tests {
    use clap::Parser;

    use super::*;
    use crate::protocols::faults::Faults;

    #[derive(clap::Parser)]
    struct Cli {
        #[command(subcommand)]
        sim: SimCommand,
    }

    fn faults_of(line: &str) -> FaultArgs {
        let cli = Cli::try_parse_from(line.split_whitespace()).unwrap_or_else(|e| panic!("{line}: {e}"));
        match cli.sim {
            SimCommand::Modbus(a) => a.faults,
            SimCommand::Shelf(a) => a.faults,
            SimCommand::Mc3e(a) => a.faults,
            SimCommand::Crane(a) => a.faults,
            SimCommand::Mewtocol(a) | SimCommand::Ppi(a) => a.faults,
            SimCommand::Replay(_) => unreachable!("the replay takes no faults"),
        }
    }

    #[test]
    fn every_simulator_takes_the_same_fault_flags() {
        let flags = "--drop 0.5 --delay-ms 7 --jitter-ms 2.5 --late-ms 90 --garbage 0.1 --close 0.2 --duplicate 0.3 --wrong-id 0.4 --wrong-unit 9";
        let expected = Faults {
            drop_rate: 0.5,
            delay: Duration::from_millis(7),
            jitter: Duration::from_micros(2500),
            late: Duration::from_millis(90),
            garbage_rate: 0.1,
            close_rate: 0.2,
            duplicate_rate: 0.3,
            wrong_id_rate: 0.4,
            wrong_unit: Some(9),
            device_error: None,
        };
        for sim in ["modbus --listen 127.0.0.1:0", "shelf", "mc3e", "crane", "mewtocol", "ppi"] {
            let args = faults_of(&format!("sim {sim} {flags}"));
            assert_eq!(args.faults_with(|_| unreachable!()).unwrap(), expected, "{sim}");
        }
    }

    #[test]
    fn replay_takes_a_file_and_its_own_flags() {
        let cli =
            Cli::try_parse_from("sim replay site.pcapng --listen 127.0.0.1:9000 --idle-secs 2".split(' '));
        let SimCommand::Replay(args) = cli.unwrap().sim else { panic!("not the replay") };
        let o = args.options();
        assert_eq!(o.file, std::path::PathBuf::from("site.pcapng"));
        assert_eq!(
            (o.listen, o.idle, o.reorder),
            (Some("127.0.0.1:9000".parse().unwrap()), Duration::from_secs(2), Duration::from_millis(100))
        );
        assert!(Cli::try_parse_from(["sim", "replay"]).is_err(), "the file is needed");
    }

    #[test]
    fn device_errors_are_read_in_each_protocols_notation() {
        let code = |line: &str, parse: &dyn Fn(&FaultArgs) -> anyhow::Result<Faults>| {
            parse(&faults_of(line)).map(|f| f.device_error)
        };
        use crate::protocols::{mc3e, mewtocol, modbus, ppi};
        assert_eq!(
            code("sim mc3e --device-error C051", &|a| a.faults::<mc3e::EndCode>()).unwrap(),
            Some(0xC051)
        );
        assert_eq!(
            code("sim mewtocol --device-error 63", &|a| a.faults::<mewtocol::ErrorCode>()).unwrap(),
            Some(63)
        );
        assert_eq!(
            code("sim ppi --device-error 0x8500", &|a| a.faults::<ppi::ReturnCode>()).unwrap(),
            Some(0x8500)
        );
        assert_eq!(
            code("sim modbus --listen x --device-error 2", &|a| a.faults::<modbus::Exception>()).unwrap(),
            Some(2)
        );
        assert!(code("sim mewtocol --device-error C051", &|a| a.faults::<mewtocol::ErrorCode>()).is_err());
        let shelf = |line: &str| match Cli::try_parse_from(line.split_whitespace()).unwrap().sim {
            SimCommand::Shelf(a) => a.options().map(|o| o.faults.device_error),
            _ => unreachable!(),
        };
        assert_eq!(shelf("sim shelf --protocol ppi --device-error 0x0A").unwrap(), Some(0x0A));
        assert!(shelf("sim shelf --protocol modbus-udp --device-error 300").is_err());
        assert!(faults_of("sim ppi --drop 2").faults::<ppi::ReturnCode>().is_err(), "rates are fractions");
    }
}
