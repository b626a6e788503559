//! The S7-200 memory from the field's side, and the server handler that keeps its
//! read-only ranges against a master's writes (item return code 0x03, access denied).
//!
//! Every area is kept in bits here, so `VW100`, `VB101` and `V101.3` are the same items;
//! timers and counters take 16 bits per number.

use std::ops::Range;
use std::sync::{Arc, Mutex, MutexGuard};

use super::{ProtectError, SimMemory, Span, items};
use crate::protocols::ppi::address::{self, Target};
use crate::protocols::ppi::return_code::ACCESS_DENIED;
use crate::protocols::ppi::server::Handler;
use crate::protocols::ppi::{Bank, Item, MemArea, Reply, Request, SharedBank, Size};
use crate::protocols::read_only::ReadOnly;
use crate::protocols::{Address, PlcError};

/// A PPI bank with read-only ranges; serve it with [`PpiMemory::handler`].
#[derive(Clone)]
pub struct PpiMemory {
    bank: SharedBank,
    read_only: Arc<Mutex<ReadOnly<MemArea>>>,
}

/// The bits a write item covers.
fn item_bits(item: &Item) -> Range<u64> {
    let offset = u64::from(item.offset);
    match item.size {
        Size::Bit => items(offset, 1),
        Size::Timer | Size::Counter => items(offset * 16, u64::from(item.count) * 16),
        _ => items(offset, item.data_len() as u64 * 8),
    }
}

/// Bytes per word value an address's words take (a `VB` item holds one byte).
fn bytes_per_word(size: Size) -> usize {
    if size == Size::Byte { 1 } else { 2 }
}

impl PpiMemory {
    /// The memory over `bank`, nothing read-only.
    pub fn new(bank: SharedBank) -> Self {
        PpiMemory { bank, read_only: Arc::default() }
    }

    /// The server handler: refuses a master's write into a read-only range with item
    /// return code 0x03, carries out everything else on the bank.
    pub fn handler(&self) -> Handler {
        let read_only = self.read_only.clone();
        Arc::new(move |bank: &mut Bank, request: &Request| {
            if let Request::Write(item, _) = request {
                let mut read_only = read_only.lock().unwrap_or_else(|p| p.into_inner());
                if read_only.refuses(&item.area, item_bits(item)) {
                    return Reply::ItemError(ACCESS_DENIED);
                }
            }
            bank.execute(request)
        })
    }

    fn lock(&self) -> MutexGuard<'_, Bank> {
        self.bank.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// The target, and the bits `count` words (bytes for `VB`) or bits from `start` cover,
    /// checked against the area's size.
    fn bits(&self, start: &Address, count: u32) -> Result<(Target, Range<u64>), PlcError> {
        let target = address::resolve(start)?;
        let index = u64::from(target.index);
        let count = u64::from(count);
        let bits = match target.size {
            Size::Bit => items(index, count),
            Size::Timer | Size::Counter => items(index * 16, count * 16),
            Size::DWord if count % 2 != 0 => {
                return Err(PlcError::OutOfRange("double words are an even number of words"));
            }
            size => items(index * 8, count * bytes_per_word(size) as u64 * 8),
        };
        let size = self.lock().bytes(target.area).len() as u64;
        if count == 0 || bits.end > size * 8 {
            return Err(PlcError::OutOfRange("past the end of the simulated S7 area"));
        }
        Ok((target, bits))
    }

    /// The bytes of `count` words from `start`, for reading or writing.
    fn byte_range(&self, start: &Address, count: usize) -> Result<(Target, Range<usize>), PlcError> {
        let (target, bits) = self.bits(start, count as u32)?;
        if target.size == Size::Bit {
            return Err(PlcError::OutOfRange("bits are read and written with read_bits / write_bits"));
        }
        Ok((target, bits.start as usize / 8..bits.end as usize / 8))
    }
}

impl SimMemory for PpiMemory {
    fn read_words(&self, start: &Address, count: u16) -> Result<Vec<u16>, PlcError> {
        let (target, bytes) = self.byte_range(start, count.into())?;
        let bank = self.lock();
        let bytes = &bank.bytes(target.area)[bytes];
        Ok(match target.size {
            Size::Byte => bytes.iter().map(|&b| b.into()).collect(),
            _ => bytes.chunks(2).map(|c| u16::from_be_bytes([c[0], c[1]])).collect(),
        })
    }

    fn write_words(&self, start: &Address, values: &[u16]) -> Result<(), PlcError> {
        let (target, bytes) = self.byte_range(start, values.len())?;
        let data: Vec<u8> = match target.size {
            Size::Byte => values
                .iter()
                .map(|&v| u8::try_from(v).map_err(|_| PlcError::OutOfRange("byte values are 0..=255")))
                .collect::<Result<_, _>>()?,
            _ => values.iter().flat_map(|v| v.to_be_bytes()).collect(),
        };
        self.lock().bytes_mut(target.area)[bytes].copy_from_slice(&data);
        Ok(())
    }

    fn read_bits(&self, start: &Address, count: u16) -> Result<Vec<bool>, PlcError> {
        let (target, bits) = self.bits(start, count.into())?;
        if target.size != Size::Bit {
            return Err(PlcError::OutOfRange("words are read with read_words"));
        }
        let bank = self.lock();
        let area = bank.bytes(target.area);
        Ok(bits.map(|n| area[n as usize / 8] & (1 << (n % 8)) != 0).collect())
    }

    fn write_bits(&self, start: &Address, values: &[bool]) -> Result<(), PlcError> {
        let (target, bits) = self.bits(start, values.len() as u32)?;
        if target.size != Size::Bit {
            return Err(PlcError::OutOfRange("words are written with write_words"));
        }
        let mut bank = self.lock();
        let area = bank.bytes_mut(target.area);
        for (n, &on) in bits.zip(values) {
            let (byte, mask) = (n as usize / 8, 1 << (n % 8));
            area[byte] = if on { area[byte] | mask } else { area[byte] & !mask };
        }
        Ok(())
    }

    fn span(&self, start: &Address, count: u32) -> Result<Span, PlcError> {
        let (target, items) = self.bits(start, count)?;
        Ok(Span { area: format!("{:?}", target.area), items })
    }

    fn protect(&self, start: &Address, count: u32) -> Result<(), ProtectError> {
        let (target, items) = self.bits(start, count)?;
        let mut read_only = self.read_only.lock().unwrap_or_else(|p| p.into_inner());
        Ok(read_only.add(target.area, items)?)
    }

    fn refused(&self) -> u64 {
        self.read_only.lock().unwrap_or_else(|p| p.into_inner()).refused()
    }
}
