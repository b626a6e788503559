//! Read Device Identification (43 / 0x0E): the client against the server over UDP, TCP,
//! RTU over TCP and a pty, paging across several replies, individual access and the
//! exceptions of section 6.21.

use rackd::protocols::modbus::server::ServerOptions;
use rackd::protocols::modbus::{DeviceIdentification, Exception, ObjectId, ReadDeviceIdCode, Transport};
use rackd::protocols::{DeviceCode, PlcError};

use super::{client, pty, serve};

/// Objects that need two replies for the extended category: 4 short ones and four
/// extended ones of 90 bytes (a reply holds 253).
fn objects() -> DeviceIdentification {
    let mut ids = DeviceIdentification::empty();
    for (id, value) in [(0, "ACME Automation"), (1, "AX-200"), (2, "V2.11"), (5, "AX-200 shelf")] {
        ids.set(id, value).unwrap();
    }
    for id in 0x80..0x84u8 {
        ids.set(id, vec![b'a' + (id - 0x80); 90]).unwrap();
    }
    ids
}

#[tokio::test]
async fn categories_are_read_across_pages_on_every_transport() {
    let options = ServerOptions { identification: Some(objects()), ..ServerOptions::default() };
    for transport in [Transport::Udp, Transport::Tcp, Transport::RtuOverTcp] {
        let (server, _bank, address) = serve(transport, options.clone()).await;
        let plc = client(transport, &address, 500, 1).await;
        let basic = plc.read_device_identification(ReadDeviceIdCode::Basic).await.unwrap();
        let texts: Vec<_> = basic.iter().map(|o| (o.kind(), o.text())).collect();
        assert_eq!(
            texts,
            [
                (ObjectId::VendorName, "ACME Automation".to_string()),
                (ObjectId::ProductCode, "AX-200".to_string()),
                (ObjectId::MajorMinorRevision, "V2.11".to_string()),
            ],
            "{transport:?}"
        );
        let regular = plc.read_device_identification(ReadDeviceIdCode::Regular).await.unwrap();
        assert_eq!(
            regular.last().map(|o| (o.kind(), o.text())),
            Some((ObjectId::ModelName, "AX-200 shelf".into()))
        );
        let before = server.stats().replies;
        let extended = plc.read_device_identification(ReadDeviceIdCode::Extended).await.unwrap();
        let ids: Vec<u8> = extended.iter().map(|o| o.id).collect();
        assert_eq!(ids, [0, 1, 2, 5, 0x80, 0x81, 0x82, 0x83], "{transport:?}");
        assert_eq!(extended[7].kind(), ObjectId::Extended(0x83));
        assert_eq!(server.stats().replies - before, 2, "{transport:?}: two pages");
    }
}

#[tokio::test]
async fn individual_access_and_exceptions() {
    let options = ServerOptions { identification: Some(objects()), ..ServerOptions::default() };
    let (_server, _bank, plc) = pty(options, 500, 0);
    let one = plc.read_device_object(0x81).await.unwrap();
    assert_eq!((one.id, one.value.len()), (0x81, 90));
    let err = plc.read_device_object(0x42).await.unwrap_err();
    assert!(matches!(err, PlcError::Device(DeviceCode::Modbus(Exception::ILLEGAL_DATA_ADDRESS))), "{err:?}");
    // A device without the function (here: identification passed to the bank) says 01.
    let options = ServerOptions { identification: None, ..ServerOptions::default() };
    let (_server, _bank, address) = serve(Transport::Tcp, options).await;
    let plc = client(Transport::Tcp, &address, 500, 0).await;
    let err = plc.read_device_identification(ReadDeviceIdCode::Basic).await.unwrap_err();
    assert!(matches!(err, PlcError::Device(DeviceCode::Modbus(Exception::ILLEGAL_FUNCTION))), "{err:?}");
}

/// A bad read device id code (05) and another MEI type, sent raw over UDP: exceptions 03
/// and 01, as section 6.21's state diagram and this server's documentation say.
#[tokio::test]
async fn bad_codes_on_the_wire() {
    let (_server, _bank, address) = serve(Transport::Udp, ServerOptions::default()).await;
    let socket = tokio::net::UdpSocket::bind("127.0.0.1:0").await.unwrap();
    socket.connect(&address).await.unwrap();
    for (pdu, exception) in [([0x2B, 0x0E, 0x05, 0x00], 0x03), ([0x2B, 0x0D, 0x01, 0x00], 0x01)] {
        let mut frame = vec![0, 7, 0, 0, 0, 5, 1];
        frame.extend_from_slice(&pdu);
        socket.send(&frame).await.unwrap();
        let mut buf = [0u8; 64];
        let wait = std::time::Duration::from_secs(2);
        let n = tokio::time::timeout(wait, socket.recv(&mut buf)).await.unwrap().unwrap();
        assert_eq!(&buf[..n], &[0, 7, 0, 0, 0, 3, 1, 0xAB, exception]);
    }
    // rackd's own objects answer by default.
    let plc = client(Transport::Udp, &address, 500, 0).await;
    let basic = plc.read_device_identification(ReadDeviceIdCode::Basic).await.unwrap();
    assert_eq!(basic[0].text(), "rackd");
}
