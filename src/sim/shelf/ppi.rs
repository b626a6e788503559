//! The shelf as an S7-200 over PPI: the slots are V memory words (`VW`), big-endian, two
//! byte addresses each. Writes of any size (bytes, words, double words, single bits) that
//! touch a slot are watched word by word.

use std::sync::{Arc, MutexGuard};

use super::slots::{SlotMemory, SlotWords};
use super::{Endpoint, Setup, Started};
use crate::protocols::faults::SharedFaults;
use crate::protocols::ppi::{self, Bank, MemArea, Reply, Request, ServerState, SharedBank, Size};
use crate::protocols::transport::StreamServer;

/// Word `n` of the area starting at V byte `base`.
fn word(bank: &Bank, base: usize, n: usize) -> u16 {
    let v = bank.bytes(MemArea::V);
    let at = |i: usize| v.get(i).copied().unwrap_or(0);
    u16::from_be_bytes([at(base + 2 * n), at(base + 2 * n + 1)])
}

/// The `(area word, value)` pairs a write request leaves in the slot area starting at V
/// byte `base`: every word with a byte written, as it will read afterwards.
fn writes(bank: &Bank, base: usize, request: &Request) -> Vec<(usize, u16)> {
    let Request::Write(item, data) = request else { return Vec::new() };
    if item.area != MemArea::V {
        return Vec::new();
    }
    let first = (item.offset / 8) as usize;
    let len = if item.size == Size::Bit { 1 } else { data.len() };
    let v = bank.bytes(MemArea::V);
    let after = |b: usize| -> u8 {
        let old = v.get(b).copied().unwrap_or(0);
        match b.checked_sub(first).filter(|&i| i < len) {
            None => old,
            Some(_) if item.size == Size::Bit => {
                let mask = 1 << (item.offset % 8);
                if data.first().is_some_and(|d| d & 1 != 0) { old | mask } else { old & !mask }
            }
            Some(i) => data.get(i).copied().unwrap_or(old),
        }
    };
    let last = first + len;
    if len == 0 || last <= base {
        return Vec::new();
    }
    let (lo, hi) = (first.max(base) - base, last - 1 - base);
    (lo / 2..=hi / 2)
        .map(|n| (n, u16::from_be_bytes([after(base + 2 * n), after(base + 2 * n + 1)])))
        .collect()
}

/// V memory as slot memory.
struct VMemory {
    bank: SharedBank,
    base: usize,
}

struct VGuard<'a> {
    bank: MutexGuard<'a, Bank>,
    base: usize,
}

impl SlotWords for VGuard<'_> {
    fn get(&self, n: usize) -> u16 {
        word(&self.bank, self.base, n)
    }

    fn set(&mut self, n: usize, value: u16) {
        let at = self.base + 2 * n;
        if let Some(bytes) = self.bank.bytes_mut(MemArea::V).get_mut(at..at + 2) {
            bytes.copy_from_slice(&value.to_be_bytes());
        }
    }
}

impl SlotMemory for VMemory {
    fn lock(&self) -> Box<dyn SlotWords + '_> {
        Box::new(VGuard { bank: self.bank.lock().unwrap_or_else(|p| p.into_inner()), base: self.base })
    }
}

fn invalid(message: String) -> std::io::Error {
    std::io::Error::new(std::io::ErrorKind::InvalidInput, message)
}

/// Serves the shelf over PPI at `endpoint`, slot 1's task id at a `VW` address; the unit
/// is the PLC's station address.
pub(super) async fn start(endpoint: Endpoint<'_>, setup: &Setup<'_>) -> std::io::Result<Started> {
    let Setup { base, unit: address, core, faults, .. } = *setup;
    let at = ppi::address::parse(base).map_err(|e| invalid(e.to_string()))?;
    if at.area.name() != "VW" {
        return Err(invalid(format!("the PPI slots must be V memory words (VW...), not {base}")));
    }
    if !(1..=126).contains(&address) {
        return Err(invalid(format!("a PPI station address is 1..=126, got {address}")));
    }
    let base = at.index as usize;
    let bank = Bank::default();
    let size = bank.bytes(MemArea::V).len();
    if base + 2 * core.layout.words() > size {
        return Err(invalid(format!(
            "{} slots of {} words from VW{base} pass the end of V memory (VB{})",
            core.layout.slots,
            core.layout.stride,
            size - 1
        )));
    }
    let bank = bank.shared();
    let watch = core.clone();
    let handler: ppi::server::Handler = Arc::new(move |bank: &mut Bank, request: &Request| {
        let check = watch.check(&|n| word(bank, base, n), &writes(bank, base, request));
        let reply = bank.execute(request);
        if reply == Reply::Written {
            watch.commit(check);
        }
        reply
    });
    let state =
        ServerState { address, faults: SharedFaults::new(faults.clone()), ..ServerState::new(bank.clone()) }
            .with_handler(handler);
    let shared_faults = state.faults.clone();
    let server: StreamServer = match endpoint {
        Endpoint::Listen(at) => ppi::server::serve_tcp(at, state).await?,
        Endpoint::Stream(stream) => ppi::server::serve_stream(stream, state),
        Endpoint::Datagrams(_) => return Err(super::invalid("ppi is not served on datagrams")),
    };
    let memory: Arc<dyn SlotMemory> = Arc::new(VMemory { bank, base });
    Ok(Started { memory, server: super::Server::Line(server), faults: shared_faults })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocols::ppi::Item;

    fn item(size: Size, count: u16, byte: u32, bit: u32) -> Item {
        Item { size, count, area: MemArea::V, offset: byte * 8 + bit }
    }

    #[test]
    fn writes_of_every_size_become_the_words_they_leave() {
        let mut bank = Bank::default();
        bank.bytes_mut(MemArea::V)[1000..1004].copy_from_slice(&[0x12, 0x34, 0x56, 0x78]);
        let w = |r: Request| writes(&bank, 1000, &r);
        assert_eq!(w(Request::Write(item(Size::Word, 2, 1000, 0), vec![0, 7, 0, 8])), vec![(0, 7), (1, 8)]);
        assert_eq!(w(Request::Write(item(Size::Byte, 1, 1001, 0), vec![0xFF])), vec![(0, 0x12FF)]);
        assert_eq!(
            w(Request::Write(item(Size::Byte, 2, 1001, 0), vec![0xAA, 0xBB])),
            vec![(0, 0x12AA), (1, 0xBB78)],
            "a word write at an odd byte straddles two slot words"
        );
        assert_eq!(w(Request::Write(item(Size::Bit, 1, 1002, 0), vec![0])), vec![(1, 0x5678)]);
        assert_eq!(w(Request::Write(item(Size::Bit, 1, 1002, 7), vec![1])), vec![(1, 0xD678)]);
        assert_eq!(w(Request::Write(item(Size::DWord, 1, 998, 0), vec![1, 2, 3, 4])), vec![(0, 0x0304)]);
        assert!(w(Request::Write(item(Size::Word, 1, 998, 0), vec![1, 2])).is_empty(), "before the area");
        let q = Item { area: MemArea::Q, ..item(Size::Byte, 1, 0, 0) };
        assert!(w(Request::Write(q, vec![1])).is_empty(), "outputs are not V memory");
        assert!(w(Request::Read(item(Size::Word, 1, 1000, 0))).is_empty());
    }
}
