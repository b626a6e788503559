//! The PPI master: one S7-200 over a serial line (9600/19200/187500 baud, 8E1) or raw TCP
//! through a gateway, with the two-step exchange, timeouts and retries in one place.

use std::time::Duration;

use tokio::sync::Mutex;

use super::frame::{self, FC_POLL, FC_RESPONSE, Frame, FrameError};
use super::pdu::{Item, Reply, Request};
use super::return_code::ReturnCode;
use crate::capture::{Limits, Recorder, SerialProtocol, Verdict};
use crate::protocols::serial::SerialSettings;
use crate::protocols::transport::{
    Attempt, AttemptError, Backoff, ByteStream, Dial, Endpoint, Guard, LinkHealth, LinkStats, LinkTuning,
    RecentIds, Retry, RetryPolicy, Scanner, StreamLink, recorder_for,
};
use crate::protocols::{DeviceCode, DropReason, PlcError};

/// How the PLC is reached.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PpiTransport {
    /// The RS-485 port through a serial adapter.
    Serial,
    /// Raw TCP to a serial-to-Ethernet gateway (`HOST:PORT`).
    Tcp,
}

/// Settings of a [`PpiClient`].
#[derive(Clone, Debug, PartialEq)]
pub struct PpiConfig {
    /// Serial or TCP.
    pub transport: PpiTransport,
    /// Serial device path or `HOST:PORT`.
    pub address: String,
    /// Serial settings (default 9600,8E1; the S7-200 also runs 19200 and 187500).
    pub serial: SerialSettings,
    /// The PLC's station address (default 2).
    pub plc: u8,
    /// Our (master) address (default 0).
    pub master: u8,
    /// Time allowed for the whole exchange (request, E5, poll, response) of one attempt.
    pub timeout: Duration,
    /// Resends after a timeout or bad reply (never after a return code from the PLC).
    pub retries: u32,
    /// The adaptive timeout's floor and when the link counts as degraded.
    pub tuning: LinkTuning,
    /// Take only responses carrying the PDU reference of this request's attempts. Turn off
    /// for a device that answers with reference 0 whatever it was sent.
    pub match_pdu_ref: bool,
    /// The flight recorder's bounds; `None` records nothing.
    pub capture: Option<Limits>,
}

impl PpiConfig {
    /// Defaults: PLC 2, master 0, 9600,8E1, 1 s, 2 retries, PDU references matched, no
    /// recorder.
    pub fn new(transport: PpiTransport, address: impl Into<String>) -> Self {
        PpiConfig {
            transport,
            address: address.into(),
            serial: SerialSettings::default(),
            plc: 2,
            master: 0,
            timeout: Duration::from_secs(1),
            retries: 2,
            tuning: LinkTuning::default(),
            match_pdu_ref: true,
            capture: None,
        }
    }
}

/// A PPI master for one S7-200. Requests from concurrent callers go one at a time.
/// Implements [`crate::protocols::PlcMemory`] (see `memory.rs`).
pub struct PpiClient {
    config: PpiConfig,
    health: LinkHealth,
    link: Mutex<PpiLink>,
}

/// The line and the PDU references given on it (see the transport's `ids.rs`).
struct PpiLink {
    line: StreamLink,
    refs: RecentIds,
}

fn check(config: &PpiConfig) -> Result<(), PlcError> {
    if config.plc > 126 || config.master > 126 || config.plc == config.master {
        return Err(PlcError::OutOfRange("PPI addresses are 0..=126 and the PLC's differs from ours"));
    }
    Ok(())
}

impl PpiClient {
    /// A client for `config`; the port or connection opens on the first request.
    pub fn new(config: PpiConfig) -> Result<Self, PlcError> {
        let endpoint = match config.transport {
            PpiTransport::Serial => {
                Endpoint::Serial { path: config.address.clone(), settings: config.serial }
            }
            PpiTransport::Tcp => Endpoint::Tcp(config.address.clone()),
        };
        Self::with(config, endpoint)
    }

    /// A client over a stream the caller opened (a pty in tests); it cannot be reopened.
    pub fn over_stream(config: PpiConfig, stream: impl ByteStream + 'static) -> Result<Self, PlcError> {
        Self::with(config, Endpoint::given(stream))
    }

    /// A client over a line the caller dials (the seeded wire simulation of the tests).
    pub fn over(config: PpiConfig, dial: std::sync::Arc<dyn Dial>) -> Result<Self, PlcError> {
        Self::with(config, Endpoint::Dial(dial))
    }

    fn with(config: PpiConfig, endpoint: Endpoint) -> Result<Self, PlcError> {
        check(&config)?;
        let recorder = recorder_for(config.capture, &endpoint, Some(SerialProtocol::Ppi));
        let mut link = StreamLink::new(endpoint, Backoff::default(), Guard::Wait);
        link.set_recorder(recorder.clone());
        Ok(PpiClient {
            health: LinkHealth::new(RetryPolicy {
                timeout: config.timeout,
                retries: config.retries,
                tuning: config.tuning,
            })
            .recording(recorder),
            config,
            link: Mutex::new(PpiLink { line: link, refs: RecentIds::new() }),
        })
    }

    /// The link's flight recorder, when the configuration asked for one.
    pub fn recorder(&self) -> Option<std::sync::Arc<Recorder>> {
        self.health.recorder().cloned()
    }

    /// The configuration.
    pub fn config(&self) -> &PpiConfig {
        &self.config
    }

    /// The link's health (adaptive timeout, degraded flag, counters).
    pub fn link_stats(&self) -> LinkStats {
        self.health.stats()
    }

    /// Reads one item; the item's return code, if not success, is the error.
    pub async fn read(&self, item: Item) -> Result<Vec<u8>, PlcError> {
        match self.call(&Request::Read(item)).await? {
            Reply::Data(bytes) => Ok(bytes),
            _ => Err(PlcError::Malformed("reply of the wrong kind")),
        }
    }

    /// Writes one item.
    pub async fn write(&self, item: Item, data: &[u8]) -> Result<(), PlcError> {
        self.call(&Request::Write(item, data.to_vec())).await.map(|_| ())
    }

    /// Puts the PLC in RUN (the mode switch must be at RUN or TERM).
    pub async fn run(&self) -> Result<(), PlcError> {
        self.call(&Request::Run).await.map(|_| ())
    }

    /// Puts the PLC in STOP.
    pub async fn stop(&self) -> Result<(), PlcError> {
        self.call(&Request::Stop).await.map(|_| ())
    }

    /// Sends one request through the two-step exchange. Item return codes and refusals
    /// come back as [`PlcError::Device`] at once; timeouts and bad frames are retried.
    pub async fn call(&self, request: &Request) -> Result<Reply, PlcError> {
        request.check().map_err(PlcError::OutOfRange)?;
        let mut link = self.link.lock().await;
        let link = &mut *link;
        let mut refs = Vec::with_capacity(self.health.policy().attempts().min(8) as usize);
        let mut retry = Retry::start(&self.health, "ppi");
        while let Some(attempt) = retry.next_attempt() {
            refs.push(link.refs.next());
            match self.attempt(&mut link.line, &link.refs, request, &refs, &attempt).await {
                Ok(Reply::ItemError(code)) => retry.failed(device(ReturnCode::Item(code)))?,
                Ok(Reply::Refused { class, code }) => {
                    retry.failed(device(ReturnCode::Refused { class, code }))?
                }
                Ok(reply) => {
                    retry.succeeded();
                    return Ok(reply);
                }
                Err(e) => retry.failed(e)?,
            }
        }
        Err(retry.spent())
    }

    /// One attempt of the two-step exchange; `refs` are the PDU references of this request's
    /// attempts so far, the last one this attempt's.
    async fn attempt(
        &self,
        link: &mut StreamLink,
        given: &RecentIds,
        request: &Request,
        refs: &[u16],
        attempt: &Attempt,
    ) -> Result<Reply, AttemptError> {
        let c = &self.config;
        let mut pdu = Vec::with_capacity(64);
        request.encode(*refs.last().unwrap_or(&0), &mut pdu);
        let mut tx = Vec::with_capacity(pdu.len() + 9);
        frame::encode_long(&mut tx, c.plc, c.master, request.fc(), &pdu);
        self.health.settled(link.settle(attempt, request.is_write()).await?);
        link.send(&tx, attempt.timeout).await?;
        let attempt = &attempt.restarted();
        let mut frames = Scanner::new(frame::scan);
        // Step 1: the short acknowledgement. Whole frames before it are stale and skipped.
        loop {
            match link.read_frame(&mut frames, attempt.deadline).await? {
                None => return Err(AttemptError::Timeout),
                Some(Ok(Frame::Ack(_))) => {
                    link.judged(Verdict::Ok);
                    break;
                }
                Some(_) => {
                    link.judged(Verdict::StaleReply);
                    self.health.dropped(DropReason::Stale);
                    link.unsettle();
                }
            }
        }
        // Step 2: the poll, and the response frame.
        tx.clear();
        frame::encode_short(&mut tx, c.plc, c.master, FC_POLL);
        link.send(&tx, attempt.timeout).await?;
        let mut reason = None;
        loop {
            match link.read_frame(&mut frames, attempt.deadline).await? {
                None => return Err(reason.map_or(AttemptError::Timeout, AttemptError::Malformed)),
                Some(Ok(Frame::Long { da, sa, fc: FC_RESPONSE, payload })) => {
                    if da != c.master || sa != c.plc {
                        link.judged(Verdict::WrongUnit);
                        self.health.dropped(DropReason::Unit);
                        continue;
                    }
                    match Reply::decode(&payload, request) {
                        Ok((r, reply)) if !c.match_pdu_ref || refs.contains(&r) => {
                            link.judged(Verdict::Ok);
                            link.answered();
                            return Ok(reply);
                        }
                        // A reference this link gave an earlier request: a late reply, stale;
                        // one it never gave: foreign (another master, a previous rackd).
                        Ok((r, _)) => {
                            let why = match given.ours(r) {
                                true => DropReason::Stale,
                                false => DropReason::PduReference,
                            };
                            link.judged(crate::protocols::transport::verdict_of(why));
                            self.health.dropped(why);
                            link.unsettle();
                            reason = Some(match why {
                                DropReason::Stale => "stale reply (PDU reference of an earlier request)",
                                _ => "foreign reply (a PDU reference this master never sent)",
                            });
                        }
                        Err(e) => {
                            let why = if matches!(e, super::pdu::PduError::Mismatch) {
                                link.unsettle();
                                DropReason::Stale
                            } else {
                                DropReason::Malformed
                            };
                            link.judged(crate::protocols::transport::verdict_of(why));
                            self.health.dropped(why);
                            reason = Some(pdu_message(e));
                        }
                    }
                }
                // An acknowledgement to the poll (the PLC has no response for it: lost) or
                // another frame nobody waited for: counted stale, so that a capture and the
                // counters agree. The attempt goes on waiting, and times out.
                Some(Ok(_)) => {
                    link.judged(Verdict::StaleReply);
                    self.health.dropped(DropReason::Stale);
                }
                Some(Err(FrameError::BadHeader | FrameError::BadEnd)) => {
                    link.judged(Verdict::Malformed);
                    self.health.dropped(DropReason::Malformed);
                    reason = reason.or(Some("broken frame instead of the response"));
                }
                Some(Err(FrameError::BadFcs)) => {
                    link.judged(Verdict::CrcError);
                    self.health.dropped(DropReason::Malformed);
                    reason = Some("FCS error in the response");
                }
            }
        }
    }
}

fn device(code: ReturnCode) -> AttemptError {
    AttemptError::Device(DeviceCode::Ppi(code))
}

fn pdu_message(e: super::pdu::PduError) -> &'static str {
    use super::pdu::PduError;
    match e {
        PduError::NotS7 => "response is not an S7 acknowledgement",
        PduError::BadLength => "response PDU lengths do not add up",
        PduError::Unsupported => "response to an unsupported function",
        PduError::BadItem => "malformed data item in the response",
        PduError::Mismatch => "response does not match the request",
    }
}
