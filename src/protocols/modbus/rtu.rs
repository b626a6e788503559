//! Modbus RTU framing: unit + PDU + CRC-16 (poly 0xA001 reflected, init 0xFFFF, low byte
//! first), frames separated by 3.5 character times of silence.
//!
//! RTU frames carry no length, so a reader works out each frame's length from its function
//! code and byte count ([`super::decode`]). [`scan`] finds the first frame with a valid
//! CRC anywhere in a buffer: bytes before it (line noise, a partial frame from before a
//! timeout) are skipped, which is how readers resynchronise after garbage on the line.

use std::time::Duration;

use super::decode::DecodeError;

/// Smallest RTU frame: unit, function, one byte, CRC.
pub const MIN_FRAME: usize = 4;
/// Largest RTU frame allowed by the specification.
pub const MAX_FRAME: usize = 256;

/// CRC-16/MODBUS of `bytes`.
pub fn crc16(bytes: &[u8]) -> u16 {
    let mut crc: u16 = 0xFFFF;
    for &b in bytes {
        crc ^= u16::from(b);
        for _ in 0..8 {
            crc = if crc & 1 != 0 { (crc >> 1) ^ 0xA001 } else { crc >> 1 };
        }
    }
    crc
}

/// Appends a complete RTU frame to `buf`: unit, `pdu`, CRC low byte first.
pub fn encode(buf: &mut Vec<u8>, unit: u8, pdu: &[u8]) {
    let start = buf.len();
    buf.push(unit);
    buf.extend_from_slice(pdu);
    let crc = crc16(&buf[start..]);
    buf.extend_from_slice(&crc.to_le_bytes());
}

/// True if `frame` (unit + PDU + CRC) ends with the right CRC.
pub fn crc_ok(frame: &[u8]) -> bool {
    frame.len() >= MIN_FRAME && {
        let (body, crc) = frame.split_at(frame.len() - 2);
        crc16(body).to_le_bytes() == [crc[0], crc[1]]
    }
}

/// Which way a frame travels: this decides how its PDU length is worked out.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Direction {
    /// Master to slave.
    Request,
    /// Slave to master.
    Response,
}

/// A frame found by [`scan`]: where it starts in the buffer and how long it is (CRC included).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Found {
    /// Offset of the unit byte.
    pub start: usize,
    /// Frame length, unit and CRC included.
    pub len: usize,
}

impl Found {
    /// The unit byte of the frame in `buf`.
    pub fn unit(&self, buf: &[u8]) -> u8 {
        buf[self.start]
    }

    /// The PDU of the frame in `buf` (without unit and CRC).
    pub fn pdu<'a>(&self, buf: &'a [u8]) -> &'a [u8] {
        &buf[self.start + 1..self.start + self.len - 2]
    }
}

/// The length (unit + PDU + CRC) of a frame starting at `bytes[0]`, if it can be told yet.
fn frame_len(bytes: &[u8], dir: Direction) -> Option<usize> {
    let pdu = bytes.get(1..)?;
    let len: Result<Option<usize>, DecodeError> = match dir {
        Direction::Request => super::decode::request_pdu_len(pdu),
        Direction::Response => super::decode::response_pdu_len(pdu),
    };
    len.ok().flatten().map(|n| n + 3)
}

/// Finds the first complete frame with a valid CRC in `buf`, trying every offset.
pub fn scan(buf: &[u8], dir: Direction) -> Option<Found> {
    (0..buf.len()).find_map(|start| {
        let len = frame_len(&buf[start..], dir)?;
        let frame = buf.get(start..start + len)?;
        crc_ok(frame).then_some(Found { start, len })
    })
}

/// The 3.5-character silence that separates frames at `baud` (11 bits per character), at
/// least 1.75 ms as the specification fixes for rates above 19200 baud.
pub fn silence(baud: u32) -> Duration {
    let floor = Duration::from_micros(1750);
    if baud == 0 {
        return floor;
    }
    Duration::from_micros(38_500_000 / u64::from(baud)).max(floor)
}

#[cfg(test)]
#[path = "rtu_tests.rs"]
mod tests;
