//! The MEWTOCOL-COM client (the computer side): one PLC station over a serial line or raw
//! TCP to a serial-to-Ethernet gateway, with timeouts and retries in one place.

use std::time::Duration;

use tokio::sync::Mutex;

use super::command::{Request, Response};
use super::error_code::{self, ErrorCode};
use super::frame::{self, Bcc, GLOBAL_STATION, Kind, MAX_LONG, MAX_SHORT};
use crate::capture::{Limits, Recorder, SerialProtocol, Verdict};
use crate::protocols::serial::SerialSettings;
use crate::protocols::transport::{
    Attempt, AttemptError, Backoff, ByteStream, Dial, Endpoint, Guard, LinkHealth, LinkStats, LinkTuning,
    Retry, RetryPolicy, Scanner, StreamLink, recorder_for,
};
use crate::protocols::{DeviceCode, DropReason, PlcError};

/// How the PLC is reached.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MewtocolTransport {
    /// A serial port (RS-232C / RS-485).
    Serial,
    /// Raw TCP to a serial-to-Ethernet gateway (`HOST:PORT`).
    Tcp,
}

/// Settings of a [`MewtocolClient`].
#[derive(Clone, Debug, PartialEq)]
pub struct MewtocolConfig {
    /// Serial or TCP.
    pub transport: MewtocolTransport,
    /// Serial device path or `HOST:PORT`.
    pub address: String,
    /// Serial line settings (default 9600,8O1, the FP series' factory setting).
    pub serial: SerialSettings,
    /// Station number of the PLC, 1..=99 (the seed's `01` is only the default).
    /// (1..=99, or [`GLOBAL_STATION`] = 238 for `EE`, which the one PLC on the line answers
    /// whatever its number; its reply is taken whatever station signs it).
    pub station: u8,
    /// Reply timeout of each attempt.
    pub timeout: Duration,
    /// Resends after a timeout or a bad reply (never after an error reply).
    pub retries: u32,
    /// The adaptive timeout's floor and when the link counts as degraded.
    pub tuning: LinkTuning,
    /// Send a BCC and require one in replies; false sends `**` (PLCs set up without the
    /// check) and also accepts `**` in replies.
    pub bcc: bool,
    /// Use `<` long frames (2048 characters) instead of `%` frames (118).
    pub long_frames: bool,
    /// The flight recorder's bounds; `None` records nothing.
    pub capture: Option<Limits>,
}

impl MewtocolConfig {
    /// Defaults: station 1, 1 s timeout, 2 retries, BCC on, `%` frames, 9600,8O1, no
    /// recorder.
    pub fn new(transport: MewtocolTransport, address: impl Into<String>) -> Self {
        let serial = SerialSettings { parity: tokio_serial::Parity::Odd, ..SerialSettings::default() };
        MewtocolConfig {
            transport,
            address: address.into(),
            serial,
            station: 1,
            timeout: Duration::from_secs(1),
            retries: 2,
            tuning: LinkTuning::default(),
            bcc: true,
            long_frames: false,
            capture: None,
        }
    }

    fn frame_limit(&self) -> usize {
        if self.long_frames { MAX_LONG } else { MAX_SHORT }
    }

    /// Most words one RD or RCC reply carries (`%01$RD` + 4 per word + BCC + CR).
    pub fn max_read_words(&self) -> usize {
        (self.frame_limit() - 9) / 4
    }

    /// Most words one WD or WCC command carries (`%01#WDD` + 10 digits + 4 per word + 3).
    pub fn max_write_words(&self) -> usize {
        (self.frame_limit() - 20) / 4
    }
}

/// A MEWTOCOL-COM client for one station. Requests from concurrent callers go one at a
/// time. Implements [`crate::protocols::PlcMemory`] (see `memory.rs`).
pub struct MewtocolClient {
    config: MewtocolConfig,
    health: LinkHealth,
    link: Mutex<StreamLink>,
}

fn check_station(station: u8) -> Result<(), PlcError> {
    match (1..=99).contains(&station) || station == GLOBAL_STATION {
        true => Ok(()),
        false => Err(PlcError::OutOfRange("station must be 1..=99, or 238 (EE, the global station)")),
    }
}

impl MewtocolClient {
    /// A client for `config`; the port or connection is opened on the first request and
    /// reopened after it is lost.
    pub fn new(config: MewtocolConfig) -> Result<Self, PlcError> {
        let endpoint = match config.transport {
            MewtocolTransport::Serial => {
                Endpoint::Serial { path: config.address.clone(), settings: config.serial }
            }
            MewtocolTransport::Tcp => Endpoint::Tcp(config.address.clone()),
        };
        Self::with(config, endpoint)
    }

    /// A client over a stream the caller opened (a pty in tests); it cannot be reopened.
    pub fn over_stream(config: MewtocolConfig, stream: impl ByteStream + 'static) -> Result<Self, PlcError> {
        Self::with(config, Endpoint::given(stream))
    }

    /// A client over a line the caller dials (the seeded wire simulation of the tests).
    pub fn over(config: MewtocolConfig, dial: std::sync::Arc<dyn Dial>) -> Result<Self, PlcError> {
        Self::with(config, Endpoint::Dial(dial))
    }

    fn with(config: MewtocolConfig, endpoint: Endpoint) -> Result<Self, PlcError> {
        check_station(config.station)?;
        let policy = RetryPolicy { timeout: config.timeout, retries: config.retries, tuning: config.tuning };
        let recorder = recorder_for(config.capture, &endpoint, Some(SerialProtocol::Mewtocol));
        let health = LinkHealth::new(policy).recording(recorder.clone());
        let mut link = StreamLink::new(endpoint, Backoff::default(), Guard::Wait);
        link.set_recorder(recorder);
        Ok(MewtocolClient { config, health, link: Mutex::new(link) })
    }

    /// The link's flight recorder, when the configuration asked for one.
    pub fn recorder(&self) -> Option<std::sync::Arc<Recorder>> {
        self.health.recorder().cloned()
    }

    /// The link's health (adaptive timeout, degraded flag, counters).
    pub fn link_stats(&self) -> LinkStats {
        self.health.stats()
    }

    /// The configuration.
    pub fn config(&self) -> &MewtocolConfig {
        &self.config
    }

    /// Sends one command and returns its response. An error reply (`!` + code) returns
    /// [`PlcError::Device`] at once; timeouts and bad replies are retried.
    pub async fn call(&self, request: &Request) -> Result<Response, PlcError> {
        request.check().map_err(PlcError::OutOfRange)?;
        let mut body = Vec::new();
        request.encode(&mut body);
        let mut tx = Vec::with_capacity(body.len() + 8);
        let c = &self.config;
        frame::encode(&mut tx, c.long_frames, c.station, Kind::Command, &body, c.bcc);
        if tx.len() > c.frame_limit() {
            return Err(PlcError::OutOfRange("command longer than one frame"));
        }
        let mut link = self.link.lock().await;
        let mut retry = Retry::start(&self.health, "mewtocol");
        while let Some(attempt) = retry.next_attempt() {
            match self.attempt(&mut link, &tx, request, &attempt).await {
                Ok(response) => {
                    retry.succeeded();
                    return Ok(response);
                }
                Err(e) => retry.failed(e)?,
            }
        }
        Err(retry.spent())
    }

    /// One attempt: keep the transport's rule for a line (hold it while a reply may be
    /// owed, flush stale input), send, and wait for this station's reply.
    async fn attempt(
        &self,
        link: &mut StreamLink,
        tx: &[u8],
        request: &Request,
        attempt: &Attempt,
    ) -> Result<Response, AttemptError> {
        self.health.settled(link.settle(attempt, request.is_write()).await?);
        link.send(tx, attempt.timeout).await?;
        let attempt = &attempt.restarted();
        let mut reason = None;
        let mut frames = Scanner::new(frame::scan);
        loop {
            let Some(scanned) = link.read_frame(&mut frames, attempt.deadline).await? else {
                return Err(reason.map_or(AttemptError::Timeout, AttemptError::Malformed));
            };
            let Ok(frame) = scanned else {
                link.judged(Verdict::Malformed);
                self.health.dropped(DropReason::Malformed);
                reason = Some("reply is not a MEWTOCOL frame");
                continue;
            };
            // Our own command echoed by a 2-wire RS-485 adapter.
            if frame.kind == Kind::Command {
                link.judged(Verdict::Dropped);
                continue;
            }
            // Addressed to EE, the one PLC on the line answers; FP-X signs the reply EE,
            // another model may sign it with its own number, so any station is taken.
            if frame.station != self.config.station && self.config.station != GLOBAL_STATION {
                link.judged(Verdict::WrongUnit);
                self.health.dropped(DropReason::Unit);
                continue;
            }
            match frame.bcc {
                Bcc::Wrong { .. } => {
                    link.judged(Verdict::CrcError);
                    self.health.dropped(DropReason::Malformed);
                    reason = Some("BCC error in the reply");
                    continue;
                }
                Bcc::Skipped if self.config.bcc => {
                    link.judged(Verdict::Malformed);
                    self.health.dropped(DropReason::Malformed);
                    reason = Some("reply without a BCC (`**`) while BCC is required");
                    continue;
                }
                _ => {}
            }
            if frame.kind == Kind::Error {
                link.judged(Verdict::Ok);
                link.answered();
                return Err(match error_code::parse(&frame.body) {
                    Some(code) => AttemptError::Device(DeviceCode::Mewtocol(ErrorCode(code))),
                    None => AttemptError::Malformed("error reply without a 2-digit code"),
                });
            }
            let decoded = request.decode_response(&frame.body);
            link.judged(if decoded.is_ok() { Verdict::Ok } else { Verdict::StaleReply });
            match decoded {
                Ok(response) => {
                    link.answered();
                    return Ok(response);
                }
                // A reply to another command or size (a late one): dropped as stale, never
                // data; the line is held before the next request.
                Err(msg) => {
                    self.health.dropped(DropReason::Stale);
                    link.unsettle();
                    reason = Some(msg);
                }
            }
        }
    }
}
