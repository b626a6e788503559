//! Modbus UDP, server side: one request datagram, one reply datagram.
//!
//! The request's PDU is the rest of the datagram, whatever its MBAP length says (the
//! seed's shelf-PLC client sends length 6 for a 13-byte function 16 request). Requests are
//! served one at a time, so a `delay` fault also holds back the requests behind it.

use std::sync::Arc;

use super::{Addressing, Outcome, Shared};
use crate::protocols::modbus::frame::{self, LengthField, MBAP_LEN};
use crate::protocols::transport::{DatagramServerPort, recv_from, send_to};

pub(crate) async fn serve(socket: Box<dyn DatagramServerPort>, shared: Arc<Shared>) {
    let socket = socket.as_ref();
    let mut rx = vec![0u8; 1024];
    let mut tx = Vec::with_capacity(300);
    loop {
        let (n, peer) = match recv_from(socket, &mut rx).await {
            Ok(got) => got,
            // ICMP errors from earlier replies surface here; they concern no one now.
            Err(_) => continue,
        };
        let Ok(header) = frame::decode_header(&rx[..n]) else { continue };
        let Some(Outcome { unit, pdu, plan }) =
            shared.process(header.unit, &rx[MBAP_LEN..n], Addressing::Mbap)
        else {
            continue;
        };
        if plan.close {
            continue;
        }
        if !plan.delay.is_zero() {
            tokio::time::sleep(plan.delay).await;
        }
        if let Some(garbage) = &plan.garbage {
            let _ = send_to(socket, garbage, peer).await;
        }
        let tid = if shared.options.zero_transaction_id { 0 } else { header.transaction };
        let tid = if plan.wrong_id { !tid } else { tid };
        let length = if shared.options.length0 { LengthField::Zero } else { LengthField::Standard };
        tx.clear();
        frame::encode(&mut tx, tid, unit, &pdu, length);
        if send_to(socket, &tx, peer).await.is_ok() {
            shared.replied();
        }
        if plan.duplicate {
            let _ = send_to(socket, &tx, peer).await;
        }
    }
}
