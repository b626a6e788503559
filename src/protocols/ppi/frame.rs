//! PPI framing (FDL, as the S7-200 uses it): the long frame `68 LE LE 68 DA SA FC ...
//! FCS 16`, the short frame `10 DA SA FC FCS 16` (the master's poll), and the one-byte
//! acknowledgement `E5` (or `F9`). Pure bytes, no I/O; [`scan`] finds frames in a stream.

/// Start of a long (variable length) frame.
pub const SD2: u8 = 0x68;
/// Start of a short (fixed length, no data) frame.
pub const SD1: u8 = 0x10;
/// End of every frame.
pub const ED: u8 = 0x16;
/// The short acknowledgement.
pub const ACK: u8 = 0xE5;
/// The other acknowledgement byte some devices send.
pub const ACK_ALT: u8 = 0xF9;
/// Function code of the master's poll (request for the response).
pub const FC_POLL: u8 = 0x5C;
/// Function code of a read (and run/stop) request, as the seed sends it.
pub const FC_READ: u8 = 0x6C;
/// Function code of a write request, as the seed sends it.
pub const FC_WRITE: u8 = 0x7C;
/// Function code of the PLC's response frame.
pub const FC_RESPONSE: u8 = 0x08;
/// Smallest LE: DA, SA and FC.
const MIN_LE: usize = 3;

/// A decoded frame.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Frame {
    /// `E5` or `F9`.
    Ack(u8),
    /// A short frame (the poll).
    Short {
        /// Destination address.
        da: u8,
        /// Source address.
        sa: u8,
        /// Function code.
        fc: u8,
    },
    /// A long frame.
    Long {
        /// Destination address.
        da: u8,
        /// Source address.
        sa: u8,
        /// Function code.
        fc: u8,
        /// The bytes after FC (DSAP/SSAP/data: here the S7 PDU).
        payload: Vec<u8>,
    },
}

/// Why bytes at a start delimiter are not a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum FrameError {
    /// The two LE bytes differ, the second `68` is missing, or LE is below 3.
    #[error("bad long-frame header")]
    BadHeader,
    /// The frame check sequence does not match.
    #[error("FCS error")]
    BadFcs,
    /// The end byte is not `16`.
    #[error("missing end delimiter 16")]
    BadEnd,
}

/// The result of looking for a frame in buffered input.
pub type Scan = crate::protocols::transport::Scan<Frame, FrameError>;

/// The frame check sequence: the sum of the bytes, modulo 256.
pub fn fcs(bytes: &[u8]) -> u8 {
    bytes.iter().fold(0u8, |acc, b| acc.wrapping_add(*b))
}

/// Appends a long frame. `payload` must be at most 252 bytes (LE fits one byte).
pub fn encode_long(out: &mut Vec<u8>, da: u8, sa: u8, fc: u8, payload: &[u8]) {
    let le = (MIN_LE + payload.len()).min(255) as u8;
    out.extend_from_slice(&[SD2, le, le, SD2]);
    let body = out.len();
    out.extend_from_slice(&[da, sa, fc]);
    out.extend_from_slice(payload);
    let check = fcs(&out[body..]);
    out.extend_from_slice(&[check, ED]);
}

/// Appends a short frame (`10 DA SA FC FCS 16`).
pub fn encode_short(out: &mut Vec<u8>, da: u8, sa: u8, fc: u8) {
    out.extend_from_slice(&[SD1, da, sa, fc, fcs(&[da, sa, fc]), ED]);
}

/// Looks for the first frame in `buf`. Bytes that start no frame are skipped; a start
/// byte whose frame is broken is dropped alone, so a frame right after it is still found.
pub fn scan(buf: &[u8]) -> Scan {
    let Some(start) = buf.iter().position(|b| matches!(*b, SD2 | SD1 | ACK | ACK_ALT)) else {
        return Scan::NeedMore { discard: buf.len() };
    };
    let b = &buf[start..];
    let bad = |error| Scan::Bad { end: start + 1, error };
    match b[0] {
        ACK | ACK_ALT => Scan::Found { end: start + 1, frame: Frame::Ack(b[0]) },
        SD1 => {
            if b.len() < 6 {
                return Scan::NeedMore { discard: start };
            }
            if fcs(&b[1..4]) != b[4] {
                return bad(FrameError::BadFcs);
            }
            if b[5] != ED {
                return bad(FrameError::BadEnd);
            }
            Scan::Found { end: start + 6, frame: Frame::Short { da: b[1], sa: b[2], fc: b[3] } }
        }
        _ => {
            if b.len() < 4 {
                if b.len() >= 3 && b[1] != b[2] {
                    return bad(FrameError::BadHeader);
                }
                return Scan::NeedMore { discard: start };
            }
            let le = b[1] as usize;
            if b[1] != b[2] || b[3] != SD2 || le < MIN_LE {
                return bad(FrameError::BadHeader);
            }
            let total = 4 + le + 2;
            if b.len() < total {
                return Scan::NeedMore { discard: start };
            }
            if fcs(&b[4..4 + le]) != b[4 + le] {
                return bad(FrameError::BadFcs);
            }
            if b[total - 1] != ED {
                return bad(FrameError::BadEnd);
            }
            let frame = Frame::Long { da: b[4], sa: b[5], fc: b[6], payload: b[7..4 + le].to_vec() };
            Scan::Found { end: start + total, frame }
        }
    }
}

#[cfg(test)]
#[path = "frame_tests.rs"]
pub(crate) mod tests;
