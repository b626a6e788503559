//! Tests of the tag value codec: every type, both word orders, bits of words, the range of
//! each type, and floats that are not finite.

use serde_json::json;

use super::*;
use TagType::*;
use WordOrder::*;

#[test]
fn sixteen_bit_types() {
    assert_eq!(decode(U16, HighFirst, &[0xFFFE]), Ok(TagValue::Int(65534)));
    assert_eq!(decode(I16, HighFirst, &[0xFFFE]), Ok(TagValue::Int(-2)));
    assert_eq!(decode(I16, LowFirst, &[0x7FFF]), Ok(TagValue::Int(32767)));
    assert_eq!(encode(I16, HighFirst, TagValue::Int(-2)), Ok(vec![0xFFFE]));
    assert_eq!(encode(U16, LowFirst, TagValue::Int(65535)), Ok(vec![0xFFFF]));
    assert!(matches!(decode(U16, HighFirst, &[1, 2]), Err(ValueError::WordCount { .. })));
    assert!(matches!(decode(Bool, HighFirst, &[1]), Err(ValueError::WordCount { .. })));
}

#[test]
fn thirty_two_bit_types_in_both_word_orders() {
    assert_eq!(encode(U32, HighFirst, TagValue::Int(0x1234_5678)), Ok(vec![0x1234, 0x5678]));
    assert_eq!(encode(U32, LowFirst, TagValue::Int(0x1234_5678)), Ok(vec![0x5678, 0x1234]));
    assert_eq!(decode(U32, HighFirst, &[0x1234, 0x5678]), Ok(TagValue::Int(0x1234_5678)));
    assert_eq!(decode(U32, LowFirst, &[0x5678, 0x1234]), Ok(TagValue::Int(0x1234_5678)));
    assert_eq!(decode(U32, HighFirst, &[0xFFFF, 0xFFFF]), Ok(TagValue::Int(4_294_967_295)));
    assert_eq!(encode(I32, HighFirst, TagValue::Int(-2)), Ok(vec![0xFFFF, 0xFFFE]));
    assert_eq!(encode(I32, LowFirst, TagValue::Int(-100_000)), Ok(vec![0x7960, 0xFFFE]));
    assert_eq!(decode(I32, LowFirst, &[0x7960, 0xFFFE]), Ok(TagValue::Int(-100_000)));
    assert_eq!(decode(I32, HighFirst, &[0x8000, 0x0000]), Ok(TagValue::Int(i32::MIN as i64)));
    // 1.5f32 = 0x3FC00000; -0.1f32 = 0xBDCCCCCD.
    assert_eq!(encode(F32, HighFirst, TagValue::Float(1.5)), Ok(vec![0x3FC0, 0x0000]));
    assert_eq!(encode(F32, LowFirst, TagValue::Float(1.5)), Ok(vec![0x0000, 0x3FC0]));
    assert_eq!(decode(F32, HighFirst, &[0xBDCC, 0xCCCD]), Ok(TagValue::Float(-0.1)));
    assert_eq!(decode(F32, LowFirst, &[0xCCCD, 0xBDCC]), Ok(TagValue::Float(-0.1)));
    for order in [HighFirst, LowFirst] {
        for v in [0.0, 2.5, -1234.5, 3.4e38, 1e-30] {
            let words = encode(F32, order, TagValue::Float(v)).unwrap();
            assert_eq!(decode(F32, order, &words), Ok(TagValue::Float(v)), "{v} {order:?}");
        }
        for v in [0, 1, -1, i32::MIN as i64, i32::MAX as i64] {
            let words = encode(I32, order, TagValue::Int(v)).unwrap();
            assert_eq!(decode(I32, order, &words), Ok(TagValue::Int(v)));
        }
    }
}

#[test]
fn plc_nan_and_infinity_are_refused() {
    for bits in [0x7FC0_0000u32, 0x7F80_0000, 0xFF80_0000, 0x7FFF_FFFF] {
        let words = [(bits >> 16) as u16, bits as u16];
        assert!(matches!(decode(F32, HighFirst, &words), Err(ValueError::NotFinite(_))), "{bits:#x}");
    }
}

#[test]
fn bits_of_words() {
    assert!(bit_of(0x0008, 3) && !bit_of(0x0008, 2) && bit_of(0x8000, 15));
    assert_eq!(with_bit(0x00F0, 0, true), 0x00F1);
    assert_eq!(with_bit(0x00F0, 4, false), 0x00E0);
    assert_eq!(with_bit(0xFFFF, 15, false), 0x7FFF);
}

#[test]
fn json_values_are_checked_against_the_type() {
    assert_eq!(from_json(Bool, &json!(true)), Ok(TagValue::Bool(true)));
    assert!(matches!(from_json(Bool, &json!(1)), Err(ValueError::Type { .. })));
    assert!(matches!(from_json(Bool, &json!("true")), Err(ValueError::Type { .. })));
    assert_eq!(from_json(U16, &json!(65535)), Ok(TagValue::Int(65535)));
    assert!(matches!(from_json(U16, &json!(65536)), Err(ValueError::Range { .. })));
    assert!(matches!(from_json(U16, &json!(-1)), Err(ValueError::Range { .. })));
    assert!(matches!(from_json(U16, &json!(1.5)), Err(ValueError::Type { .. })));
    assert!(matches!(from_json(U16, &json!(true)), Err(ValueError::Type { .. })));
    assert!(matches!(from_json(U16, &json!(null)), Err(ValueError::Type { .. })));
    assert_eq!(from_json(I16, &json!(-32768)), Ok(TagValue::Int(-32768)));
    assert!(matches!(from_json(I16, &json!(32768)), Err(ValueError::Range { .. })));
    assert_eq!(from_json(U32, &json!(4_294_967_295u64)), Ok(TagValue::Int(4_294_967_295)));
    assert!(matches!(from_json(U32, &json!(4_294_967_296u64)), Err(ValueError::Range { .. })));
    assert!(matches!(from_json(U32, &json!(u64::MAX)), Err(ValueError::Range { .. })));
    assert!(matches!(from_json(I32, &json!(-2_147_483_649i64)), Err(ValueError::Range { .. })));
    assert_eq!(from_json(F32, &json!(2)), Ok(TagValue::Float(2.0)));
    assert_eq!(from_json(F32, &json!(0.1)), Ok(TagValue::Float(0.1)));
    assert!(matches!(from_json(F32, &json!(1e39)), Err(ValueError::Range { .. })));
    assert!(matches!(from_json(F32, &json!(-1e39)), Err(ValueError::Range { .. })));
    assert!(matches!(from_json(F32, &json!("1.5")), Err(ValueError::Type { .. })));
    // JSON has no NaN: serde_json turns it into null, which is refused.
    assert!(matches!(from_json(F32, &json!(f64::NAN)), Err(ValueError::Type { .. })));
    assert!(matches!(from_json(F32, &json!(f64::INFINITY)), Err(ValueError::Type { .. })));
    let err = from_json(I16, &json!(40000)).unwrap_err().to_string();
    assert!(err.contains("40000") && err.contains("-32768..=32767"), "{err}");
    let err = from_json(F32, &json!(1e39)).unwrap_err().to_string();
    assert!(err.contains("-3.4028235e38..=3.4028235e38"), "{err}");
}

#[test]
fn values_of_the_wrong_kind_are_not_encoded() {
    assert!(encode(U16, HighFirst, TagValue::Float(1.0)).is_err());
    assert!(encode(F32, HighFirst, TagValue::Int(1)).is_err());
    assert!(encode(Bool, HighFirst, TagValue::Bool(true)).is_err());
}

#[test]
fn values_serialise_as_plain_json() {
    assert_eq!(serde_json::to_value(TagValue::Bool(true)).unwrap(), json!(true));
    assert_eq!(serde_json::to_value(TagValue::Int(-5)).unwrap(), json!(-5));
    assert_eq!(serde_json::to_value(TagValue::Float(0.1)).unwrap(), json!(0.1));
}
