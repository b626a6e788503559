//! The S7 PDU inside a PPI long frame: header `32 ROSCTR 00 00 REF REF PL PL DL DL` (plus
//! the error class and code in acknowledgements), parameters, data. Requests: read and
//! write of one item, RUN and STOP, setup communication ([`super::setup`]). Pure bytes, no
//! I/O.

pub use super::area::{MemArea, Size};
use super::return_code::SUCCESS;
use super::setup::SETUP;
pub use super::setup::Setup;

/// S7 protocol id, the first PDU byte.
const PROTOCOL_ID: u8 = 0x32;
/// ROSCTR of a request (job).
const JOB: u8 = 0x01;
/// ROSCTR of an acknowledgement without data (used for refusals).
const ACK: u8 = 0x02;
/// ROSCTR of an acknowledgement with data.
const ACK_DATA: u8 = 0x03;
/// Function: read variable.
const READ: u8 = 0x04;
/// Function: write variable.
const WRITE: u8 = 0x05;
/// Function: start (RUN).
pub const RUN: u8 = 0x28;
/// Function: stop.
pub const STOP: u8 = 0x29;
/// The program block name RUN and STOP name.
const P_PROGRAM: &[u8] = b"P_PROGRAM";
/// Most data bytes rackd puts in one read or write (the frame's LE must fit a byte).
pub const MAX_DATA: usize = 200;

/// One variable: what to read or write.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Item {
    /// Transport size.
    pub size: Size,
    /// Number of elements.
    pub count: u16,
    /// Memory area.
    pub area: MemArea,
    /// Bit offset: byte address x 8 + bit (timers and counters: their number).
    pub offset: u32,
}

impl Item {
    /// Data bytes the item covers.
    pub fn data_len(&self) -> usize {
        self.count as usize * self.size.bytes()
    }

    fn encode(&self, out: &mut Vec<u8>) {
        let [_, o2, o1, o0] = self.offset.to_be_bytes();
        let [c1, c0] = self.count.to_be_bytes();
        let db = u8::from(self.area == MemArea::V);
        out.extend_from_slice(&[
            0x12,
            0x0A,
            0x10,
            self.size.code(),
            c1,
            c0,
            0x00,
            db,
            self.area.code(),
            o2,
            o1,
            o0,
        ]);
    }

    fn decode(b: &[u8]) -> Result<Item, PduError> {
        match b {
            [0x12, 0x0A, 0x10, size, c1, c0, _, _, area, o2, o1, o0] => Ok(Item {
                size: Size::from_code(*size).ok_or(PduError::BadItem)?,
                count: u16::from_be_bytes([*c1, *c0]),
                area: MemArea::from_code(*area).ok_or(PduError::BadItem)?,
                offset: u32::from_be_bytes([0, *o2, *o1, *o0]),
            }),
            _ => Err(PduError::BadItem),
        }
    }
}

/// A request PDU.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Request {
    /// Read one item.
    Read(Item),
    /// Write one item with these bytes.
    Write(Item, Vec<u8>),
    /// Put the PLC in RUN.
    Run,
    /// Put the PLC in STOP.
    Stop,
    /// Setup communication: the master's proposal.
    Setup(Setup),
}

/// A reply PDU.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Reply {
    /// A read item's data.
    Data(Vec<u8>),
    /// A write item was accepted.
    Written,
    /// The item failed with this return code.
    ItemError(u8),
    /// RUN or STOP done (the function code answered).
    Done(u8),
    /// Setup communication: what the PLC grants.
    Setup(Setup),
    /// The whole request was refused with this error class and code.
    Refused {
        /// Error class (0x85, ...).
        class: u8,
        /// Error code.
        code: u8,
    },
}

/// Why a PDU cannot be decoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum PduError {
    /// The protocol id is not 32 or the message type is unexpected.
    #[error("not an S7 PDU of the expected type")]
    NotS7,
    /// The parameter and data lengths do not add up to the PDU.
    #[error("PDU lengths do not match its size")]
    BadLength,
    /// A function this side does not handle.
    #[error("unsupported S7 function")]
    Unsupported,
    /// An item specification or data item is malformed.
    #[error("malformed item")]
    BadItem,
    /// The reply does not answer the request (function, size or count differ).
    #[error("reply does not match the request")]
    Mismatch,
}

fn header(out: &mut Vec<u8>, rosctr: u8, pdu_ref: u16, params: usize, data: usize) {
    out.extend_from_slice(&[PROTOCOL_ID, rosctr, 0, 0]);
    out.extend_from_slice(&pdu_ref.to_be_bytes());
    out.extend_from_slice(&(params as u16).to_be_bytes());
    out.extend_from_slice(&(data as u16).to_be_bytes());
}

impl Request {
    /// Whether the request changes the PLC (a write, RUN, STOP, a setup), rather than reads.
    pub fn is_write(&self) -> bool {
        !matches!(self, Request::Read(_))
    }

    /// The frame function code the seed uses for this request.
    pub fn fc(&self) -> u8 {
        match self {
            Request::Write(..) => super::frame::FC_WRITE,
            _ => super::frame::FC_READ,
        }
    }

    /// Checks sizes before sending.
    pub fn check(&self) -> Result<(), &'static str> {
        match self {
            Request::Read(item) | Request::Write(item, _)
                if item.count == 0 || item.data_len() > MAX_DATA =>
            {
                Err("PPI item count is 0 or too large for one frame")
            }
            Request::Read(item) | Request::Write(item, _) if item.offset > 0xFF_FFFF => {
                Err("PPI offset out of range")
            }
            Request::Read(item) | Request::Write(item, _) if item.size == Size::Bit && item.count != 1 => {
                Err("PPI bit access is one bit per item")
            }
            Request::Write(item, data) if data.len() != item.data_len() => {
                Err("PPI write data does not fit the item")
            }
            _ => Ok(()),
        }
    }

    /// Appends the request PDU with this PDU reference.
    pub fn encode(&self, pdu_ref: u16, out: &mut Vec<u8>) {
        match self {
            Request::Read(item) => {
                header(out, JOB, pdu_ref, 14, 0);
                out.extend_from_slice(&[READ, 1]);
                item.encode(out);
            }
            Request::Write(item, data) => {
                header(out, JOB, pdu_ref, 14, 4 + data.len());
                out.extend_from_slice(&[WRITE, 1]);
                item.encode(out);
                let (ts, bits) =
                    if item.size == Size::Bit { (0x03, item.count as usize) } else { (0x04, data.len() * 8) };
                out.extend_from_slice(&[0x00, ts]);
                out.extend_from_slice(&(bits as u16).to_be_bytes());
                out.extend_from_slice(data);
            }
            Request::Stop => {
                header(out, JOB, pdu_ref, 7 + P_PROGRAM.len(), 0);
                out.extend_from_slice(&[STOP, 0, 0, 0, 0, 0, P_PROGRAM.len() as u8]);
                out.extend_from_slice(P_PROGRAM);
            }
            Request::Run => {
                header(out, JOB, pdu_ref, 11 + P_PROGRAM.len(), 0);
                out.extend_from_slice(&[RUN, 0, 0, 0, 0, 0, 0, 0xFD, 0, 0, P_PROGRAM.len() as u8]);
                out.extend_from_slice(P_PROGRAM);
            }
            Request::Setup(setup) => {
                header(out, JOB, pdu_ref, 8, 0);
                setup.encode(out);
            }
        }
    }

    /// Decodes a request PDU (server side): its PDU reference and the request.
    pub fn decode(p: &[u8]) -> Result<(u16, Request), PduError> {
        if p.len() < 10 || p[0] != PROTOCOL_ID || p[1] != JOB {
            return Err(PduError::NotS7);
        }
        let pdu_ref = u16::from_be_bytes([p[4], p[5]]);
        let plen = u16::from_be_bytes([p[6], p[7]]) as usize;
        let dlen = u16::from_be_bytes([p[8], p[9]]) as usize;
        if 10 + plen + dlen != p.len() || plen == 0 {
            return Err(PduError::BadLength);
        }
        let (param, data) = p[10..].split_at(plen);
        let request = match param[0] {
            READ if plen == 14 && param[1] == 1 && dlen == 0 => Request::Read(Item::decode(&param[2..])?),
            WRITE if plen == 14 && param[1] == 1 => {
                let item = Item::decode(&param[2..])?;
                let values = data.get(4..).ok_or(PduError::BadItem)?;
                if values.len() != item.data_len() {
                    return Err(PduError::BadItem);
                }
                Request::Write(item, values.to_vec())
            }
            STOP => Request::Stop,
            RUN => Request::Run,
            SETUP if dlen == 0 => Request::Setup(Setup::decode(param).ok_or(PduError::BadLength)?),
            _ => return Err(PduError::Unsupported),
        };
        Ok((pdu_ref, request))
    }
}

impl Reply {
    /// Appends the reply PDU to `request` with this PDU reference.
    pub fn encode(&self, request: &Request, pdu_ref: u16, out: &mut Vec<u8>) {
        let ack_data = |out: &mut Vec<u8>, params: usize, data: usize| {
            header(out, ACK_DATA, pdu_ref, params, data);
            out.extend_from_slice(&[0, 0]);
        };
        match (self, request) {
            (Reply::Refused { class, code }, _) => {
                header(out, ACK, pdu_ref, 0, 0);
                out.extend_from_slice(&[*class, *code]);
            }
            (Reply::Done(function), _) => {
                ack_data(out, 1, 0);
                out.push(*function);
            }
            (Reply::Setup(setup), _) => {
                ack_data(out, 8, 0);
                setup.encode(out);
            }
            (Reply::Data(bytes), Request::Read(item)) => {
                ack_data(out, 2, 4 + bytes.len());
                let (ts, bits) = if item.size == Size::Bit {
                    (0x03, item.count as usize)
                } else {
                    (0x04, bytes.len() * 8)
                };
                out.extend_from_slice(&[READ, 1, SUCCESS, ts]);
                out.extend_from_slice(&(bits as u16).to_be_bytes());
                out.extend_from_slice(bytes);
            }
            (Reply::ItemError(rc), Request::Read(_)) => {
                ack_data(out, 2, 4);
                out.extend_from_slice(&[READ, 1, *rc, 0, 0, 0]);
            }
            (Reply::ItemError(rc), _) => {
                ack_data(out, 2, 1);
                out.extend_from_slice(&[WRITE, 1, *rc]);
            }
            (_, _) => {
                ack_data(out, 2, 1);
                out.extend_from_slice(&[WRITE, 1, SUCCESS]);
            }
        }
    }

    /// Decodes a reply PDU to `request` (client side): its PDU reference and the reply.
    pub fn decode(p: &[u8], request: &Request) -> Result<(u16, Reply), PduError> {
        if p.len() < 12 || p[0] != PROTOCOL_ID || !matches!(p[1], ACK | ACK_DATA) {
            return Err(PduError::NotS7);
        }
        let pdu_ref = u16::from_be_bytes([p[4], p[5]]);
        let (class, code) = (p[10], p[11]);
        if class != 0 || code != 0 {
            return Ok((pdu_ref, Reply::Refused { class, code }));
        }
        let plen = u16::from_be_bytes([p[6], p[7]]) as usize;
        let dlen = u16::from_be_bytes([p[8], p[9]]) as usize;
        if 12 + plen + dlen != p.len() {
            return Err(PduError::BadLength);
        }
        let (param, data) = p[12..].split_at(plen);
        let reply = match (request, param) {
            (Request::Read(item), [READ, 1]) => match data {
                [SUCCESS, ts, l1, l0, values @ ..] => {
                    let len = u16::from_be_bytes([*l1, *l0]) as usize;
                    let bytes = if matches!(ts, 3..=5) { len.div_ceil(8) } else { len };
                    if bytes != values.len() || bytes != item.data_len() {
                        return Err(PduError::Mismatch);
                    }
                    Reply::Data(values.to_vec())
                }
                [rc, ..] if *rc != SUCCESS => Reply::ItemError(*rc),
                _ => return Err(PduError::BadItem),
            },
            (Request::Write(..), [WRITE, 1]) => match data {
                [SUCCESS] => Reply::Written,
                [rc] => Reply::ItemError(*rc),
                _ => return Err(PduError::BadItem),
            },
            (Request::Run | Request::Stop, [f @ (RUN | STOP)]) => Reply::Done(*f),
            (Request::Setup(_), [SETUP, ..]) if data.is_empty() => {
                Reply::Setup(Setup::decode(param).ok_or(PduError::BadLength)?)
            }
            _ => return Err(PduError::Mismatch),
        };
        Ok((pdu_ref, reply))
    }
}

#[cfg(test)]
#[path = "pdu_tests.rs"]
mod tests;
