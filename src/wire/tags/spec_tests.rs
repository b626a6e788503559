//! Tests of tag resolution: defaults by area and protocol, types against addresses,
//! addresses in each notation, limits, and values checked and read.

use serde_json::json;

use super::*;

fn def(address: &str, edit: impl FnOnce(&mut TagDef)) -> TagDef {
    let mut d = TagDef::at(address);
    edit(&mut d);
    d
}

fn resolve(protocol: &str, name: &str, def: &TagDef) -> Result<TagSpec, String> {
    TagSpec::resolve(protocol.parse().unwrap(), name, def).map_err(|e| e.to_string())
}

fn ok(protocol: &str, address: &str, edit: impl FnOnce(&mut TagDef)) -> TagSpec {
    resolve(protocol, "a.b", &def(address, edit)).unwrap()
}

fn err(protocol: &str, address: &str, edit: impl FnOnce(&mut TagDef)) -> String {
    resolve(protocol, "a.b", &def(address, edit)).unwrap_err()
}

#[test]
fn defaults_follow_the_area_and_protocol() {
    let coil = ok("modbus-tcp", "0x5", |_| {});
    assert_eq!((coil.place, coil.ty, coil.writable), (Place::Bit, TagType::Bool, true));
    let reg = ok("modbus-udp", "4x100", |_| {});
    assert_eq!(
        (reg.place, reg.ty, reg.order, reg.count()),
        (Place::Words, TagType::U16, WordOrder::HighFirst, 1)
    );
    assert_eq!(reg.limits, Some((0.0, 65535.0)));
    let input = ok("modbus-tcp", "3x7", |_| {});
    assert!(!input.writable);
    let word_bit = ok("modbus-tcp", "4x100.15", |_| {});
    assert_eq!((word_bit.place, word_bit.ty, word_bit.at.index), (Place::WordBit(15), TagType::Bool, 100));
    assert_eq!(ok("mc3e", "D200", |d| d.ty = Some(TagType::U32)).order, WordOrder::LowFirst);
    assert_eq!(ok("mewtocol-tcp", "DT10", |d| d.ty = Some(TagType::F32)).order, WordOrder::LowFirst);
    assert_eq!(ok("mc3e", "D200.3", |_| {}).place, Place::WordBit(3));
    let s7_bit = ok("ppi", "V10.3", |_| {});
    assert_eq!((s7_bit.place, s7_bit.at.index), (Place::Bit, 83));
    let s7_word_bit = ok("ppi-tcp", "VW10.3", |_| {});
    assert_eq!((s7_word_bit.place, s7_word_bit.step), (Place::WordBit(3), 2));
    let vd = ok("ppi-tcp", "VD4", |_| {});
    assert_eq!((vd.ty, vd.order, vd.count(), vd.double_words), (TagType::U32, WordOrder::HighFirst, 2, true));
    assert_eq!(ok("ppi-tcp", "VB3", |_| {}).limits, Some((0.0, 255.0)));
    assert!(!ok("mewtocol-tcp", "X0001", |_| {}).writable);
    assert!(!ok("ppi-tcp", "I0.0", |_| {}).writable);
    assert!(ok("modbus-tcp", "4x1", |d| d.writable = Some(false)).writable.eq(&false));
    let f = ok("modbus-tcp", "4x1", |d| {
        d.ty = Some(TagType::F32);
        d.word_order = Some(WordOrder::LowFirst);
        d.min = Some(-1.5);
    });
    assert_eq!((f.order, f.limits), (WordOrder::LowFirst, Some((-1.5, f32::MAX as f64))));
}

#[test]
fn types_must_suit_the_address() {
    assert!(err("modbus-tcp", "0x5", |d| d.ty = Some(TagType::U16)).contains("is a bit"));
    assert!(err("modbus-tcp", "4x5", |d| d.ty = Some(TagType::Bool)).contains("4x5.0"));
    assert!(err("modbus-tcp", "4x5.3", |d| d.ty = Some(TagType::I16)).contains("bit of a word"));
    assert!(err("ppi", "VB3", |d| d.ty = Some(TagType::I16)).contains("byte"));
    assert!(err("ppi", "VD4", |d| d.ty = Some(TagType::U16)).contains("double word"));
    assert!(err("modbus-tcp", "4x65535", |d| d.ty = Some(TagType::F32)).contains("past the end"));
    assert!(err("ppi", "VW65534", |d| d.ty = Some(TagType::I32)).contains("past the end"));
    assert!(err("modbus-tcp", "4x1", |d| d.word_order = Some(WordOrder::LowFirst)).contains("32-bit"));
    assert!(err("modbus-tcp", "1x1", |d| d.writable = Some(true)).contains("input"));
    assert!(err("mc3e", "X10", |d| d.writable = Some(true)).contains("input"));
}

#[test]
fn addresses_must_parse_for_the_protocol() {
    assert!(err("modbus-tcp", "D200", |_| {}).contains("D200"));
    assert!(err("modbus-tcp", "4x70000", |_| {}).contains("65535"));
    assert!(err("mc3e", "4x100", |_| {}).contains("4x100"));
    assert!(err("modbus-tcp", "4x100.16", |_| {}).contains("0..=15"));
    assert!(err("modbus-tcp", "4x100.x", |_| {}).contains("0..=15"));
    assert!(err("modbus-tcp", "0x100.1", |_| {}).contains("16-bit word"));
    assert!(err("ppi", "VD4.1", |_| {}).contains("16-bit word"));
    assert!(err("mewtocol", "u16", |_| {}).contains("u16"));
    assert!(resolve("modbus-tcp", "1bad", &TagDef::at("4x1")).unwrap_err().contains("1bad"));
}

#[test]
fn min_and_max_are_checked() {
    let u16_tag = |min, max| {
        resolve(
            "modbus-tcp",
            "t",
            &def("4x1", |d| {
                d.min = min;
                d.max = max;
            }),
        )
    };
    assert!(u16_tag(Some(-1.0), None).unwrap_err().contains("outside"));
    assert!(u16_tag(None, Some(70000.0)).unwrap_err().contains("outside"));
    assert!(u16_tag(Some(0.5), None).unwrap_err().contains("whole"));
    assert!(u16_tag(Some(10.0), Some(5.0)).unwrap_err().contains("above"));
    assert!(u16_tag(Some(f64::NAN), None).is_err());
    assert_eq!(u16_tag(Some(10.0), Some(20.0)).unwrap().limits, Some((10.0, 20.0)));
    assert!(err("modbus-tcp", "0x1", |d| d.min = Some(0.0)).contains("numeric"));
    assert!(err("ppi", "VB1", |d| d.max = Some(256.0)).contains("outside"));
    assert!(
        err("modbus-tcp", "4x1", |d| {
            d.ty = Some(TagType::F32);
            d.max = Some(f64::INFINITY);
        })
        .contains("outside")
    );
}

#[test]
fn writes_are_checked_against_type_and_limits() {
    let speed = ok("modbus-tcp", "4x1", |d| {
        d.ty = Some(TagType::F32);
        d.min = Some(0.0);
        d.max = Some(2.5);
    });
    assert_eq!(speed.check(&json!(2.5)), Ok(TagValue::Float(2.5)));
    assert!(matches!(speed.check(&json!(2.6)), Err(ValueError::Range { .. })));
    assert!(matches!(speed.check(&json!(-0.1)), Err(ValueError::Range { .. })));
    assert!(matches!(speed.check(&json!(true)), Err(ValueError::Type { .. })));
    let byte = ok("ppi", "VB1", |_| {});
    assert!(matches!(byte.check(&json!(256)), Err(ValueError::Range { .. })));
    assert_eq!(byte.check(&json!(255)), Ok(TagValue::Int(255)));
    let lamp = ok("ppi", "Q0.1", |_| {});
    assert_eq!(lamp.check(&json!(false)), Ok(TagValue::Bool(false)));
    assert!(matches!(lamp.check(&json!(0)), Err(ValueError::Type { .. })));
}

#[test]
fn values_from_what_was_read() {
    let bit = ok("modbus-tcp", "4x1.2", |_| {});
    assert_eq!(bit.from_words(&[0b100]), Ok(TagValue::Bool(true)));
    assert_eq!(bit.from_words(&[0b011]), Ok(TagValue::Bool(false)));
    assert!(bit.from_words(&[]).is_err());
    let coil = ok("modbus-tcp", "0x1", |_| {});
    assert_eq!(coil.from_bits(&[true]), Ok(TagValue::Bool(true)));
    assert!(coil.from_bits(&[]).is_err());
    let i32_tag = ok("mc3e", "D0", |d| d.ty = Some(TagType::I32));
    assert_eq!(i32_tag.from_words(&[0xFFFE, 0xFFFF]), Ok(TagValue::Int(-2)));
    assert!(i32_tag.from_words(&[1]).is_err());
}
