//! The MBAP framing of Modbus TCP and Modbus UDP: a 7-byte header, then the PDU.
//!
//! ```text
//! transaction id (2) | protocol id (2) = 0 | length (2) = unit + PDU bytes | unit (1) | PDU
//! ```
//!
//! Encoding always writes the standard length, unless a server is told to imitate the
//! shelf PLC ([`LengthField::Zero`]). Decoding tolerates a length of 0 when the caller allows
//! it: over UDP the PDU is then the rest of the datagram; over TCP the stream reader infers
//! the PDU length from its content ([`super::decode::response_pdu_len`]).

use super::decode::DecodeError;

/// Size of the MBAP header, unit id included.
pub const MBAP_LEN: usize = 7;
/// Largest PDU the protocol allows (256-byte RTU frame less unit and CRC).
pub const MAX_PDU_LEN: usize = 253;

/// A decoded MBAP header.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MbapHeader {
    /// Transaction id, echoed by the server.
    pub transaction: u16,
    /// Protocol id, 0 for Modbus.
    pub protocol: u16,
    /// Byte count of unit id + PDU (0 from the shelf PLC).
    pub length: u16,
    /// Unit (station) id.
    pub unit: u8,
}

/// What to write in the length field when encoding.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum LengthField {
    /// The standard value: unit id + PDU byte count.
    #[default]
    Standard,
    /// Always 0, as the shelf PLC answers (for simulators).
    Zero,
}

/// Why an MBAP frame was rejected.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum FrameError {
    /// Fewer than 7 header bytes, or a PDU shorter than the length field says.
    #[error("truncated MBAP frame")]
    Truncated,
    /// The protocol id is not 0: not a Modbus frame.
    #[error("MBAP protocol id is not 0")]
    NotModbus,
    /// The length field is 0 (and that was not allowed), 1, beyond the maximum, or
    /// disagrees with the datagram size.
    #[error("MBAP length field does not fit the frame")]
    BadLength,
    /// The PDU inside did not decode.
    #[error("{0}")]
    Pdu(#[from] DecodeError),
}

impl FrameError {
    /// A fixed description, for [`crate::protocols::PlcError::Malformed`].
    pub fn message(self) -> &'static str {
        match self {
            FrameError::Truncated => "truncated MBAP frame",
            FrameError::NotModbus => "MBAP protocol id is not 0",
            FrameError::BadLength => "MBAP length field does not fit the frame",
            FrameError::Pdu(e) => e.message(),
        }
    }
}

/// Appends a complete MBAP frame to `buf`: header, then `pdu`.
pub fn encode(buf: &mut Vec<u8>, transaction: u16, unit: u8, pdu: &[u8], length: LengthField) {
    let len = match length {
        LengthField::Standard => (pdu.len() + 1) as u16,
        LengthField::Zero => 0,
    };
    buf.extend_from_slice(&transaction.to_be_bytes());
    buf.extend_from_slice(&[0, 0]);
    buf.extend_from_slice(&len.to_be_bytes());
    buf.push(unit);
    buf.extend_from_slice(pdu);
}

/// Decodes the header at the start of `bytes` (which must hold at least 7 bytes).
pub fn decode_header(bytes: &[u8]) -> Result<MbapHeader, FrameError> {
    let h = bytes.get(..MBAP_LEN).ok_or(FrameError::Truncated)?;
    let header = MbapHeader {
        transaction: u16::from_be_bytes([h[0], h[1]]),
        protocol: u16::from_be_bytes([h[2], h[3]]),
        length: u16::from_be_bytes([h[4], h[5]]),
        unit: h[6],
    };
    if header.protocol != 0 {
        return Err(FrameError::NotModbus);
    }
    if header.length == 1 || header.length as usize > MAX_PDU_LEN + 1 {
        return Err(FrameError::BadLength);
    }
    Ok(header)
}

/// Splits a whole datagram into header and PDU. A length field of 0 is accepted only if
/// `allow_length0`; the PDU is then the rest of the datagram. Any other length must match
/// the datagram exactly.
pub fn split_datagram(datagram: &[u8], allow_length0: bool) -> Result<(MbapHeader, &[u8]), FrameError> {
    let header = decode_header(datagram)?;
    let pdu = &datagram[MBAP_LEN..];
    if pdu.is_empty() || pdu.len() > MAX_PDU_LEN {
        return Err(FrameError::BadLength);
    }
    match header.length as usize {
        0 if allow_length0 => Ok((header, pdu)),
        n if n == pdu.len() + 1 => Ok((header, pdu)),
        _ => Err(FrameError::BadLength),
    }
}

#[cfg(test)]
#[path = "frame_tests.rs"]
mod tests;
