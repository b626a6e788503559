use super::*;

fn view(format: Format, order: Order) -> View {
    View { format, order, double: false }
}

fn text(v: View, words: &[u16]) -> String {
    v.show(words).unwrap().text
}

#[test]
fn words_show_in_every_format() {
    let abcd = |f| view(f, Order::Abcd);
    assert_eq!(text(abcd(Format::U16), &[0xFFFF]), "65535");
    assert_eq!(text(abcd(Format::I16), &[0xFFFF]), "-1");
    assert_eq!(text(abcd(Format::Hex), &[0x00AB]), "0x00AB");
    assert_eq!(text(abcd(Format::Bin), &[0x1234]), "0b00010010_00110100");
    assert_eq!(text(abcd(Format::U32), &[0x1234, 0x5678]), "305419896");
    assert_eq!(text(view(Format::U32, Order::Cdab), &[0x5678, 0x1234]), "305419896");
    assert_eq!(text(abcd(Format::I32), &[0xFFFF, 0xFFFE]), "-2");
    assert_eq!(abcd(Format::Hex).show(&[1]).unwrap().json, Json::String("0x0001".into()));
    assert_eq!(abcd(Format::I16).show(&[0x8000]).unwrap().json, Json::from(-32768));
}

#[test]
#[allow(clippy::approx_constant, reason = "3.14 is the common test vector, not an approximation of pi")]
fn floats_in_the_four_orders() {
    // 3.14f32 is 0x4048F5C3 (IEEE 754; the byte orders as Modbus Poll names them:
    // ABCD, CDAB, BADC, DCBA).
    for (order, words) in [
        (Order::Abcd, [0x4048, 0xF5C3]),
        (Order::Cdab, [0xF5C3, 0x4048]),
        (Order::Badc, [0x4840, 0xC3F5]),
        (Order::Dcba, [0xC3F5, 0x4840]),
    ] {
        let v = view(Format::F32, order);
        assert_eq!(text(v, &words), "3.14", "{order:?}");
        assert_eq!(v.show(&words).unwrap().json, serde_json::json!(3.14));
        assert_eq!(v.parse("3.14").unwrap(), words, "{order:?}");
    }
    assert_eq!(text(view(Format::F32, Order::Abcd), &[0xF5C3, 0x4048]), "-4.9502034e32");
    assert_eq!(text(view(Format::F32, Order::Abcd), &[0x0000, 0x0001]), "1e-45");
    assert_eq!(text(view(Format::F32, Order::Abcd), &[0x4996, 0xB438]), "1234567");
    let nan = view(Format::F32, Order::Abcd).show(&[0x7FC0, 0]).unwrap();
    assert_eq!((nan.text.as_str(), nan.json), ("NaN", Json::Null));
    assert!(view(Format::F32, Order::Abcd).parse("inf").is_err());
}

#[test]
fn values_to_write_take_the_format_and_its_range() {
    let abcd = |f| view(f, Order::Abcd);
    assert_eq!(abcd(Format::U16).parse("10000").unwrap(), [10000]);
    assert_eq!(abcd(Format::U16).parse("-1").unwrap(), [0xFFFF]);
    assert_eq!(abcd(Format::I16).parse("-32768").unwrap(), [0x8000]);
    assert_eq!(abcd(Format::U32).parse("305419896").unwrap(), [0x1234, 0x5678]);
    assert_eq!(view(Format::I32, Order::Cdab).parse("-2").unwrap(), [0xFFFE, 0xFFFF]);
    assert_eq!(abcd(Format::Hex).parse("0xBEEF").unwrap(), [0xBEEF]);
    assert_eq!(abcd(Format::Bin).parse("0b1_0000_0001").unwrap(), [0x0101]);
    for (f, bad) in [
        (Format::U16, "65536"),
        (Format::U16, "-32769"),
        (Format::I16, "32768"),
        (Format::U32, "4294967296"),
        (Format::Hex, "0x10000"),
        (Format::Hex, "zz"),
        (Format::Bin, "2"),
        (Format::F32, "pi"),
        (Format::Ascii, "ü"),
    ] {
        let err = abcd(f).parse(bad).unwrap_err();
        assert!(err.starts_with(&format!("bad {} value", abcd(f).name())), "{err}");
    }
    assert!(abcd(Format::U16).parse("65536").unwrap_err().contains("0..=65535 or -32768..=-1"));
    assert!(abcd(Format::Hex).parse("0x10000").unwrap_err().contains("at most 16 bits"));
    let vd = View { format: Format::Hex, order: Order::Abcd, double: true };
    assert_eq!(vd.parse("0x12345678").unwrap(), [0x1234, 0x5678]);
}

#[test]
fn too_few_words_are_an_error_not_a_panic() {
    assert!(view(Format::U16, Order::Abcd).show(&[]).is_err());
    assert!(view(Format::F32, Order::Abcd).show(&[1]).is_err());
    assert!(view(Format::Ascii, Order::Abcd).show(&[]).is_err());
}

#[test]
fn ascii_is_high_byte_first_without_trailing_nuls() {
    let v = view(Format::Ascii, Order::Abcd);
    assert_eq!(v.parse("HELLO").unwrap(), [0x4845, 0x4C4C, 0x4F00]);
    let shown = v.show(&[0x4845, 0x4C4C, 0x4F00, 0]).unwrap();
    assert_eq!((shown.text.as_str(), shown.json), ("\"HELLO\"", Json::String("HELLO".into())));
    assert_eq!(text(v, &[0x410D, 0x0142]), "\"A\\r\\x01B\"");
    assert_eq!(text(view(Format::Ascii, Order::Badc), &[0x4548]), "\"HE\"");
    assert_eq!(v.width(), None);
}

#[test]
fn s7_double_words_are_32_bit_high_first_whatever_the_order() {
    let vd = |format| View { format, order: Order::Cdab, double: true };
    assert_eq!(vd(Format::U16).width(), Some(2));
    assert_eq!(text(vd(Format::U16), &[0x1234, 0x5678]), "305419896");
    assert_eq!(text(vd(Format::I16), &[0xFFFF, 0xFFFF]), "-1");
    assert_eq!(text(vd(Format::Hex), &[0x1234, 0x5678]), "0x12345678");
    assert_eq!(vd(Format::U16).parse("305419896").unwrap(), [0x1234, 0x5678]);
    assert_eq!(vd(Format::U16).name(), "u32");
    assert_eq!(text(vd(Format::F32), &[0x4048, 0xF5C3]), "3.14");
}
