use std::path::Path;

use super::*;
use crate::protocols::mc3e;
use crate::protocols::modbus::server::Bank;
use crate::sim::memory::{Mc3eMemory, ModbusMemory};

fn preset(json: serde_json::Value) -> Preset {
    serde_json::from_value(json).unwrap()
}

/// Applies a preset to a fresh Modbus memory; the error's whole chain as one line.
fn modbus(json: serde_json::Value) -> Result<(ModbusMemory, Vec<ReadOnlyRange>), String> {
    let memory = ModbusMemory::new(Bank::new());
    let ranges = preset(json).apply(Path::new("p.json"), Protocol::ModbusTcp, &memory);
    ranges.map(|r| (memory, r)).map_err(|e| format!("{e:#}"))
}

#[test]
fn typed_values_land_in_the_protocols_words() {
    let (memory, ranges) = modbus(serde_json::json!({"values": [
        {"address": "4x100", "type": "f32", "word_order": "cdab", "value": 3.5},
        {"address": "4x102", "type": "f32", "value": 3.5},
        {"address": "4x104", "type": "i16", "values": [-1, 2]},
        {"address": "4x110", "type": "string", "length": 5, "value": "ABC"},
        {"address": "4x120.3", "value": true},
        {"address": "4x120.4", "value": true},
        {"address": "0x7", "values": [true, false, true], "read_only": true},
    ], "read_only": [{"address": "3x0", "count": 4}]}))
    .unwrap();
    // 3.5 is 0x40600000.
    assert_eq!(memory.bank().holding(100, 6), [0x0000, 0x4060, 0x4060, 0x0000, 0xFFFF, 2]);
    assert_eq!(memory.bank().holding(110, 3), [0x4142, 0x4300, 0], "high byte first, NUL-padded");
    assert_eq!(memory.bank().holding(120, 1), [0x18]);
    assert_eq!(memory.bank().lock().coils[7..10], [true, false, true]);
    let listed = |a: &str, count| ReadOnlyRange { address: a.into(), count };
    assert_eq!(ranges, [listed("0x7", 3), listed("3x0", 4)]);
}

#[test]
fn mc_strings_put_the_first_character_in_the_low_byte() {
    let memory = Mc3eMemory::new(mc3e::Bank::default().shared());
    let p = preset(serde_json::json!({"values": [
        {"address": "D0", "type": "string", "value": "AB"},
        {"address": "D10", "type": "u32", "value": 65536},
    ]}));
    p.apply(Path::new("p.json"), Protocol::Mc3e, &memory).unwrap();
    let at = |t| mc3e::address::parse_address(t).unwrap();
    assert_eq!(memory.read_words(&at("D0"), 1).unwrap(), [0x4241]);
    assert_eq!(memory.read_words(&at("D10"), 2).unwrap(), [0, 1], "MC keeps the low word first");
}

#[test]
fn refusals_name_the_file_the_entry_and_the_problem() {
    let refused = |json| modbus(json).err().expect("refused");
    let e = refused(
        serde_json::json!({"values": [{"address": "4x1", "value": 1}, {"address": "D5", "value": 1}]}),
    );
    assert!(e.starts_with("p.json: values[1] (D5): ") && e.contains("D5"), "{e}");
    let e = refused(serde_json::json!({"values": [{"address": "4x1", "type": "f32", "value": "x"}]}));
    assert!(e.contains("values[0] (4x1)") && e.contains("f32"), "{e}");
    let e = refused(serde_json::json!({"values": [{"address": "4x1", "value": 70000}]}));
    assert!(e.contains("out of range"), "{e}");
    let e = refused(serde_json::json!({"values": [{"address": "0x1", "type": "u16", "value": 1}]}));
    assert!(e.contains("is a bit"), "{e}");
    let e = refused(serde_json::json!({"values": [
        {"address": "4x10", "type": "u32", "value": 1}, {"address": "4x11", "value": 2}]}));
    assert!(e.contains("values[1] (4x11): sets items values[0] (4x10) sets too"), "{e}");
    let e = refused(serde_json::json!({"read_only": [
        {"address": "1x0", "count": 8}, {"address": "1x7"}]}));
    assert!(e.contains("read_only[1] (1x7): overlaps read_only[0] (1x0)"), "{e}");
    let e = refused(serde_json::json!({"read_only": [{"address": "4x65535", "count": 2}]}));
    assert!(e.contains("read_only[0] (4x65535)") && e.contains("65535"), "{e}");
    let e = refused(
        serde_json::json!({"values": [{"address": "4x1", "type": "string", "length": 2, "value": "ABC"}]}),
    );
    assert!(e.contains("longer than length 2"), "{e}");
    let e = refused(serde_json::json!({"values": [{"address": "4x1"}]}));
    assert!(e.contains("give `value` or `values`"), "{e}");
}

#[test]
fn nothing_is_written_when_an_entry_is_bad() {
    let memory = ModbusMemory::new(Bank::new());
    let p = preset(serde_json::json!({"values": [
        {"address": "4x1", "value": 5}, {"address": "4x2", "value": -1}]}));
    assert!(p.apply(Path::new("p.json"), Protocol::ModbusTcp, &memory).is_err());
    assert_eq!(memory.bank().holding(1, 1), [0]);
}

#[test]
fn toml_presets_and_unknown_keys() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("bench.toml");
    let text = "[[values]]\naddress = \"4x5\"\ntype = \"i32\"\nword_order = \"abcd\"\nvalue = -2\n\n\
                [[read_only]]\naddress = \"4x5\"\ncount = 2\n";
    std::fs::write(&file, text).unwrap();
    let memory = ModbusMemory::new(Bank::new());
    Preset::read(&file).unwrap().apply(&file, Protocol::ModbusTcp, &memory).unwrap();
    assert_eq!(memory.bank().holding(5, 2), [0xFFFF, 0xFFFE]);
    let json = dir.path().join("bad.json");
    std::fs::write(&json, r#"{"values": [{"address": "4x1", "word_ordr": "abcd", "value": 1}]}"#).unwrap();
    let e = format!("{:#}", Preset::read(&json).unwrap_err());
    assert!(e.contains("bad.json: not a preset") && e.contains("word_ordr"), "{e}");
}
