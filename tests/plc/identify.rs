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
