//! Modbus PDUs (function code + data) as plain Rust values, and their encoding to bytes.
//!
//! The PDU is the same in every framing (TCP, UDP, RTU); [`super::frame`] and
//! [`super::rtu`] wrap it. Decoding lives in [`super::decode`]; Read Device Identification's
//! objects in [`super::device_id`]. Nothing here does I/O.

use super::device_id::{DeviceIdPage, MEI_DEVICE_ID, ReadDeviceIdCode};

/// Function codes this crate speaks.
pub mod fc {
    /// 01 read coils.
    pub const READ_COILS: u8 = 0x01;
    /// 02 read discrete inputs.
    pub const READ_DISCRETE_INPUTS: u8 = 0x02;
    /// 03 read holding registers.
    pub const READ_HOLDING_REGISTERS: u8 = 0x03;
    /// 04 read input registers.
    pub const READ_INPUT_REGISTERS: u8 = 0x04;
    /// 05 write single coil.
    pub const WRITE_SINGLE_COIL: u8 = 0x05;
    /// 06 write single register.
    pub const WRITE_SINGLE_REGISTER: u8 = 0x06;
    /// 08 diagnostics (sub-function 0000 echoes its data: a link check).
    pub const DIAGNOSTICS: u8 = 0x08;
    /// 15 (0x0F) write multiple coils.
    pub const WRITE_MULTIPLE_COILS: u8 = 0x0F;
    /// 16 (0x10) write multiple registers.
    pub const WRITE_MULTIPLE_REGISTERS: u8 = 0x10;
    /// 24 (0x18) read FIFO queue.
    pub const READ_FIFO_QUEUE: u8 = 0x18;
    /// 43 (0x2B) encapsulated interface transport (MEI 0x0E: read device identification).
    pub const ENCAPSULATED: u8 = 0x2B;
    /// Set in the function code of an exception reply.
    pub const EXCEPTION_FLAG: u8 = 0x80;
}

/// Most bits one read (01, 02) may ask for.
pub const MAX_READ_BITS: u16 = 2000;
/// Most registers one read (03, 04) may ask for.
pub const MAX_READ_REGISTERS: u16 = 125;
/// Most coils one write multiple (15) may carry.
pub const MAX_WRITE_BITS: u16 = 1968;
/// Most registers one write multiple (16) may carry.
pub const MAX_WRITE_REGISTERS: u16 = 123;
/// Most registers a FIFO queue (24) may hold.
pub const MAX_FIFO_COUNT: u16 = 31;

/// Diagnostics sub-function 0000: return query data (echo).
pub const DIAG_RETURN_QUERY_DATA: u16 = 0x0000;
/// Diagnostics sub-function 000A: clear counters and diagnostic register.
pub const DIAG_CLEAR_COUNTERS: u16 = 0x000A;
/// Diagnostics sub-function 0002: return the diagnostic register.
pub const DIAG_DIAGNOSTIC_REGISTER: u16 = 0x0002;
/// Diagnostics sub-function 000B: return the bus message count.
pub const DIAG_BUS_MESSAGES: u16 = 0x000B;
/// Diagnostics sub-function 000C: return the bus communication error count.
pub const DIAG_BUS_COMM_ERRORS: u16 = 0x000C;
/// Diagnostics sub-function 000D: return the bus exception error count.
pub const DIAG_BUS_EXCEPTIONS: u16 = 0x000D;
/// Diagnostics sub-function 000E: return the server message count.
pub const DIAG_SERVER_MESSAGES: u16 = 0x000E;
/// Diagnostics sub-function 000F: return the server no response count.
pub const DIAG_SERVER_NO_RESPONSES: u16 = 0x000F;

/// Whether a diagnostics sub-function is one this crate speaks.
pub fn diag_known(sub_function: u16) -> bool {
    matches!(sub_function, DIAG_RETURN_QUERY_DATA | DIAG_DIAGNOSTIC_REGISTER | DIAG_CLEAR_COUNTERS)
        || (DIAG_BUS_MESSAGES..=DIAG_SERVER_NO_RESPONSES).contains(&sub_function)
}

/// Whether the reply to a diagnostics sub-function echoes the request's data word (0000,
/// 000A); the others answer a register or counter in it.
pub fn diag_echoes(sub_function: u16) -> bool {
    matches!(sub_function, DIAG_RETURN_QUERY_DATA | DIAG_CLEAR_COUNTERS)
}

/// A request PDU. Addresses are PDU addresses (0-based, as on the wire).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Request {
    /// 01: read `count` coils from `address`.
    ReadCoils {
        /// First PDU address.
        address: u16,
        /// Number of items.
        count: u16,
    },
    /// 02: read `count` discrete inputs from `address`.
    ReadDiscreteInputs {
        /// First PDU address.
        address: u16,
        /// Number of items.
        count: u16,
    },
    /// 03: read `count` holding registers from `address`.
    ReadHoldingRegisters {
        /// First PDU address.
        address: u16,
        /// Number of items.
        count: u16,
    },
    /// 04: read `count` input registers from `address`.
    ReadInputRegisters {
        /// First PDU address.
        address: u16,
        /// Number of items.
        count: u16,
    },
    /// 05: set one coil.
    WriteSingleCoil {
        /// First PDU address.
        address: u16,
        /// The value.
        value: bool,
    },
    /// 06: set one holding register.
    WriteSingleRegister {
        /// First PDU address.
        address: u16,
        /// The value.
        value: u16,
    },
    /// 15: set consecutive coils.
    WriteMultipleCoils {
        /// First PDU address.
        address: u16,
        /// The values, in address order.
        values: Vec<bool>,
    },
    /// 16: set consecutive holding registers.
    WriteMultipleRegisters {
        /// First PDU address.
        address: u16,
        /// The values, in address order.
        values: Vec<u16>,
    },
    /// 08: diagnostics with one data word (sub-function 0000 echoes it back).
    Diagnostics {
        /// Diagnostics sub-function.
        sub_function: u16,
        /// Data word (echoed by sub-function 0000).
        data: u16,
    },
    /// 24: read the FIFO queue whose count register is at `address`.
    ReadFifoQueue {
        /// The FIFO pointer address: the queue's count register.
        address: u16,
    },
    /// 43 / MEI 0x0E: read device identification objects from `object_id` on.
    ReadDeviceId {
        /// Which objects: a category as a stream, or one object.
        code: ReadDeviceIdCode,
        /// The first object (stream access) or the one object (individual access).
        object_id: u8,
    },
}

/// A normal (non-exception) response PDU.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Response {
    /// 01: coil states, as many as requested.
    ReadCoils(Vec<bool>),
    /// 02: discrete input states, as many as requested.
    ReadDiscreteInputs(Vec<bool>),
    /// 03: holding register values.
    ReadHoldingRegisters(Vec<u16>),
    /// 04: input register values.
    ReadInputRegisters(Vec<u16>),
    /// 05: echo of the request.
    WriteSingleCoil {
        /// First PDU address.
        address: u16,
        /// The value.
        value: bool,
    },
    /// 06: echo of the request.
    WriteSingleRegister {
        /// First PDU address.
        address: u16,
        /// The value.
        value: u16,
    },
    /// 15: start address and count written.
    WriteMultipleCoils {
        /// First PDU address.
        address: u16,
        /// Number of items.
        count: u16,
    },
    /// 16: start address and count written.
    WriteMultipleRegisters {
        /// First PDU address.
        address: u16,
        /// Number of items.
        count: u16,
    },
    /// 08: echo of sub-function and data.
    Diagnostics {
        /// Diagnostics sub-function.
        sub_function: u16,
        /// Data word (echoed by sub-function 0000).
        data: u16,
    },
    /// 24: the queued registers (at most 31), oldest first.
    ReadFifoQueue(Vec<u16>),
    /// 43 / MEI 0x0E: one page of device identification objects.
    ReadDeviceId(DeviceIdPage),
}

impl Request {
    /// The request's function code.
    pub fn function(&self) -> u8 {
        match self {
            Request::ReadCoils { .. } => fc::READ_COILS,
            Request::ReadDiscreteInputs { .. } => fc::READ_DISCRETE_INPUTS,
            Request::ReadHoldingRegisters { .. } => fc::READ_HOLDING_REGISTERS,
            Request::ReadInputRegisters { .. } => fc::READ_INPUT_REGISTERS,
            Request::WriteSingleCoil { .. } => fc::WRITE_SINGLE_COIL,
            Request::WriteSingleRegister { .. } => fc::WRITE_SINGLE_REGISTER,
            Request::WriteMultipleCoils { .. } => fc::WRITE_MULTIPLE_COILS,
            Request::WriteMultipleRegisters { .. } => fc::WRITE_MULTIPLE_REGISTERS,
            Request::Diagnostics { .. } => fc::DIAGNOSTICS,
            Request::ReadFifoQueue { .. } => fc::READ_FIFO_QUEUE,
            Request::ReadDeviceId { .. } => fc::ENCAPSULATED,
        }
    }

    /// True for the writes (05, 06, 15, 16): the only requests that may be broadcast.
    pub fn is_write(&self) -> bool {
        matches!(
            self,
            Request::WriteSingleCoil { .. }
                | Request::WriteSingleRegister { .. }
                | Request::WriteMultipleCoils { .. }
                | Request::WriteMultipleRegisters { .. }
        )
    }

    /// Checks counts against the per-function limits and the 16-bit address space, so that
    /// [`Request::encode`] produces a frame a device can accept.
    pub fn check(&self) -> Result<(), &'static str> {
        let (address, count, max) = match self {
            Request::ReadCoils { address, count } | Request::ReadDiscreteInputs { address, count } => {
                (*address, *count as usize, MAX_READ_BITS)
            }
            Request::ReadHoldingRegisters { address, count }
            | Request::ReadInputRegisters { address, count } => {
                (*address, *count as usize, MAX_READ_REGISTERS)
            }
            Request::WriteMultipleCoils { address, values } => (*address, values.len(), MAX_WRITE_BITS),
            Request::WriteMultipleRegisters { address, values } => {
                (*address, values.len(), MAX_WRITE_REGISTERS)
            }
            _ => return Ok(()),
        };
        if count == 0 || count > max as usize {
            return Err("count outside the per-function limit");
        }
        if address as usize + count > 0x1_0000 {
            return Err("address + count beyond 65535");
        }
        Ok(())
    }

    /// Appends the PDU bytes to `buf`. Counts must be within limits (see [`Request::check`]).
    pub fn encode(&self, buf: &mut Vec<u8>) {
        buf.push(self.function());
        match self {
            Request::ReadCoils { address, count }
            | Request::ReadDiscreteInputs { address, count }
            | Request::ReadHoldingRegisters { address, count }
            | Request::ReadInputRegisters { address, count } => put_words(buf, &[*address, *count]),
            Request::WriteSingleCoil { address, value } => put_words(buf, &[*address, coil_word(*value)]),
            Request::WriteSingleRegister { address, value } => put_words(buf, &[*address, *value]),
            Request::WriteMultipleCoils { address, values } => {
                put_words(buf, &[*address, values.len() as u16]);
                buf.push(values.len().div_ceil(8) as u8);
                pack_bits(values, buf);
            }
            Request::WriteMultipleRegisters { address, values } => {
                put_words(buf, &[*address, values.len() as u16]);
                buf.push((values.len() * 2) as u8);
                put_words(buf, values);
            }
            Request::Diagnostics { sub_function, data } => put_words(buf, &[*sub_function, *data]),
            Request::ReadFifoQueue { address } => put_words(buf, &[*address]),
            Request::ReadDeviceId { code, object_id } => {
                buf.extend_from_slice(&[MEI_DEVICE_ID, *code as u8, *object_id])
            }
        }
    }
}

impl Response {
    /// The response's function code.
    pub fn function(&self) -> u8 {
        match self {
            Response::ReadCoils(_) => fc::READ_COILS,
            Response::ReadDiscreteInputs(_) => fc::READ_DISCRETE_INPUTS,
            Response::ReadHoldingRegisters(_) => fc::READ_HOLDING_REGISTERS,
            Response::ReadInputRegisters(_) => fc::READ_INPUT_REGISTERS,
            Response::WriteSingleCoil { .. } => fc::WRITE_SINGLE_COIL,
            Response::WriteSingleRegister { .. } => fc::WRITE_SINGLE_REGISTER,
            Response::WriteMultipleCoils { .. } => fc::WRITE_MULTIPLE_COILS,
            Response::WriteMultipleRegisters { .. } => fc::WRITE_MULTIPLE_REGISTERS,
            Response::Diagnostics { .. } => fc::DIAGNOSTICS,
            Response::ReadFifoQueue(_) => fc::READ_FIFO_QUEUE,
            Response::ReadDeviceId(_) => fc::ENCAPSULATED,
        }
    }

    /// Appends the PDU bytes to `buf`.
    pub fn encode(&self, buf: &mut Vec<u8>) {
        if let Response::ReadDeviceId(page) = self {
            return page.encode(buf);
        }
        buf.push(self.function());
        match self {
            Response::ReadCoils(bits) | Response::ReadDiscreteInputs(bits) => {
                buf.push(bits.len().div_ceil(8) as u8);
                pack_bits(bits, buf);
            }
            Response::ReadHoldingRegisters(words) | Response::ReadInputRegisters(words) => {
                buf.push((words.len() * 2) as u8);
                put_words(buf, words);
            }
            Response::WriteSingleCoil { address, value } => put_words(buf, &[*address, coil_word(*value)]),
            Response::WriteSingleRegister { address, value } => put_words(buf, &[*address, *value]),
            Response::WriteMultipleCoils { address, count }
            | Response::WriteMultipleRegisters { address, count } => put_words(buf, &[*address, *count]),
            Response::Diagnostics { sub_function, data } => put_words(buf, &[*sub_function, *data]),
            Response::ReadFifoQueue(words) => {
                put_words(buf, &[(2 + words.len() * 2) as u16, words.len() as u16]);
                put_words(buf, words);
            }
            Response::ReadDeviceId(_) => {}
        }
    }
}

impl DeviceIdPage {
    /// Appends the Read Device Identification reply PDU.
    pub fn encode(&self, out: &mut Vec<u8>) {
        let (more, next) = match self.next {
            Some(id) => (0xFF, id),
            None => (0x00, 0x00),
        };
        out.extend_from_slice(&[fc::ENCAPSULATED, MEI_DEVICE_ID, self.code as u8]);
        out.extend_from_slice(&[self.conformity, more, next, self.objects.len() as u8]);
        for o in &self.objects {
            out.extend_from_slice(&[o.id, o.value.len() as u8]);
            out.extend_from_slice(&o.value);
        }
    }
}

/// Appends an exception reply PDU for `function`.
pub fn encode_exception(function: u8, code: u8, buf: &mut Vec<u8>) {
    buf.push(function | fc::EXCEPTION_FLAG);
    buf.push(code);
}

/// The value of a coil in 05 requests and replies: FF00 on, 0000 off.
fn coil_word(on: bool) -> u16 {
    if on { 0xFF00 } else { 0x0000 }
}

fn put_words(buf: &mut Vec<u8>, words: &[u16]) {
    for w in words {
        buf.extend_from_slice(&w.to_be_bytes());
    }
}

/// Packs bits LSB first, eight to a byte, the last byte padded with zeros.
pub(crate) fn pack_bits(bits: &[bool], buf: &mut Vec<u8>) {
    for chunk in bits.chunks(8) {
        buf.push(chunk.iter().enumerate().fold(0u8, |b, (i, &on)| b | (u8::from(on) << i)));
    }
}

/// Unpacks the first `count` bits (LSB first) of `bytes`; `bytes` must hold at least `count` bits.
pub(crate) fn unpack_bits(bytes: &[u8], count: usize) -> Vec<bool> {
    (0..count).map(|i| bytes[i / 8] & (1 << (i % 8)) != 0).collect()
}
