//! The shelf over Modbus: the slots are holding registers. UDP answers like the seed's PLC
//! (MBAP length 0), TCP with standard lengths, and RTU (serial or over TCP) like an S7-1200
//! Modbus_Slave ([`S7Mapping`]).

use std::sync::{Arc, MutexGuard};

use super::options::ShelfProtocol;
use super::s7_1200::S7Mapping;
use super::slots::{Core, SlotMemory, SlotWords};
use super::{Endpoint, Setup, Started};
use crate::protocols::modbus::exception::Exception;
use crate::protocols::modbus::pdu::{Request, Response};
use crate::protocols::modbus::server::{
    Bank, Handler, ModbusServer, RegisterBank, ServerOptions, TABLE_SIZE,
};

/// The shelf's holding registers, watched.
struct Shelf {
    bank: Bank,
    base: usize,
    core: Core,
    s7: Option<S7Mapping>,
}

impl Shelf {
    /// The `(area word, value)` pairs a request writes; empty for reads and coils.
    fn writes(&self, request: &Request) -> Vec<(usize, u16)> {
        let (address, values) = match request {
            Request::WriteSingleRegister { address, value } => (*address, std::slice::from_ref(value)),
            Request::WriteMultipleRegisters { address, values } => (*address, values.as_slice()),
            _ => return Vec::new(),
        };
        let first = address as usize;
        values
            .iter()
            .enumerate()
            .filter_map(|(i, &v)| (first + i).checked_sub(self.base).map(|n| (n, v)))
            .collect()
    }
}

impl Handler for Shelf {
    fn handle(&self, _unit: u8, request: &Request) -> Result<Response, Exception> {
        if let Some(s7) = &self.s7 {
            s7.admit(request)?;
        }
        let mut bank = self.bank.lock();
        let writes = self.writes(request);
        let regs = &bank.holding_registers;
        let check = self.core.check(&|n| regs.get(self.base + n).copied().unwrap_or(0), &writes);
        let response = bank.apply(request)?;
        self.core.commit(check);
        Ok(response)
    }
}

/// The holding registers as slot memory.
struct Holding {
    bank: Bank,
    base: usize,
}

struct HoldingGuard<'a> {
    bank: MutexGuard<'a, RegisterBank>,
    base: usize,
}

impl SlotWords for HoldingGuard<'_> {
    fn get(&self, n: usize) -> u16 {
        self.bank.holding_registers.get(self.base + n).copied().unwrap_or(0)
    }

    fn set(&mut self, n: usize, value: u16) {
        if let Some(w) = self.bank.holding_registers.get_mut(self.base + n) {
            *w = value;
        }
    }
}

impl SlotMemory for Holding {
    fn lock(&self) -> Box<dyn SlotWords + '_> {
        Box::new(HoldingGuard { bank: self.bank.lock(), base: self.base })
    }
}

fn invalid(message: String) -> std::io::Error {
    std::io::Error::new(std::io::ErrorKind::InvalidInput, message)
}

/// Serves the shelf over a Modbus protocol at `endpoint`, slot 1's task id at a `4x`
/// address.
pub(super) async fn start(endpoint: Endpoint<'_>, setup: &Setup<'_>) -> std::io::Result<Started> {
    let Setup { protocol, base, unit, baud, core, faults, zero_transaction_id } = *setup;
    let address = crate::protocols::modbus::address::parse(base).map_err(|e| invalid(e.to_string()))?;
    if address.area.name() != "4X" {
        return Err(invalid(format!("the Modbus slots must be holding registers (4x...), not {base}")));
    }
    let base = address.index as usize;
    let end = base + core.layout.words();
    if end > TABLE_SIZE {
        return Err(invalid(format!(
            "{} slots of {} words from {} pass 4x65535",
            core.layout.slots, core.layout.stride, address.index
        )));
    }
    if !(1..=247).contains(&unit) {
        return Err(invalid(format!("a Modbus unit is 1..=247, got {unit}")));
    }
    let bank = Bank::new();
    // The S7-1200's MB_HOLD_REG data block ends where the slots do.
    let s7 = protocol.is_s7_1200().then_some(S7Mapping { hold_words: end as u32 });
    let handler = Shelf { bank: bank.clone(), base, core: core.clone(), s7 };
    let options = ServerOptions {
        unit,
        length0: protocol == ShelfProtocol::ModbusUdp,
        zero_transaction_id,
        faults: faults.clone(),
        // An S7-1200's Modbus_Slave has no device identification (exception 01).
        identification: if s7.is_some() { None } else { ServerOptions::default().identification },
        // Its diagnostics are Modbus_Slave's own (0000 and 000A only, see s7_1200.rs).
        diagnostic_counters: s7.is_none(),
    };
    let server = ModbusServer::new(Arc::new(handler), options);
    let handle = match (protocol, endpoint) {
        (ShelfProtocol::ModbusUdp, Endpoint::Listen(at)) => server.serve_udp(at).await?,
        (ShelfProtocol::ModbusTcp, Endpoint::Listen(at)) => server.serve_tcp(at).await?,
        (ShelfProtocol::ModbusRtuTcp, Endpoint::Listen(at)) => server.serve_rtu_over_tcp(at).await?,
        (ShelfProtocol::ModbusRtu, Endpoint::Stream(stream)) => server.serve_rtu_stream(stream, baud),
        (ShelfProtocol::ModbusUdp, Endpoint::Datagrams(port)) => server.serve_boxed_datagrams(port),
        (p, _) => return Err(invalid(format!("{p} is not served on that kind of endpoint"))),
    };
    let memory: Arc<dyn SlotMemory> = Arc::new(Holding { bank, base });
    Ok(Started { memory, faults: handle.faults(), server: super::Server::Modbus(handle) })
}
