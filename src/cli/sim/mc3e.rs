//! `rackd sim mc3e`: the arguments of the MC PLC simulator
//! ([`crate::sim::standalone::mc3e`]).

use std::net::SocketAddr;

use super::bench::PresetArgs;
use super::faults::FaultArgs;
use crate::protocols::mc3e::{EndCode, Mc3eServer, TransportKind, TypeName};
use crate::sim::standalone::Running;
use crate::sim::standalone::mc3e::{self as sim, Mc3eOptions};

/// Transport of the simulated PLC.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum SimTransport {
    /// TCP.
    Tcp,
    /// UDP.
    Udp,
}

/// `rackd sim mc3e` options.
#[derive(clap::Args, Clone, Debug)]
pub struct SimMc3eArgs {
    /// Address to listen on.
    #[arg(long, default_value = "127.0.0.1:5000")]
    pub listen: SocketAddr,
    /// TCP or UDP.
    #[arg(long, value_enum, default_value_t = SimTransport::Tcp)]
    pub transport: SimTransport,
    /// Link faults.
    #[command(flatten)]
    pub faults: FaultArgs,
    /// The answer to "read CPU model name" (command 0101).
    #[command(flatten)]
    pub cpu: CpuArgs,
    /// Preset and control surface.
    #[command(flatten)]
    pub bench: PresetArgs,
}

/// What the simulated CPU says it is.
#[derive(clap::Args, Clone, Debug, PartialEq)]
pub struct CpuArgs {
    /// Model name answered to "read CPU model name" (up to 16 ASCII characters).
    #[arg(long = "cpu-model", default_value = "Q03UDVCPU")]
    pub model: String,
    /// Model code answered with it, in hexadecimal as the manual writes it (0366 = Q03UDVCPU).
    #[arg(long = "cpu-code", default_value = "0366", value_parser = parse_code)]
    pub code: u16,
}

impl Default for CpuArgs {
    /// A Q03UDVCPU, model code 0366.
    fn default() -> Self {
        let TypeName { model, code } = TypeName::default();
        CpuArgs { model, code }
    }
}

fn parse_code(text: &str) -> Result<u16, String> {
    let hex = text.trim().trim_start_matches("0x").trim_start_matches("0X");
    u16::from_str_radix(hex, 16)
        .map_err(|_| format!("bad model code {text:?}: expected 4 hex digits such as 0366"))
}

impl SimTransport {
    /// The MC transport it names.
    pub fn kind(self) -> TransportKind {
        match self {
            SimTransport::Tcp => TransportKind::Tcp,
            SimTransport::Udp => TransportKind::Udp,
        }
    }
}

impl SimMc3eArgs {
    /// The simulator options these arguments select.
    pub fn options(&self) -> anyhow::Result<Mc3eOptions> {
        let faults = self.faults.faults::<EndCode>()?;
        let Some(type_name) = TypeName::new(&self.cpu.model, self.cpu.code) else {
            anyhow::bail!("bad --cpu-model {:?}: up to 16 printable ASCII characters", self.cpu.model);
        };
        Ok(Mc3eOptions {
            listen: self.listen,
            transport: self.transport.kind(),
            faults,
            type_name,
            bench: self.bench.bench(),
        })
    }
}

/// Loads the preset, starts the simulated PLC described by `args` and returns it running.
pub async fn start(args: &SimMc3eArgs) -> anyhow::Result<Running<Mc3eServer>> {
    sim::start(&args.options()?).await
}
