//! A capture turned into the device's script: rackd's requests in order, each with the
//! replies the device gave it (every frame received until rackd's next request, stale and
//! dropped ones included, each with its delay after the request).
//!
//! Over TCP both directions are cut into frames again by the dialect's length fields: a
//! recorder keeps what each read returned, and a frame may lie across two reads or two
//! frames in one. Frames the device sent before rackd's first request answer nothing and
//! are left out (counted).

use std::net::SocketAddr;
use std::time::Duration;

use super::dialect::Dialect;
use crate::capture::{Capture, Direction, Link, Transport};

/// One frame the device sent, as the answer (or part of it) to a request.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Reply {
    /// How long after the request it was received.
    pub after: Duration,
    /// Its bytes as recorded.
    pub bytes: Vec<u8>,
}

/// One request of rackd's, with what the device did about it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Recorded {
    /// When, since the recording's first request.
    pub at: Duration,
    /// The bytes as recorded.
    pub bytes: Vec<u8>,
    /// The bytes as compared (the dialect's id zeroed).
    pub key: Vec<u8>,
    /// The request only reads.
    pub read: bool,
    /// A write naming one place: where its data begins ([`Dialect::data_at`]).
    pub data_at: Option<usize>,
    /// What the device sent until rackd's next request; empty: no answer.
    pub replies: Vec<Reply>,
}

/// The device's side of a recorded conversation.
#[derive(Clone, Debug)]
pub struct Script {
    /// UDP or TCP.
    pub transport: Transport,
    /// Where the device was.
    pub device: SocketAddr,
    /// The protocol, as the replay knows it.
    pub dialect: Dialect,
    /// rackd's requests, in order.
    pub requests: Vec<Recorded>,
    /// Frames the device sent before any request (not replayed).
    pub unsolicited: usize,
}

/// Why a capture cannot be replayed.
#[derive(Debug, thiserror::Error)]
pub enum ScriptError {
    /// A serial capture: the replay serves UDP and TCP.
    #[error("the capture is of serial line {0}: the replay serves UDP and TCP captures")]
    Serial(String),
    /// rackd sent nothing in the capture.
    #[error("the capture holds no request of rackd's")]
    NoRequest,
}

impl Script {
    /// The script of `capture`.
    pub fn new(capture: &Capture) -> Result<Script, ScriptError> {
        let (transport, device) = match &capture.link {
            Link::Ip { transport, remote, .. } => (*transport, *remote),
            Link::Serial { port, .. } => return Err(ScriptError::Serial(port.clone())),
        };
        let first =
            capture.frames.iter().find(|f| f.direction == Direction::Sent).ok_or(ScriptError::NoRequest)?;
        // The first request may be cut over two TCP reads: the dialect is told from the
        // start of rackd's stream.
        let sent = capture.frames.iter().filter(|f| f.direction == Direction::Sent);
        let head: Vec<u8> = sent.flat_map(|f| f.bytes.iter().copied()).take(64).collect();
        let dialect = Dialect::detect(&head);
        let start = first.time_us;
        let since = |us: u64| Duration::from_micros(us.saturating_sub(start));
        let mut script = Script { transport, device, dialect, requests: Vec::new(), unsolicited: 0 };
        // Bytes of a TCP stream not yet a whole frame: rackd's, the device's.
        let (mut sent, mut received) = (Vec::new(), Vec::new());
        for f in &capture.frames {
            let frames = match (transport, f.direction) {
                (Transport::Udp, _) => vec![f.bytes.to_vec()],
                (Transport::Tcp, Direction::Sent) => cut(dialect, &mut sent, &f.bytes),
                (Transport::Tcp, Direction::Received) => cut(dialect, &mut received, &f.bytes),
            };
            let at = since(f.time_us);
            for bytes in frames {
                match f.direction {
                    Direction::Sent => script.requests.push(Recorded {
                        at,
                        key: dialect.key(&bytes),
                        read: dialect.is_read(&bytes),
                        data_at: dialect.data_at(&bytes),
                        bytes,
                        replies: Vec::new(),
                    }),
                    Direction::Received => match script.requests.last_mut() {
                        Some(r) => r.replies.push(Reply { after: at.saturating_sub(r.at), bytes }),
                        None => script.unsolicited += 1,
                    },
                }
            }
        }
        Ok(script)
    }
}

/// Appends `chunk` to `pending` and takes the whole frames off its front.
fn cut(dialect: Dialect, pending: &mut Vec<u8>, chunk: &[u8]) -> Vec<Vec<u8>> {
    pending.extend_from_slice(chunk);
    let mut out = Vec::new();
    while let Some(n) = dialect.frame_len(pending) {
        out.push(pending.drain(..n).collect());
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::capture::{Frame, SerialProtocol};

    const READ: [u8; 21] =
        [0x50, 0, 0, 0xFF, 0xFF, 3, 0, 0x0C, 0, 0x10, 0, 1, 4, 0, 0, 0xE8, 3, 0, 0xA8, 2, 0];
    const ANSWER: [u8; 15] = [0xD0, 0, 0, 0xFF, 0xFF, 3, 0, 6, 0, 0, 0, 1, 0, 2, 0];

    fn tcp(frames: Vec<Frame>) -> Capture {
        let link = Link::Ip {
            transport: Transport::Tcp,
            local: "127.0.0.1:40000".parse().unwrap(),
            remote: "127.0.0.1:8000".parse().unwrap(),
        };
        Capture { link, frames }
    }

    #[test]
    fn tcp_frames_cut_or_joined_become_whole_requests_and_replies() {
        let two_answers = [&ANSWER[..], &ANSWER].concat();
        let capture = tcp(vec![
            Frame::new(Direction::Received, 500, ANSWER.to_vec()),
            Frame::new(Direction::Sent, 1_000, READ[..5].to_vec()),
            Frame::new(Direction::Sent, 2_000, READ[5..].to_vec()),
            Frame::new(Direction::Received, 3_000, two_answers[..20].to_vec()),
            Frame::new(Direction::Received, 9_000, two_answers[20..].to_vec()),
            Frame::new(Direction::Sent, 10_000, READ.to_vec()),
        ]);
        let s = Script::new(&capture).unwrap();
        assert_eq!((s.dialect, s.unsolicited, s.device.port()), (Dialect::Mc3e, 1, 8000));
        assert_eq!(s.requests.len(), 2);
        let r = &s.requests[0];
        assert_eq!((r.at, r.bytes.as_slice(), r.read), (Duration::from_micros(1_000), &READ[..], true));
        let replies: Vec<(u64, &[u8])> =
            r.replies.iter().map(|p| (p.after.as_micros() as u64, p.bytes.as_slice())).collect();
        assert_eq!(replies, [(1_000, &ANSWER[..]), (7_000, &ANSWER[..])], "the second completed later");
        assert_eq!((s.requests[1].at, s.requests[1].replies.len()), (Duration::from_micros(9_000), 0));
    }

    #[test]
    fn serial_captures_and_captures_without_requests_are_refused() {
        let serial = Capture {
            link: Link::Serial { protocol: SerialProtocol::Mewtocol, port: "ttyS0".into() },
            frames: vec![],
        };
        assert!(matches!(Script::new(&serial), Err(ScriptError::Serial(p)) if p == "ttyS0"));
        let silent = tcp(vec![Frame::new(Direction::Received, 1, ANSWER.to_vec())]);
        assert!(matches!(Script::new(&silent), Err(ScriptError::NoRequest)));
    }
}
