//! Byte-exact PDU tests (the examples of the Modbus Application Protocol specification),
//! every malformed case, and property tests.

use super::*;
use proptest::prelude::*;

fn hex(s: &str) -> Vec<u8> {
    s.split_whitespace().map(|b| u8::from_str_radix(b, 16).unwrap()).collect()
}

fn enc_req(r: &Request) -> Vec<u8> {
    let mut b = Vec::new();
    r.encode(&mut b);
    b
}

fn enc_resp(r: &Response) -> Vec<u8> {
    let mut b = Vec::new();
    r.encode(&mut b);
    b
}

/// Checks one request/response example both ways.
fn example(req: Request, req_hex: &str, resp: Response, resp_hex: &str) {
    assert_eq!(enc_req(&req), hex(req_hex), "encode {req:?}");
    assert_eq!(Request::decode(&hex(req_hex)), Ok(req.clone()));
    assert_eq!(enc_resp(&resp), hex(resp_hex), "encode {resp:?}");
    assert_eq!(decode_response(&hex(resp_hex), &req), Ok(Ok(resp)));
}

fn bits(bytes: &[u8], n: usize) -> Vec<bool> {
    pdu::unpack_bits(bytes, n)
}

#[test]
fn specification_examples() {
    example(
        Request::ReadCoils { address: 0x13, count: 19 },
        "01 00 13 00 13",
        Response::ReadCoils(bits(&[0xCD, 0x6B, 0x05], 19)),
        "01 03 CD 6B 05",
    );
    example(
        Request::ReadDiscreteInputs { address: 0xC4, count: 22 },
        "02 00 C4 00 16",
        Response::ReadDiscreteInputs(bits(&[0xAC, 0xDB, 0x35], 22)),
        "02 03 AC DB 35",
    );
    example(
        Request::ReadHoldingRegisters { address: 0x6B, count: 3 },
        "03 00 6B 00 03",
        Response::ReadHoldingRegisters(vec![0x022B, 0, 0x64]),
        "03 06 02 2B 00 00 00 64",
    );
    example(
        Request::ReadInputRegisters { address: 8, count: 1 },
        "04 00 08 00 01",
        Response::ReadInputRegisters(vec![10]),
        "04 02 00 0A",
    );
    example(
        Request::WriteSingleCoil { address: 0xAC, value: true },
        "05 00 AC FF 00",
        Response::WriteSingleCoil { address: 0xAC, value: true },
        "05 00 AC FF 00",
    );
    example(
        Request::WriteSingleRegister { address: 1, value: 3 },
        "06 00 01 00 03",
        Response::WriteSingleRegister { address: 1, value: 3 },
        "06 00 01 00 03",
    );
    example(
        Request::WriteMultipleCoils { address: 0x13, values: bits(&[0xCD, 0x01], 10) },
        "0F 00 13 00 0A 02 CD 01",
        Response::WriteMultipleCoils { address: 0x13, count: 10 },
        "0F 00 13 00 0A",
    );
    example(
        Request::WriteMultipleRegisters { address: 1, values: vec![0x000A, 0x0102] },
        "10 00 01 00 02 04 00 0A 01 02",
        Response::WriteMultipleRegisters { address: 1, count: 2 },
        "10 00 01 00 02",
    );
    example(
        Request::Diagnostics { sub_function: 0, data: 0xA537 },
        "08 00 00 A5 37",
        Response::Diagnostics { sub_function: 0, data: 0xA537 },
        "08 00 00 A5 37",
    );
}

#[test]
fn exception_replies_carry_their_code() {
    let req = Request::ReadCoils { address: 0x04A1, count: 1 };
    assert_eq!(decode_response(&hex("81 02"), &req), Ok(Err(Exception::ILLEGAL_DATA_ADDRESS)));
    assert_eq!(Exception(2).meaning(), "illegal data address");
    assert_eq!(decode_response(&hex("81"), &req), Err(DecodeError::Truncated));
    assert_eq!(decode_response(&hex("81 02 00"), &req), Err(DecodeError::TrailingBytes));
    // An exception to another function is not an answer to this request.
    assert_eq!(decode_response(&hex("83 02"), &req), Err(DecodeError::FunctionMismatch));
    let mut out = Vec::new();
    pdu::encode_exception(0x10, 0x03, &mut out);
    assert_eq!(out, hex("90 03"));
}

#[test]
fn malformed_requests() {
    let cases: &[(&str, DecodeError)] = &[
        ("", DecodeError::Empty),
        ("03 00 6B 00", DecodeError::Truncated),
        ("03 00 6B 00 03 00", DecodeError::TrailingBytes),
        ("03 00 00 00 00", DecodeError::BadCount),
        ("03 00 00 00 7E", DecodeError::BadCount),
        ("01 00 00 07 D1", DecodeError::BadCount),
        ("05 00 AC 12 34", DecodeError::BadCoilValue),
        ("07 00 00 00 00", DecodeError::UnknownFunction(7)),
        ("11", DecodeError::UnknownFunction(0x11)),
        ("2B", DecodeError::Truncated),
        ("2B 0D 01 00", DecodeError::BadMeiType),
        ("08 00 01 00 00", DecodeError::UnknownSubFunction),
        ("0F 00 13 00 0A 01 CD", DecodeError::ByteCountMismatch),
        ("0F 00 13 00 0A 02 CD", DecodeError::Truncated),
        ("10 00 01 00 02 04 00 0A 01", DecodeError::Truncated),
        ("10 00 01 00 02 03 00 0A 01", DecodeError::ByteCountMismatch),
        ("10 00 01 00 02 04 00 0A 01 02 03", DecodeError::TrailingBytes),
        ("10 00 01 00 7C F8", DecodeError::BadCount),
    ];
    for (bytes, err) in cases {
        assert_eq!(Request::decode(&hex(bytes)), Err(*err), "{bytes}");
    }
    assert_eq!(DecodeError::UnknownFunction(7).exception(), Exception::ILLEGAL_FUNCTION);
    assert_eq!(DecodeError::BadCount.exception(), Exception::ILLEGAL_DATA_VALUE);
}

#[test]
fn malformed_responses() {
    let read = Request::ReadHoldingRegisters { address: 0x6B, count: 3 };
    assert_eq!(decode_response(&hex(""), &read), Err(DecodeError::Empty));
    assert_eq!(decode_response(&hex("04 06 02 2B 00 00 00 64"), &read), Err(DecodeError::FunctionMismatch));
    assert_eq!(decode_response(&hex("03 04 02 2B 00 00"), &read), Err(DecodeError::ByteCountMismatch));
    assert_eq!(decode_response(&hex("03 06 02 2B 00 00 00"), &read), Err(DecodeError::Truncated));
    assert_eq!(decode_response(&hex("03 06 02 2B 00 00 00 64 00"), &read), Err(DecodeError::TrailingBytes));
    let write = Request::WriteSingleRegister { address: 1, value: 3 };
    assert_eq!(decode_response(&hex("06 00 01 00 04"), &write), Err(DecodeError::EchoMismatch));
    assert_eq!(decode_response(&hex("06 00 02 00 03"), &write), Err(DecodeError::EchoMismatch));
    let multi = Request::WriteMultipleRegisters { address: 1, values: vec![1, 2] };
    assert_eq!(decode_response(&hex("10 00 01 00 03"), &multi), Err(DecodeError::EchoMismatch));
    let coil = Request::WriteSingleCoil { address: 0xAC, value: true };
    assert_eq!(decode_response(&hex("05 00 AC 00 00"), &coil), Err(DecodeError::EchoMismatch));
    assert_eq!(decode_response(&hex("05 00 AC 12 34"), &coil), Err(DecodeError::BadCoilValue));
}

#[test]
fn pdu_lengths_from_prefixes() {
    assert_eq!(request_pdu_len(&hex("")), Ok(None));
    assert_eq!(request_pdu_len(&hex("03")), Ok(Some(5)));
    assert_eq!(request_pdu_len(&hex("10 00 01 00 02")), Ok(None));
    assert_eq!(request_pdu_len(&hex("10 00 01 00 02 04")), Ok(Some(10)));
    assert_eq!(request_pdu_len(&hex("11")), Err(DecodeError::UnknownFunction(0x11)));
    assert_eq!(request_pdu_len(&hex("2B")), Ok(Some(4)));
    assert_eq!(response_pdu_len(&hex("03")), Ok(None));
    assert_eq!(response_pdu_len(&hex("03 06")), Ok(Some(8)));
    assert_eq!(response_pdu_len(&hex("90")), Ok(Some(2)));
    assert_eq!(response_pdu_len(&hex("10")), Ok(Some(5)));
}

fn request_strategy() -> impl Strategy<Value = Request> {
    prop_oneof![
        (any::<u16>(), 1..=pdu::MAX_READ_BITS)
            .prop_map(|(address, count)| Request::ReadCoils { address, count }),
        (any::<u16>(), 1..=pdu::MAX_READ_BITS)
            .prop_map(|(address, count)| Request::ReadDiscreteInputs { address, count }),
        (any::<u16>(), 1..=pdu::MAX_READ_REGISTERS)
            .prop_map(|(address, count)| Request::ReadHoldingRegisters { address, count }),
        (any::<u16>(), 1..=pdu::MAX_READ_REGISTERS)
            .prop_map(|(address, count)| Request::ReadInputRegisters { address, count }),
        (any::<u16>(), any::<bool>())
            .prop_map(|(address, value)| Request::WriteSingleCoil { address, value }),
        (any::<u16>(), any::<u16>())
            .prop_map(|(address, value)| Request::WriteSingleRegister { address, value }),
        (any::<u16>(), prop::collection::vec(any::<bool>(), 1..=pdu::MAX_WRITE_BITS as usize))
            .prop_map(|(address, values)| Request::WriteMultipleCoils { address, values }),
        (any::<u16>(), prop::collection::vec(any::<u16>(), 1..=pdu::MAX_WRITE_REGISTERS as usize))
            .prop_map(|(address, values)| Request::WriteMultipleRegisters { address, values }),
        (prop_oneof![Just(pdu::DIAG_RETURN_QUERY_DATA), Just(pdu::DIAG_CLEAR_COUNTERS)], any::<u16>())
            .prop_map(|(sub_function, data)| Request::Diagnostics { sub_function, data }),
        (pdu::DIAG_BUS_MESSAGES..=pdu::DIAG_SERVER_NO_RESPONSES, Just(0u16))
            .prop_map(|(sub_function, data)| Request::Diagnostics { sub_function, data }),
        any::<u16>().prop_map(|address| Request::ReadFifoQueue { address }),
        (1..=4u8, any::<u8>()).prop_map(|(code, object_id)| Request::ReadDeviceId {
            code: crate::protocols::modbus::ReadDeviceIdCode::from_byte(code).unwrap(),
            object_id
        }),
    ]
}

/// A request and a valid response to it.
fn exchange_strategy() -> impl Strategy<Value = (Request, Response)> {
    request_strategy().prop_flat_map(|req| {
        let resp: BoxedStrategy<Response> = match &req {
            Request::ReadCoils { count, .. } => {
                prop::collection::vec(any::<bool>(), *count as usize).prop_map(Response::ReadCoils).boxed()
            }
            Request::ReadDiscreteInputs { count, .. } => {
                prop::collection::vec(any::<bool>(), *count as usize)
                    .prop_map(Response::ReadDiscreteInputs)
                    .boxed()
            }
            Request::ReadHoldingRegisters { count, .. } => {
                prop::collection::vec(any::<u16>(), *count as usize)
                    .prop_map(Response::ReadHoldingRegisters)
                    .boxed()
            }
            Request::ReadInputRegisters { count, .. } => prop::collection::vec(any::<u16>(), *count as usize)
                .prop_map(Response::ReadInputRegisters)
                .boxed(),
            Request::WriteSingleCoil { address, value } => {
                Just(Response::WriteSingleCoil { address: *address, value: *value }).boxed()
            }
            Request::WriteSingleRegister { address, value } => {
                Just(Response::WriteSingleRegister { address: *address, value: *value }).boxed()
            }
            Request::WriteMultipleCoils { address, values } => {
                Just(Response::WriteMultipleCoils { address: *address, count: values.len() as u16 }).boxed()
            }
            Request::WriteMultipleRegisters { address, values } => {
                Just(Response::WriteMultipleRegisters { address: *address, count: values.len() as u16 })
                    .boxed()
            }
            Request::Diagnostics { sub_function, data } if pdu::diag_echoes(*sub_function) => {
                Just(Response::Diagnostics { sub_function: *sub_function, data: *data }).boxed()
            }
            Request::Diagnostics { sub_function, .. } => {
                let sub_function = *sub_function;
                any::<u16>().prop_map(move |data| Response::Diagnostics { sub_function, data }).boxed()
            }
            Request::ReadFifoQueue { .. } => {
                prop::collection::vec(any::<u16>(), 0..=31).prop_map(Response::ReadFifoQueue).boxed()
            }
            Request::ReadDeviceId { code, .. } => {
                let object = (any::<u8>(), prop::collection::vec(any::<u8>(), 0..40))
                    .prop_map(|(id, value)| crate::protocols::modbus::DeviceObject { id, value });
                let code = *code;
                (any::<u8>(), prop::option::of(any::<u8>()), prop::collection::vec(object, 0..5))
                    .prop_map(move |(conformity, next, objects)| {
                        Response::ReadDeviceId(crate::protocols::modbus::DeviceIdPage {
                            code,
                            conformity,
                            next,
                            objects,
                        })
                    })
                    .boxed()
            }
        };
        (Just(req), resp)
    })
}

proptest! {
    #[test]
    fn requests_round_trip(req in request_strategy()) {
        let bytes = enc_req(&req);
        prop_assert_eq!(request_pdu_len(&bytes), Ok(Some(bytes.len())));
        prop_assert_eq!(Request::decode(&bytes), Ok(req));
    }

    #[test]
    fn responses_round_trip((req, resp) in exchange_strategy()) {
        let bytes = enc_resp(&resp);
        prop_assert_eq!(response_pdu_len(&bytes), Ok(Some(bytes.len())));
        prop_assert_eq!(decode_response(&bytes, &req), Ok(Ok(resp)));
    }

    #[test]
    fn arbitrary_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..300), req in request_strategy()) {
        let _ = Request::decode(&bytes);
        let _ = decode_response(&bytes, &req);
        let _ = request_pdu_len(&bytes);
        let _ = response_pdu_len(&bytes);
    }
}

/// Diagnostics counters (spec V1.1b3 section 6.8: sub-function, then the counter in the
/// data field of the reply; the request's data field is 0000).
#[test]
fn diagnostics_counters_carry_a_value_not_an_echo() {
    let request = Request::decode(&hex("08 00 0B 00 00")).unwrap();
    assert_eq!(request, Request::Diagnostics { sub_function: pdu::DIAG_BUS_MESSAGES, data: 0 });
    assert_eq!(
        decode_response(&hex("08 00 0B 01 2C"), &request),
        Ok(Ok(Response::Diagnostics { sub_function: pdu::DIAG_BUS_MESSAGES, data: 300 }))
    );
    assert_eq!(decode_response(&hex("08 00 0C 01 2C"), &request), Err(DecodeError::EchoMismatch));
    assert_eq!(decode_response(&hex("08 00 0B 01"), &request), Err(DecodeError::Truncated));
    assert_eq!(Request::decode(&hex("08 00 01 00 00")), Err(DecodeError::UnknownSubFunction));
    assert_eq!(Request::decode(&hex("08 00 10 00 00")), Err(DecodeError::UnknownSubFunction));
}

/// Read FIFO queue, the example of spec V1.1b3 section 6.18: pointer 0x04DE, two queued
/// registers 0x01B8 and 0x1284.
#[test]
fn read_fifo_queue_as_in_the_specification() {
    let request = Request::ReadFifoQueue { address: 0x04DE };
    assert_eq!(enc_req(&request), hex("18 04 DE"));
    assert_eq!(Request::decode(&hex("18 04 DE")), Ok(request.clone()));
    assert_eq!(request_pdu_len(&hex("18")), Ok(Some(3)));
    let reply = hex("18 00 06 00 02 01 B8 12 84");
    let values = Response::ReadFifoQueue(vec![0x01B8, 0x1284]);
    assert_eq!(decode_response(&reply, &request), Ok(Ok(values.clone())));
    assert_eq!(enc_resp(&values), reply);
    assert_eq!(response_pdu_len(&reply[..2]), Ok(None));
    assert_eq!(response_pdu_len(&reply[..3]), Ok(Some(9)));
    assert_eq!(
        decode_response(&hex("18 00 06 00 03 01 B8 12 84"), &request),
        Err(DecodeError::ByteCountMismatch)
    );
    assert_eq!(decode_response(&hex("18 00 42 00 20"), &request), Err(DecodeError::BadCount));
    assert_eq!(decode_response(&hex("18 00 06 00 02 01 B8"), &request), Err(DecodeError::Truncated));
    assert_eq!(Request::decode(&hex("18 04 DE 00")), Err(DecodeError::TrailingBytes));
}
