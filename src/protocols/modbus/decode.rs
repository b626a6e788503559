//! Decoding PDUs from bytes, and finding a PDU's length from its first bytes.
//!
//! Every function here takes untrusted bytes: none panics, none trusts a count or length
//! field without checking it against the bytes actually present, and each failure says
//! what was wrong ([`DecodeError`]).

use super::device_id::{DeviceIdPage, DeviceObject, HEADER_LEN, MAX_PDU, MEI_DEVICE_ID, ReadDeviceIdCode};
use super::exception::Exception;
use super::pdu::{self, Request, Response, fc};

/// What is wrong with a PDU.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum DecodeError {
    /// No bytes at all.
    #[error("empty PDU")]
    Empty,
    /// Fewer bytes than the function code and counts call for.
    #[error("truncated PDU")]
    Truncated,
    /// More bytes than the function code and counts call for.
    #[error("trailing bytes after the PDU")]
    TrailingBytes,
    /// A function code this crate does not know.
    #[error("unknown function code {0:#04X}")]
    UnknownFunction(u8),
    /// A diagnostics sub-function this crate does not serve.
    #[error("unsupported diagnostics sub-function")]
    UnknownSubFunction,
    /// A count outside the per-function limit.
    #[error("count outside the per-function limit")]
    BadCount,
    /// The byte count does not agree with the item count.
    #[error("byte count does not match the item count")]
    ByteCountMismatch,
    /// A coil value other than FF00 or 0000.
    #[error("coil value is neither FF00 nor 0000")]
    BadCoilValue,
    /// The reply's function code is not the request's.
    #[error("function code in the reply differs from the request")]
    FunctionMismatch,
    /// A write reply does not echo the request's address, value or count (or a device
    /// identification reply another read device id code).
    #[error("write echo does not match the request")]
    EchoMismatch,
    /// An encapsulated interface (43) MEI type other than 0x0E, read device identification.
    #[error("MEI type is not 0x0E (read device identification)")]
    BadMeiType,
    /// A read device id code outside 01..=04.
    #[error("read device id code is not 01..04")]
    BadReadDeviceIdCode,
    /// A device identification reply's "more follows" is neither 00 nor FF.
    #[error("more follows is neither 00 nor FF")]
    BadMoreFollows,
    /// A device identification object's length runs past the end of the reply.
    #[error("a device identification object runs past the end of the reply")]
    ObjectOverrun,
}

impl DecodeError {
    /// A fixed description, for [`crate::protocols::PlcError::Malformed`].
    pub fn message(self) -> &'static str {
        match self {
            DecodeError::Empty => "empty PDU",
            DecodeError::Truncated => "truncated PDU",
            DecodeError::TrailingBytes => "trailing bytes after the PDU",
            DecodeError::UnknownFunction(_) => "unknown function code",
            DecodeError::UnknownSubFunction => "unsupported diagnostics sub-function",
            DecodeError::BadCount => "count outside the per-function limit",
            DecodeError::ByteCountMismatch => "byte count does not match the item count",
            DecodeError::BadCoilValue => "coil value is neither FF00 nor 0000",
            DecodeError::FunctionMismatch => "function code in the reply differs from the request",
            DecodeError::EchoMismatch => "write echo does not match the request",
            DecodeError::BadMeiType => "MEI type is not 0x0E (read device identification)",
            DecodeError::BadReadDeviceIdCode => "read device id code is not 01..04",
            DecodeError::BadMoreFollows => "more follows is neither 00 nor FF",
            DecodeError::ObjectOverrun => "a device identification object runs past the end of the reply",
        }
    }

    /// The exception a server answers for a request that failed to decode this way.
    pub fn exception(self) -> Exception {
        match self {
            DecodeError::UnknownFunction(_) | DecodeError::UnknownSubFunction | DecodeError::BadMeiType => {
                Exception::ILLEGAL_FUNCTION
            }
            _ => Exception::ILLEGAL_DATA_VALUE,
        }
    }
}

/// Reads the big-endian word at byte `i`, if present.
fn word(b: &[u8], i: usize) -> Result<u16, DecodeError> {
    match (b.get(i), b.get(i + 1)) {
        (Some(&hi), Some(&lo)) => Ok(u16::from_be_bytes([hi, lo])),
        _ => Err(DecodeError::Truncated),
    }
}

/// Checks that `b` is exactly `len` bytes long.
fn exact(b: &[u8], len: usize) -> Result<(), DecodeError> {
    match b.len().cmp(&len) {
        std::cmp::Ordering::Less => Err(DecodeError::Truncated),
        std::cmp::Ordering::Greater => Err(DecodeError::TrailingBytes),
        std::cmp::Ordering::Equal => Ok(()),
    }
}

fn coil(v: u16) -> Result<bool, DecodeError> {
    match v {
        0xFF00 => Ok(true),
        0x0000 => Ok(false),
        _ => Err(DecodeError::BadCoilValue),
    }
}

fn count_in(count: u16, max: u16) -> Result<u16, DecodeError> {
    if (1..=max).contains(&count) { Ok(count) } else { Err(DecodeError::BadCount) }
}

impl Request {
    /// Decodes a request PDU (function code first), as a server receives it.
    pub fn decode(pdu: &[u8]) -> Result<Request, DecodeError> {
        let (&f, d) = pdu.split_first().ok_or(DecodeError::Empty)?;
        if request_pdu_len(pdu).is_err() {
            return Err(DecodeError::UnknownFunction(f));
        }
        if f == fc::READ_FIFO_QUEUE {
            exact(d, 2)?;
            return Ok(Request::ReadFifoQueue { address: word(d, 0)? });
        }
        if f == fc::ENCAPSULATED {
            return match d {
                [MEI_DEVICE_ID, code, object_id] => Ok(Request::ReadDeviceId {
                    code: ReadDeviceIdCode::from_byte(*code).ok_or(DecodeError::BadReadDeviceIdCode)?,
                    object_id: *object_id,
                }),
                [] | [MEI_DEVICE_ID] | [MEI_DEVICE_ID, _] => Err(DecodeError::Truncated),
                [MEI_DEVICE_ID, ..] => Err(DecodeError::TrailingBytes),
                _ => Err(DecodeError::BadMeiType),
            };
        }
        let (a, n) = (word(d, 0)?, word(d, 2)?);
        let req = match f {
            fc::READ_COILS => Request::ReadCoils { address: a, count: count_in(n, pdu::MAX_READ_BITS)? },
            fc::READ_DISCRETE_INPUTS => {
                Request::ReadDiscreteInputs { address: a, count: count_in(n, pdu::MAX_READ_BITS)? }
            }
            fc::READ_HOLDING_REGISTERS => {
                Request::ReadHoldingRegisters { address: a, count: count_in(n, pdu::MAX_READ_REGISTERS)? }
            }
            fc::READ_INPUT_REGISTERS => {
                Request::ReadInputRegisters { address: a, count: count_in(n, pdu::MAX_READ_REGISTERS)? }
            }
            fc::WRITE_SINGLE_COIL => Request::WriteSingleCoil { address: a, value: coil(n)? },
            fc::WRITE_SINGLE_REGISTER => Request::WriteSingleRegister { address: a, value: n },
            fc::DIAGNOSTICS if pdu::diag_known(a) => Request::Diagnostics { sub_function: a, data: n },
            fc::DIAGNOSTICS => return Err(DecodeError::UnknownSubFunction),
            fc::WRITE_MULTIPLE_COILS => {
                let count = count_in(n, pdu::MAX_WRITE_BITS)? as usize;
                let data = byte_counted(d, count.div_ceil(8))?;
                Request::WriteMultipleCoils { address: a, values: pdu::unpack_bits(data, count) }
            }
            fc::WRITE_MULTIPLE_REGISTERS => {
                let count = count_in(n, pdu::MAX_WRITE_REGISTERS)? as usize;
                let data = byte_counted(d, count * 2)?;
                Request::WriteMultipleRegisters { address: a, values: words(data) }
            }
            other => return Err(DecodeError::UnknownFunction(other)),
        };
        if !matches!(f, fc::WRITE_MULTIPLE_COILS | fc::WRITE_MULTIPLE_REGISTERS) {
            exact(d, 4)?;
        }
        Ok(req)
    }
}

/// For write-multiple requests: checks the byte count at `d[4]` and returns the data after it.
fn byte_counted(d: &[u8], expected: usize) -> Result<&[u8], DecodeError> {
    let bc = *d.get(4).ok_or(DecodeError::Truncated)? as usize;
    if bc != expected {
        return Err(DecodeError::ByteCountMismatch);
    }
    exact(d, 5 + bc)?;
    Ok(&d[5..])
}

fn words(data: &[u8]) -> Vec<u16> {
    data.chunks_exact(2).map(|c| u16::from_be_bytes([c[0], c[1]])).collect()
}

/// For read replies: checks the byte count at `d[0]` and returns the data after it.
fn read_data(d: &[u8], expected: usize) -> Result<&[u8], DecodeError> {
    let bc = *d.first().ok_or(DecodeError::Truncated)? as usize;
    if bc != expected {
        return Err(DecodeError::ByteCountMismatch);
    }
    exact(d, 1 + bc)?;
    Ok(&d[1..])
}

/// Decodes the reply PDU to `req`: `Ok(Ok(..))` data, `Ok(Err(..))` an exception reply,
/// `Err(..)` a reply that does not decode or does not answer `req` (wrong function, wrong
/// byte count, write echo that differs).
pub fn decode_response(pdu: &[u8], req: &Request) -> Result<Result<Response, Exception>, DecodeError> {
    let (&f, d) = pdu.split_first().ok_or(DecodeError::Empty)?;
    if f == req.function() | fc::EXCEPTION_FLAG {
        exact(d, 1)?;
        return Ok(Err(Exception(d[0])));
    }
    if f != req.function() {
        return Err(DecodeError::FunctionMismatch);
    }
    let echo = |expected: [u16; 2]| -> Result<(), DecodeError> {
        exact(d, 4)?;
        if [word(d, 0)?, word(d, 2)?] == expected { Ok(()) } else { Err(DecodeError::EchoMismatch) }
    };
    let resp = match req {
        Request::ReadCoils { count, .. } | Request::ReadDiscreteInputs { count, .. } => {
            let n = *count as usize;
            let bits = pdu::unpack_bits(read_data(d, n.div_ceil(8))?, n);
            if f == fc::READ_COILS { Response::ReadCoils(bits) } else { Response::ReadDiscreteInputs(bits) }
        }
        Request::ReadHoldingRegisters { count, .. } | Request::ReadInputRegisters { count, .. } => {
            let values = words(read_data(d, *count as usize * 2)?);
            if f == fc::READ_HOLDING_REGISTERS {
                Response::ReadHoldingRegisters(values)
            } else {
                Response::ReadInputRegisters(values)
            }
        }
        Request::WriteSingleCoil { address, value } => {
            exact(d, 4)?;
            if word(d, 0)? != *address || coil(word(d, 2)?)? != *value {
                return Err(DecodeError::EchoMismatch);
            }
            Response::WriteSingleCoil { address: *address, value: *value }
        }
        Request::WriteSingleRegister { address, value } => {
            echo([*address, *value])?;
            Response::WriteSingleRegister { address: *address, value: *value }
        }
        Request::WriteMultipleCoils { address, values } => {
            echo([*address, values.len() as u16])?;
            Response::WriteMultipleCoils { address: *address, count: values.len() as u16 }
        }
        Request::WriteMultipleRegisters { address, values } => {
            echo([*address, values.len() as u16])?;
            Response::WriteMultipleRegisters { address: *address, count: values.len() as u16 }
        }
        Request::Diagnostics { sub_function, data } if pdu::diag_echoes(*sub_function) => {
            echo([*sub_function, *data])?;
            Response::Diagnostics { sub_function: *sub_function, data: *data }
        }
        // A register or counter: any value, under the request's sub-function.
        Request::Diagnostics { sub_function, .. } => {
            exact(d, 4)?;
            if word(d, 0)? != *sub_function {
                return Err(DecodeError::EchoMismatch);
            }
            Response::Diagnostics { sub_function: *sub_function, data: word(d, 2)? }
        }
        Request::ReadFifoQueue { .. } => {
            let (byte_count, count) = (word(d, 0)? as usize, word(d, 2)?);
            if count > pdu::MAX_FIFO_COUNT {
                return Err(DecodeError::BadCount);
            }
            if byte_count != 2 + count as usize * 2 {
                return Err(DecodeError::ByteCountMismatch);
            }
            exact(d, 2 + byte_count)?;
            Response::ReadFifoQueue(words(&d[4..]))
        }
        Request::ReadDeviceId { code, .. } => Response::ReadDeviceId(device_id_page(d, *code)?),
    };
    Ok(Ok(resp))
}

/// The full length of a request PDU that starts with `prefix`: `Ok(None)` if more bytes are
/// needed to tell. Used where the frame itself carries no length (RTU, length-0 MBAP).
pub fn request_pdu_len(prefix: &[u8]) -> Result<Option<usize>, DecodeError> {
    let Some(&f) = prefix.first() else { return Ok(None) };
    match f {
        fc::READ_COILS..=fc::WRITE_SINGLE_REGISTER | fc::DIAGNOSTICS => Ok(Some(5)),
        fc::WRITE_MULTIPLE_COILS | fc::WRITE_MULTIPLE_REGISTERS => {
            Ok(prefix.get(5).map(|&bc| 6 + bc as usize))
        }
        fc::READ_FIFO_QUEUE => Ok(Some(3)),
        fc::ENCAPSULATED => Ok(Some(4)),
        other => Err(DecodeError::UnknownFunction(other)),
    }
}

/// The full length of a response PDU that starts with `prefix`: `Ok(None)` if more bytes
/// are needed to tell.
pub fn response_pdu_len(prefix: &[u8]) -> Result<Option<usize>, DecodeError> {
    let Some(&f) = prefix.first() else { return Ok(None) };
    match f {
        f if f & fc::EXCEPTION_FLAG != 0 => Ok(Some(2)),
        fc::READ_COILS..=fc::READ_INPUT_REGISTERS => Ok(prefix.get(1).map(|&bc| 2 + bc as usize)),
        fc::WRITE_SINGLE_COIL | fc::WRITE_SINGLE_REGISTER | fc::DIAGNOSTICS => Ok(Some(5)),
        fc::WRITE_MULTIPLE_COILS | fc::WRITE_MULTIPLE_REGISTERS => Ok(Some(5)),
        fc::READ_FIFO_QUEUE => Ok(prefix.get(1..3).map(|b| 3 + u16::from_be_bytes([b[0], b[1]]) as usize)),
        fc::ENCAPSULATED => device_id_reply_len(prefix),
        other => Err(DecodeError::UnknownFunction(other)),
    }
}

/// Decodes the data of a Read Device Identification reply PDU (after the function code) to
/// a request of `code`.
fn device_id_page(d: &[u8], code: ReadDeviceIdCode) -> Result<DeviceIdPage, DecodeError> {
    let [mei, echoed, conformity, more, next, count, objects_bytes @ ..] = d else {
        return Err(DecodeError::Truncated);
    };
    let mut rest: &[u8] = objects_bytes;
    if *mei != MEI_DEVICE_ID {
        return Err(DecodeError::BadMeiType);
    }
    if *echoed != code as u8 {
        return Err(DecodeError::EchoMismatch);
    }
    let next = match more {
        0x00 => None,
        0xFF => Some(*next),
        _ => return Err(DecodeError::BadMoreFollows),
    };
    let mut objects = Vec::with_capacity(*count as usize);
    for _ in 0..*count {
        let [id, len, tail @ ..] = rest else { return Err(DecodeError::ObjectOverrun) };
        let (id, len) = (*id, *len as usize);
        let value = tail.get(..len).ok_or(DecodeError::ObjectOverrun)?;
        objects.push(DeviceObject { id, value: value.to_vec() });
        rest = &tail[len..];
    }
    if !rest.is_empty() {
        return Err(DecodeError::TrailingBytes);
    }
    Ok(DeviceIdPage { code, conformity: *conformity, next, objects })
}

/// The length of a Read Device Identification reply PDU (function code included) from its
/// first bytes: `Ok(None)` until enough bytes are there to tell.
fn device_id_reply_len(prefix: &[u8]) -> Result<Option<usize>, DecodeError> {
    let Some(&count) = prefix.get(HEADER_LEN - 1) else { return Ok(None) };
    let mut at = HEADER_LEN;
    for _ in 0..count {
        let Some(&len) = prefix.get(at + 1) else { return Ok(None) };
        at += 2 + len as usize;
        if at > MAX_PDU {
            return Err(DecodeError::ObjectOverrun);
        }
    }
    Ok(Some(at))
}

#[cfg(test)]
#[path = "decode_tests.rs"]
mod tests;
