//! The register bank behind a simulated device: the four Modbus tables, shared.
//!
//! [`Bank`] is a cheap handle (`Arc<Mutex<RegisterBank>>`): the server and the simulator
//! that owns the device logic hold clones of it. A simulator reads and changes registers
//! with [`Bank::lock`] (e.g. a shelf PLC setting a slot's execution state), and can watch
//! every request by wrapping the bank in its own [`super::Handler`].

use std::sync::{Arc, Mutex, MutexGuard};

use super::handler::Handler;
use crate::protocols::modbus::exception::Exception;
use crate::protocols::modbus::pdu::{self, Request, Response};

/// Items in each table: the whole 16-bit address range.
pub const TABLE_SIZE: usize = 0x1_0000;

/// The four tables of a Modbus device, each covering addresses 0..65535.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RegisterBank {
    /// `0x` coils.
    pub coils: Vec<bool>,
    /// `1x` discrete inputs.
    pub discrete_inputs: Vec<bool>,
    /// `3x` input registers.
    pub input_registers: Vec<u16>,
    /// `4x` holding registers.
    pub holding_registers: Vec<u16>,
}

impl Default for RegisterBank {
    fn default() -> Self {
        RegisterBank {
            coils: vec![false; TABLE_SIZE],
            discrete_inputs: vec![false; TABLE_SIZE],
            input_registers: vec![0; TABLE_SIZE],
            holding_registers: vec![0; TABLE_SIZE],
        }
    }
}

/// The items `address .. address + count` of a table, or exception 02.
fn range<T>(table: &[T], address: u16, count: usize) -> Result<&[T], Exception> {
    table.get(address as usize..address as usize + count).ok_or(Exception::ILLEGAL_DATA_ADDRESS)
}

fn range_mut<T>(table: &mut [T], address: u16, count: usize) -> Result<&mut [T], Exception> {
    table.get_mut(address as usize..address as usize + count).ok_or(Exception::ILLEGAL_DATA_ADDRESS)
}

impl RegisterBank {
    /// Performs one request on the tables, as a device would.
    pub fn apply(&mut self, request: &Request) -> Result<Response, Exception> {
        Ok(match request {
            Request::ReadCoils { address, count } => {
                Response::ReadCoils(range(&self.coils, *address, *count as usize)?.to_vec())
            }
            Request::ReadDiscreteInputs { address, count } => Response::ReadDiscreteInputs(
                range(&self.discrete_inputs, *address, *count as usize)?.to_vec(),
            ),
            Request::ReadHoldingRegisters { address, count } => Response::ReadHoldingRegisters(
                range(&self.holding_registers, *address, *count as usize)?.to_vec(),
            ),
            Request::ReadInputRegisters { address, count } => Response::ReadInputRegisters(
                range(&self.input_registers, *address, *count as usize)?.to_vec(),
            ),
            Request::WriteSingleCoil { address, value } => {
                range_mut(&mut self.coils, *address, 1)?[0] = *value;
                Response::WriteSingleCoil { address: *address, value: *value }
            }
            Request::WriteSingleRegister { address, value } => {
                range_mut(&mut self.holding_registers, *address, 1)?[0] = *value;
                Response::WriteSingleRegister { address: *address, value: *value }
            }
            Request::WriteMultipleCoils { address, values } => {
                range_mut(&mut self.coils, *address, values.len())?.copy_from_slice(values);
                Response::WriteMultipleCoils { address: *address, count: values.len() as u16 }
            }
            Request::WriteMultipleRegisters { address, values } => {
                range_mut(&mut self.holding_registers, *address, values.len())?.copy_from_slice(values);
                Response::WriteMultipleRegisters { address: *address, count: values.len() as u16 }
            }
            Request::Diagnostics { sub_function, data } => {
                Response::Diagnostics { sub_function: *sub_function, data: *data }
            }
            // The count register at the pointer, then the queued registers; reading does
            // not empty the queue (spec V1.1b3 section 6.18).
            Request::ReadFifoQueue { address } => {
                let count = range(&self.holding_registers, *address, 1)?[0];
                if count > pdu::MAX_FIFO_COUNT {
                    return Err(Exception::ILLEGAL_DATA_VALUE);
                }
                let first = address.checked_add(1).ok_or(Exception::ILLEGAL_DATA_ADDRESS)?;
                Response::ReadFifoQueue(range(&self.holding_registers, first, count as usize)?.to_vec())
            }
            // Answered by the server from its options' identification, never by the tables.
            Request::ReadDeviceId { .. } => return Err(Exception::ILLEGAL_FUNCTION),
        })
    }
}

/// A shared handle to a [`RegisterBank`]; clones see the same tables.
#[derive(Clone, Debug, Default)]
pub struct Bank(Arc<Mutex<RegisterBank>>);

impl Bank {
    /// A bank with every item 0 / off.
    pub fn new() -> Self {
        Bank::default()
    }

    /// Locks the tables for reading or changing them. Keep the guard short: the server
    /// waits on it.
    pub fn lock(&self) -> MutexGuard<'_, RegisterBank> {
        // A panic while holding the lock leaves plain data behind; keep serving it.
        self.0.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    /// Holding registers `address .. address + count` (clamped to the table).
    pub fn holding(&self, address: u16, count: usize) -> Vec<u16> {
        let bank = self.lock();
        let end = (address as usize + count).min(TABLE_SIZE);
        bank.holding_registers[address as usize..end].to_vec()
    }

    /// Sets holding registers from `address` on (values past 65535 are ignored).
    pub fn set_holding(&self, address: u16, values: &[u16]) {
        let mut bank = self.lock();
        let start = address as usize;
        let end = (start + values.len()).min(TABLE_SIZE);
        bank.holding_registers[start..end].copy_from_slice(&values[..end - start]);
    }
}

impl Handler for Bank {
    fn handle(&self, _unit: u8, request: &Request) -> Result<Response, Exception> {
        self.lock().apply(request)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn apply_reads_what_was_written_and_checks_ranges() {
        let mut bank = RegisterBank::default();
        let w = Request::WriteMultipleRegisters { address: 65534, values: vec![7, 8] };
        assert_eq!(bank.apply(&w), Ok(Response::WriteMultipleRegisters { address: 65534, count: 2 }));
        let r = Request::ReadHoldingRegisters { address: 65534, count: 2 };
        assert_eq!(bank.apply(&r), Ok(Response::ReadHoldingRegisters(vec![7, 8])));
        let r = Request::ReadHoldingRegisters { address: 65535, count: 2 };
        assert_eq!(bank.apply(&r), Err(Exception::ILLEGAL_DATA_ADDRESS));
        bank.apply(&Request::WriteSingleCoil { address: 9, value: true }).unwrap();
        assert_eq!(
            bank.apply(&Request::ReadCoils { address: 8, count: 3 }),
            Ok(Response::ReadCoils(vec![false, true, false]))
        );
    }

    #[test]
    fn bank_handle_is_shared() {
        let bank = Bank::new();
        let other = bank.clone();
        other.set_holding(4700, &[10000, 10001]);
        assert_eq!(bank.holding(4700, 3), vec![10000, 10001, 0]);
        assert_eq!(bank.holding(65535, 5), vec![0]);
    }
}
