//! The MC device memory from the field's side; its read-only ranges live in the bank,
//! where the server's writes go through.

use super::{ProtectError, SimMemory, Span, items};
use crate::protocols::mc3e::{Device, EndCode, SharedBank};
use crate::protocols::{Address, DeviceCode, PlcError};

/// An MC bank as the field sees it.
#[derive(Clone)]
pub struct Mc3eMemory {
    bank: SharedBank,
}

/// A bank error (an end code) as the field's error: the end code's meaning.
fn refused(code: u16) -> PlcError {
    PlcError::Device(DeviceCode::Mc3e(EndCode(code)))
}

impl Mc3eMemory {
    /// The memory over `bank`.
    pub fn new(bank: SharedBank) -> Self {
        Mc3eMemory { bank }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, crate::protocols::mc3e::Bank> {
        self.bank.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// The device and the points `count` words (word devices) or bits (bit devices) from
    /// `start` cover.
    fn points(&self, start: &Address, count: u32) -> Result<(Device, std::ops::Range<u64>), PlcError> {
        let device = Device::of_area(&start.area)?;
        let range = items(start.index.into(), count.into());
        if count == 0 || range.end > u64::from(self.lock().size(device)) {
            return Err(PlcError::OutOfRange("past the end of the simulated device"));
        }
        Ok((device, range))
    }
}

impl SimMemory for Mc3eMemory {
    fn read_words(&self, start: &Address, count: u16) -> Result<Vec<u16>, PlcError> {
        let device = Device::of_area(&start.area)?;
        self.lock().read_words(device, start.index, count).map_err(refused)
    }

    fn write_words(&self, start: &Address, values: &[u16]) -> Result<(), PlcError> {
        let device = Device::of_area(&start.area)?;
        self.lock().set_words(device, start.index, values).map_err(refused)
    }

    fn read_bits(&self, start: &Address, count: u16) -> Result<Vec<bool>, PlcError> {
        let device = Device::of_area(&start.area)?;
        self.lock().read_bits(device, start.index, count).map_err(refused)
    }

    fn write_bits(&self, start: &Address, values: &[bool]) -> Result<(), PlcError> {
        let device = Device::of_area(&start.area)?;
        self.lock().set_bits(device, start.index, values).map_err(refused)
    }

    fn span(&self, start: &Address, count: u32) -> Result<Span, PlcError> {
        let (device, items) = self.points(start, count)?;
        Ok(Span { area: device.name().to_owned(), items })
    }

    fn protect(&self, start: &Address, count: u32) -> Result<(), ProtectError> {
        let (device, items) = self.points(start, count)?;
        Ok(self.lock().protect(device, start.index, (items.end - items.start) as u32)?)
    }

    fn refused(&self) -> u64 {
        self.lock().read_only().refused()
    }
}
