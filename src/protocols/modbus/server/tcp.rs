//! Stream servers on TCP: Modbus TCP (MBAP) and RTU over TCP, one task per connection.
//!
//! MBAP request lengths are taken from the PDU itself where the function is known, so a
//! length field of 0 or the seed's short length for function 16 does not desynchronise the
//! stream; the length field is used only for unknown functions (answered with exception 01).

use std::sync::Arc;

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpListener;
use tokio::task::JoinSet;

use super::{Addressing, Outcome, Shared};
use crate::protocols::modbus::decode::request_pdu_len;
use crate::protocols::modbus::frame::{self, LengthField, MAX_PDU_LEN, MBAP_LEN};
use crate::protocols::transport::ByteStream;

/// What runs over the TCP connections.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Framing {
    Mbap,
    Rtu,
}

/// Accepts connections until aborted; aborting drops the set and so every connection.
pub(crate) async fn serve(listener: TcpListener, shared: Arc<Shared>, framing: Framing) {
    let mut connections = JoinSet::new();
    loop {
        tokio::select! {
            accepted = listener.accept() => {
                let Ok((stream, _)) = accepted else { continue };
                let _ = stream.set_nodelay(true);
                let shared = shared.clone();
                match framing {
                    Framing::Mbap => connections.spawn(serve_mbap(Box::new(stream), shared)),
                    Framing::Rtu => connections.spawn(super::rtu::serve(Box::new(stream), shared, 0)),
                };
            }
            Some(_) = connections.join_next(), if !connections.is_empty() => {}
        }
    }
}

/// The PDU length of the request at the start of `buf` (header included in `buf`):
/// `Ok(None)` needs more bytes, `Err(())` the stream is not Modbus.
fn request_len(buf: &[u8]) -> Result<Option<usize>, ()> {
    if buf.len() < MBAP_LEN {
        return Ok(None);
    }
    let header = frame::decode_header(buf).map_err(|_| ())?;
    match request_pdu_len(&buf[MBAP_LEN..]) {
        Ok(Some(n)) if n <= MAX_PDU_LEN => Ok(Some(n)),
        Ok(Some(_)) => Err(()),
        Ok(None) => Ok(None),
        Err(_) if header.length >= 2 => Ok(Some(header.length as usize - 1)),
        Err(_) => Err(()),
    }
}

/// Serves MBAP frames on one connection until it closes.
pub(crate) async fn serve_mbap(mut stream: Box<dyn ByteStream>, shared: Arc<Shared>) {
    let mut rx = Vec::with_capacity(1024);
    let mut tx = Vec::with_capacity(300);
    loop {
        let len = match request_len(&rx) {
            Err(()) => return,
            Ok(Some(n)) if rx.len() >= MBAP_LEN + n => n,
            Ok(_) => match stream.read_buf(&mut rx).await {
                Ok(0) | Err(_) => return,
                Ok(_) => continue,
            },
        };
        let Ok(header) = frame::decode_header(&rx) else { return };
        let outcome = shared.process(header.unit, &rx[MBAP_LEN..MBAP_LEN + len], Addressing::Mbap);
        rx.drain(..MBAP_LEN + len);
        let Some(Outcome { unit, pdu, plan }) = outcome else { continue };
        if plan.close {
            return;
        }
        if !plan.delay.is_zero() {
            tokio::time::sleep(plan.delay).await;
        }
        tx.clear();
        if let Some(garbage) = &plan.garbage {
            tx.extend_from_slice(garbage);
        }
        let tid = if shared.options.zero_transaction_id { 0 } else { header.transaction };
        let tid = if plan.wrong_id { !tid } else { tid };
        let length = if shared.options.length0 { LengthField::Zero } else { LengthField::Standard };
        let start = tx.len();
        frame::encode(&mut tx, tid, unit, &pdu, length);
        if plan.duplicate {
            tx.extend_from_within(start..);
        }
        if stream.write_all(&tx).await.is_err() {
            return;
        }
        shared.replied();
    }
}
