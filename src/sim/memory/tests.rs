use super::*;
use crate::protocols::modbus::server::{Bank, Handler};
use crate::protocols::{mc3e, mewtocol, modbus, ppi};

fn at(parse: fn(&str) -> Result<Address, PlcError>, text: &str) -> Address {
    parse(text).unwrap_or_else(|e| panic!("{text}: {e}"))
}

#[test]
fn modbus_field_writes_pass_and_master_writes_are_refused() {
    let memory = ModbusMemory::new(Bank::new());
    let a = |t| at(modbus::address::parse, t);
    memory.write_words(&a("3x10"), &[1, 2]).unwrap();
    memory.protect(&a("4x100"), 2).unwrap();
    assert!(matches!(memory.protect(&a("4x101"), 1), Err(ProtectError::Overlap(_))));
    memory.write_words(&a("4x100"), &[7, 8]).unwrap();
    assert_eq!(memory.read_words(&a("4x100"), 2).unwrap(), vec![7, 8]);
    let write = modbus::Request::WriteMultipleRegisters { address: 99, values: vec![0, 0] };
    assert_eq!(memory.handle(1, &write), Err(modbus::Exception::ILLEGAL_DATA_ADDRESS));
    assert_eq!(memory.bank().holding(99, 3), vec![0, 7, 8], "nothing written");
    let write = modbus::Request::WriteSingleRegister { address: 102, value: 5 };
    assert!(memory.handle(1, &write).is_ok());
    assert_eq!(memory.refused(), 1);
    assert_eq!(memory.span(&a("0x5"), 3).unwrap(), Span { area: "0X".into(), items: 5..8 });
    assert!(memory.read_bits(&a("4x1"), 1).is_err(), "registers are words");
}

#[test]
fn mc3e_bit_and_word_devices() {
    let memory = Mc3eMemory::new(mc3e::Bank::default().shared());
    let a = |t| at(mc3e::address::parse_address, t);
    memory.write_bits(&a("X1A"), &[true, true]).unwrap();
    assert_eq!(memory.read_bits(&a("X19"), 4).unwrap(), vec![false, true, true, false]);
    memory.protect(&a("X10"), 16).unwrap();
    memory.write_bits(&a("X10"), &[true]).unwrap();
    assert!(memory.read_bits(&a("X10"), 1).unwrap()[0], "the field writes inputs");
    assert!(matches!(memory.protect(&a("D12288"), 1), Err(ProtectError::Address(_))), "past D's end");
    assert_eq!(memory.span(&a("D100"), 2).unwrap(), Span { area: "D".into(), items: 100..102 });
}

#[test]
fn mewtocol_contacts_are_bits_of_their_words() {
    let bank = mewtocol::Bank::default().shared();
    let memory = MewtocolMemory::new(bank.clone());
    let a = |t| at(mewtocol::address::parse, t);
    memory.write_bits(&a("Y1A"), &[true]).unwrap();
    assert_eq!(memory.read_words(&a("WY1"), 1).unwrap(), vec![0x0400]);
    assert_eq!(memory.span(&a("WX2"), 1).unwrap(), memory.span(&a("X20"), 16).unwrap());
    memory.protect(&a("WX0"), 1).unwrap();
    assert!(matches!(memory.protect(&a("X5"), 1), Err(ProtectError::Overlap(_))));
    memory.protect(&a("DT10"), 2).unwrap();
    let handler = memory.handler();
    let mut bank = bank.lock().unwrap();
    let write = mewtocol::Request::WriteData { start: 11, values: vec![1] };
    assert_eq!(handler(&mut bank, &write), Err(65));
    let contact = mewtocol::Contact { area: mewtocol::ContactArea::X, word: 0, bit: 15 };
    assert_eq!(handler(&mut bank, &mewtocol::Request::WriteContact(contact, true)), Err(65));
    let write = mewtocol::Request::WriteData { start: 12, values: vec![1] };
    assert_eq!(handler(&mut bank, &write), Ok(mewtocol::Response::Written));
    drop(bank);
    assert_eq!(memory.refused(), 2);
}

#[test]
fn ppi_words_bytes_and_bits_share_the_same_bits() {
    let bank = ppi::Bank::default().shared();
    let memory = PpiMemory::new(bank.clone());
    let a = |t| at(ppi::address::parse, t);
    memory.write_words(&a("VD4"), &[0x1234, 0x5678]).unwrap();
    assert_eq!(memory.read_words(&a("VW6"), 1).unwrap(), vec![0x5678]);
    assert_eq!(memory.read_words(&a("VB4"), 2).unwrap(), vec![0x12, 0x34]);
    assert!(memory.read_words(&a("VD4"), 1).is_err(), "double words come in pairs");
    memory.write_bits(&a("Q0.1"), &[true]).unwrap();
    assert_eq!(memory.read_words(&a("QB0"), 1).unwrap(), vec![2]);
    memory.protect(&a("VW100"), 1).unwrap();
    assert!(matches!(memory.protect(&a("V101.7"), 1), Err(ProtectError::Overlap(_))));
    let handler = memory.handler();
    let item = ppi::Item { size: Size::Bit, count: 1, area: MemArea::V, offset: 101 * 8 + 7 };
    let mut bank = bank.lock().unwrap();
    assert_eq!(handler(&mut bank, &Request::Write(item, vec![1])), Reply::ItemError(0x03));
    let item = ppi::Item { size: Size::Byte, count: 1, area: MemArea::V, offset: 102 * 8 };
    assert_eq!(handler(&mut bank, &Request::Write(item, vec![1])), Reply::Written);
    drop(bank);
    assert_eq!(memory.refused(), 1);
}

use crate::protocols::ppi::{MemArea, Reply, Request, Size};
