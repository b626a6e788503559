//! The MEWTOCOL memory from the field's side, and the server handler that keeps its
//! read-only ranges against a master's writes (error 65, protect error).

use std::ops::Range;
use std::sync::{Arc, Mutex, MutexGuard};

use super::{ProtectError, SimMemory, Span, items};
use crate::protocols::mewtocol::address::{self, Target};
use crate::protocols::mewtocol::error_code::PROTECT_ERROR;
use crate::protocols::mewtocol::server::Handler;
use crate::protocols::mewtocol::{Bank, ContactArea, Request, SharedBank};
use crate::protocols::read_only::ReadOnly;
use crate::protocols::{Address, PlcError};

/// Where MEWTOCOL memory lives: data registers (in words) or a contact area (in bits, so
/// `WX0` and `X0`..`XF` are the same items).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Region {
    Dt,
    Contacts(ContactArea),
}

impl Region {
    fn name(self) -> String {
        match self {
            Region::Dt => "DT".to_owned(),
            Region::Contacts(area) => format!("{area:?}"),
        }
    }
}

/// A MEWTOCOL bank with read-only ranges; serve it with [`MewtocolMemory::handler`].
#[derive(Clone)]
pub struct MewtocolMemory {
    bank: SharedBank,
    read_only: Arc<Mutex<ReadOnly<Region>>>,
}

fn out_of_range() -> PlcError {
    PlcError::OutOfRange("past the end of the simulated MEWTOCOL area")
}

/// The regions and items a write command touches; empty for reads.
fn written(request: &Request) -> Vec<(Region, Range<u64>)> {
    let bit = |c: &crate::protocols::mewtocol::Contact| {
        (Region::Contacts(c.area), items(u64::from(c.word) * 16 + u64::from(c.bit), 1))
    };
    match request {
        Request::WriteContact(c, _) => vec![bit(c)],
        Request::WriteContacts(list) => list.iter().map(|(c, _)| bit(c)).collect(),
        Request::WriteContactWords { area, start, values } => {
            vec![(Region::Contacts(*area), items(u64::from(*start) * 16, values.len() as u64 * 16))]
        }
        Request::WriteData { start, values } => {
            vec![(Region::Dt, items((*start).into(), values.len() as u64))]
        }
        _ => Vec::new(),
    }
}

impl MewtocolMemory {
    /// The memory over `bank`, nothing read-only.
    pub fn new(bank: SharedBank) -> Self {
        MewtocolMemory { bank, read_only: Arc::default() }
    }

    /// The server handler: refuses a master's write into a read-only range with error 65,
    /// carries out everything else on the bank.
    pub fn handler(&self) -> Handler {
        let read_only = self.read_only.clone();
        Arc::new(move |bank: &mut Bank, request: &Request| {
            let touched = written(request);
            let mut read_only = read_only.lock().unwrap_or_else(|p| p.into_inner());
            if touched.into_iter().any(|(region, items)| read_only.refuses(&region, items)) {
                return Err(PROTECT_ERROR);
            }
            bank.execute(request)
        })
    }

    fn lock(&self) -> MutexGuard<'_, Bank> {
        self.bank.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// The region and items `count` words or bits from `start` cover.
    fn region(&self, start: &Address, count: u32) -> Result<(Region, Range<u64>), PlcError> {
        if count == 0 {
            return Err(PlcError::OutOfRange("count must be at least 1"));
        }
        let (region, items, last_word) = match address::resolve(start, count as usize)? {
            Target::Data(n) => (Region::Dt, items(n.into(), count.into()), None),
            Target::Words(area, n) => {
                let bits = items(u64::from(n) * 16, u64::from(count) * 16);
                (Region::Contacts(area), bits, Some((area, u64::from(n) + u64::from(count) - 1)))
            }
            Target::Bits(area, n) => {
                let bits = items(n.into(), count.into());
                (Region::Contacts(area), bits.clone(), Some((area, (bits.end - 1) / 16)))
            }
        };
        let bank = self.lock();
        let fits = match last_word {
            None => bank.dt(items.end as usize - 1).is_some(),
            Some((area, word)) => bank.word(area, word as usize).is_some(),
        };
        if fits { Ok((region, items)) } else { Err(out_of_range()) }
    }
}

impl SimMemory for MewtocolMemory {
    fn read_words(&self, start: &Address, count: u16) -> Result<Vec<u16>, PlcError> {
        if let Target::Bits(..) = address::resolve(start, count.into())? {
            return Err(PlcError::OutOfRange("contacts are read with read_bits"));
        }
        let (region, items) = self.region(start, count.into())?;
        let bank = self.lock();
        Ok(match region {
            Region::Dt => items.map(|n| bank.dt(n as usize).unwrap_or(0)).collect(),
            Region::Contacts(area) => {
                items.step_by(16).map(|bit| bank.word(area, bit as usize / 16).unwrap_or(0)).collect()
            }
        })
    }

    fn write_words(&self, start: &Address, values: &[u16]) -> Result<(), PlcError> {
        if let Target::Bits(..) = address::resolve(start, values.len())? {
            return Err(PlcError::OutOfRange("contacts are written with write_bits"));
        }
        let (region, items) = self.region(start, values.len() as u32)?;
        let mut bank = self.lock();
        match region {
            Region::Dt => items.zip(values).for_each(|(n, &v)| bank.set_dt(n as usize, v)),
            Region::Contacts(area) => {
                items.step_by(16).zip(values).for_each(|(bit, &v)| bank.set_word(area, bit as usize / 16, v))
            }
        }
        Ok(())
    }

    fn read_bits(&self, start: &Address, count: u16) -> Result<Vec<bool>, PlcError> {
        let Target::Bits(..) = address::resolve(start, count.into())? else {
            return Err(PlcError::OutOfRange("words are read with read_words"));
        };
        let (region, items) = self.region(start, count.into())?;
        let Region::Contacts(area) = region else { return Err(out_of_range()) };
        let bank = self.lock();
        Ok(items.map(|n| bank.bit(area, n as usize).unwrap_or(false)).collect())
    }

    fn write_bits(&self, start: &Address, values: &[bool]) -> Result<(), PlcError> {
        let Target::Bits(..) = address::resolve(start, values.len())? else {
            return Err(PlcError::OutOfRange("words are written with write_words"));
        };
        let (region, items) = self.region(start, values.len() as u32)?;
        let Region::Contacts(area) = region else { return Err(out_of_range()) };
        let mut bank = self.lock();
        for (n, &on) in items.zip(values) {
            let (word, bit) = (n as usize / 16, n % 16);
            let old = bank.word(area, word).unwrap_or(0);
            let new = if on { old | 1 << bit } else { old & !(1 << bit) };
            bank.set_word(area, word, new);
        }
        Ok(())
    }

    fn span(&self, start: &Address, count: u32) -> Result<Span, PlcError> {
        let (region, items) = self.region(start, count)?;
        Ok(Span { area: region.name(), items })
    }

    fn protect(&self, start: &Address, count: u32) -> Result<(), ProtectError> {
        let (region, items) = self.region(start, count)?;
        let mut read_only = self.read_only.lock().unwrap_or_else(|p| p.into_inner());
        Ok(read_only.add(region, items)?)
    }

    fn refused(&self) -> u64 {
        self.read_only.lock().unwrap_or_else(|p| p.into_inner()).refused()
    }
}
