//! 3E and 4E binary requests, encoded by the client, decoded by the server.
//!
//! ```text
//! header(9, 4E: 13) | monitoring timer(2) command(2) subcommand(2) | command data (see command.rs)
//! ```
//! Decoding is split so the server can always answer: [`RequestHeader::decode`] fails only
//! when the bytes are not a 3E request at all; [`Command::decode`] fails with the end code
//! the server should answer.

pub use super::command::{
    CMD_BATCH_READ, CMD_BATCH_WRITE, CMD_RANDOM_READ, CMD_READ_BLOCKS, CMD_READ_TYPE_NAME, Command, SUB_BITS,
    SUB_WORDS,
};
use super::device::MAX_DEVICE_NUMBER;
use super::frame::{self, Direction, FrameError, Route};

/// A whole request.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Request {
    /// The 4E serial number; None sends a 3E frame.
    pub serial: Option<u16>,
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
        debug_assert!(self.command.first_device_number() <= MAX_DEVICE_NUMBER);
        let mut out = frame::start_any(
            Direction::Request,
            self.serial,
            &self.route,
            12 + self.command.reply_data_len(),
        );
        out.extend_from_slice(&self.monitor_timer.to_le_bytes());
        let (command, subcommand) = self.command.numbers();
        out.extend_from_slice(&command.to_le_bytes());
        out.extend_from_slice(&subcommand.to_le_bytes());
        self.command.encode(&mut out);
        frame::finish_frame(&mut out);
        out
    }

    /// Decodes a whole request as the server does.
    pub fn decode(bytes: &[u8]) -> Result<Request, Refusal<'_>> {
        let header = RequestHeader::decode(bytes).map_err(Refusal::Frame)?;
        match Command::decode(header.command, header.subcommand, header.data) {
            Ok(command) => Ok(Request {
                serial: header.serial,
                route: header.route,
                monitor_timer: header.monitor_timer,
                command,
            }),
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
    /// The 4E serial number (None: 3E).
    pub serial: Option<u16>,
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
        let (header, data) = frame::split_any(bytes, Direction::Request)?;
        let [t0, t1, m0, m1, s0, s1, data @ ..] = data else {
            return Err(FrameError::Truncated { need: header.size() + 6, have: bytes.len() });
        };
        Ok(RequestHeader {
            serial: header.serial,
            route: header.route,
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

    use crate::protocols::mc3e::device::Device;

    fn req(command: Command) -> Request {
        Request { serial: None, route: Route::default(), monitor_timer: 0x10, command }
    }

    #[test]
    fn four_e_read_d1000_and_type_name() {
        // The seed's read of D1000 x2 in a 4E frame with serial 0x1234 (layout of
        // pymcprotocol's type4e.py: 54 00, serial LE, 00 00, then the 3E header's route).
        let mut request = req(Command::ReadWords { device: Device::D, start: 1000, count: 2 });
        request.serial = Some(0x1234);
        let bytes = request.encode();
        let expect = [
            0x54, 0x00, 0x34, 0x12, 0x00, 0x00, 0x00, 0xFF, 0xFF, 0x03, 0x00, 0x0C, 0x00, 0x10, 0x00, 0x01,
            0x04, 0x00, 0x00, 0xE8, 0x03, 0x00, 0xA8, 0x02, 0x00,
        ];
        assert_eq!(bytes, expect);
        assert_eq!(Request::decode(&expect).unwrap(), request);
        // Read CPU model name: command 0101, subcommand 0000, no data (request length 6).
        let bytes = req(Command::ReadTypeName).encode();
        assert_eq!(
            bytes,
            [0x50, 0x00, 0x00, 0xFF, 0xFF, 0x03, 0x00, 0x06, 0x00, 0x10, 0x00, 0x01, 0x01, 0x00, 0x00]
        );
        assert_eq!(Request::decode(&bytes).unwrap().command, Command::ReadTypeName);
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
