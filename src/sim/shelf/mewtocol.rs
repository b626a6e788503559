//! The shelf as a Panasonic FP over MEWTOCOL-COM: the slots are DT data registers, written
//! with WD and read with RD.

use std::sync::{Arc, MutexGuard};

use super::slots::{SlotMemory, SlotWords};
use super::{Endpoint, Setup, Started};
use crate::protocols::faults::SharedFaults;
use crate::protocols::mewtocol::{self, Bank, Request, Response, ServerState, SharedBank};
use crate::protocols::transport::StreamServer;

/// The `(area word, value)` pairs a command writes into the area starting at DT `base`.
fn writes(base: usize, request: &Request) -> Vec<(usize, u16)> {
    let Request::WriteData { start, values } = request else { return Vec::new() };
    let first = *start as usize;
    values.iter().enumerate().filter_map(|(i, &v)| (first + i).checked_sub(base).map(|n| (n, v))).collect()
}

/// The DT registers as slot memory.
struct DtMemory {
    bank: SharedBank,
    base: usize,
}

struct DtGuard<'a> {
    bank: MutexGuard<'a, Bank>,
    base: usize,
}

impl SlotWords for DtGuard<'_> {
    fn get(&self, n: usize) -> u16 {
        self.bank.dt(self.base + n).unwrap_or(0)
    }

    fn set(&mut self, n: usize, value: u16) {
        self.bank.set_dt(self.base + n, value);
    }
}

impl SlotMemory for DtMemory {
    fn lock(&self) -> Box<dyn SlotWords + '_> {
        Box::new(DtGuard { bank: self.bank.lock().unwrap_or_else(|p| p.into_inner()), base: self.base })
    }
}

fn invalid(message: String) -> std::io::Error {
    std::io::Error::new(std::io::ErrorKind::InvalidInput, message)
}

/// Serves the shelf over MEWTOCOL-COM at `endpoint`, slot 1's task id at a `DT` address;
/// the unit is the PLC's station number.
pub(super) async fn start(endpoint: Endpoint<'_>, setup: &Setup<'_>) -> std::io::Result<Started> {
    let Setup { base, unit: station, core, faults, .. } = *setup;
    let at = mewtocol::address::parse(base).map_err(|e| invalid(e.to_string()))?;
    if at.area.name() != "DT" {
        return Err(invalid(format!("the MEWTOCOL slots must be data registers (DT...), not {base}")));
    }
    if !(1..=99).contains(&station) {
        return Err(invalid(format!("a MEWTOCOL station is 1..=99, got {station}")));
    }
    let base = at.index as usize;
    let bank = Bank::default();
    let end = base + core.layout.words();
    if end == 0 || bank.dt(end - 1).is_none() {
        return Err(invalid(format!(
            "{} slots of {} words from DT{base} pass the last data register",
            core.layout.slots, core.layout.stride
        )));
    }
    let bank = bank.shared();
    let watch = core.clone();
    let handler: mewtocol::server::Handler = Arc::new(move |bank: &mut Bank, request: &Request| {
        let check = watch.check(&|n| bank.dt(base + n).unwrap_or(0), &writes(base, request));
        let response = bank.execute(request)?;
        if response == Response::Written {
            watch.commit(check);
        }
        Ok(response)
    });
    let state =
        ServerState { station, faults: SharedFaults::new(faults.clone()), ..ServerState::new(bank.clone()) }
            .with_handler(handler);
    let shared_faults = state.faults.clone();
    let server: StreamServer = match endpoint {
        Endpoint::Listen(at) => mewtocol::server::serve_tcp(at, state).await?,
        Endpoint::Stream(stream) => mewtocol::server::serve_stream(stream, state),
        Endpoint::Datagrams(_) => return Err(super::invalid("mewtocol is not served on datagrams")),
    };
    let memory: Arc<dyn SlotMemory> = Arc::new(DtMemory { bank, base });
    Ok(Started { memory, server: super::Server::Line(server), faults: shared_faults })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn data_writes_become_area_words_and_the_rest_is_ignored() {
        let w = writes(4000, &Request::WriteData { start: 3999, values: vec![1, 2, 3] });
        assert_eq!(w, vec![(0, 2), (1, 3)]);
        assert!(writes(4000, &Request::ReadData { start: 4000, end: 4001 }).is_empty());
    }
}
