//! `rackd sim mewtocol` and `rackd sim ppi`: the arguments of the MEWTOCOL and PPI
//! simulators ([`crate::sim::standalone::line`]).

use super::bench::PresetArgs;
use super::faults::FaultArgs;
use crate::protocols::faults::Faults;
use crate::protocols::serial::SerialSettings;
use crate::protocols::transport::StreamServer;
use crate::protocols::{mewtocol, ppi};
use crate::sim::standalone::Running;
use crate::sim::standalone::line::{self as sim, LineOptions};

/// Options shared by both simulators.
#[derive(clap::Args, Clone, Debug)]
pub struct SimLineArgs {
    /// `HOST:PORT` to listen on (TCP), or a serial device such as /dev/ttyUSB0.
    #[arg(long, default_value = "127.0.0.1:9094")]
    pub listen: String,
    /// Serial settings when listening on a serial device [default: 9600,8O1 for MEWTOCOL,
    /// 9600,8E1 for PPI].
    #[arg(long)]
    pub serial: Option<SerialSettings>,
    /// Station number (MEWTOCOL 1..=99, default 1; the global station EE is answered too)
    /// or PPI address (1..=126, default 2).
    #[arg(long)]
    pub station: Option<u8>,
    /// Link faults.
    #[command(flatten)]
    pub faults: FaultArgs,
    /// Preset and control surface.
    #[command(flatten)]
    pub bench: PresetArgs,
}

impl SimLineArgs {
    /// The MEWTOCOL simulator's options: station 1 unless given.
    pub fn mewtocol(&self) -> anyhow::Result<LineOptions> {
        let faults = self.faults.faults::<mewtocol::ErrorCode>()?;
        let station = self.station.unwrap_or(1);
        anyhow::ensure!((1..=99).contains(&station), "--station must be 1..=99");
        Ok(self.options(station, faults))
    }

    /// The PPI simulator's options: address 2 unless given.
    pub fn ppi(&self) -> anyhow::Result<LineOptions> {
        let faults = self.faults.faults::<ppi::ReturnCode>()?;
        let station = self.station.unwrap_or(2);
        anyhow::ensure!((1..=126).contains(&station), "--station must be 1..=126");
        Ok(self.options(station, faults))
    }

    fn options(&self, station: u8, faults: Faults) -> LineOptions {
        LineOptions {
            listen: self.listen.clone(),
            serial: self.serial,
            station,
            faults,
            bench: self.bench.bench(),
        }
    }
}

/// Loads the preset and starts the MEWTOCOL simulator.
pub async fn start_mewtocol(args: &SimLineArgs) -> anyhow::Result<Running<StreamServer>> {
    sim::start_mewtocol(&args.mewtocol()?).await
}

/// Loads the preset and starts the PPI simulator.
pub async fn start_ppi(args: &SimLineArgs) -> anyhow::Result<Running<StreamServer>> {
    sim::start_ppi(&args.ppi()?).await
}
