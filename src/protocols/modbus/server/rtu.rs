//! Modbus RTU, server side, on any byte stream (serial port, pty, TCP connection).
//!
//! Incoming bytes are scanned for the first request frame with a valid CRC; bytes before it
//! (noise, frames cut short) are skipped. Frames to other units are consumed silently, as on
//! a shared bus. A function this server does not know cannot be framed in RTU and is never
//! answered. Replies wait for 3.5 characters of silence after the last byte seen.

use std::sync::Arc;

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::time::Instant;

use super::{Addressing, Outcome, Shared};
use crate::protocols::modbus::rtu::{self, Direction};
use crate::protocols::transport::ByteStream;

pub(crate) async fn serve(mut stream: Box<dyn ByteStream>, shared: Arc<Shared>, baud: u32) {
    let silence = rtu::silence(baud);
    let mut rx = Vec::with_capacity(1024);
    let mut tx = Vec::with_capacity(300);
    let mut last_io = Instant::now();
    loop {
        while let Some(found) = rtu::scan(&rx, Direction::Request) {
            let outcome = shared.process(found.unit(&rx), found.pdu(&rx), Addressing::Rtu);
            rx.drain(..found.start + found.len);
            let Some(Outcome { unit, pdu, plan }) = outcome else { continue };
            if plan.close {
                return;
            }
            if !plan.delay.is_zero() {
                tokio::time::sleep(plan.delay).await;
            }
            tokio::time::sleep_until(last_io + silence).await;
            tx.clear();
            if let Some(garbage) = &plan.garbage {
                tx.extend_from_slice(garbage);
            }
            let start = tx.len();
            rtu::encode(&mut tx, unit, &pdu);
            if plan.duplicate {
                tx.extend_from_within(start..);
            }
            if stream.write_all(&tx).await.is_err() || stream.flush().await.is_err() {
                return;
            }
            last_io = Instant::now();
            shared.replied();
        }
        if rx.len() > 2 * rtu::MAX_FRAME {
            rx.drain(..rx.len() - rtu::MAX_FRAME);
        }
        match stream.read_buf(&mut rx).await {
            Ok(0) | Err(_) => return,
            Ok(_) => last_io = Instant::now(),
        }
    }
}
