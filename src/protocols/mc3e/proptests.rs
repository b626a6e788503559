//! Property tests of the codec: what one side encodes, the other decodes back; arbitrary
//! bytes never panic a decoder or the server's handler.

use std::sync::Mutex;

use proptest::prelude::*;

use super::bank::Bank;
use super::device::{Device, MAX_DEVICE_NUMBER};
use super::frame::Route;
use super::handler;
use super::request::{Command, Request};
use super::response::{ErrorInfo, Outcome, Response};
use super::scattered::Block;
use super::type_name::TypeName;

fn route() -> impl Strategy<Value = Route> {
    (any::<u8>(), any::<u8>(), any::<u16>(), any::<u8>())
        .prop_map(|(network, pc, module_io, station)| Route { network, pc, module_io, station })
}

fn device() -> impl Strategy<Value = Device> {
    prop::sample::select(Device::ALL.to_vec())
}

fn bit_device() -> impl Strategy<Value = Device> {
    prop::sample::select(Device::ALL.into_iter().filter(|d| d.is_bit()).collect::<Vec<_>>())
}

fn word_device() -> impl Strategy<Value = Device> {
    prop::sample::select(Device::ALL.into_iter().filter(|d| !d.is_bit()).collect::<Vec<_>>())
}

fn command() -> impl Strategy<Value = Command> {
    let start = 0..=MAX_DEVICE_NUMBER;
    prop_oneof![
        (device(), start.clone(), any::<u16>()).prop_map(|(device, start, count)| Command::ReadWords {
            device,
            start,
            count
        }),
        (bit_device(), start.clone(), any::<u16>()).prop_map(|(device, start, count)| Command::ReadBits {
            device,
            start,
            count
        }),
        (device(), start.clone(), prop::collection::vec(any::<u16>(), 0..1000))
            .prop_map(|(device, start, values)| Command::WriteWords { device, start, values }),
        (bit_device(), start.clone(), prop::collection::vec(any::<bool>(), 0..2000))
            .prop_map(|(device, start, values)| Command::WriteBits { device, start, values }),
        Just(Command::ReadTypeName),
        (
            prop::collection::vec((device(), start.clone()), 0..100),
            prop::collection::vec((device(), start.clone()), 0..100)
        )
            .prop_map(|(words, dwords)| Command::RandomRead { words, dwords }),
        (
            prop::collection::vec((word_device(), start.clone(), any::<u16>()), 0..60),
            prop::collection::vec((bit_device(), start, any::<u16>()), 0..60)
        )
            .prop_map(|(words, bits)| Command::ReadBlocks {
                words: words
                    .into_iter()
                    .map(|(device, start, points)| Block { device, start, points })
                    .collect(),
                bits: bits
                    .into_iter()
                    .map(|(device, start, points)| Block { device, start, points })
                    .collect(),
            }),
    ]
}

fn outcome() -> impl Strategy<Value = Outcome> {
    let info = (route(), any::<u16>(), any::<u16>()).prop_map(|(route, command, subcommand)| ErrorInfo {
        route,
        command,
        subcommand,
    });
    prop_oneof![
        prop::collection::vec(any::<u8>(), 0..2000).prop_map(Outcome::Ok),
        (1..=u16::MAX, info).prop_map(|(end_code, info)| Outcome::Failed {
            end_code,
            info: Some(info),
            trailing: vec![]
        }),
        // Anything but 9 bytes after the end code stays trailing data.
        (1..=u16::MAX, prop::collection::vec(any::<u8>(), 0..40).prop_filter("not 9", |t| t.len() != 9))
            .prop_map(|(end_code, trailing)| Outcome::Failed { end_code, info: None, trailing }),
    ]
}

proptest! {
    #[test]
    fn every_request_decodes_back_in_the_server(serial in prop::option::of(any::<u16>()), route in route(), monitor_timer in any::<u16>(), command in command()) {
        let request = Request { serial, route, monitor_timer, command };
        prop_assert_eq!(Request::decode(&request.encode()).ok(), Some(request));
    }

    #[test]
    fn every_response_decodes_back_in_the_client(serial in prop::option::of(any::<u16>()), route in route(), outcome in outcome()) {
        let response = Response { serial, route, outcome };
        prop_assert_eq!(Response::decode(&response.encode()), Ok(response));
    }

    #[test]
    fn arbitrary_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..64)) {
        let _ = Request::decode(&bytes);
        let _ = Response::decode(&bytes);
        let bank = Mutex::new(Bank::with_sizes(&[(Device::D, 100), (Device::M, 100)]));
        if let Some(answer) = handler::answer(&bank, &TypeName::default(), &bytes, None) {
            prop_assert!(Response::decode(&answer.bytes).is_ok());
        }
    }

    #[test]
    fn headers_with_arbitrary_tails_never_panic(tail in prop::collection::vec(any::<u8>(), 0..40), len in any::<u16>()) {
        let mut bytes = vec![0x50, 0x00, 0x00, 0xFF, 0xFF, 0x03, 0x00];
        bytes.extend_from_slice(&len.to_le_bytes());
        bytes.extend_from_slice(&tail);
        let _ = Request::decode(&bytes);
        let bank = Mutex::new(Bank::with_sizes(&[(Device::D, 100), (Device::M, 100)]));
        let _ = handler::answer(&bank, &TypeName::default(), &bytes, None);
        bytes[0] = 0xD0;
        let _ = Response::decode(&bytes);
        let mut four = vec![0x54, 0x00, 0x01, 0x00, 0x00, 0x00];
        four.extend_from_slice(&bytes[2..]);
        let _ = handler::answer(&bank, &TypeName::default(), &four, None);
        four[0] = 0xD4;
        let _ = Response::decode(&four);
    }
}
