//! What the replay must know of a protocol, told from the recording's first request: where
//! a frame ends in a TCP stream, which bytes legitimately differ from run to run (an id
//! the master picks), and whether a request only reads.
//!
//! - MC 3E (subheader `50 00`, replies `D0 00`): no id; length at bytes 7..9 counts what
//!   follows it; command at 11..13.
//! - MC 4E (`54 00`, replies `D4 00`): the serial number at 2..4; length at 11..13;
//!   command at 15..17.
//! - Modbus TCP/UDP (an MBAP header: protocol id 0, a length that fits): the transaction
//!   id at 0..2; length at 4..6; function code at 7.
//! - Anything else: compared byte for byte, never reframed (a TCP read is one frame), and
//!   every request counts as a write (matched strictly in order).
//!
//! A write that names one place and then its data (MC batch write 1401; Modbus functions
//! 5, 6, 15, 16) is split there ([`Dialect::data_at`]): the replay then knows what the
//! device holds after it, so that a recorded write of what the device already holds is
//! not waited for (the matcher's "Writes already in place").

/// The protocol of a recording, as far as the replay cares.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Dialect {
    /// MC protocol 3E binary.
    Mc3e,
    /// MC protocol 4E binary (3E with a serial number).
    Mc4e,
    /// Modbus with an MBAP header (TCP or UDP).
    Mbap,
    /// Bytes the replay does not know.
    Other,
}

impl Dialect {
    /// The dialect of a recording whose requests start with `head` (the first request, or
    /// the start of rackd's stream).
    pub fn detect(head: &[u8]) -> Dialect {
        let request = head;
        let mbap = request.len() >= 8
            && request[2..4] == [0, 0]
            && (2..=request.len() - 6).contains(&usize::from(u16::from_be_bytes([request[4], request[5]])));
        match request {
            [0x50, 0x00, ..] if request.len() >= 13 => Dialect::Mc3e,
            [0x54, 0x00, ..] if request.len() >= 17 => Dialect::Mc4e,
            _ if mbap => Dialect::Mbap,
            _ => Dialect::Other,
        }
    }

    /// The length of the frame at the start of `buf`: `Some` once it is all there (the
    /// whole of `buf` for bytes that do not look like a frame of the dialect, so that
    /// nothing waits forever), `None` while more is needed.
    pub fn frame_len(self, buf: &[u8]) -> Option<usize> {
        if buf.is_empty() {
            return None;
        }
        let (head, len_at, first) = match self {
            Dialect::Mc3e => (9, 7, [0x50, 0xD0]),
            Dialect::Mc4e => (13, 11, [0x54, 0xD4]),
            Dialect::Mbap => (6, 4, [0, 0]),
            Dialect::Other => return Some(buf.len()),
        };
        if self != Dialect::Mbap && !first.contains(&buf[0]) {
            return Some(buf.len());
        }
        if buf.len() < head {
            return None;
        }
        let len = match self {
            Dialect::Mbap => u16::from_be_bytes([buf[len_at], buf[len_at + 1]]),
            _ => u16::from_le_bytes([buf[len_at], buf[len_at + 1]]),
        };
        let total = head + usize::from(len);
        (buf.len() >= total).then_some(total)
    }

    /// Where the frame's id lies, if the dialect has one and the frame is long enough.
    fn id_range(self, frame: &[u8]) -> Option<std::ops::Range<usize>> {
        let range = match self {
            Dialect::Mc4e => 2..4,
            Dialect::Mbap => 0..2,
            Dialect::Mc3e | Dialect::Other => return None,
        };
        (frame.len() >= range.end + 2).then_some(range)
    }

    /// The frame's id (MC 4E serial, Modbus transaction), if any.
    pub fn id(self, frame: &[u8]) -> Option<[u8; 2]> {
        self.id_range(frame).map(|r| [frame[r.start], frame[r.start + 1]])
    }

    /// The frame as compared: its id zeroed.
    pub fn key(self, frame: &[u8]) -> Vec<u8> {
        self.with_id(frame, [0, 0])
    }

    /// The frame with its id (if it has one) set to `id`.
    pub fn with_id(self, frame: &[u8], id: [u8; 2]) -> Vec<u8> {
        let mut out = frame.to_vec();
        if let Some(r) = self.id_range(frame) {
            out[r].copy_from_slice(&id);
        }
        out
    }

    /// Where a write's data begins, for a write that names one place before its data (the
    /// bytes before it, ids zeroed, name the place): MC batch write (1401: head, device
    /// code and count, then the data); Modbus write single coil or register (5, 6: unit,
    /// function, address, then the value) and multiple (15, 16: after the byte count).
    /// `None` for reads, other writes and frames too short to hold data.
    pub fn data_at(self, request: &[u8]) -> Option<usize> {
        let at = match self {
            Dialect::Mc3e | Dialect::Mc4e => {
                let command = if self == Dialect::Mc3e { 11 } else { 15 };
                (request.get(command..command + 2)? == [0x01, 0x14]).then_some(command + 10)?
            }
            Dialect::Mbap => match request.get(7)? {
                5 | 6 => 10,
                15 | 16 => 13,
                _ => return None,
            },
            Dialect::Other => return None,
        };
        (request.len() > at).then_some(at)
    }

    /// Whether the request only reads (its answer may change while it stays the same).
    pub fn is_read(self, request: &[u8]) -> bool {
        let command = |at: usize| request.get(at..at + 2).map(|c| u16::from_le_bytes([c[0], c[1]]));
        match self {
            // Batch, random and block reads (04xx), the CPU model (0101), buffer memory
            // (0613), the loopback test (0619).
            Dialect::Mc3e | Dialect::Mc4e => {
                let at = if self == Dialect::Mc3e { 11 } else { 15 };
                command(at).is_some_and(|c| c >> 8 == 0x04 || [0x0101, 0x0613, 0x0619].contains(&c))
            }
            // Coils, inputs, holding and input registers, diagnostics and the event
            // counters, report server id, FIFO queue, device identification.
            Dialect::Mbap => {
                request.get(7).is_some_and(|f| [1, 2, 3, 4, 7, 8, 11, 12, 17, 24, 43].contains(f))
            }
            Dialect::Other => false,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The spec's example: read D1000, 2 words.
    const READ_3E: [u8; 21] =
        [0x50, 0, 0, 0xFF, 0xFF, 3, 0, 0x0C, 0, 0x10, 0, 1, 4, 0, 0, 0xE8, 3, 0, 0xA8, 2, 0];
    /// The spec's answer to a write.
    const WRITTEN_3E: [u8; 11] = [0xD0, 0, 0, 0xFF, 0xFF, 3, 0, 2, 0, 0, 0];

    fn read_4e(serial: u16) -> Vec<u8> {
        let s = serial.to_le_bytes();
        [&[0x54, 0, s[0], s[1], 0, 0][..], &READ_3E[2..]].concat()
    }

    /// Read holding registers 0..2, transaction `tid`.
    fn read_mbap(tid: u16) -> Vec<u8> {
        let t = tid.to_be_bytes();
        vec![t[0], t[1], 0, 0, 0, 6, 1, 3, 0, 0, 0, 2]
    }

    #[test]
    fn the_first_request_tells_the_dialect() {
        assert_eq!(Dialect::detect(&READ_3E), Dialect::Mc3e);
        assert_eq!(Dialect::detect(&read_4e(9)), Dialect::Mc4e);
        assert_eq!(Dialect::detect(&read_mbap(7)), Dialect::Mbap);
        assert_eq!(Dialect::detect(b"%01#RCSX0000**\r"), Dialect::Other);
        assert_eq!(Dialect::detect(&[0x50, 0]), Dialect::Other, "too short for 3E");
        assert_eq!(Dialect::detect(&[0, 1, 0, 0, 0, 9, 1, 3]), Dialect::Other, "MBAP length past the end");
        assert_eq!(Dialect::detect(&[read_mbap(1), read_mbap(2)].concat()), Dialect::Mbap, "two joined");
    }

    #[test]
    fn frames_are_cut_by_their_length_fields() {
        let two = [&READ_3E[..], &READ_3E].concat();
        assert_eq!(Dialect::Mc3e.frame_len(&two), Some(21));
        assert_eq!(Dialect::Mc3e.frame_len(&READ_3E[..20]), None);
        assert_eq!(Dialect::Mc3e.frame_len(&READ_3E[..5]), None);
        assert_eq!(Dialect::Mc3e.frame_len(&WRITTEN_3E), Some(11));
        assert_eq!(Dialect::Mc3e.frame_len(b"junk"), Some(4), "not a frame: taken whole");
        assert_eq!(Dialect::Mc4e.frame_len(&read_4e(1)), Some(25));
        assert_eq!(Dialect::Mbap.frame_len(&[read_mbap(1), read_mbap(2)].concat()), Some(12));
        assert_eq!(Dialect::Mbap.frame_len(&read_mbap(1)[..7]), None);
        assert_eq!(Dialect::Other.frame_len(b"abc"), Some(3));
        assert_eq!(Dialect::Other.frame_len(b""), None);
    }

    #[test]
    fn ids_are_left_out_of_the_comparison_and_copied_into_replies() {
        assert_eq!(Dialect::Mc4e.key(&read_4e(1)), Dialect::Mc4e.key(&read_4e(500)));
        assert_eq!(Dialect::Mc4e.id(&read_4e(500)), Some(500u16.to_le_bytes()));
        assert_eq!(Dialect::Mbap.key(&read_mbap(1)), Dialect::Mbap.key(&read_mbap(2)));
        assert_eq!(Dialect::Mbap.with_id(&read_mbap(1), [0, 9]), read_mbap(9));
        assert_eq!(Dialect::Mc3e.key(&READ_3E), READ_3E, "3E has no id");
        assert_eq!(Dialect::Mc3e.id(&READ_3E), None);
        assert_eq!(Dialect::Mbap.id(&[1, 2]), None, "too short to carry one");
    }

    #[test]
    fn reads_are_told_from_writes() {
        assert!(Dialect::Mc3e.is_read(&READ_3E));
        let mut write = READ_3E.to_vec();
        write[11..13].copy_from_slice(&[1, 0x14]);
        assert!(!Dialect::Mc3e.is_read(&write));
        assert!(Dialect::Mc4e.is_read(&read_4e(3)));
        assert!(Dialect::Mbap.is_read(&read_mbap(3)));
        let mut write = read_mbap(3);
        write[7] = 16;
        assert!(!Dialect::Mbap.is_read(&write));
        assert!(!Dialect::Other.is_read(b"%01#RCSX0000**\r"));
        assert!(!Dialect::Mc3e.is_read(&READ_3E[..11]), "cut short: strict order");
    }

    #[test]
    fn writes_that_name_one_place_are_split_before_their_data() {
        // Batch write D0, one word: 1.
        let mut write = READ_3E.to_vec();
        write[11..13].copy_from_slice(&[1, 0x14]);
        write[19..21].copy_from_slice(&[1, 0]);
        write.extend_from_slice(&[1, 0]);
        assert_eq!(Dialect::Mc3e.data_at(&write), Some(21));
        assert_eq!(Dialect::Mc3e.data_at(&READ_3E), None, "a read");
        assert_eq!(Dialect::Mc3e.data_at(&write[..21]), None, "no data");
        let write_4e = [&[0x54, 0, 7, 0, 0, 0][..], &write[2..]].concat();
        assert_eq!(Dialect::Mc4e.data_at(&write_4e), Some(25));
        // Write single register 1 := 3; write multiple registers 0..2 := 1, 2.
        assert_eq!(Dialect::Mbap.data_at(&[0, 1, 0, 0, 0, 6, 1, 6, 0, 1, 0, 3]), Some(10));
        let multiple = [0, 1, 0, 0, 0, 11, 1, 16, 0, 0, 0, 2, 4, 0, 1, 0, 2];
        assert_eq!(Dialect::Mbap.data_at(&multiple), Some(13));
        assert_eq!(Dialect::Mbap.data_at(&read_mbap(1)), None);
        assert_eq!(Dialect::Other.data_at(b"%01#WDD0000000000**\r"), None);
    }
}
