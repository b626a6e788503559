//! Frames found in a byte stream, for the protocols whose frames carry no length up front
//! (MEWTOCOL ends a frame with CR, PPI with an end byte after a length that may be noise):
//! what a protocol's scanner says of the input buffered so far ([`Scan`]), and the decoder
//! a [`super::StreamLink`] reads frames with, made from that scanner ([`Scanner`]). The
//! simulators' servers loop over [`Scan`] themselves, as they answer what they find.

use tokio_util::bytes::{Buf, BytesMut};
use tokio_util::codec::Decoder;

use super::AttemptError;

/// The result of looking for a frame in buffered input.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Scan<F, E> {
    /// A frame ends at `end` (exclusive); the bytes before it are dropped with it.
    Found {
        /// Bytes consumed, the frame's last one included.
        end: usize,
        /// The frame.
        frame: F,
    },
    /// The bytes up to `end` are not a frame (the error says why); drop them and scan again.
    Bad {
        /// Bytes to drop.
        end: usize,
        /// Why they are not a frame.
        error: E,
    },
    /// No whole frame yet; the first `discard` bytes are noise and may be dropped.
    NeedMore {
        /// Bytes before the first possible frame.
        discard: usize,
    },
}

/// A decoder of frames that a protocol's `scan` finds: each whole frame, or the bytes that
/// turned out not to be one as an error, consumed either way; noise before a possible frame
/// is dropped while it waits for more.
pub(crate) struct Scanner<F, E> {
    scan: fn(&[u8]) -> Scan<F, E>,
}

impl<F, E> Scanner<F, E> {
    /// The decoder of the frames `scan` finds.
    pub(crate) fn new(scan: fn(&[u8]) -> Scan<F, E>) -> Self {
        Scanner { scan }
    }
}

impl<F, E> Decoder for Scanner<F, E> {
    type Item = Result<F, E>;
    type Error = AttemptError;

    fn decode(&mut self, src: &mut BytesMut) -> Result<Option<Self::Item>, AttemptError> {
        Ok(match (self.scan)(src) {
            Scan::Found { end, frame } => {
                src.advance(end);
                Some(Ok(frame))
            }
            Scan::Bad { end, error } => {
                src.advance(end);
                Some(Err(error))
            }
            Scan::NeedMore { discard } => {
                src.advance(discard);
                None
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Frames of this test: `[` … `]`, anything else before `[` is noise, `[[` is bad.
    fn brackets(buf: &[u8]) -> Scan<Vec<u8>, &'static str> {
        let Some(start) = buf.iter().position(|&b| b == b'[') else {
            return Scan::NeedMore { discard: buf.len() };
        };
        match buf[start + 1..].iter().position(|&b| b == b'[' || b == b']') {
            Some(i) if buf[start + 1 + i] == b']' => {
                Scan::Found { end: start + i + 2, frame: buf[start + 1..start + 1 + i].to_vec() }
            }
            Some(_) => Scan::Bad { end: start + 1, error: "nested" },
            None => Scan::NeedMore { discard: start },
        }
    }

    #[test]
    fn frames_errors_and_noise_are_consumed() {
        let mut scanner = Scanner::new(brackets);
        let mut buf = BytesMut::from(&b"xx[ab]y[[c]z["[..]);
        assert_eq!(scanner.decode(&mut buf).unwrap(), Some(Ok(b"ab".to_vec())));
        assert_eq!(scanner.decode(&mut buf).unwrap(), Some(Err("nested")));
        assert_eq!(scanner.decode(&mut buf).unwrap(), Some(Ok(b"c".to_vec())));
        assert_eq!(scanner.decode(&mut buf).unwrap(), None);
        assert_eq!(&buf[..], b"[", "the noise before a possible frame is dropped, the frame kept");
        buf.extend_from_slice(b"d]");
        assert_eq!(scanner.decode(&mut buf).unwrap(), Some(Ok(b"d".to_vec())));
        assert!(buf.is_empty());
    }
}
