//! Diagnostics (08) beyond the echo: the server's counters read by the client over UDP
//! and RTU over TCP, cleared by 000A; and Read FIFO queue (24).

use rackd::protocols::PlcError;
use rackd::protocols::modbus::pdu::{
    DIAG_BUS_COMM_ERRORS, DIAG_BUS_EXCEPTIONS, DIAG_BUS_MESSAGES, DIAG_CLEAR_COUNTERS,
    DIAG_DIAGNOSTIC_REGISTER, DIAG_SERVER_MESSAGES, DIAG_SERVER_NO_RESPONSES,
};
use rackd::protocols::modbus::server::ServerOptions;
use rackd::protocols::modbus::{ModbusClient, Request, Transport};

use super::{client, config, serve};

#[tokio::test]
async fn counters_count_messages_exceptions_and_silence() {
    let (_server, _bank, address) = serve(Transport::Udp, ServerOptions::default()).await;
    let plc = client(Transport::Udp, &address, 300, 0).await;
    plc.call(&Request::ReadHoldingRegisters { address: 0, count: 1 }).await.unwrap();
    assert_eq!(plc.diagnostic(DIAG_CLEAR_COUNTERS).await.unwrap(), 0);
    assert_eq!(plc.diagnostic(DIAG_BUS_MESSAGES).await.unwrap(), 1, "itself, after the clear");
    for _ in 0..3 {
        plc.call(&Request::ReadHoldingRegisters { address: 0, count: 4 }).await.unwrap();
    }
    // An exception (a read of 0 registers), and a request to another unit.
    assert!(plc.call_unchecked(&Request::ReadHoldingRegisters { address: 0, count: 0 }).await.is_err());
    let mut other = config(Transport::Udp, &address, 100, 0);
    other.unit = 7;
    let other = ModbusClient::connect(other).await.unwrap();
    assert!(other.call(&Request::ReadCoils { address: 0, count: 1 }).await.is_err());
    // So far: 000B, 3 reads, the exception, the other unit's request.
    assert_eq!(plc.diagnostic(DIAG_BUS_EXCEPTIONS).await.unwrap(), 1);
    assert_eq!(
        plc.diagnostic(DIAG_BUS_MESSAGES).await.unwrap(),
        8,
        "000B 3 reads 1 exception 1 other 000D 000B"
    );
    assert_eq!(
        plc.diagnostic(DIAG_SERVER_MESSAGES).await.unwrap(),
        8,
        "the same less the other unit's, plus 000E"
    );
    assert_eq!(plc.diagnostic(DIAG_SERVER_NO_RESPONSES).await.unwrap(), 0);
    assert_eq!(plc.diagnostic(DIAG_BUS_COMM_ERRORS).await.unwrap(), 0);
    assert_eq!(plc.diagnostic(DIAG_DIAGNOSTIC_REGISTER).await.unwrap(), 0);
    assert!(matches!(plc.diagnostic(0x0001).await, Err(PlcError::OutOfRange(_))));
}

#[tokio::test]
async fn rtu_broadcasts_are_counted_as_unanswered() {
    let (_server, _bank, address) = serve(Transport::RtuOverTcp, ServerOptions::default()).await;
    let mut c = config(Transport::RtuOverTcp, &address, 300, 0);
    c.unit = 0;
    let broadcast = ModbusClient::connect(c).await.unwrap();
    let plc = client(Transport::RtuOverTcp, &address, 300, 0).await;
    plc.diagnostic(DIAG_CLEAR_COUNTERS).await.unwrap();
    broadcast.call(&Request::WriteSingleRegister { address: 1, value: 2 }).await.unwrap();
    // The broadcast is not answered; give the server time to take it before asking.
    let mut unanswered = 0;
    for _ in 0..50 {
        unanswered = plc.diagnostic(DIAG_SERVER_NO_RESPONSES).await.unwrap();
        if unanswered == 1 {
            break;
        }
        tokio::time::sleep(std::time::Duration::from_millis(10)).await;
    }
    assert_eq!(unanswered, 1);
}

/// Read FIFO queue (24) against the bank: the count register at the pointer, then the
/// queue, over TCP and RTU over TCP; more than 31 is exception 03.
#[tokio::test]
async fn fifo_queues_are_read_from_the_bank() {
    use rackd::protocols::DeviceCode;
    use rackd::protocols::modbus::Exception;
    for transport in [Transport::Tcp, Transport::RtuOverTcp] {
        let (_server, bank, address) = serve(transport, ServerOptions::default()).await;
        bank.set_holding(0x04DE, &[2, 0x01B8, 0x1284, 0x9999]);
        let plc = client(transport, &address, 300, 0).await;
        assert_eq!(plc.read_fifo_queue(0x04DE).await.unwrap(), vec![0x01B8, 0x1284], "{transport:?}");
        bank.set_holding(0x04DE, &[0]);
        assert_eq!(plc.read_fifo_queue(0x04DE).await.unwrap(), Vec::<u16>::new());
        bank.set_holding(0x04DE, &[32]);
        let err = plc.read_fifo_queue(0x04DE).await.unwrap_err();
        assert!(
            matches!(err, PlcError::Device(DeviceCode::Modbus(Exception::ILLEGAL_DATA_VALUE))),
            "{err:?}"
        );
    }
}
