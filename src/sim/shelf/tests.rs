//! The simulator behind every transport, driven by rackd's own clients over real sockets
//! and pty pairs: the same task runs, a rejected one fails alike, and the same write into
//! a busy slot is caught.

use std::sync::Arc;
use std::time::Duration;

use super::*;
use crate::domain::JobSpec;
use crate::protocols::modbus::{Exception, ModbusClient, ModbusConfig, Transport};
use crate::protocols::{DeviceCode, PlcError, PlcMemory, link, mewtocol, ppi};
use crate::wire::slot::{EXEC_STATE, FAILURE_KIND, encode_body};

fn options(protocol: ShelfProtocol) -> ShelfSimOptions {
    ShelfSimOptions { task_time: Duration::ZERO, ..ShelfSimOptions::for_protocol(protocol) }
}

/// A network simulator and rackd's client for it, opened from the device entry.
async fn over_network(protocol: ShelfProtocol) -> (ShelfSim, Arc<dyn PlcMemory>) {
    let sim = ShelfSim::start("127.0.0.1:0", options(protocol)).await.unwrap();
    let address = sim.local_addr().unwrap().to_string();
    let mut device = sim.link(&address);
    device.timeout = Duration::from_millis(500);
    let plc = link::connect(&device).await.unwrap();
    (sim, plc)
}

/// A serial simulator on one end of a pty pair and rackd's client on the other.
async fn over_pty(protocol: ShelfProtocol) -> (ShelfSim, Arc<dyn PlcMemory>) {
    over_pty_with(options(protocol)).await
}

async fn over_pty_with(options: ShelfSimOptions) -> (ShelfSim, Arc<dyn PlcMemory>) {
    let (a, b) = tokio_serial::SerialStream::pair().expect("pty pair");
    let protocol = options.protocol;
    let sim = ShelfSim::serve_stream(a, options).await.unwrap();
    (sim, client_over(protocol, b))
}

fn client_over(protocol: ShelfProtocol, stream: tokio_serial::SerialStream) -> Arc<dyn PlcMemory> {
    let timeout = Duration::from_millis(500);
    match protocol {
        ShelfProtocol::ModbusRtu => {
            let mut c = ModbusConfig::new(Transport::RtuSerial, "pty");
            c.timeout = timeout;
            Arc::new(ModbusClient::rtu_over_stream(c, stream).unwrap())
        }
        ShelfProtocol::Ppi => {
            let mut c = ppi::PpiConfig::new(ppi::PpiTransport::Serial, "pty");
            c.timeout = timeout;
            Arc::new(ppi::PpiClient::over_stream(c, stream).unwrap())
        }
        ShelfProtocol::Mewtocol => {
            let mut c = mewtocol::MewtocolConfig::new(mewtocol::MewtocolTransport::Serial, "pty");
            c.timeout = timeout;
            Arc::new(mewtocol::MewtocolClient::over_stream(c, stream).unwrap())
        }
        other => panic!("{other} is not a serial protocol"),
    }
}

/// Polls a slot until its state is `want`; the slot's words.
async fn wait_state(plc: &dyn PlcMemory, slot: &crate::protocols::Address, want: u16) -> Vec<u16> {
    let deadline = std::time::Instant::now() + Duration::from_secs(5);
    loop {
        let words = plc.read_words(slot, SLOT_WORDS as u16).await.unwrap();
        if words[EXEC_STATE] == want {
            return words;
        }
        assert!(std::time::Instant::now() < deadline, "slot never reached state {want}: {words:?}");
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
}

/// Hands a task to a free slot as rackd does: task id := 0, the body, then the task id.
async fn hand_over(plc: &dyn PlcMemory, slot: &crate::protocols::Address, id: u16, spec: &JobSpec) {
    let body = encode_body(spec, 3, Some("BOX-9")).unwrap();
    plc.write_words(slot, &[0]).await.unwrap();
    plc.write_words(&plc.word_address(slot, 1), &body).await.unwrap();
    plc.write_words(slot, &[id]).await.unwrap();
}

/// The same story on every transport: a store runs, a retrieve from an empty place is
/// rejected, a write into the failed slot is a violation and acknowledging it is not.
async fn exercise(sim: &ShelfSim, plc: &dyn PlcMemory) {
    let what = sim.protocol();
    let base = plc.parse_address(sim.base()).unwrap();
    let slot2 = plc.word_address(&base, sim.stride() as u32);
    let at = Location { aisle: 1, row: 2, bay: 3, level: 4, position: 1 };
    hand_over(plc, &slot2, 41, &JobSpec::Store { to: at }).await;
    let words = wait_state(plc, &slot2, 2).await;
    assert_eq!((words[0], words[FAILURE_KIND]), (41, 0), "{what}");
    assert_eq!(sim.inventory().get(&at).map(String::as_str), Some("BOX-9"), "{what}");
    assert_eq!(sim.slot(2), Some(words), "{what}: the sim's view of the slot");
    assert_eq!((sim.received(41), sim.finished()), (1, (1, 0)), "{what}");

    let empty = Location { position: 2, ..at };
    hand_over(plc, &slot2, 42, &JobSpec::Retrieve { from: empty }).await;
    let words = wait_state(plc, &slot2, 3).await;
    assert_eq!(words[FAILURE_KIND], 2, "{what}: rejected, the PLC's data disagrees");
    assert_eq!(sim.violations(), 0, "{what}: a finished slot is free");
    plc.write_words(&plc.word_address(&slot2, 1), &[1]).await.unwrap();
    assert_eq!(sim.violations(), 1, "{what}: writing a failed task's body breaks rule 1");
    plc.write_words(&slot2, &[0]).await.unwrap();
    assert_eq!(sim.violations(), 1, "{what}: acknowledging a failure does not");
    assert_eq!(sim.finished(), (1, 1), "{what}");
}

#[tokio::test]
async fn every_network_transport_runs_tasks_and_catches_violations() {
    for protocol in [
        ShelfProtocol::ModbusUdp,
        ShelfProtocol::ModbusTcp,
        ShelfProtocol::ModbusRtuTcp,
        ShelfProtocol::PpiTcp,
        ShelfProtocol::MewtocolTcp,
    ] {
        let (sim, plc) = over_network(protocol).await;
        exercise(&sim, plc.as_ref()).await;
        sim.shutdown().await;
    }
}

#[tokio::test]
async fn every_serial_transport_runs_tasks_and_catches_violations_on_a_pty() {
    for protocol in [ShelfProtocol::ModbusRtu, ShelfProtocol::Ppi, ShelfProtocol::Mewtocol] {
        let (sim, plc) = over_pty(protocol).await;
        exercise(&sim, plc.as_ref()).await;
        sim.shutdown().await;
    }
}

#[tokio::test]
async fn a_serial_simulator_opens_its_device_by_path() {
    let (master, slave) = tokio_serial::SerialStream::pair().expect("pty pair");
    let path = tokio_serial::SerialPort::name(&slave).expect("a pty slave has a path");
    let sim = ShelfSim::start(&path, options(ShelfProtocol::Ppi)).await.unwrap();
    drop(slave); // the simulator holds its own descriptor
    let plc = client_over(ShelfProtocol::Ppi, master);
    exercise(&sim, plc.as_ref()).await;
    assert!(sim.local_addr().is_none());
}

#[tokio::test]
async fn the_rtu_slave_answers_like_an_s7_1200() {
    let (sim, plc) = over_pty(ShelfProtocol::ModbusRtu).await;
    assert_eq!(sim.base(), "4x0", "MB_HOLD_REG from 40001");
    let at = |t: &str| plc.parse_address(t).unwrap();
    let last = plc.read_words(&at("4x5965"), 35).await.unwrap();
    assert_eq!(last.len(), 35, "slot 60 is the data block's end");
    let past = plc.read_words(&at("4x5966"), 35).await;
    assert!(matches!(past, Err(PlcError::Device(DeviceCode::Modbus(Exception(2))))), "{past:?}");
    let written = plc.write_words(&at("4x6000"), &[1]).await;
    assert!(matches!(written, Err(PlcError::Device(DeviceCode::Modbus(Exception(2))))), "{written:?}");
    let inputs = plc.read_words(&at("3x512"), 1).await;
    assert!(
        matches!(inputs, Err(PlcError::Device(DeviceCode::Modbus(Exception(2))))),
        "IW0..IW1022 only: {inputs:?}"
    );
    plc.write_bits(&at("0x8191"), &[true]).await.unwrap();
    assert_eq!(plc.read_bits(&at("0x8191"), 1).await.unwrap(), vec![true], "Q1023.7");

    // Another station on the line gets no answer from this one.
    let (a, b) = tokio_serial::SerialStream::pair().expect("pty pair");
    let mut other = options(ShelfProtocol::ModbusRtu);
    other.unit = Some(7);
    let sim7 = ShelfSim::serve_stream(a, other).await.unwrap();
    let mut c = ModbusConfig::new(Transport::RtuSerial, "pty");
    (c.timeout, c.retries) = (Duration::from_millis(100), 0);
    let to_unit_1 = ModbusClient::rtu_over_stream(c.clone(), b).unwrap();
    assert!(matches!(to_unit_1.read_words(&at("4x0"), 1).await, Err(PlcError::Timeout { .. })));
    assert_eq!(sim7.unit(), 7);
}

#[tokio::test]
async fn link_faults_apply_from_the_start_and_change_at_run_time() {
    for protocol in [ShelfProtocol::ModbusTcp, ShelfProtocol::PpiTcp, ShelfProtocol::MewtocolTcp] {
        let mut o = options(protocol);
        o.faults.drop_rate = 1.0;
        let sim = ShelfSim::start("127.0.0.1:0", o).await.unwrap();
        let mut device = sim.link(&sim.local_addr().unwrap().to_string());
        (device.timeout, device.retries) = (Duration::from_millis(400), 0);
        let plc = link::connect(&device).await.unwrap();
        let base = plc.parse_address(sim.base()).unwrap();
        assert!(matches!(plc.read_words(&base, 1).await, Err(PlcError::Timeout { .. })), "{protocol}");
        sim.set_faults(Faults { delay: Duration::from_millis(5), ..Faults::default() });
        assert_eq!(plc.read_words(&base, 1).await.unwrap(), vec![0], "{protocol}");
        sim.shutdown().await;
    }
}

#[tokio::test]
async fn the_fail_rate_fails_tasks_with_kind_one_on_every_family() {
    for protocol in [ShelfProtocol::ModbusUdp, ShelfProtocol::PpiTcp, ShelfProtocol::MewtocolTcp] {
        let sim = ShelfSim::start("127.0.0.1:0", ShelfSimOptions { fail_rate: 1.0, ..options(protocol) })
            .await
            .unwrap();
        let device = sim.link(&sim.local_addr().unwrap().to_string());
        let plc = link::connect(&device).await.unwrap();
        let slot1 = plc.parse_address(sim.base()).unwrap();
        let to = Location { aisle: 1, row: 1, bay: 1, level: 1, position: 1 };
        hand_over(plc.as_ref(), &slot1, 5, &JobSpec::Store { to }).await;
        let words = wait_state(plc.as_ref(), &slot1, 3).await;
        assert_eq!(words[FAILURE_KIND], 1, "{protocol}: a PLC fault");
        assert!(sim.inventory().is_empty(), "{protocol}");
        sim.shutdown().await;
    }
}

#[tokio::test]
async fn a_ppi_write_repeated_after_a_lost_response_is_no_violation() {
    // Tasks take longer than the client's timeout: the retry finds the task running.
    let slow = ShelfSimOptions { task_time: Duration::from_millis(900), ..options(ShelfProtocol::Ppi) };
    let (sim, plc) = over_pty_with(slow).await;
    let faults = sim.faults();
    let slot1 = plc.parse_address(sim.base()).unwrap();
    let to = Location { aisle: 1, row: 1, bay: 2, level: 1, position: 1 };
    let body = encode_body(&JobSpec::Store { to }, 1, None).unwrap();
    plc.write_words(&plc.word_address(&slot1, 1), &body).await.unwrap();
    // The PLC writes the task id, then the response to the master's poll is lost: the
    // client's retry writes the same id into what is now a busy slot.
    faults.push(crate::protocols::faults::Fault::Drop);
    plc.write_words(&slot1, &[9]).await.unwrap();
    assert_eq!(faults.requests_seen(), 3, "body, id, the same id again");
    assert_eq!(sim.slot(1).map(|w| w[EXEC_STATE]), Some(1), "the retry reached a running task");
    wait_state(plc.as_ref(), &slot1, 2).await;
    assert_eq!((sim.violations(), sim.received(9)), (0, 1));
}

#[tokio::test]
async fn settings_that_cannot_fit_are_refused() {
    let refused = |protocol, base: &str, stride| {
        let o = ShelfSimOptions { base: Some(base.into()), stride: Some(stride), ..options(protocol) };
        async move { ShelfSim::start("127.0.0.1:0", o).await.err().map(|e| e.kind()) }
    };
    use std::io::ErrorKind::InvalidInput;
    assert_eq!(refused(ShelfProtocol::ModbusUdp, "4x60000", 100).await, Some(InvalidInput));
    assert_eq!(refused(ShelfProtocol::ModbusTcp, "DT0", 100).await, Some(InvalidInput));
    assert_eq!(refused(ShelfProtocol::PpiTcp, "VW1000", 100).await, Some(InvalidInput), "12 KB of V");
    assert_eq!(refused(ShelfProtocol::PpiTcp, "MW0", 50).await, Some(InvalidInput));
    assert_eq!(refused(ShelfProtocol::MewtocolTcp, "DT30000", 100).await, Some(InvalidInput));
    assert_eq!(refused(ShelfProtocol::MewtocolTcp, "DT0", 20).await, Some(InvalidInput), "stride < 35");
    let serial_on_udp = ShelfSim::serve_stream(tokio::io::empty(), options(ShelfProtocol::ModbusUdp)).await;
    assert!(serial_on_udp.is_err());
}
