//! What a Siemens S7-1200 running `Modbus_Slave` (on a CM/CB RS-485 port) accepts, so the
//! RTU shelf simulator answers like that PLC (spec: modbus.md, seed 003; Siemens S7-1200
//! system manual, Modbus_Slave address mapping).
//!
//! Mirrored:
//! - Holding registers (03 read, 06 write, 16 write) are `MB_HOLD_REG`, a data block mapped
//!   from PDU address 0 (40001): the task-slot DB, `hold_words` long. Anything past its end
//!   is refused with exception 02, as is any part of a request that runs past it.
//! - Coils (01, 05, 15) are the output process image Q0.0..Q1023.7 (8192 bits), discrete
//!   inputs (02) the input image I0.0..I1023.7, input registers (04) IW0..IW1022 (512
//!   words); past those, exception 02.
//! - Diagnostics 08: sub-function 0000 echoes its data, 000A clears the counters and echoes;
//!   others are refused with exception 01 (the S7-1200 implements no more).
//! - Counts beyond the Modbus limits (125 registers read, 123 written, 2000 / 1968 bits)
//!   get exception 03, and an unknown function exception 01 where the frame can be
//!   delimited: the server's codec does that for every transport.
//! - Its station address (`MB_ADDR`, 1..=247) only; broadcasts (unit 0) of writes to valid
//!   addresses are carried out without reply. Normal RTU framing with CRC-16, no MBAP.
//!
//! Not mirrored: function 11 (get communication event counter) — rackd's Modbus codec does
//! not know it, so its RTU frames cannot be delimited and go unanswered; the HR_Start_Offset
//! and per-area access limits of newer Modbus_Slave versions (use `base` to move the slots).

use crate::protocols::modbus::exception::Exception;
use crate::protocols::modbus::pdu::{DIAG_CLEAR_COUNTERS, DIAG_RETURN_QUERY_DATA, Request};

/// Bits in the S7-1200's process images (1024 bytes each).
const IMAGE_BITS: u32 = 8192;
/// Words of the input image readable as input registers (IW0..IW1022).
const INPUT_WORDS: u32 = 512;

/// The address ranges an S7-1200 Modbus_Slave serves.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct S7Mapping {
    /// Words of the `MB_HOLD_REG` data block, from PDU address 0.
    pub hold_words: u32,
}

impl S7Mapping {
    /// Refuses what the PLC would refuse, before the request reaches the bank.
    pub fn admit(&self, request: &Request) -> Result<(), Exception> {
        let within = |address: u16, count: usize, size: u32| {
            if address as u32 + count as u32 <= size { Ok(()) } else { Err(Exception::ILLEGAL_DATA_ADDRESS) }
        };
        match request {
            Request::ReadCoils { address, count } | Request::ReadDiscreteInputs { address, count } => {
                within(*address, *count as usize, IMAGE_BITS)
            }
            Request::ReadInputRegisters { address, count } => within(*address, *count as usize, INPUT_WORDS),
            Request::ReadHoldingRegisters { address, count } => {
                within(*address, *count as usize, self.hold_words)
            }
            Request::WriteSingleCoil { address, .. } => within(*address, 1, IMAGE_BITS),
            Request::WriteMultipleCoils { address, values } => within(*address, values.len(), IMAGE_BITS),
            Request::WriteSingleRegister { address, .. } => within(*address, 1, self.hold_words),
            Request::WriteMultipleRegisters { address, values } => {
                within(*address, values.len(), self.hold_words)
            }
            Request::Diagnostics { sub_function, .. } => match *sub_function {
                DIAG_RETURN_QUERY_DATA | DIAG_CLEAR_COUNTERS => Ok(()),
                _ => Err(Exception::ILLEGAL_FUNCTION),
            },
            // Modbus_Slave has no device identification and no FIFO queue.
            Request::ReadDeviceId { .. } | Request::ReadFifoQueue { .. } => Err(Exception::ILLEGAL_FUNCTION),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refuses_what_lies_outside_the_plcs_areas() {
        let plc = S7Mapping { hold_words: 6000 };
        let ok = |r: Request| assert_eq!(plc.admit(&r), Ok(()), "{r:?}");
        let refused = |r: Request, e: Exception| assert_eq!(plc.admit(&r), Err(e), "{r:?}");
        ok(Request::ReadHoldingRegisters { address: 5965, count: 35 });
        refused(Request::ReadHoldingRegisters { address: 5966, count: 35 }, Exception::ILLEGAL_DATA_ADDRESS);
        ok(Request::WriteSingleRegister { address: 5999, value: 1 });
        refused(Request::WriteSingleRegister { address: 6000, value: 1 }, Exception::ILLEGAL_DATA_ADDRESS);
        refused(
            Request::WriteMultipleRegisters { address: 5990, values: vec![0; 11] },
            Exception::ILLEGAL_DATA_ADDRESS,
        );
        ok(Request::ReadCoils { address: 8190, count: 2 });
        refused(Request::WriteSingleCoil { address: 8192, value: true }, Exception::ILLEGAL_DATA_ADDRESS);
        refused(Request::ReadDiscreteInputs { address: 8000, count: 193 }, Exception::ILLEGAL_DATA_ADDRESS);
        ok(Request::ReadInputRegisters { address: 511, count: 1 });
        refused(Request::ReadInputRegisters { address: 512, count: 1 }, Exception::ILLEGAL_DATA_ADDRESS);
        ok(Request::Diagnostics { sub_function: DIAG_RETURN_QUERY_DATA, data: 0x1234 });
        ok(Request::Diagnostics { sub_function: DIAG_CLEAR_COUNTERS, data: 0 });
        refused(Request::Diagnostics { sub_function: 0x0001, data: 0 }, Exception::ILLEGAL_FUNCTION);
    }
}
