//! [`PlcMemory`] for the Modbus client: `0x`/`1x`/`3x`/`4x` addresses, and requests split
//! at the per-function limits.
//!
//! A single word or bit is written with 06 or 05 (as the shelf PLC's seed does), more with
//! 16 or 15 in chunks of at most 123 registers or 1968 coils. Reads are split in chunks of
//! 125 registers or 2000 bits. Chunks go out in address order; if one fails, the call fails
//! and the earlier chunks stay written.

use async_trait::async_trait;

use super::address::{self, Table};
use super::client::ModbusClient;
use super::pdu::{self, Request, Response};
use crate::protocols::{Address, PlcError, PlcMemory};

fn unexpected() -> PlcError {
    PlcError::Malformed("reply of the wrong kind")
}

impl ModbusClient {
    async fn read_chunk(&self, table: Table, address: u16, count: u16) -> Result<Response, PlcError> {
        let request = match table {
            Table::Coils => Request::ReadCoils { address, count },
            Table::DiscreteInputs => Request::ReadDiscreteInputs { address, count },
            Table::InputRegisters => Request::ReadInputRegisters { address, count },
            Table::HoldingRegisters => Request::ReadHoldingRegisters { address, count },
        };
        self.call(&request).await
    }
}

/// Splits `count` items from `first` into (address, count) chunks of at most `max`.
fn chunks(first: u16, count: usize, max: u16) -> impl Iterator<Item = (u16, u16)> {
    (0..count).step_by(max as usize).map(move |done| {
        let n = (count - done).min(max as usize);
        (first + done as u16, n as u16)
    })
}

#[async_trait]
impl PlcMemory for ModbusClient {
    fn link_stats(&self) -> crate::protocols::transport::LinkStats {
        self.link_stats()
    }

    fn recorder(&self) -> Option<std::sync::Arc<crate::capture::Recorder>> {
        self.recorder()
    }

    fn parse_address(&self, text: &str) -> Result<Address, PlcError> {
        address::parse(text)
    }

    async fn read_words(&self, start: &Address, count: u16) -> Result<Vec<u16>, PlcError> {
        let (table, first) = address::resolve(start, count as usize)?;
        if !table.holds_words() {
            return Err(PlcError::OutOfRange("words are read from 3x or 4x"));
        }
        let mut words = Vec::with_capacity(count as usize);
        for (address, n) in chunks(first, count as usize, pdu::MAX_READ_REGISTERS) {
            match self.read_chunk(table, address, n).await? {
                Response::ReadHoldingRegisters(w) | Response::ReadInputRegisters(w) => words.extend(w),
                _ => return Err(unexpected()),
            }
        }
        Ok(words)
    }

    async fn write_words(&self, start: &Address, values: &[u16]) -> Result<(), PlcError> {
        let (table, first) = address::resolve(start, values.len())?;
        if table != Table::HoldingRegisters {
            return Err(PlcError::OutOfRange("words are written to 4x only"));
        }
        if let [value] = values {
            self.call(&Request::WriteSingleRegister { address: first, value: *value }).await?;
            return Ok(());
        }
        for (address, n) in chunks(first, values.len(), pdu::MAX_WRITE_REGISTERS) {
            let at = (address - first) as usize;
            let values = values[at..at + n as usize].to_vec();
            self.call(&Request::WriteMultipleRegisters { address, values }).await?;
        }
        Ok(())
    }

    async fn read_bits(&self, start: &Address, count: u16) -> Result<Vec<bool>, PlcError> {
        let (table, first) = address::resolve(start, count as usize)?;
        if table.holds_words() {
            return Err(PlcError::OutOfRange("bits are read from 0x or 1x"));
        }
        let mut bits = Vec::with_capacity(count as usize);
        for (address, n) in chunks(first, count as usize, pdu::MAX_READ_BITS) {
            match self.read_chunk(table, address, n).await? {
                Response::ReadCoils(b) | Response::ReadDiscreteInputs(b) => bits.extend(b),
                _ => return Err(unexpected()),
            }
        }
        Ok(bits)
    }

    async fn write_bits(&self, start: &Address, values: &[bool]) -> Result<(), PlcError> {
        let (table, first) = address::resolve(start, values.len())?;
        if table != Table::Coils {
            return Err(PlcError::OutOfRange("bits are written to 0x only"));
        }
        if let [value] = values {
            self.call(&Request::WriteSingleCoil { address: first, value: *value }).await?;
            return Ok(());
        }
        for (address, n) in chunks(first, values.len(), pdu::MAX_WRITE_BITS) {
            let at = (address - first) as usize;
            let values = values[at..at + n as usize].to_vec();
            self.call(&Request::WriteMultipleCoils { address, values }).await?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::chunks;

    #[test]
    fn chunks_split_at_the_limit() {
        let c: Vec<_> = chunks(65000, 300, 125).collect();
        assert_eq!(c, vec![(65000, 125), (65125, 125), (65250, 50)]);
        assert_eq!(chunks(0, 125, 125).collect::<Vec<_>>(), vec![(0, 125)]);
        let last: Vec<_> = chunks(65535 - 1999, 2000, 2000).collect();
        assert_eq!(last, vec![(63536, 2000)]);
    }
}
