//! The fault flags every `rackd sim` subcommand takes, with the same names and meanings
//! ([`crate::protocols::faults`]).

use std::str::FromStr;
use std::time::Duration;

use anyhow::Context;

use crate::protocols::faults::Faults;
use crate::protocols::{BadDeviceCode, DeviceCode};

/// The link faults of every `rackd sim` subcommand.
#[derive(clap::Args, Clone, Debug, Default, PartialEq)]
pub struct FaultArgs {
    /// Fraction (0..1) of requests left unanswered.
    #[arg(long, default_value_t = 0.0)]
    pub drop: f64,
    /// Milliseconds before each reply (more than the client's timeout: every reply is late).
    #[arg(long, default_value_t = 0)]
    pub delay_ms: u64,
    /// Mean milliseconds of a random wait added to each reply (exponential, cut at ten
    /// means): jitter with a long tail; a client's timeout above delay + 10 x jitter gets
    /// every reply in time.
    #[arg(long, default_value_t = 0.0)]
    pub jitter_ms: f64,
    /// Milliseconds added to the first reply only: a PLC late once, then answering after
    /// `--delay-ms` again (the late reply and a retry's answer both arrive).
    #[arg(long, default_value_t = 0)]
    pub late_ms: u64,
    /// Fraction (0..1) of replies preceded by random bytes (a separate datagram over UDP).
    #[arg(long, default_value_t = 0.0)]
    pub garbage: f64,
    /// Fraction (0..1) of requests answered by closing the connection (UDP: dropped).
    #[arg(long, default_value_t = 0.0)]
    pub close: f64,
    /// Fraction (0..1) of replies sent twice.
    #[arg(long, default_value_t = 0.0)]
    pub duplicate: f64,
    /// Fraction (0..1) of replies with a wrong transaction id (Modbus TCP/UDP) or PDU
    /// reference (PPI); no effect where frames carry none.
    #[arg(long, default_value_t = 0.0)]
    pub wrong_id: f64,
    /// Answer as this unit / station / PPI address instead of the one asked (not MC 3E).
    #[arg(long)]
    pub wrong_unit: Option<u8>,
    /// Answer every request with this device error code, as the protocol's manual writes
    /// it: Modbus exception (2, 0x0B), MC end code in hexadecimal (C051), MEWTOCOL code
    /// (63), PPI item return code (0x0A) or class x 256 + code (0x8500).
    #[arg(long)]
    pub device_error: Option<String>,
}

impl FaultArgs {
    /// The faults these flags select, reading `--device-error` as a `C` code (the
    /// protocol's code type, e.g. [`crate::protocols::mc3e::EndCode`]).
    pub fn faults<C>(&self) -> anyhow::Result<Faults>
    where
        C: FromStr<Err = BadDeviceCode> + Into<DeviceCode>,
    {
        self.faults_with(|text| text.parse::<C>().map(Into::into))
    }

    /// The faults these flags select, reading `--device-error` with `code`.
    pub fn faults_with(
        &self,
        code: impl Fn(&str) -> Result<DeviceCode, BadDeviceCode>,
    ) -> anyhow::Result<Faults> {
        let device_error = match &self.device_error {
            Some(text) => {
                let code = code(text)?;
                Some(u16::try_from(code.number()).context("the device error code must fit 16 bits")?)
            }
            None => None,
        };
        let faults = Faults {
            drop_rate: self.drop,
            delay: Duration::from_millis(self.delay_ms),
            jitter: Duration::try_from_secs_f64(self.jitter_ms / 1000.0)
                .map_err(|_| anyhow::anyhow!("--jitter-ms must be a positive number of milliseconds"))?,
            late: Duration::from_millis(self.late_ms),
            garbage_rate: self.garbage,
            close_rate: self.close,
            duplicate_rate: self.duplicate,
            wrong_id_rate: self.wrong_id,
            wrong_unit: self.wrong_unit,
            device_error,
        };
        faults.check()?;
        Ok(faults)
    }
}
