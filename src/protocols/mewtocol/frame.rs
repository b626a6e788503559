//! MEWTOCOL-COM framing: `%` (or `<`) + station + `#`/`$`/`!` + body + BCC + CR.
//!
//! Pure bytes, no I/O. [`scan`] finds frames in a byte stream: noise before a start
//! character is skipped, and a candidate that does not decode is reported with how many
//! bytes to drop, so a real frame after it is still found.
//!
//! The station is two decimal digits (`01`..`99`), or `EE`, Panasonic's global station
//! ("answer whatever your station number", for a computer linked to one PLC). A station is
//! a `u8` everywhere in rackd; the global one is [`GLOBAL_STATION`], 238 = 0xEE, a value no
//! two-digit station can take, written `EE` on the wire.

/// The global station `EE` (238 = 0xEE): every PLC answers it, whatever its own number.
pub const GLOBAL_STATION: u8 = 0xEE;
/// The carriage return ending every frame.
pub const CR: u8 = 0x0D;
/// Longest `%` frame in characters, CR included.
pub const MAX_SHORT: usize = 118;
/// Longest `<` (long) frame in characters, CR included.
pub const MAX_LONG: usize = 2048;
/// Shortest frame: `%01$` + 2 body characters... `%01!` + BCC + CR is 7.
const MIN_FRAME: usize = 7;

/// What a frame carries.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// `#`: a command from the computer.
    Command,
    /// `$`: a normal response.
    Ok,
    /// `!`: an error response (body: 2-digit error code).
    Error,
}

impl Kind {
    fn mark(self) -> u8 {
        match self {
            Kind::Command => b'#',
            Kind::Ok => b'$',
            Kind::Error => b'!',
        }
    }
}

/// What the frame's block check said.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Bcc {
    /// Two hex digits that match.
    Good,
    /// `**`: the sender skipped the check.
    Skipped,
    /// Two hex digits that do not match (carries the computed and received values).
    Wrong {
        /// The BCC computed over the frame.
        computed: u8,
        /// The BCC the frame carries.
        received: u8,
    },
}

/// A decoded frame.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Frame {
    /// `<` (long frame) rather than `%`.
    pub long: bool,
    /// Station number (0..=99), or [`GLOBAL_STATION`] for `EE`.
    pub station: u8,
    /// Command, response or error.
    pub kind: Kind,
    /// The characters between the kind mark and the BCC.
    pub body: Vec<u8>,
    /// The block check.
    pub bcc: Bcc,
}

/// Why bytes from a start character to a CR are not a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum FrameError {
    /// Fewer characters than the smallest frame.
    #[error("frame too short")]
    TooShort,
    /// The station is not two decimal digits nor `EE`.
    #[error("station number is not two decimal digits nor EE")]
    BadStation,
    /// The character after the station is not `#`, `$` or `!`.
    #[error("unknown frame type character")]
    BadKind,
    /// The BCC is neither two hex digits nor `**`.
    #[error("BCC is not two hex digits")]
    BadBcc,
}

/// XOR of every byte: the MEWTOCOL block check code.
pub fn bcc(bytes: &[u8]) -> u8 {
    bytes.iter().fold(0, |acc, b| acc ^ b)
}

/// Appends a whole frame: header, body, BCC (or `**` when `with_bcc` is false) and CR.
pub fn encode(out: &mut Vec<u8>, long: bool, station: u8, kind: Kind, body: &[u8], with_bcc: bool) {
    let start = out.len();
    out.push(if long { b'<' } else { b'%' });
    match station {
        GLOBAL_STATION => out.extend_from_slice(b"EE"),
        n => out.extend_from_slice(format!("{:02}", n % 100).as_bytes()),
    }
    out.push(kind.mark());
    out.extend_from_slice(body);
    if with_bcc {
        let check = bcc(&out[start..]);
        out.extend_from_slice(format!("{check:02X}").as_bytes());
    } else {
        out.extend_from_slice(b"**");
    }
    out.push(CR);
}

/// Decodes one frame: `bytes` runs from the start character to the CR, both included.
pub fn decode(bytes: &[u8]) -> Result<Frame, FrameError> {
    if bytes.len() < MIN_FRAME {
        return Err(FrameError::TooShort);
    }
    let long = bytes[0] == b'<';
    let station = match (bytes[1], bytes[2]) {
        (a @ b'0'..=b'9', b @ b'0'..=b'9') => (a - b'0') * 10 + (b - b'0'),
        (b'E', b'E') => GLOBAL_STATION,
        _ => return Err(FrameError::BadStation),
    };
    let kind = match bytes[3] {
        b'#' => Kind::Command,
        b'$' => Kind::Ok,
        b'!' => Kind::Error,
        _ => return Err(FrameError::BadKind),
    };
    let end = bytes.len() - 3;
    let bcc_chars = &bytes[end..end + 2];
    let bcc = if bcc_chars == b"**" {
        Bcc::Skipped
    } else {
        let text = std::str::from_utf8(bcc_chars).map_err(|_| FrameError::BadBcc)?;
        let received = u8::from_str_radix(text, 16).map_err(|_| FrameError::BadBcc)?;
        if !text.bytes().all(|c| c.is_ascii_hexdigit()) {
            return Err(FrameError::BadBcc);
        }
        let computed = self::bcc(&bytes[..end]);
        if computed == received { Bcc::Good } else { Bcc::Wrong { computed, received } }
    };
    Ok(Frame { long, station, kind, body: bytes[4..end].to_vec(), bcc })
}

/// The result of looking for a frame in buffered input.
pub type Scan = crate::protocols::transport::Scan<Frame, FrameError>;

fn is_start(b: u8) -> bool {
    b == b'%' || b == b'<'
}

/// Looks for the first frame in `buf`.
pub fn scan(buf: &[u8]) -> Scan {
    let Some(start) = buf.iter().position(|&b| is_start(b)) else {
        return Scan::NeedMore { discard: buf.len() };
    };
    let rest = &buf[start..];
    let limit = if rest[0] == b'<' { MAX_LONG } else { MAX_SHORT };
    let next_start = rest[1..].iter().position(|&b| is_start(b)).map(|p| start + 1 + p);
    match rest.iter().take(limit).position(|&b| b == CR) {
        Some(cr) => match decode(&rest[..=cr]) {
            Ok(frame) => Scan::Found { end: start + cr + 1, frame },
            Err(error) => {
                let end = next_start.filter(|&n| n < start + cr).unwrap_or(start + cr + 1);
                Scan::Bad { end, error }
            }
        },
        None if rest.len() >= limit => {
            Scan::Bad { end: next_start.unwrap_or(buf.len()), error: FrameError::TooShort }
        }
        None => Scan::NeedMore { discard: start },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(text: &str) -> Vec<u8> {
        let mut v = text.as_bytes().to_vec();
        v.push(CR);
        v
    }

    #[test]
    fn bcc_of_the_seed_responses() {
        // spec/mewtocol.md, checked against seed 001.
        assert_eq!(bcc(b"%01$RC1"), 0x20);
        assert_eq!(bcc(b"%01$RC0"), 0x21);
        assert_eq!(bcc(b"%01$WC"), 0x14);
    }

    #[test]
    fn encodes_with_and_without_bcc() {
        let mut out = Vec::new();
        encode(&mut out, false, 1, Kind::Ok, b"RC1", true);
        assert_eq!(out, frame("%01$RC120"));
        out.clear();
        encode(&mut out, false, 1, Kind::Command, b"RCSY0001", false);
        assert_eq!(out, frame("%01#RCSY0001**"));
        out.clear();
        encode(&mut out, true, 12, Kind::Ok, b"WC", true);
        assert_eq!(out, frame(&format!("<12$WC{:02X}", bcc(b"<12$WC"))));
    }

    #[test]
    fn decodes_good_skipped_and_wrong_bcc() {
        let f = decode(&frame("%01$WC14")).unwrap();
        assert_eq!((f.station, f.kind, f.body.as_slice(), f.bcc), (1, Kind::Ok, &b"WC"[..], Bcc::Good));
        assert_eq!(decode(&frame("%01#RCSY0001**")).unwrap().bcc, Bcc::Skipped);
        assert_eq!(decode(&frame("%01$WC15")).unwrap().bcc, Bcc::Wrong { computed: 0x14, received: 0x15 });
        assert_eq!(
            decode(&frame("%01!40")).unwrap().bcc,
            Bcc::Wrong { computed: bcc(b"%01!"), received: 0x40 }
        );
    }

    /// The global station: Panasonic's MEWTOCOL-COM command reference (FP series
    /// programming manuals, "station number EE: global") has `%EE#RT**` read the PLC's
    /// status from whichever PLC is on the line, which answers `%EE$RT...`.
    #[test]
    fn the_global_station_ee() {
        let mut out = Vec::new();
        encode(&mut out, false, GLOBAL_STATION, Kind::Command, b"RT", false);
        assert_eq!(out, frame("%EE#RT**"));
        out.clear();
        encode(&mut out, false, GLOBAL_STATION, Kind::Command, b"RDD0010000101", true);
        // XOR by hand: '%'^'#' = 06, 'E'^'E' = 00, 'R'^'D' = 16, 'D' = 44, seven '0' and
        // three '1' = 01: 06 ^ 16 ^ 44 ^ 01 = 55.
        assert_eq!(out, frame("%EE#RDD001000010155"));
        // The PLC's reply is signed EE too: '%'^'$'^'R'^'D' = 17, "6300" = 05 -> 12.
        let f = decode(&frame("%EE$RD630012")).unwrap();
        assert_eq!((f.station, f.kind, f.body.as_slice()), (GLOBAL_STATION, Kind::Ok, &b"RD6300"[..]));
        assert_eq!(f.bcc, Bcc::Good);
        assert_eq!(decode(&frame("%EF$WC14")), Err(FrameError::BadStation));
        assert_eq!(decode(&frame("%E1$WC14")), Err(FrameError::BadStation));
    }

    #[test]
    fn rejects_malformed_frames() {
        assert_eq!(decode(&frame("%01$W")), Err(FrameError::TooShort));
        assert_eq!(decode(&frame("%A1$WC14")), Err(FrameError::BadStation));
        assert_eq!(decode(&frame("%01?WC14")), Err(FrameError::BadKind));
        assert_eq!(decode(&frame("%01$WCG4")), Err(FrameError::BadBcc));
        assert_eq!(decode(&frame("%01$WC+4")), Err(FrameError::BadBcc));
    }

    #[test]
    fn scan_skips_noise_and_broken_candidates() {
        let mut buf = b"xx%0".to_vec();
        buf.extend(frame("%01$WC14"));
        assert_eq!(scan(&buf), Scan::Bad { end: 4, error: FrameError::BadStation });
        let rest = &buf[4..];
        assert!(matches!(scan(rest), Scan::Found { end: 9, .. }));
        assert_eq!(scan(b"ab%01$R"), Scan::NeedMore { discard: 2 });
        assert_eq!(scan(b"abc"), Scan::NeedMore { discard: 3 });
        let long = vec![b'%'; MAX_SHORT + 1];
        assert!(matches!(scan(&long), Scan::Bad { end: 1, .. }));
        let mut no_cr = b"%".to_vec();
        no_cr.extend(vec![b'0'; MAX_SHORT]);
        assert!(matches!(scan(&no_cr), Scan::Bad { error: FrameError::TooShort, .. }));
    }
}
