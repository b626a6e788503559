//! Display formats, word orders, notations and S7 double words, over sockets.

use super::{ok, plc, sim};

#[test]
fn f32_and_i32_round_trip_in_both_word_orders() {
    let modbus = sim(&["modbus", "--transport", "tcp"]);
    let m = |args: &[&str]| ok("modbus-tcp", &modbus.address, args);
    // 3.14f32 = 0x4048F5C3; -2i32 = 0xFFFFFFFE.
    m(&["write", "4x100", "-f", "f32", "3.14"]);
    assert_eq!(
        m(&["read", "4x100", "2", "-f", "hex"]),
        "4x100 0x4048\n4x101 0xF5C3\n",
        "Modbus: high word first"
    );
    assert_eq!(m(&["read", "4x100", "-f", "f32"]), "4x100 3.14\n");
    m(&["write", "4x100", "-f", "f32", "--word-order", "cdab", "3.14", "-1.5"]);
    assert_eq!(m(&["read", "4x100", "2", "-f", "hex"]), "4x100 0xF5C3\n4x101 0x4048\n");
    assert_eq!(m(&["read", "4x100", "2", "-f", "f32", "--word-order", "little"]), "4x100 3.14\n4x102 -1.5\n");
    m(&["write", "4x200", "-f", "i32", "-2"]);
    assert_eq!(m(&["read", "4x200", "-f", "i32"]), "4x200 -2\n");
    assert_eq!(m(&["read", "4x200", "2"]), "4x200 65535\n4x201 65534\n");
    assert_eq!(m(&["read", "4x200", "-f", "i16", "--json"]), "[{\"address\":\"4x200\",\"value\":-1}]\n");

    let mc3e = sim(&["mc3e"]);
    let c = |args: &[&str]| ok("mc3e", &mc3e.address, args);
    c(&["write", "D0", "-f", "i32", "-2", "305419896"]);
    assert_eq!(
        c(&["read", "D0", "4", "-f", "hex"]),
        "D0 0xFFFE\nD1 0xFFFF\nD2 0x5678\nD3 0x1234\n",
        "MC: low first"
    );
    assert_eq!(c(&["read", "D0", "2", "-f", "i32"]), "D0 -2\nD2 305419896\n");
    assert_eq!(c(&["read", "D2", "-f", "u32", "--word-order", "abcd"]), "D2 1450709556\n");
    c(&["write", "D10", "-f", "ascii", "HELLO"]);
    assert_eq!(c(&["read", "D10", "4", "-f", "ascii"]), "D10 \"HELLO\"\n");
}

#[test]
fn modicon_and_schneider_references_name_the_same_registers() {
    let modbus = sim(&["modbus", "--transport", "udp"]);
    let m = |args: &[&str]| ok("modbus-udp", &modbus.address, args);
    m(&["write", "40001", "11", "12"]);
    assert_eq!(m(&["read", "4x0", "2"]), "4x0 11\n4x1 12\n");
    m(&["write", "%MW100", "7"]);
    assert_eq!(m(&["read", "400101"]), "4x100 7\n");
    assert_eq!(m(&["read", "MW100"]), "4x100 7\n");
    m(&["write", "00011", "1"]);
    assert_eq!(m(&["read", "0x10"]), "0x10 1\n");
    let (ok, _, err) = plc("modbus-udp", &modbus.address, &["read", "0x10", "-f", "f32"]);
    assert!(!ok && err.contains("0x10 is coil 10 in the Modicon area notation, not hex 16"), "{err}");
    let (ok, _, err) = plc("modbus-udp", &modbus.address, &["read", "4000"]);
    assert!(!ok && err.contains("5 or 6 digits"), "{err}");
}

#[test]
fn s7_double_words_read_as_one_32_bit_value() {
    let ppi = sim(&["ppi"]);
    let p = |args: &[&str]| ok("ppi-tcp", &ppi.address, args);
    p(&["write", "VW4", "4660", "22136"]);
    assert_eq!(p(&["read", "VD4"]), "VD4 305419896\n");
    p(&["write", "VD8", "-1"]);
    assert_eq!(p(&["read", "VD4", "2"]), "VD4 305419896\nVD8 4294967295\n");
    assert_eq!(p(&["read", "VD8", "-f", "i32"]), "VD8 -1\n");
    assert_eq!(p(&["read", "VW4", "2"]), "VW4 4660\nVW6 22136\n");
    p(&["write", "VD12", "-f", "f32", "3.14"]);
    assert_eq!(p(&["read", "VW12", "2", "-f", "hex"]), "VW12 0x4048\nVW14 0xF5C3\n");
    assert_eq!(p(&["read", "VD12", "-f", "f32", "--json"]), "[{\"address\":\"VD12\",\"value\":3.14}]\n");

    let mewtocol = sim(&["mewtocol"]);
    let w = |args: &[&str]| ok("mewtocol-tcp", &mewtocol.address, args);
    w(&["write", "DT100", "-f", "i32", "-70000"]);
    assert_eq!(
        w(&["read", "DT100", "2", "-f", "hex"]),
        "DT100 0xEE90\nDT101 0xFFFE\n",
        "Panasonic: low first"
    );
    assert_eq!(w(&["read", "DT100", "-f", "i32"]), "DT100 -70000\n");
}

#[test]
fn mc_bit_devices_read_as_words_are_labelled_by_their_first_bit() {
    let mc = sim(&["mc3e"]);
    ok("mc3e", &mc.address, &["write", "M116", "1"]);
    let lines = ok("mc3e", &mc.address, &["read", "K4M100", "2"]);
    assert_eq!(lines.lines().collect::<Vec<_>>(), ["K4M100 0", "K4M116 1"]);
}
