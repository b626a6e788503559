//! 3E binary requests: the four batch commands, encoded by the client, decoded by the server.
//!
//! ```text
//! header(9) | monitoring timer(2) command(2) subcommand(2) | device no(3) code(1) points(2) [data]
//! ```
//! Decoding is split so the server can always answer: [`RequestHeader::decode`] fails only
//! when the bytes are not a 3E request at all; [`Command::decode`] fails with the end code
//! the server should answer.

use super::device::{Device, MAX_DEVICE_NUMBER};
use super::end_code;
use super::frame::{self, FrameError, REQUEST_SUBHEADER, Route};

/// Batch read command.
pub const CMD_BATCH_READ: u16 = 0x0401;
/// Batch write command.
pub const CMD_BATCH_WRITE: u16 = 0x1401;
/// Subcommand: word units (Q/L device specification).
pub const SUB_WORDS: u16 = 0x0000;
/// Subcommand: bit units (Q/L device specification).
pub const SUB_BITS: u16 = 0x0001;

/// What a request asks for.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Command {
    /// Batch read in word units (0401/0000); on a bit device each word is 16 points.
    ReadWords {
        /// The device.
        device: Device,
        /// The first device number.
        start: u32,
        /// Number of words.
        count: u16,
    },
    /// Batch write in word units (1401/0000).
    WriteWords {
        /// The device.
        device: Device,
        /// The first device number.
        start: u32,
        /// The words.
        values: Vec<u16>,
    },
    /// Batch read in bit units (0401/0001).
    ReadBits {
        /// The device.
        device: Device,
        /// The first device number.
        start: u32,
        /// Number of bits.
        count: u16,
    },
    /// Batch write in bit units (1401/0001).
    WriteBits {
        /// The device.
        device: Device,
        /// The first device number.
        start: u32,
        /// The bits.
        values: Vec<bool>,
    },
}

impl Command {
    /// The command and subcommand numbers.
    pub fn numbers(&self) -> (u16, u16) {
        match self {
            Command::ReadWords { .. } => (CMD_BATCH_READ, SUB_WORDS),
            Command::WriteWords { .. } => (CMD_BATCH_WRITE, SUB_WORDS),
            Command::ReadBits { .. } => (CMD_BATCH_READ, SUB_BITS),
            Command::WriteBits { .. } => (CMD_BATCH_WRITE, SUB_BITS),
        }
    }

    /// Bytes of data a normal response to this command carries after the end code.
    pub fn reply_data_len(&self) -> usize {
        match self {
            Command::ReadWords { count, .. } => 2 * usize::from(*count),
            Command::ReadBits { count, .. } => frame::bit_bytes(usize::from(*count)),
            Command::WriteWords { .. } | Command::WriteBits { .. } => 0,
        }
    }

    fn encode(&self, out: &mut Vec<u8>) {
        let head = |out: &mut Vec<u8>, device: &Device, start: u32, count: usize| {
            out.extend_from_slice(&start.to_le_bytes()[..3]);
            out.push(device.code());
            out.extend_from_slice(&u16::try_from(count).unwrap_or(u16::MAX).to_le_bytes());
        };
        match self {
            Command::ReadWords { device, start, count } | Command::ReadBits { device, start, count } => {
                head(out, device, *start, usize::from(*count))
            }
            Command::WriteWords { device, start, values } => {
                head(out, device, *start, values.len());
                values.iter().for_each(|v| out.extend_from_slice(&v.to_le_bytes()));
            }
            Command::WriteBits { device, start, values } => {
                head(out, device, *start, values.len());
                frame::pack_bits(values, out);
            }
        }
    }

    /// Decodes a command from its numbers and the bytes after the subcommand, or returns the
    /// end code a PLC would answer. Point-count limits are not checked here (the server
    /// does, so the codec can carry any count).
    pub fn decode(command: u16, subcommand: u16, data: &[u8]) -> Result<Command, u16> {
        let bits = match (command, subcommand) {
            (CMD_BATCH_READ | CMD_BATCH_WRITE, SUB_WORDS) => false,
            (CMD_BATCH_READ | CMD_BATCH_WRITE, SUB_BITS) => true,
            _ => return Err(end_code::UNKNOWN_COMMAND),
        };
        let [n0, n1, n2, code, c0, c1, rest @ ..] = data else { return Err(end_code::LENGTH_MISMATCH) };
        let start = u32::from_le_bytes([*n0, *n1, *n2, 0]);
        let count = u16::from_le_bytes([*c0, *c1]);
        let device = Device::from_code(*code).ok_or(end_code::DEVICE_NOT_ACCESSIBLE)?;
        if bits && !device.is_bit() {
            return Err(end_code::BAD_REQUEST_CONTENTS);
        }
        let expect_rest = match (command, bits) {
            (CMD_BATCH_READ, _) => 0,
            (_, false) => 2 * usize::from(count),
            (_, true) => frame::bit_bytes(usize::from(count)),
        };
        if rest.len() != expect_rest {
            return Err(end_code::LENGTH_MISMATCH);
        }
        Ok(match (command, bits) {
            (CMD_BATCH_READ, false) => Command::ReadWords { device, start, count },
            (CMD_BATCH_READ, true) => Command::ReadBits { device, start, count },
            (_, false) => Command::WriteWords {
                device,
                start,
                values: rest.chunks_exact(2).map(|w| u16::from_le_bytes([w[0], w[1]])).collect(),
            },
            (_, true) => Command::WriteBits {
                device,
                start,
                values: frame::unpack_bits(rest, usize::from(count)).ok_or(end_code::BAD_REQUEST_DATA)?,
            },
        })
    }
}

/// A whole request.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Request {
    /// Where the request goes.
    pub route: Route,
    /// CPU monitoring timer in units of 250 ms (0 = wait forever).
    pub monitor_timer: u16,
    /// What it asks for.
    pub command: Command,
}

impl Request {
    /// The request's bytes. Device numbers above [`MAX_DEVICE_NUMBER`] are truncated to 3
    /// bytes; the client checks ranges before it gets here.
    pub fn encode(&self) -> Vec<u8> {
        debug_assert!(self.start() <= MAX_DEVICE_NUMBER);
        let mut out = frame::start_frame(REQUEST_SUBHEADER, &self.route, 12 + self.command.reply_data_len());
        out.extend_from_slice(&self.monitor_timer.to_le_bytes());
        let (command, subcommand) = self.command.numbers();
        out.extend_from_slice(&command.to_le_bytes());
        out.extend_from_slice(&subcommand.to_le_bytes());
        self.command.encode(&mut out);
        frame::finish_frame(&mut out);
        out
    }

    fn start(&self) -> u32 {
        match &self.command {
            Command::ReadWords { start, .. }
            | Command::WriteWords { start, .. }
            | Command::ReadBits { start, .. }
            | Command::WriteBits { start, .. } => *start,
        }
    }

    /// Decodes a whole request as the server does.
    pub fn decode(bytes: &[u8]) -> Result<Request, Refusal<'_>> {
        let header = RequestHeader::decode(bytes).map_err(Refusal::Frame)?;
        match Command::decode(header.command, header.subcommand, header.data) {
            Ok(command) => Ok(Request { route: header.route, monitor_timer: header.monitor_timer, command }),
            Err(end_code) => Err(Refusal::Command { header, end_code }),
        }
    }
}

/// Why bytes do not decode to a [`Request`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Refusal<'a> {
    /// Not a whole 3E binary request frame.
    Frame(FrameError),
    /// A well-framed request whose command a PLC refuses with `end_code`.
    Command {
        /// The request's fixed part.
        header: RequestHeader<'a>,
        /// The end code to answer.
        end_code: u16,
    },
}

/// The fixed part of a request, decoded before its command.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RequestHeader<'a> {
    /// The route.
    pub route: Route,
    /// The monitoring timer.
    pub monitor_timer: u16,
    /// The command number.
    pub command: u16,
    /// The subcommand number.
    pub subcommand: u16,
    /// The bytes after the subcommand.
    pub data: &'a [u8],
}

impl<'a> RequestHeader<'a> {
    /// Decodes the header of a whole request frame (length field checked against the bytes).
    pub fn decode(bytes: &'a [u8]) -> Result<RequestHeader<'a>, FrameError> {
        let (route, data) = frame::split_frame(bytes, REQUEST_SUBHEADER)?;
        let [t0, t1, m0, m1, s0, s1, data @ ..] = data else {
            return Err(FrameError::Truncated { need: frame::HEADER_LEN + 6, have: bytes.len() });
        };
        Ok(RequestHeader {
            route,
            monitor_timer: u16::from_le_bytes([*t0, *t1]),
            command: u16::from_le_bytes([*m0, *m1]),
            subcommand: u16::from_le_bytes([*s0, *s1]),
            data,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn req(command: Command) -> Request {
        Request { route: Route::default(), monitor_timer: 0x10, command }
    }

    #[test]
    fn seed_read_d1000_two_words() {
        let bytes = req(Command::ReadWords { device: Device::D, start: 1000, count: 2 }).encode();
        let seed = [
            0x50, 0x00, 0x00, 0xFF, 0xFF, 0x03, 0x00, 0x0C, 0x00, 0x10, 0x00, 0x01, 0x04, 0x00, 0x00, 0xE8,
            0x03, 0x00, 0xA8, 0x02, 0x00,
        ];
        assert_eq!(bytes, seed);
        assert_eq!(
            Request::decode(&seed).unwrap().command,
            Command::ReadWords { device: Device::D, start: 1000, count: 2 }
        );
    }

    #[test]
    fn seed_write_d2000_header_has_length_0x10() {
        let bytes = req(Command::WriteWords { device: Device::D, start: 2000, values: vec![0x1234, 0xABCD] })
            .encode();
        assert_eq!(&bytes[..9], [0x50, 0x00, 0x00, 0xFF, 0xFF, 0x03, 0x00, 0x10, 0x00]);
        assert_eq!(
            &bytes[9..],
            [0x10, 0x00, 0x01, 0x14, 0x00, 0x00, 0xD0, 0x07, 0x00, 0xA8, 0x02, 0x00, 0x34, 0x12, 0xCD, 0xAB]
        );
    }

    #[test]
    fn manual_bit_examples() {
        // Batch read M100..M107 in bit units: the binary-code example of the MELSEC-Q/L MC
        // Protocol Reference Manual (SH-080008), batch read in bit units.
        let bytes = req(Command::ReadBits { device: Device::M, start: 100, count: 8 }).encode();
        assert_eq!(&bytes[11..], [0x01, 0x04, 0x01, 0x00, 0x64, 0x00, 0x00, 0x90, 0x08, 0x00]);
        // Batch write M100..M107 = 1,1,0,0,1,1,0,0 in bit units.
        let values = vec![true, true, false, false, true, true, false, false];
        let bytes = req(Command::WriteBits { device: Device::M, start: 100, values }).encode();
        assert_eq!(&bytes[7..9], [0x10, 0x00]);
        assert_eq!(
            &bytes[11..],
            [0x01, 0x14, 0x01, 0x00, 0x64, 0x00, 0x00, 0x90, 0x08, 0x00, 0x11, 0x00, 0x11, 0x00]
        );
        // X1A is device number 0x1A with code 9C.
        let bytes = req(Command::ReadBits { device: Device::X, start: 0x1A, count: 1 }).encode();
        assert_eq!(&bytes[15..19], [0x1A, 0x00, 0x00, 0x9C]);
    }

    #[test]
    fn server_side_refusals_carry_end_codes() {
        let mut bytes = req(Command::ReadWords { device: Device::D, start: 0, count: 1 }).encode();
        bytes[11] = 0x19; // command 0419: not supported
        assert!(matches!(Request::decode(&bytes), Err(Refusal::Command { end_code: 0xC059, .. })));
        let mut bytes = req(Command::ReadBits { device: Device::M, start: 0, count: 1 }).encode();
        bytes[18] = 0xA8; // bit units on D
        assert!(matches!(Request::decode(&bytes), Err(Refusal::Command { end_code: 0xC05C, .. })));
        bytes[18] = 0x01; // no such device
        assert!(matches!(Request::decode(&bytes), Err(Refusal::Command { end_code: 0xC05B, .. })));
        let mut bytes = req(Command::WriteWords { device: Device::D, start: 0, values: vec![1, 2] }).encode();
        bytes.pop();
        bytes[7] -= 1; // length consistent, but one data byte short of 2 points
        assert!(matches!(Request::decode(&bytes), Err(Refusal::Command { end_code: 0xC061, .. })));
        let mut bytes = req(Command::WriteBits { device: Device::M, start: 0, values: vec![true] }).encode();
        *bytes.last_mut().unwrap() = 0x20;
        assert!(matches!(Request::decode(&bytes), Err(Refusal::Command { end_code: 0xC060, .. })));
    }

    #[test]
    fn malformed_frames() {
        assert!(matches!(Request::decode(&[]), Err(Refusal::Frame(FrameError::Truncated { .. }))));
        let short = [0x50, 0x00, 0x00, 0xFF, 0xFF, 0x03, 0x00, 0x02, 0x00, 0x10, 0x00];
        assert!(matches!(Request::decode(&short), Err(Refusal::Frame(FrameError::Truncated { .. }))));
        let resp = [0xD0, 0x00, 0x00, 0xFF, 0xFF, 0x03, 0x00, 0x02, 0x00, 0x00, 0x00];
        assert!(matches!(Request::decode(&resp), Err(Refusal::Frame(FrameError::Subheader(_)))));
    }
}
