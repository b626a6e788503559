//! A simulated Panasonic PLC answering MEWTOCOL-COM on a byte stream (serial port, pty) or
//! on TCP connections (like a serial-to-Ethernet gateway in front of a PLC).
//!
//! Commands with a wrong BCC get `!40`; a command that does not parse gets `!41` or `!42`;
//! an address past the bank gets `!61`. Commands for other stations are ignored, as on a
//! shared RS-485 line. Commands to the global station `EE` are answered whatever the
//! simulated PLC's number, with the reply signed `EE`, as an FP-X does (`%EE$RT...`). Faults ([`SharedFaults`]) drop, delay, prefix noise, duplicate,
//! answer from another station or with a chosen error code, or close the connection;
//! MEWTOCOL frames carry no id, so a wrong-id fault has no effect. A [`Handler`] lets a machine simulator see each command against the
//! memory as it was, and carry it out itself.

use std::sync::Arc;

use tokio::io::{AsyncReadExt, AsyncWriteExt};

use super::bank::{Bank, SharedBank};
use super::command::{Request, Response};
use super::error_code::BCC_ERROR;
use super::frame::{self, Bcc, Frame, GLOBAL_STATION, Kind, Scan};
use crate::protocols::faults::SharedFaults;
use crate::protocols::transport::{self, ByteStream, StreamServer};

/// Carries out a decoded command on the locked bank in place of [`Bank::execute`], which it
/// normally calls: the seam where a simulator watches the host's writes against the memory
/// as it was before them (a shelf PLC counting writes into busy task slots). The error is
/// the MEWTOCOL code to answer. Runs on the reply path with the bank locked: keep it short.
pub type Handler = Arc<dyn Fn(&mut Bank, &Request) -> Result<Response, u8> + Send + Sync>;

/// What a server serves.
#[derive(Clone)]
pub struct ServerState {
    /// The PLC memory.
    pub bank: SharedBank,
    /// The fault settings.
    pub faults: SharedFaults,
    /// The station number answered to.
    pub station: u8,
    /// Carries out commands instead of the bank itself, when set.
    pub handler: Option<Handler>,
}

impl ServerState {
    /// Station 1 serving `bank`, without faults or handler.
    pub fn new(bank: SharedBank) -> Self {
        ServerState { bank, faults: SharedFaults::default(), station: 1, handler: None }
    }

    /// The same state with commands carried out by `handler`.
    pub fn with_handler(mut self, handler: Handler) -> Self {
        self.handler = Some(handler);
        self
    }

    /// Whether `frame` is a command for this PLC: its own station or the global `EE`.
    fn answers(&self, frame: &Frame) -> bool {
        frame.kind == Kind::Command && (frame.station == self.station || frame.station == GLOBAL_STATION)
    }

    /// The reply to one command frame, or None when it is not for this station; `error`
    /// is answered instead of carrying the command out, and `station` signs the reply.
    fn reply(&self, frame: &Frame, error: Option<u16>, station: u8) -> Option<Vec<u8>> {
        if !self.answers(frame) {
            return None;
        }
        let mut body = Vec::new();
        let kind = match (frame.bcc, error) {
            (Bcc::Wrong { .. }, _) => Err(BCC_ERROR),
            (_, Some(code)) => Err((code % 100) as u8),
            _ => Request::decode(&frame.body).and_then(|request| {
                let mut bank = self.bank.lock().unwrap_or_else(|p| p.into_inner());
                let response = match &self.handler {
                    Some(handler) => handler(&mut bank, &request)?,
                    None => bank.execute(&request)?,
                };
                response.encode(&request, &mut body);
                Ok(())
            }),
        };
        let kind = match kind {
            Ok(()) => Kind::Ok,
            Err(code) => {
                body = format!("{code:02}").into_bytes();
                Kind::Error
            }
        };
        let mut out = Vec::new();
        frame::encode(&mut out, frame.long, station, kind, &body, true);
        Some(out)
    }
}

/// Serves one stream until it closes or the returned server is dropped.
pub fn serve_stream(stream: impl ByteStream + 'static, state: ServerState) -> StreamServer {
    StreamServer::new(None, tokio::spawn(serve(Box::new(stream), state)))
}

/// Listens on `addr` (port 0 picks one) and serves each TCP connection as a stream.
pub async fn serve_tcp(addr: &str, state: ServerState) -> std::io::Result<StreamServer> {
    transport::spawn_tcp(addr, move |stream| serve(Box::new(stream), state.clone())).await
}

async fn serve(mut stream: Box<dyn ByteStream>, state: ServerState) {
    let mut rx = Vec::with_capacity(256);
    loop {
        loop {
            match frame::scan(&rx) {
                Scan::Found { end, frame } => {
                    rx.drain(..end);
                    if !state.answers(&frame) {
                        continue;
                    }
                    let plan = state.faults.plan();
                    if plan.close {
                        return;
                    }
                    if plan.unanswered() {
                        continue;
                    }
                    // A reply is signed with the station addressed: its own, or EE.
                    let station = plan.wrong_unit.unwrap_or(frame.station);
                    let Some(reply) = state.reply(&frame, plan.device_error, station) else { continue };
                    if !plan.delay.is_zero() {
                        tokio::time::sleep(plan.delay).await;
                    }
                    let mut out = plan.garbage.unwrap_or_default();
                    out.extend_from_slice(&reply);
                    if plan.duplicate {
                        out.extend_from_slice(&reply);
                    }
                    if stream.write_all(&out).await.is_err() || stream.flush().await.is_err() {
                        return;
                    }
                }
                Scan::Bad { end, .. } => {
                    rx.drain(..end);
                }
                Scan::NeedMore { discard } => {
                    rx.drain(..discard);
                    break;
                }
            }
        }
        match stream.read_buf(&mut rx).await {
            Ok(0) | Err(_) => return,
            Ok(_) => {}
        }
    }
}
