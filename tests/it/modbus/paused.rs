//! The transport's retry policy on paused time: the real Modbus RTU client and server on
//! the two ends of an in-memory byte stream (`tokio::io::duplex`), so timeouts are exact and
//! cost nothing. (Over a socket paused time would race the I/O; see the transport's docs.)
//!
//! What is checked: a request gets `retries + 1` attempts of `timeout` each and fails after
//! exactly that long; a reply after a retry ends the request at once; the device's own
//! answer (an exception) is never retried; a reply that comes after its request gave up is
//! never taken for the next request's answer (the line is held silent for the reply window
//! before the next request, draining it; one of another size arriving later is dropped as
//! stale), and the adaptive timeout learns the line's round trip. A new line is held for
//! the reply window before its first request ([`HELD`]): a reply a process before this one
//! asked for may still come on it.

use std::sync::Arc;
use std::time::Duration;

use rackd::protocols::faults::Fault;
use rackd::protocols::modbus::server::{Bank, ModbusServer, ServerHandle, ServerOptions};
use rackd::protocols::modbus::{Exception, ModbusClient, Transport};
use rackd::protocols::{DeviceCode, PlcError, PlcMemory};
use tokio::time::Instant;

const MS: fn(u64) -> Duration = Duration::from_millis;
/// What RTU framing adds to an exchange at 115200 baud: the 1.75 ms silence before each
/// frame, on both sides.
const FRAMING: Duration = Duration::from_millis(10);
/// The hold of a new line before its first request: the configured timeout.
const HELD: Duration = Duration::from_millis(1000);

/// An RTU server and client over an in-memory stream; each attempt may take 1 s.
fn line(retries: u32) -> (ServerHandle, Bank, ModbusClient) {
    let (near, far) = tokio::io::duplex(1024);
    let bank = Bank::new();
    let server =
        ModbusServer::new(Arc::new(bank.clone()), ServerOptions::default()).serve_rtu_stream(far, 115200);
    let mut c = super::config(Transport::RtuSerial, "duplex", 1000, retries);
    c.serial.baud = 115200;
    (server, bank, ModbusClient::rtu_over_stream(c, near).unwrap())
}

#[tokio::test(start_paused = true)]
async fn every_attempt_gets_its_timeout_and_the_request_fails_after_all_of_them() {
    let (server, _bank, plc) = line(2);
    let at = plc.parse_address("4x0").unwrap();
    server.faults().push(Fault::Drop).push(Fault::Drop).push(Fault::Drop);
    let start = Instant::now();
    let err = plc.read_words(&at, 2).await.unwrap_err();
    let took = start.elapsed();
    assert!(matches!(err, PlcError::Timeout { attempts: 3, timeout, .. } if timeout == MS(1000)), "{err:?}");
    assert!(took >= HELD + MS(3000) && took <= HELD + MS(3000) + FRAMING, "failed after {took:?}");
    assert_eq!(server.faults().requests_seen(), 3, "one request per attempt");
}

#[tokio::test(start_paused = true)]
async fn an_answer_to_a_retry_ends_the_request_at_once() {
    let (server, bank, plc) = line(2);
    bank.set_holding(0, &[7, 8]);
    let at = plc.parse_address("4x0").unwrap();
    server.faults().push(Fault::Drop).push(Fault::Drop);
    let start = Instant::now();
    assert_eq!(plc.read_words(&at, 2).await.unwrap(), [7, 8]);
    let took = start.elapsed();
    assert!(took >= HELD + MS(2000) && took <= HELD + MS(2000) + FRAMING, "answered after {took:?}");
    assert_eq!(plc.stats().sends, 3);
}

#[tokio::test(start_paused = true)]
async fn a_device_exception_is_an_answer_and_never_retried() {
    let (server, _bank, plc) = line(5);
    let at = plc.parse_address("4x0").unwrap();
    server.faults().push(Fault::DeviceError(0x06));
    let start = Instant::now();
    let err = plc.read_words(&at, 1).await.unwrap_err();
    assert!(matches!(err, PlcError::Device(DeviceCode::Modbus(Exception::SERVER_DEVICE_BUSY))), "{err:?}");
    assert!(start.elapsed() <= HELD + FRAMING, "at once, not after a timeout");
    assert_eq!(server.faults().requests_seen(), 1);
}

#[tokio::test(start_paused = true)]
async fn a_late_reply_is_never_taken_for_the_next_answer() {
    let (server, bank, plc) = line(0);
    bank.set_holding(0, &[1, 1]);
    bank.set_holding(10, &[2, 2]);
    let (first, second) = (plc.parse_address("4x0").unwrap(), plc.parse_address("4x10").unwrap());

    // The reply comes 500 ms after the request gave up, before the next request: flushed.
    server.faults().push(Fault::Delay(MS(1500)));
    let start = Instant::now();
    assert!(matches!(plc.read_words(&first, 2).await, Err(PlcError::Timeout { attempts: 1, .. })));
    assert!(start.elapsed() >= HELD + MS(1000) && start.elapsed() <= HELD + MS(1000) + FRAMING);
    while server.stats().replies < 1 {
        tokio::time::sleep(MS(1)).await;
    }
    let dropped = plc.stats().dropped;
    assert_eq!(plc.read_words(&second, 2).await.unwrap(), [2, 2], "its own answer");
    assert_eq!(plc.stats().dropped, dropped + 1, "the late reply was thrown away");
}

#[tokio::test(start_paused = true)]
async fn a_late_reply_to_an_abandoned_request_is_not_the_next_answer() {
    let (server, bank, plc) = line(1);
    bank.set_holding(0, &[1, 1]);
    bank.set_holding(10, &[3, 3, 3]);
    let (first, second) = (plc.parse_address("4x0").unwrap(), plc.parse_address("4x10").unwrap());
    // The caller gives up 300 ms after the send; the reply comes at 1 s. The abandoned request's
    // answer was never taken, so the next request holds the line until it has been silent
    // for the reply window (from the abandoned send), and the late reply, whether it comes
    // during the hold or just after it, is dropped as stale (2 words, not 3): the next
    // request's first attempt gets its own answer.
    server.faults().push(Fault::Delay(MS(1000)));
    assert!(tokio::time::timeout(HELD + MS(300), plc.read_words(&first, 2)).await.is_err(), "abandoned");
    let (sends, dropped) = (plc.stats().sends, plc.stats().dropped);
    assert_eq!(plc.read_words(&second, 3).await.unwrap(), [3, 3, 3], "its own answer");
    assert_eq!(plc.stats().sends, sends + 1, "sent once");
    assert_eq!(plc.stats().dropped, dropped + 1, "the late reply was dropped");
}

#[tokio::test(start_paused = true)]
async fn the_timer_learns_the_round_trip_but_a_retry_waits_out_the_configured_silence() {
    let (server, bank, plc) = line(2);
    bank.set_holding(0, &[4, 4]);
    let at = plc.parse_address("4x0").unwrap();
    assert_eq!(plc.link_stats().timeout_ms, 1000.0, "the ceiling before any round trip");
    for _ in 0..30 {
        plc.read_words(&at, 2).await.unwrap();
    }
    let learned = plc.link_stats();
    // A few ms of RTU framing per exchange: the timer settles near the 20 ms floor.
    assert!(learned.timeout_ms <= 30.0, "{learned:?}");
    assert!(learned.srtt_ms.is_some_and(|ms| ms < 10.0), "{learned:?}");
    // A lost request times out after the learned timeout, but on a line without ids the
    // retry goes out only after the configured timeout of silence (a late reply would be
    // drained in it).
    server.faults().push(Fault::Drop);
    let start = Instant::now();
    assert_eq!(plc.read_words(&at, 2).await.unwrap(), [4, 4]);
    let took = start.elapsed();
    assert!(took >= MS(1000) && took <= MS(1000) + FRAMING, "retried after {took:?}");
    let after = plc.link_stats();
    assert_eq!((after.timeouts, after.retries), (1, 1), "{after:?}");
}
