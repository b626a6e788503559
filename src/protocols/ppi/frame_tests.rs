//! Byte tests of PPI framing against spec/ppi.md (seed 004).

use proptest::prelude::*;

use super::*;

/// Parses the spec's hex notation (`68 1B 1B ...`).
pub(crate) fn hex(text: &str) -> Vec<u8> {
    text.split_whitespace().map(|b| u8::from_str_radix(b, 16).unwrap()).collect()
}

const READ_VB100: &str =
    "68 1B 1B 68 02 00 6C 32 01 00 00 00 00 00 0E 00 00 04 01 12 0A 10 02 00 03 00 01 84 00 03 20 8D 16";
/// The seed's second read example, whose FCS is wrong (the bytes sum to 7F).
const BAD_FCS: &str =
    "68 1B 1B 68 02 00 6C 32 01 00 00 00 00 00 0E 00 00 04 01 12 0A 10 04 00 01 00 01 84 00 0D 08 84 16";

#[test]
fn poll_frame_of_the_seed() {
    let mut out = Vec::new();
    encode_short(&mut out, 2, 0, FC_POLL);
    assert_eq!(out, hex("10 02 00 5C 5E 16"));
    assert_eq!(scan(&out), Scan::Found { end: 6, frame: Frame::Short { da: 2, sa: 0, fc: FC_POLL } });
}

#[test]
fn long_frame_round_trips_the_seed_read() {
    let bytes = hex(READ_VB100);
    let Scan::Found { end, frame: Frame::Long { da, sa, fc, payload } } = scan(&bytes) else {
        panic!("{:?}", scan(&bytes));
    };
    assert_eq!((end, da, sa, fc), (33, 2, 0, FC_READ));
    let mut again = Vec::new();
    encode_long(&mut again, da, sa, fc, &payload);
    assert_eq!(again, bytes);
}

#[test]
fn the_seed_frame_with_a_wrong_fcs_is_rejected() {
    let bytes = hex(BAD_FCS);
    assert_eq!(fcs(&bytes[4..31]), 0x7F);
    assert_eq!(scan(&bytes), Scan::Bad { end: 1, error: FrameError::BadFcs });
}

#[test]
fn acks_noise_and_broken_frames() {
    assert_eq!(scan(&[0x00, ACK]), Scan::Found { end: 2, frame: Frame::Ack(ACK) });
    assert_eq!(scan(&[ACK_ALT]), Scan::Found { end: 1, frame: Frame::Ack(ACK_ALT) });
    assert_eq!(scan(&[1, 2, 3]), Scan::NeedMore { discard: 3 });
    assert_eq!(scan(&[9, 0x68, 0x1B]), Scan::NeedMore { discard: 1 });
    assert_eq!(scan(&hex("68 1B 1C 68")), Scan::Bad { end: 1, error: FrameError::BadHeader });
    assert_eq!(scan(&hex("68 1B 1C")), Scan::Bad { end: 1, error: FrameError::BadHeader });
    assert_eq!(scan(&hex("68 02 02 68 00 00 00 00")), Scan::Bad { end: 1, error: FrameError::BadHeader });
    assert_eq!(scan(&hex("68 03 03 69")), Scan::Bad { end: 1, error: FrameError::BadHeader });
    assert_eq!(scan(&hex("10 02 00 5C 5F 16")), Scan::Bad { end: 1, error: FrameError::BadFcs });
    assert_eq!(scan(&hex("10 02 00 5C 5E 17")), Scan::Bad { end: 1, error: FrameError::BadEnd });
    assert_eq!(scan(&hex("10 02 00 5C")), Scan::NeedMore { discard: 0 });
    let mut wrong_end = hex(READ_VB100);
    wrong_end[32] = 0x17;
    assert_eq!(scan(&wrong_end), Scan::Bad { end: 1, error: FrameError::BadEnd });
    // A truncated frame waits for more.
    assert_eq!(scan(&hex(READ_VB100)[..20]), Scan::NeedMore { discard: 0 });
}

proptest! {
    #[test]
    fn long_frames_round_trip(da: u8, sa: u8, fc: u8, payload in prop::collection::vec(any::<u8>(), 0..252)) {
        let mut out = Vec::new();
        encode_long(&mut out, da, sa, fc, &payload);
        let expected = Frame::Long { da, sa, fc, payload };
        prop_assert_eq!(scan(&out), Scan::Found { end: out.len(), frame: expected });
    }

    #[test]
    fn random_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..300)) {
        let mut rest = &bytes[..];
        // Scanning always makes progress or asks for more.
        loop {
            match scan(rest) {
                Scan::Found { end, .. } | Scan::Bad { end, .. } => {
                    prop_assert!(end > 0 && end <= rest.len());
                    rest = &rest[end..];
                }
                Scan::NeedMore { discard } => {
                    prop_assert!(discard <= rest.len());
                    break;
                }
            }
        }
    }
}
