//! 3E binary responses: encoded by the server, decoded and checked by the client.
//!
//! ```text
//! D0 00 | route(5) | data length(2) | end code(2) | data            (end code 0)
//! D0 00 | route(5) | data length(2) | end code(2) | [error info(9)] (end code != 0)
//! ```
//! The error information (network, PC, module I/O, station, command, subcommand of the
//! failed request) is optional on decode: some modules and gateways send the end code alone,
//! and peer servers have been seen sending other data after the end code. Whatever follows a
//! nonzero end code, the end code is what the PLC meant: it is surfaced as long as the length
//! field matches the frame; 9 trailing bytes are read as error information, any other number
//! is kept as-is in `Outcome::Failed`'s `trailing` (logged, never trusted).
//!
//! A 4E response (`D4 00`) is the same with the request's serial number after the subheader.

use super::frame::{self, Direction, FrameError, Route};

/// The error information of an error response: the failed request's route and command.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ErrorInfo {
    /// The route of the station that raised the error.
    pub route: Route,
    /// The failed request's command.
    pub command: u16,
    /// The failed request's subcommand.
    pub subcommand: u16,
}

impl ErrorInfo {
    /// Encoded size.
    pub const LEN: usize = 9;
}

/// How a request ended.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Outcome {
    /// End code 0 and the response data (words little-endian, or packed bits).
    Ok(Vec<u8>),
    /// A nonzero end code, with error information when the device sent it.
    Failed {
        /// The end code (never 0 when decoded).
        end_code: u16,
        /// The error information, if exactly 9 bytes followed the end code.
        info: Option<ErrorInfo>,
        /// Bytes after the end code that are not 9 bytes of error information (empty
        /// otherwise; never encoded when `info` is set).
        trailing: Vec<u8>,
    },
}

/// A whole response.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Response {
    /// The 4E serial number echoed from the request; None for a 3E response.
    pub serial: Option<u16>,
    /// The route, echoed from the request.
    pub route: Route,
    /// The end code and data.
    pub outcome: Outcome,
}

impl Response {
    /// The response's bytes.
    pub fn encode(&self) -> Vec<u8> {
        let mut out = frame::start_any(Direction::Response, self.serial, &self.route, 2 + ErrorInfo::LEN);
        match &self.outcome {
            Outcome::Ok(data) => {
                out.extend_from_slice(&[0, 0]);
                out.extend_from_slice(data);
            }
            Outcome::Failed { end_code, info, trailing } => {
                out.extend_from_slice(&end_code.to_le_bytes());
                match info {
                    Some(info) => {
                        info.route.encode(&mut out);
                        out.extend_from_slice(&info.command.to_le_bytes());
                        out.extend_from_slice(&info.subcommand.to_le_bytes());
                    }
                    None => out.extend_from_slice(trailing),
                }
            }
        }
        frame::finish_frame(&mut out);
        out
    }

    /// Decodes one whole response (the bytes of one datagram, or one frame cut from a
    /// stream by its length field).
    pub fn decode(bytes: &[u8]) -> Result<Response, FrameError> {
        let (header, data) = frame::split_any(bytes, Direction::Response)?;
        let [e0, e1, rest @ ..] = data else {
            return Err(FrameError::Truncated { need: header.size() + 2, have: bytes.len() });
        };
        let end_code = u16::from_le_bytes([*e0, *e1]);
        let outcome = if end_code == 0 {
            Outcome::Ok(rest.to_vec())
        } else {
            let info = match rest {
                [n, p, i0, i1, s, c0, c1, s0, s1] => Some(ErrorInfo {
                    route: Route {
                        network: *n,
                        pc: *p,
                        module_io: u16::from_le_bytes([*i0, *i1]),
                        station: *s,
                    },
                    command: u16::from_le_bytes([*c0, *c1]),
                    subcommand: u16::from_le_bytes([*s0, *s1]),
                }),
                _ => None,
            };
            let trailing = if info.is_some() { Vec::new() } else { rest.to_vec() };
            Outcome::Failed { end_code, info, trailing }
        };
        Ok(Response { serial: header.serial, route: header.route, outcome })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const HEAD: [u8; 7] = [0xD0, 0x00, 0x00, 0xFF, 0xFF, 0x03, 0x00];

    #[test]
    fn seed_normal_read_response() {
        let mut bytes = HEAD.to_vec();
        bytes.extend_from_slice(&[0x06, 0x00, 0x00, 0x00, 0x34, 0x12, 0x02, 0x00]);
        let r = Response::decode(&bytes).unwrap();
        assert_eq!(r.route, Route::default());
        assert_eq!(r.outcome, Outcome::Ok(vec![0x34, 0x12, 0x02, 0x00]));
        assert_eq!(r.encode(), bytes);
    }

    #[test]
    fn seed_write_response() {
        let bytes = [0xD0, 0x00, 0x00, 0xFF, 0xFF, 0x03, 0x00, 0x02, 0x00, 0x00, 0x00];
        let r = Response { serial: None, route: Route::default(), outcome: Outcome::Ok(vec![]) };
        assert_eq!(r.encode(), bytes);
        assert_eq!(Response::decode(&bytes).unwrap(), r);
    }

    #[test]
    fn seed_c051_with_error_info() {
        let bytes = [
            0xD0, 0x00, 0x00, 0xFF, 0xFF, 0x03, 0x00, 0x0B, 0x00, 0x51, 0xC0, 0x00, 0xFF, 0xFF, 0x03, 0x00,
            0x01, 0x04, 0x00, 0x00,
        ];
        let r = Response::decode(&bytes).unwrap();
        let info = ErrorInfo { route: Route::default(), command: 0x0401, subcommand: 0x0000 };
        assert_eq!(r.outcome, Outcome::Failed { end_code: 0xC051, info: Some(info), trailing: vec![] });
        assert_eq!(r.encode(), bytes);
    }

    #[test]
    fn error_without_info() {
        let bytes = [0xD0, 0x00, 0x00, 0xFF, 0xFF, 0x03, 0x00, 0x02, 0x00, 0x59, 0xC0];
        let r = Response::decode(&bytes).unwrap();
        assert_eq!(r.outcome, Outcome::Failed { end_code: 0xC059, info: None, trailing: vec![] });
        assert_eq!(r.encode(), bytes);
    }

    #[test]
    fn error_with_any_trailing_data_surfaces_the_end_code() {
        // Issue 15: a peer server answered an end code followed by data other than the 9
        // bytes of error information. Length field consistent: the end code is the answer.
        for trailing in [vec![0x00, 0xFF], vec![0x01; 4], vec![0xAA; 12]] {
            let mut bytes = HEAD.to_vec();
            bytes.extend_from_slice(&(2 + trailing.len() as u16).to_le_bytes());
            bytes.extend_from_slice(&[0x51, 0xC0]);
            bytes.extend_from_slice(&trailing);
            let r = Response::decode(&bytes).unwrap();
            assert_eq!(
                r.outcome,
                Outcome::Failed { end_code: 0xC051, info: None, trailing: trailing.clone() }
            );
            assert_eq!(r.encode(), bytes);
        }
        // Inconsistent length field: still malformed.
        let mut lying = HEAD.to_vec();
        lying.extend_from_slice(&[0x05, 0x00, 0x51, 0xC0, 0x00, 0xFF]);
        assert_eq!(Response::decode(&lying), Err(FrameError::Length { declared: 5, actual: 4 }));
    }

    #[test]
    fn four_e_response_echoes_the_serial() {
        // D4 00, serial 0x1234, 00 00, route, length 6, end code 0, D1000..D1001.
        let bytes = [
            0xD4, 0x00, 0x34, 0x12, 0x00, 0x00, 0x00, 0xFF, 0xFF, 0x03, 0x00, 0x06, 0x00, 0x00, 0x00, 0x34,
            0x12, 0x02, 0x00,
        ];
        let r = Response::decode(&bytes).unwrap();
        assert_eq!(r.serial, Some(0x1234));
        assert_eq!(r.outcome, Outcome::Ok(vec![0x34, 0x12, 0x02, 0x00]));
        assert_eq!(r.encode(), bytes);
    }

    #[test]
    fn malformed() {
        let mut short = HEAD.to_vec();
        short.extend_from_slice(&[0x01, 0x00, 0x00]);
        assert!(matches!(Response::decode(&short), Err(FrameError::Truncated { .. })));
        let mut lying = HEAD.to_vec();
        lying.extend_from_slice(&[0xFF, 0xFF, 0x00, 0x00]);
        assert_eq!(Response::decode(&lying), Err(FrameError::Length { declared: 0xFFFF, actual: 2 }));
        let request = [0x50, 0x00, 0x00, 0xFF, 0xFF, 0x03, 0x00, 0x02, 0x00, 0x00, 0x00];
        assert_eq!(Response::decode(&request), Err(FrameError::Subheader([0x50, 0x00])));
        assert!(matches!(Response::decode(&[0xD4, 0x00, 0x01]), Err(FrameError::Truncated { .. })));
    }
}
