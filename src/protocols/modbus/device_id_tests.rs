//! Read Device Identification byte by byte: the example of the Modbus Application Protocol
//! Specification V1.1b3, section 6.21, paging, the server's answers and malformed replies.

use super::*;
use crate::protocols::modbus::decode::{DecodeError, decode_response, request_pdu_len, response_pdu_len};
use crate::protocols::modbus::pdu::{Request, Response};

fn hex(text: &str) -> Vec<u8> {
    text.split_whitespace().map(|b| u8::from_str_radix(b, 16).unwrap()).collect()
}

fn obj(id: u8, value: &str) -> DeviceObject {
    DeviceObject { id, value: value.as_bytes().to_vec() }
}

/// Section 6.21's example: read the basic objects from 0; the reply carries conformity 01,
/// no more objects, and "Company identification", "Product code XX", "V2.11".
#[test]
fn the_specification_example() {
    let request = Request::ReadDeviceId { code: ReadDeviceIdCode::Basic, object_id: 0 };
    let mut bytes = Vec::new();
    request.encode(&mut bytes);
    assert_eq!(bytes, hex("2B 0E 01 00"));
    assert_eq!(Request::decode(&bytes), Ok(request.clone()));
    assert_eq!(request_pdu_len(&bytes), Ok(Some(4)));
    let mut reply = hex("2B 0E 01 01 00 00 03 00 16");
    reply.extend_from_slice(b"Company identification");
    reply.extend_from_slice(&[0x01, 0x0F]);
    reply.extend_from_slice(b"Product code XX");
    reply.extend_from_slice(&[0x02, 0x05]);
    reply.extend_from_slice(b"V2.11");
    let page = DeviceIdPage {
        code: ReadDeviceIdCode::Basic,
        conformity: 0x01,
        next: None,
        objects: vec![obj(0, "Company identification"), obj(1, "Product code XX"), obj(2, "V2.11")],
    };
    assert_eq!(decode_response(&reply, &request), Ok(Ok(Response::ReadDeviceId(page.clone()))));
    assert_eq!(response_pdu_len(&reply), Ok(Some(reply.len())));
    assert_eq!(response_pdu_len(&reply[..20]), Ok(None));
    let mut encoded = Vec::new();
    Response::ReadDeviceId(page.clone()).encode(&mut encoded);
    assert_eq!(encoded, reply);
    assert_eq!(page.objects[2].kind(), ObjectId::MajorMinorRevision);
    assert_eq!(page.objects[0].text(), "Company identification");
}

#[test]
fn malformed_requests_and_replies_are_typed_errors() {
    assert_eq!(Request::decode(&hex("2B 0E 05 00")), Err(DecodeError::BadReadDeviceIdCode));
    assert_eq!(DecodeError::BadReadDeviceIdCode.exception(), Exception::ILLEGAL_DATA_VALUE);
    assert_eq!(Request::decode(&hex("2B 0D 01 00")), Err(DecodeError::BadMeiType));
    assert_eq!(DecodeError::BadMeiType.exception(), Exception::ILLEGAL_FUNCTION);
    assert_eq!(Request::decode(&hex("2B 0E 01")), Err(DecodeError::Truncated));
    let request = Request::ReadDeviceId { code: ReadDeviceIdCode::Basic, object_id: 0 };
    let bad = |text: &str| decode_response(&hex(text), &request);
    assert_eq!(bad("2B 0D 01 01 00 00 00"), Err(DecodeError::BadMeiType));
    assert_eq!(bad("2B 0E 02 01 00 00 00"), Err(DecodeError::EchoMismatch), "another code");
    assert_eq!(bad("2B 0E 01 01 7F 00 00"), Err(DecodeError::BadMoreFollows));
    assert_eq!(bad("2B 0E 01 01 00 00 01 00 05 41 42"), Err(DecodeError::ObjectOverrun));
    assert_eq!(bad("2B 0E 01 01 00 00 02 00 01 41"), Err(DecodeError::ObjectOverrun), "count > objects");
    assert_eq!(bad("2B 0E 01 01 00 00 01 00 01 41 42"), Err(DecodeError::TrailingBytes));
    assert_eq!(bad("2B 0E 01 01 00"), Err(DecodeError::Truncated));
    assert_eq!(bad("AB 01"), Ok(Err(Exception::ILLEGAL_FUNCTION)));
    let mut huge = hex("2B 0E 03 83 00 00 02 80 F4");
    huge.extend(vec![b'x'; 244]);
    huge.extend_from_slice(&[0x81, 0x10]);
    assert_eq!(response_pdu_len(&huge), Err(DecodeError::ObjectOverrun), "past 253 bytes");
}

#[test]
fn the_server_pages_and_refuses_as_the_specification_says() {
    let mut ids = DeviceIdentification::empty();
    ids.set(0, "ACME").unwrap();
    ids.set(1, "X1").unwrap();
    ids.set(2, "1.0").unwrap();
    ids.set(3, "https://acme.example").unwrap();
    for id in 0x80..0x84u8 {
        ids.set(id, vec![id; 100]).unwrap();
    }
    assert!(ids.set(0x90, vec![0; MAX_OBJECT_LEN + 1]).is_err());
    let basic = ids.answer(ReadDeviceIdCode::Basic, 0).unwrap();
    assert_eq!((basic.conformity, basic.next, basic.objects.len()), (0x83, None, 3));
    let regular = ids.answer(ReadDeviceIdCode::Regular, 0).unwrap();
    assert_eq!(regular.objects.last(), Some(&obj(3, "https://acme.example")));
    // Extended: 4 small objects and two of 102 bytes fit 253; the rest follows from 0x82.
    let first = ids.answer(ReadDeviceIdCode::Extended, 0).unwrap();
    assert_eq!((first.objects.len(), first.next), (6, Some(0x82)));
    let mut bytes = Vec::new();
    first.encode(&mut bytes);
    assert!(bytes.len() <= 253, "{}", bytes.len());
    let second = ids.answer(ReadDeviceIdCode::Extended, 0x82).unwrap();
    assert_eq!((second.objects.len(), second.next), (2, None));
    // An unknown start restarts the stream at 0; individual access to it is exception 02.
    assert_eq!(ids.answer(ReadDeviceIdCode::Basic, 0x42).unwrap(), basic);
    assert_eq!(ids.answer(ReadDeviceIdCode::Individual, 0x42), Err(Exception::ILLEGAL_DATA_ADDRESS));
    let one = ids.answer(ReadDeviceIdCode::Individual, 0x81).unwrap();
    assert_eq!((one.objects.len(), one.objects[0].id, one.next), (1, 0x81, None));
    assert_eq!(DeviceIdentification::default().answer(ReadDeviceIdCode::Basic, 0).unwrap().conformity, 0x82);
}
