//! The memory a simulated S7-200 serves: bytes of V, I, Q, M, SM, S, AI and AQ, and the
//! current values of timers and counters, plus the RUN/STOP mode.

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};

use super::pdu::{self, Item, MemArea, Reply, Request, Size};
use super::return_code::{NO_OBJECT, OUT_OF_RANGE};

/// A bank shared between the server and the simulation (never lock it across an `.await`).
pub type SharedBank = Arc<Mutex<Bank>>;

/// Memory areas as bytes (timers and counters: two bytes per number, big-endian).
#[derive(Clone, Debug)]
pub struct Bank {
    areas: BTreeMap<MemArea, Vec<u8>>,
    /// True in RUN, false in STOP.
    pub running: bool,
}

impl Default for Bank {
    /// A CPU 224's sizes: V 10240 bytes, I and Q 16, M 32, SM 550, S 32, AI and AQ 64,
    /// 256 timers and 256 counters; in RUN.
    fn default() -> Self {
        let sizes = [
            (MemArea::V, 10_240),
            (MemArea::I, 16),
            (MemArea::Q, 16),
            (MemArea::M, 32),
            (MemArea::SM, 550),
            (MemArea::S, 32),
            (MemArea::AI, 64),
            (MemArea::AQ, 64),
            (MemArea::T, 512),
            (MemArea::C, 512),
        ];
        Bank { areas: sizes.into_iter().map(|(a, n)| (a, vec![0; n])).collect(), running: true }
    }
}

impl Bank {
    /// This bank wrapped for sharing.
    pub fn shared(self) -> SharedBank {
        Arc::new(Mutex::new(self))
    }

    /// The bytes of an area.
    pub fn bytes(&self, area: MemArea) -> &[u8] {
        self.areas.get(&area).map_or(&[], Vec::as_slice)
    }

    /// The bytes of an area, to change.
    pub fn bytes_mut(&mut self, area: MemArea) -> &mut [u8] {
        self.areas.get_mut(&area).map_or(&mut [], Vec::as_mut_slice)
    }

    /// The byte range of an item, or the return code refusing it.
    fn range(&self, item: &Item) -> Result<(usize, usize), u8> {
        let len = self.areas.get(&item.area).ok_or(NO_OBJECT)?.len();
        let start = match item.size {
            Size::Timer | Size::Counter => item.offset as usize * 2,
            Size::Bit => item.offset as usize / 8,
            _ if !item.offset.is_multiple_of(8) => return Err(OUT_OF_RANGE),
            _ => item.offset as usize / 8,
        };
        let bytes = if item.size == Size::Bit { 1 } else { item.data_len() };
        if start + bytes > len { Err(OUT_OF_RANGE) } else { Ok((start, bytes)) }
    }

    /// Executes a request as the PLC would.
    pub fn execute(&mut self, request: &Request) -> Reply {
        let result = match request {
            Request::Read(item) => self.range(item).map(|(start, n)| {
                let bytes = &self.areas[&item.area][start..start + n];
                match item.size {
                    Size::Bit => Reply::Data(vec![(bytes[0] >> (item.offset % 8)) & 1]),
                    _ => Reply::Data(bytes.to_vec()),
                }
            }),
            Request::Write(item, data) => self.range(item).map(|(start, n)| {
                let area = self.areas.get_mut(&item.area).expect("range checked the area");
                if item.size == Size::Bit {
                    let mask = 1 << (item.offset % 8);
                    area[start] = if data[0] & 1 != 0 { area[start] | mask } else { area[start] & !mask };
                } else {
                    area[start..start + n].copy_from_slice(data);
                }
                Reply::Written
            }),
            Request::Run => {
                self.running = true;
                Ok(Reply::Done(pdu::RUN))
            }
            Request::Stop => {
                self.running = false;
                Ok(Reply::Done(pdu::STOP))
            }
            Request::Setup(setup) => Ok(Reply::Setup(setup.negotiated())),
        };
        result.unwrap_or_else(Reply::ItemError)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_writes_and_refuses() {
        let mut bank = Bank::default();
        let vw = |offset| Item { size: Size::Word, count: 1, area: MemArea::V, offset };
        assert_eq!(bank.execute(&Request::Write(vw(800), vec![0x12, 0x34])), Reply::Written);
        assert_eq!(bank.bytes(MemArea::V)[100..102], [0x12, 0x34]);
        let bit = Item { size: Size::Bit, count: 1, area: MemArea::V, offset: 100 * 8 + 4 };
        assert_eq!(bank.execute(&Request::Read(bit)), Reply::Data(vec![1]));
        assert_eq!(bank.execute(&Request::Write(bit, vec![0])), Reply::Written);
        assert_eq!(bank.bytes(MemArea::V)[100], 0x02);
        assert_eq!(bank.execute(&Request::Read(vw(10_239 * 8))), Reply::ItemError(OUT_OF_RANGE));
        assert_eq!(bank.execute(&Request::Read(vw(3))), Reply::ItemError(OUT_OF_RANGE));
        bank.areas.remove(&MemArea::AQ);
        let aq = Item { size: Size::Word, count: 1, area: MemArea::AQ, offset: 0 };
        assert_eq!(bank.execute(&Request::Read(aq)), Reply::ItemError(NO_OBJECT));
        assert_eq!(bank.execute(&Request::Stop), Reply::Done(pdu::STOP));
        assert!(!bank.running);
    }
}
