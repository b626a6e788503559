//! `rackd plc identify` against the Modbus and MC simulators.

use super::{ok, plc, sim};

#[test]
fn a_modbus_device_and_an_mc_cpu_say_what_they_are() {
    let modbus = sim(&["modbus", "--transport", "tcp"]);
    let lines = ok("modbus-tcp", &modbus.address, &["identify"]);
    assert!(lines.lines().any(|l| l == "VendorName rackd"), "{lines}");
    assert!(lines.lines().any(|l| l.starts_with("ProductCode ")), "{lines}");
    let one = ok("modbus-tcp", &modbus.address, &["identify", "--object", "0", "--json"]);
    let json: serde_json::Value = serde_json::from_str(&one).unwrap();
    assert_eq!(json["VendorName"], "rackd");
    let (good, _, err) = plc("modbus-tcp", &modbus.address, &["identify", "--object", "200"]);
    assert!(!good && err.contains("exception 02"), "{err}");

    let mc = sim(&["mc3e", "--cpu-model", "R04CPU", "--cpu-code", "4800"]);
    let lines = ok("mc3e", &mc.address, &["identify"]);
    assert_eq!(lines.lines().collect::<Vec<_>>(), ["model R04CPU", "code 4800"]);
    let lines = ok("mc4e", &mc.address, &["identify"]);
    assert!(lines.starts_with("model R04CPU"), "{lines}");

    let (good, _, err) = plc("mewtocol-tcp", "127.0.0.1:9", &["identify"]);
    assert!(!good && err.contains("no identification request"), "{err}");
}

#[test]
fn scattered_and_block_reads_fifo_and_diagnostics() {
    let mc = sim(&["mc3e"]);
    ok("mc3e", &mc.address, &["write", "D10", "7", "8"]);
    ok("mc3e", &mc.address, &["write", "M116", "1"]);
    let lines = ok("mc3e", &mc.address, &["random", "D11", "D10", "--dword", "D10"]);
    assert_eq!(lines.lines().collect::<Vec<_>>(), ["D11 8", "D10 7", "D10 524295"]);
    let lines = ok("mc4e", &mc.address, &["blocks", "D10:2", "K4M100:2"]);
    assert_eq!(lines.lines().collect::<Vec<_>>(), ["D10 7", "D11 8", "K4M100 0", "K4M116 1"]);
    let (good, _, err) = plc("mc3e", &mc.address, &["blocks", "D10"]);
    assert!(!good && err.contains("ADDRESS:COUNT"), "{err}");

    let modbus = sim(&["modbus", "--transport", "tcp"]);
    ok("modbus-tcp", &modbus.address, &["write", "4x100", "2", "11", "12"]);
    let lines = ok("modbus-tcp", &modbus.address, &["fifo", "4x100"]);
    assert_eq!(lines.lines().collect::<Vec<_>>(), ["count 2", "fifo[0] 11", "fifo[1] 12"]);
    let lines = ok("modbus-tcp", &modbus.address, &["diag", "000B"]);
    assert!(lines.starts_with("000B "), "{lines}");
    let (good, _, err) = plc("modbus-tcp", &modbus.address, &["random", "D0"]);
    assert!(!good && err.contains("is not MC protocol"), "{err}");
}

#[test]
fn an_unchecked_read_sends_the_count_as_asked_and_shows_the_devices_answer() {
    let modbus = sim(&["modbus", "--transport", "tcp"]);
    let (good, _, err) = plc("modbus-tcp", &modbus.address, &["read", "4x0", "0"]);
    assert!(!good, "a checked read of 0 is refused before sending: {err}");
    for count in ["0", "126"] {
        let (good, _, err) = plc("modbus-tcp", &modbus.address, &["read", "4x0", count, "--unchecked"]);
        assert!(!good && err.contains("exception 03"), "count {count}: {err}");
    }
    let lines = ok("modbus-tcp", &modbus.address, &["read", "0x5", "3", "--unchecked"]);
    assert_eq!(lines.lines().collect::<Vec<_>>(), ["0x5 0", "0x6 0", "0x7 0"]);
}

#[test]
fn a_presets_identity_is_what_the_simulator_says_it_is() {
    let dir = tempfile::tempdir().unwrap();
    let modbus = dir.path().join("modbus.json");
    std::fs::write(
        &modbus,
        r#"{"identity": {"objects": {"VendorName": "ACME", "ProductCode": "X-100",
            "MajorMinorRevision": "2.1", "0x80": "line 4"}}}"#,
    )
    .unwrap();
    let sim_modbus = sim(&["modbus", "--transport", "tcp", "--preset", modbus.to_str().unwrap()]);
    let lines = ok("modbus-tcp", &sim_modbus.address, &["identify", "--category", "extended"]);
    assert_eq!(
        lines.lines().collect::<Vec<_>>(),
        ["VendorName ACME", "ProductCode X-100", "MajorMinorRevision 2.1", "object 0x80 line 4"]
    );
    let mc = dir.path().join("mc.toml");
    std::fs::write(&mc, "[identity]\nmodel = \"FX5U-32MT\"\ncode = \"4A21\"\n").unwrap();
    let sim_mc = sim(&["mc3e", "--preset", mc.to_str().unwrap()]);
    let lines = ok("mc3e", &sim_mc.address, &["identify"]);
    assert_eq!(lines.lines().collect::<Vec<_>>(), ["model FX5U-32MT", "code 4A21"]);
}
