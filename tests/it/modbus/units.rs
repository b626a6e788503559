//! Unit ids per framing: over TCP and UDP any unit 0..=255 addresses the device and is
//! answered (the server also takes 0 and 255 as "this device"); over RTU unit 0 is the
//! broadcast and 248..=255 are refused.

use rackd::protocols::PlcError;
use rackd::protocols::modbus::server::ServerOptions;
use rackd::protocols::modbus::{ModbusClient, Request, Response, Transport};

use super::{config, serve};

#[tokio::test]
async fn tcp_and_udp_clients_with_unit_255_and_0_get_replies() {
    for transport in [Transport::Tcp, Transport::Udp] {
        // A server configured as unit 1 answers 0 and 255 as "this device" too.
        let (server, bank, address) = serve(transport, ServerOptions::default()).await;
        bank.set_holding(10, &[4242]);
        for unit in [255, 0, 1] {
            let mut c = config(transport, &address, 300, 1);
            c.unit = unit;
            let plc = ModbusClient::connect(c).await.unwrap();
            let got = plc.call(&Request::ReadHoldingRegisters { address: 10, count: 1 }).await;
            assert_eq!(got.unwrap(), Response::ReadHoldingRegisters(vec![4242]), "{transport:?} unit {unit}");
            let echo = plc.call(&Request::WriteSingleRegister { address: 11, value: unit as u16 }).await;
            assert_eq!(echo.unwrap(), Response::WriteSingleRegister { address: 11, value: unit as u16 });
            assert_eq!(bank.holding(11, 1), vec![unit as u16], "{transport:?} unit {unit}: written");
        }
        assert_eq!(server.stats().replies, 6, "{transport:?}: every request answered");
        // Another unit is someone else's: no reply.
        let mut c = config(transport, &address, 100, 0);
        c.unit = 7;
        let plc = ModbusClient::connect(c).await.unwrap();
        let err = plc.call(&Request::ReadHoldingRegisters { address: 10, count: 1 }).await.unwrap_err();
        assert!(matches!(err, PlcError::Timeout { .. }), "{transport:?}: {err:?}");
    }
}

#[tokio::test]
async fn a_server_configured_as_unit_255_or_200_answers_over_tcp_and_udp() {
    for transport in [Transport::Tcp, Transport::Udp] {
        for unit in [255u8, 200] {
            let options = ServerOptions { unit, ..ServerOptions::default() };
            let (_server, bank, address) = serve(transport, options).await;
            bank.set_holding(0, &[u16::from(unit)]);
            let mut c = config(transport, &address, 300, 1);
            c.unit = unit;
            let plc = ModbusClient::connect(c).await.unwrap();
            let got = plc.call(&Request::ReadHoldingRegisters { address: 0, count: 1 }).await.unwrap();
            assert_eq!(got, Response::ReadHoldingRegisters(vec![u16::from(unit)]), "{transport:?} {unit}");
        }
    }
}

#[tokio::test]
async fn rtu_refuses_units_248_to_255_and_keeps_0_for_broadcasts() {
    for unit in [248, 255] {
        for transport in [Transport::RtuOverTcp, Transport::RtuSerial] {
            let mut c = config(transport, "127.0.0.1:9", 100, 0);
            c.unit = unit;
            let err = ModbusClient::connect(c).await.err().expect("refused");
            assert!(matches!(err, PlcError::OutOfRange(m) if m.contains("1..=247")), "{transport:?} {unit}");
        }
    }
    // Over RTU over TCP a unit-0 read is refused (broadcasts are writes) and nothing is sent.
    let (server, _bank, address) = serve(Transport::RtuOverTcp, ServerOptions::default()).await;
    let mut c = config(Transport::RtuOverTcp, &address, 100, 0);
    c.unit = 0;
    let plc = ModbusClient::connect(c).await.unwrap();
    let err = plc.call(&Request::ReadHoldingRegisters { address: 0, count: 1 }).await.unwrap_err();
    assert!(matches!(err, PlcError::OutOfRange(_)), "{err:?}");
    assert_eq!(server.stats().requests, 0);
}

/// Reads of 0 and of 126 registers (past the limit of 125) reach the device with
/// `call_unchecked`, whose exception 03 surfaces; `call` refuses them before sending.
#[tokio::test]
async fn reads_past_the_limits_reach_the_device_and_surface_its_exception() {
    use rackd::protocols::DeviceCode;
    use rackd::protocols::modbus::Exception;
    let (server, _bank, address) = serve(Transport::Tcp, ServerOptions::default()).await;
    let mut c = config(Transport::Tcp, &address, 300, 0);
    c.unit = 255;
    let plc = ModbusClient::connect(c).await.unwrap();
    for count in [0, 126] {
        let request = Request::ReadHoldingRegisters { address: 0, count };
        assert!(matches!(plc.call(&request).await, Err(PlcError::OutOfRange(_))), "{count}");
        let err = plc.call_unchecked(&request).await.unwrap_err();
        let illegal_value = PlcError::Device(DeviceCode::Modbus(Exception::ILLEGAL_DATA_VALUE));
        assert_eq!(err.to_string(), illegal_value.to_string(), "{count}");
    }
    let bits = Request::ReadCoils { address: 0, count: 2001 };
    assert!(matches!(plc.call_unchecked(&bits).await, Err(PlcError::Device(_))));
    assert_eq!(server.stats().requests, 3, "the refused calls sent nothing");
    let fine = plc.call_unchecked(&Request::ReadHoldingRegisters { address: 0, count: 125 }).await;
    assert!(matches!(fine, Ok(Response::ReadHoldingRegisters(v)) if v.len() == 125));
}
