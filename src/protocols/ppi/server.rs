//! A simulated S7-200 answering PPI on a byte stream (serial port, pty) or on TCP
//! connections (like a serial-to-Ethernet gateway), with the two-step exchange: a request
//! is acknowledged with `E5` and executed, and its response is sent when the master polls.
//!
//! A poll with nothing pending is answered with `E5`. Frames with a bad FCS are ignored, as
//! a PLC ignores a frame it did not receive intact. Faults ([`SharedFaults`]): drop (E5
//! sent, no response to the poll), lost E5 (request ignored), delay, noise and a duplicate
//! of the response, a wrong PDU reference or source address in it, a closed connection, and
//! a device error code: below 0x100 an item return code, above it a refusal with error
//! class `code >> 8`. A [`Handler`] lets a machine simulator see each request
//! against the memory as it was, and carry it out itself.

use std::sync::Arc;

use tokio::io::{AsyncReadExt, AsyncWriteExt};

use super::bank::{Bank, SharedBank};
use super::frame::{self, ACK, FC_POLL, FC_RESPONSE, Frame, Scan};
use super::pdu::{Reply, Request};
use crate::protocols::faults::{Plan, SharedFaults};
use crate::protocols::transport::{self, ByteStream, StreamServer};

/// Carries out a decoded request on the locked bank in place of [`Bank::execute`], which it
/// normally calls: the seam where a simulator watches the host's writes against the memory
/// as it was before them (a shelf PLC counting writes into busy task slots). Runs on the
/// reply path with the bank locked: keep it short.
pub type Handler = Arc<dyn Fn(&mut Bank, &Request) -> Reply + Send + Sync>;

/// What a server serves.
#[derive(Clone)]
pub struct ServerState {
    /// The PLC memory.
    pub bank: SharedBank,
    /// The fault settings.
    pub faults: SharedFaults,
    /// The PLC's station address (default 2).
    pub address: u8,
    /// Carries out requests instead of the bank itself, when set.
    pub handler: Option<Handler>,
}

impl ServerState {
    /// Address 2 serving `bank`, without faults or handler.
    pub fn new(bank: SharedBank) -> Self {
        ServerState { bank, faults: SharedFaults::default(), address: 2, handler: None }
    }

    /// The same state with requests carried out by `handler`.
    pub fn with_handler(mut self, handler: Handler) -> Self {
        self.handler = Some(handler);
        self
    }

    /// The response frame to a request PDU from `master`.
    fn respond(&self, master: u8, payload: &[u8], plan: &Plan) -> Vec<u8> {
        let (pdu_ref, reply, request) = match Request::decode(payload) {
            Ok((r, request)) => {
                let reply = match plan.device_error {
                    Some(code) if code > 0xFF => {
                        Reply::Refused { class: (code >> 8) as u8, code: code as u8 }
                    }
                    Some(code) => Reply::ItemError(code as u8),
                    None => {
                        let mut bank = self.bank.lock().unwrap_or_else(|p| p.into_inner());
                        match &self.handler {
                            Some(handler) => handler(&mut bank, &request),
                            None => bank.execute(&request),
                        }
                    }
                };
                (r, reply, request)
            }
            Err(_) => {
                let r = payload.get(4..6).map_or(0, |b| u16::from_be_bytes([b[0], b[1]]));
                (r, Reply::Refused { class: 0x84, code: 0x04 }, Request::Stop)
            }
        };
        let pdu_ref = if plan.wrong_id { !pdu_ref } else { pdu_ref };
        let mut pdu = Vec::new();
        reply.encode(&request, pdu_ref, &mut pdu);
        let mut out = Vec::new();
        let source = plan.wrong_unit.unwrap_or(self.address);
        frame::encode_long(&mut out, master, source, FC_RESPONSE, &pdu);
        out
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
    let mut rx = Vec::with_capacity(512);
    // The response waiting for the master's poll, and the plan for sending it.
    let mut pending: Option<(Vec<u8>, Plan)> = None;
    loop {
        loop {
            let out = match frame::scan(&rx) {
                Scan::Found { end, frame } => {
                    rx.drain(..end);
                    match frame {
                        Frame::Long { da, sa, payload, .. } if da == state.address => {
                            let plan = state.faults.plan();
                            if plan.close {
                                return;
                            }
                            if plan.drop_ack {
                                continue;
                            }
                            let response = state.respond(sa, &payload, &plan);
                            pending = (!plan.drop).then_some((response, plan));
                            vec![ACK]
                        }
                        Frame::Short { da, fc: FC_POLL, .. } if da == state.address => match pending.take() {
                            Some((response, plan)) => {
                                if !plan.delay.is_zero() {
                                    tokio::time::sleep(plan.delay).await;
                                }
                                let mut out = plan.garbage.unwrap_or_default();
                                out.extend_from_slice(&response);
                                if plan.duplicate {
                                    out.extend_from_slice(&response);
                                }
                                out
                            }
                            None => vec![ACK],
                        },
                        _ => continue,
                    }
                }
                Scan::Bad { end, .. } => {
                    rx.drain(..end);
                    continue;
                }
                Scan::NeedMore { discard } => {
                    rx.drain(..discard);
                    break;
                }
            };
            if stream.write_all(&out).await.is_err() || stream.flush().await.is_err() {
                return;
            }
        }
        if rx.len() > 4096 {
            rx.clear();
        }
        match stream.read_buf(&mut rx).await {
            Ok(0) | Err(_) => return,
            Ok(_) => {}
        }
    }
}
