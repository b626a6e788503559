//! The Modbus register bank from the field's side, and the handler that keeps its
//! read-only ranges against a master's writes.

use std::sync::{Arc, Mutex};

use super::{ProtectError, SimMemory, Span, items};
use crate::protocols::modbus::Exception;
use crate::protocols::modbus::address::{self, Table};
use crate::protocols::modbus::pdu::{Request, Response};
use crate::protocols::modbus::server::{Bank, Handler};
use crate::protocols::read_only::ReadOnly;
use crate::protocols::{Address, PlcError};

/// A Modbus bank with read-only ranges; serve it as the server's [`Handler`].
#[derive(Clone, Default)]
pub struct ModbusMemory {
    bank: Bank,
    read_only: Arc<Mutex<ReadOnly<Table>>>,
}

/// The table and items a write request touches; `None` for reads.
fn written(request: &Request) -> Option<(Table, std::ops::Range<u64>)> {
    let (table, address, count) = match request {
        Request::WriteSingleCoil { address, .. } => (Table::Coils, address, 1),
        Request::WriteSingleRegister { address, .. } => (Table::HoldingRegisters, address, 1),
        Request::WriteMultipleCoils { address, values } => (Table::Coils, address, values.len()),
        Request::WriteMultipleRegisters { address, values } => {
            (Table::HoldingRegisters, address, values.len())
        }
        _ => return None,
    };
    Some((table, items(u64::from(*address), count as u64)))
}

impl ModbusMemory {
    /// The memory over `bank`, nothing read-only.
    pub fn new(bank: Bank) -> Self {
        ModbusMemory { bank, read_only: Arc::default() }
    }

    /// The bank served.
    pub fn bank(&self) -> &Bank {
        &self.bank
    }

    fn read_only(&self) -> std::sync::MutexGuard<'_, ReadOnly<Table>> {
        self.read_only.lock().unwrap_or_else(|p| p.into_inner())
    }

    fn table(start: &Address, count: usize) -> Result<(Table, usize), PlcError> {
        let (table, first) = address::resolve(start, count)?;
        Ok((table, first as usize))
    }
}

impl Handler for ModbusMemory {
    fn handle(&self, unit: u8, request: &Request) -> Result<Response, Exception> {
        if let Some((table, items)) = written(request)
            && self.read_only().refuses(&table, items)
        {
            return Err(Exception::ILLEGAL_DATA_ADDRESS);
        }
        self.bank.handle(unit, request)
    }
}

impl SimMemory for ModbusMemory {
    fn read_words(&self, start: &Address, count: u16) -> Result<Vec<u16>, PlcError> {
        let (table, first) = Self::table(start, count as usize)?;
        let bank = self.bank.lock();
        let words = match table {
            Table::HoldingRegisters => &bank.holding_registers,
            Table::InputRegisters => &bank.input_registers,
            _ => return Err(PlcError::OutOfRange("coils and discrete inputs are bits")),
        };
        Ok(words[first..first + count as usize].to_vec())
    }

    fn write_words(&self, start: &Address, values: &[u16]) -> Result<(), PlcError> {
        let (table, first) = Self::table(start, values.len())?;
        let mut bank = self.bank.lock();
        let words = match table {
            Table::HoldingRegisters => &mut bank.holding_registers,
            Table::InputRegisters => &mut bank.input_registers,
            _ => return Err(PlcError::OutOfRange("coils and discrete inputs are bits")),
        };
        words[first..first + values.len()].copy_from_slice(values);
        Ok(())
    }

    fn read_bits(&self, start: &Address, count: u16) -> Result<Vec<bool>, PlcError> {
        let (table, first) = Self::table(start, count as usize)?;
        let bank = self.bank.lock();
        let bits = match table {
            Table::Coils => &bank.coils,
            Table::DiscreteInputs => &bank.discrete_inputs,
            _ => return Err(PlcError::OutOfRange("registers are words")),
        };
        Ok(bits[first..first + count as usize].to_vec())
    }

    fn write_bits(&self, start: &Address, values: &[bool]) -> Result<(), PlcError> {
        let (table, first) = Self::table(start, values.len())?;
        let mut bank = self.bank.lock();
        let bits = match table {
            Table::Coils => &mut bank.coils,
            Table::DiscreteInputs => &mut bank.discrete_inputs,
            _ => return Err(PlcError::OutOfRange("registers are words")),
        };
        bits[first..first + values.len()].copy_from_slice(values);
        Ok(())
    }

    fn span(&self, start: &Address, count: u32) -> Result<Span, PlcError> {
        let (table, first) = Self::table(start, count as usize)?;
        Ok(Span { area: table.area_name().to_owned(), items: items(first as u64, count.into()) })
    }

    fn protect(&self, start: &Address, count: u32) -> Result<(), ProtectError> {
        let (table, first) = Self::table(start, count as usize)?;
        Ok(self.read_only().add(table, items(first as u64, count.into()))?)
    }

    fn refused(&self) -> u64 {
        self.read_only().refused()
    }
}
