//! What requests and responses share: the route fields, the 9-byte (3E) or 13-byte (4E)
//! header and framing errors; the packing of bit values is in [`super::bits`].
//!
//! ```text
//! subheader(2) network(1) pc(1) module_io(2, LE) station(1) data_length(2, LE) | data...
//! ```
//! `data_length` counts every byte after itself. Requests start `50 00`, responses `D0 00`.
//!
//! A 4E frame is a 3E frame with a serial number after the subheader:
//! ```text
//! subheader(2) serial(2, LE) 00 00 | network(1) pc(1) module_io(2, LE) station(1) data_length(2, LE) | data...
//! ```
//! Requests start `54 00`, responses `D4 00`; the response echoes the request's serial so a
//! client can tell replies apart (layout as in pymcprotocol's `type4e.py` and the MC protocol
//! manual's 4E frame chapter). The two fixed bytes after the serial are sent as `00 00` and
//! not checked on decode (the manual gives them no meaning).

/// The subheader of a 3E binary request.
pub const REQUEST_SUBHEADER: [u8; 2] = [0x50, 0x00];
/// The subheader of a 3E binary response.
pub const RESPONSE_SUBHEADER: [u8; 2] = [0xD0, 0x00];
/// Bytes before the data: subheader, route and data length.
pub const HEADER_LEN: usize = 9;
/// The subheader of a 4E binary request.
pub const REQUEST_SUBHEADER_4E: [u8; 2] = [0x54, 0x00];
/// The subheader of a 4E binary response.
pub const RESPONSE_SUBHEADER_4E: [u8; 2] = [0xD4, 0x00];
/// Bytes before the data of a 4E frame: subheader, serial, `00 00`, route and data length.
pub const HEADER_LEN_4E: usize = 13;

pub use super::bits::{bit_bytes, pack_bits, unpack_bits};

/// Which frame a client sends: 3E (no serial number) or 4E (a serial number the reply
/// echoes). Servers answer both.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum FrameKind {
    /// Subheader `50 00`.
    #[default]
    E3,
    /// Subheader `54 00` with a serial number.
    E4,
}

/// Which way a frame goes: it decides the subheaders (`50`/`54` or `D0`/`D4`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Direction {
    /// Client to PLC.
    Request,
    /// PLC to client.
    Response,
}

impl Direction {
    fn subheaders(self) -> ([u8; 2], [u8; 2]) {
        match self {
            Direction::Request => (REQUEST_SUBHEADER, REQUEST_SUBHEADER_4E),
            Direction::Response => (RESPONSE_SUBHEADER, RESPONSE_SUBHEADER_4E),
        }
    }
}

/// The header of a 3E frame (`serial` None) or a 4E frame (`serial` Some).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Header {
    /// The 4E serial number; None for a 3E frame.
    pub serial: Option<u16>,
    /// The route.
    pub route: Route,
    /// The declared data length (bytes after the header).
    pub length: usize,
}

impl Header {
    /// Bytes of this header: 9 (3E) or 13 (4E).
    pub fn size(&self) -> usize {
        header_size(self.serial)
    }
}

/// Bytes of a header with this serial (None: 3E).
pub fn header_size(serial: Option<u16>) -> usize {
    if serial.is_some() { HEADER_LEN_4E } else { HEADER_LEN }
}

/// The header size announced by a frame's first two bytes (9 for 3E, 13 for 4E), or why not.
pub fn header_size_of(bytes: &[u8], direction: Direction) -> Result<usize, FrameError> {
    let (e3, e4) = direction.subheaders();
    match bytes.get(..2) {
        None => Err(FrameError::Truncated { need: 2, have: bytes.len() }),
        Some(s) if s == e3 => Ok(HEADER_LEN),
        Some(s) if s == e4 => Ok(HEADER_LEN_4E),
        Some(s) => Err(FrameError::Subheader([s[0], s[1]])),
    }
}

/// The header of a 3E or 4E frame going `direction`, or why not. Used by stream readers:
/// once this succeeds, the frame is `header.size() + header.length` bytes.
pub fn parse_any_header(bytes: &[u8], direction: Direction) -> Result<Header, FrameError> {
    let size = header_size_of(bytes, direction)?;
    if bytes.len() < size {
        return Err(FrameError::Truncated { need: size, have: bytes.len() });
    }
    let (serial, rest) = match size {
        HEADER_LEN_4E => (Some(u16::from_le_bytes([bytes[2], bytes[3]])), &bytes[6..size]),
        _ => (None, &bytes[2..size]),
    };
    let route = Route::decode(rest).ok_or(FrameError::Truncated { need: size, have: bytes.len() })?;
    Ok(Header { serial, route, length: usize::from(u16::from_le_bytes([rest[5], rest[6]])) })
}

/// Checks a whole 3E or 4E frame's header and returns it with the bytes after the length.
pub fn split_any(bytes: &[u8], direction: Direction) -> Result<(Header, &[u8]), FrameError> {
    let header = parse_any_header(bytes, direction)?;
    let data = &bytes[header.size()..];
    if data.len() != header.length {
        return Err(FrameError::Length { declared: header.length, actual: data.len() });
    }
    Ok((header, data))
}

/// Writes a 3E or 4E header with a placeholder length; [`finish_frame`] fills it in.
pub(crate) fn start_any(
    direction: Direction,
    serial: Option<u16>,
    route: &Route,
    capacity: usize,
) -> Vec<u8> {
    let (e3, e4) = direction.subheaders();
    let mut out = Vec::with_capacity(HEADER_LEN_4E + capacity);
    match serial {
        None => out.extend_from_slice(&e3),
        Some(serial) => {
            out.extend_from_slice(&e4);
            out.extend_from_slice(&serial.to_le_bytes());
            out.extend_from_slice(&[0, 0]);
        }
    }
    route.encode(&mut out);
    out.extend_from_slice(&[0, 0]);
    out
}

/// Largest point count of one batch read or write in word units (words, or 16-bit
/// groups of a bit device), per the Q-series MC protocol manual for 3E frames.
pub const MAX_WORD_POINTS: u16 = 960;
/// Largest point count of one batch read or write in bit units (binary code), per the same
/// manual (ASCII code allows fewer; rackd speaks binary only).
pub const MAX_BIT_POINTS: u16 = 7168;

/// The route to the target station; a response echoes its request's route.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Route {
    /// Network number (`00` = the local network).
    pub network: u8,
    /// PC number (`FF` = the station the Ethernet module is in).
    pub pc: u8,
    /// Request destination module I/O number (`03FF` = the own station's CPU).
    pub module_io: u16,
    /// Request destination module station number (`00`).
    pub station: u8,
}

impl Default for Route {
    /// The route to the CPU of the station the Ethernet module sits in: 00/FF/03FF/00.
    fn default() -> Self {
        Route { network: 0x00, pc: 0xFF, module_io: 0x03FF, station: 0x00 }
    }
}

impl Route {
    /// Appends the 5 route bytes.
    pub fn encode(&self, out: &mut Vec<u8>) {
        out.push(self.network);
        out.push(self.pc);
        out.extend_from_slice(&self.module_io.to_le_bytes());
        out.push(self.station);
    }

    /// Reads the 5 route bytes; `bytes` must hold at least 5.
    pub(crate) fn decode(bytes: &[u8]) -> Option<Route> {
        match bytes {
            [network, pc, io_lo, io_hi, station, ..] => Some(Route {
                network: *network,
                pc: *pc,
                module_io: u16::from_le_bytes([*io_lo, *io_hi]),
                station: *station,
            }),
            _ => None,
        }
    }
}

/// Why bytes are not a well-formed 3E binary frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum FrameError {
    /// Fewer bytes than the frame needs.
    #[error("truncated frame: need {need} bytes, have {have}")]
    Truncated {
        /// Bytes needed.
        need: usize,
        /// Bytes present.
        have: usize,
    },
    /// The subheader is not the expected one.
    #[error("unexpected subheader {0:02X?}")]
    Subheader([u8; 2]),
    /// The data length field disagrees with the bytes present.
    #[error("data length field says {declared}, {actual} bytes follow")]
    Length {
        /// What the length field says.
        declared: usize,
        /// What is there.
        actual: usize,
    },
}

/// The route and the declared data length of a frame starting with `subheader`, or why not.
///
/// Used by stream readers: once this succeeds, the frame is `HEADER_LEN + length` bytes.
pub fn parse_header(bytes: &[u8], subheader: [u8; 2]) -> Result<(Route, usize), FrameError> {
    if bytes.len() < HEADER_LEN {
        return Err(FrameError::Truncated { need: HEADER_LEN, have: bytes.len() });
    }
    if bytes[..2] != subheader {
        return Err(FrameError::Subheader([bytes[0], bytes[1]]));
    }
    let route = Route::decode(&bytes[2..7]).ok_or(FrameError::Truncated { need: 7, have: bytes.len() })?;
    Ok((route, usize::from(u16::from_le_bytes([bytes[7], bytes[8]]))))
}

/// Checks a whole frame's header and returns its route and the bytes after the length field.
pub fn split_frame(bytes: &[u8], subheader: [u8; 2]) -> Result<(Route, &[u8]), FrameError> {
    let (route, declared) = parse_header(bytes, subheader)?;
    let data = &bytes[HEADER_LEN..];
    if data.len() != declared {
        return Err(FrameError::Length { declared, actual: data.len() });
    }
    Ok((route, data))
}

/// Sets the data length field of a frame begun by [`start_any`]. Data
/// longer than 65535 bytes cannot be framed: callers keep requests within the point limits,
/// so this saturates rather than panics.
pub(crate) fn finish_frame(out: &mut [u8]) {
    let size = if matches!(out[0], 0x54 | 0xD4) { HEADER_LEN_4E } else { HEADER_LEN };
    let len = u16::try_from(out.len().saturating_sub(size)).unwrap_or(u16::MAX);
    out[size - 2..size].copy_from_slice(&len.to_le_bytes());
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn route_default_is_00_ff_03ff_00() {
        let mut out = Vec::new();
        Route::default().encode(&mut out);
        assert_eq!(out, [0x00, 0xFF, 0xFF, 0x03, 0x00]);
    }

    #[test]
    fn four_e_header_carries_the_serial() {
        // 4E layout as pymcprotocol's type4e.py builds it: 54 00, serial LE, 00 00, route.
        let mut out = start_any(Direction::Request, Some(0x1234), &Route::default(), 0);
        out.extend_from_slice(&[0x10, 0x00]);
        finish_frame(&mut out);
        assert_eq!(
            out,
            [0x54, 0x00, 0x34, 0x12, 0x00, 0x00, 0x00, 0xFF, 0xFF, 0x03, 0x00, 0x02, 0x00, 0x10, 0x00]
        );
        let (header, data) = split_any(&out, Direction::Request).unwrap();
        assert_eq!(header, Header { serial: Some(0x1234), route: Route::default(), length: 2 });
        assert_eq!(data, [0x10, 0x00]);
        assert_eq!(split_any(&out, Direction::Response), Err(FrameError::Subheader([0x54, 0x00])));
        assert!(matches!(
            parse_any_header(&out[..12], Direction::Request),
            Err(FrameError::Truncated { .. })
        ));
        let three = [0xD0, 0x00, 0x00, 0xFF, 0xFF, 0x03, 0x00, 0x00, 0x00];
        assert_eq!(parse_any_header(&three, Direction::Response).unwrap().serial, None);
        assert_eq!(header_size_of(&[0xD4, 0x00], Direction::Response), Ok(HEADER_LEN_4E));
        assert!(header_size_of(&[0xD4], Direction::Response).is_err());
    }

    #[test]
    fn header_errors() {
        assert_eq!(
            parse_header(&[0x50, 0x00, 0x00], REQUEST_SUBHEADER),
            Err(FrameError::Truncated { need: 9, have: 3 })
        );
        let frame = [0x54, 0x00, 0x00, 0xFF, 0xFF, 0x03, 0x00, 0x00, 0x00];
        assert_eq!(parse_header(&frame, REQUEST_SUBHEADER), Err(FrameError::Subheader([0x54, 0x00])));
        let frame = [0x50, 0x00, 0x00, 0xFF, 0xFF, 0x03, 0x00, 0x03, 0x00, 0x01];
        assert_eq!(
            split_frame(&frame, REQUEST_SUBHEADER),
            Err(FrameError::Length { declared: 3, actual: 1 })
        );
    }
}
