//! Reading the flat `[[devices]]` form: kinds, keys of other kinds, shared checks.

use super::*;
use crate::protocols::{Protocol, Quirk};

fn entry(kind: &str, extra: &str) -> Result<DeviceConfig, toml::de::Error> {
    let text = format!("id = \"d1\"\nkind = {kind:?}\naddress = \"127.0.0.1:1\"\n{extra}");
    toml::from_str(&text)
}

fn checked(kind: &str, extra: &str) -> Result<(), DeviceConfigError> {
    entry(kind, extra).unwrap().check()
}

#[test]
fn each_kind_reads_into_its_own_variant_with_its_defaults() {
    let shelf = entry("shelf", "").unwrap();
    assert_eq!(shelf, DeviceConfig::Shelf(ShelfConfig::new("d1", "127.0.0.1:1", vec![])));
    let crane = entry("crane", "aisles = [2]").unwrap();
    assert_eq!(crane, DeviceConfig::Crane(CraneConfig::new("d1", "127.0.0.1:1", vec![2])));
    let tags = entry("tags", "[tags]\nx = \"4x1\"\n").unwrap();
    assert_eq!((tags.kind(), tags.link().protocol), (DeviceKind::Tags, Protocol::ModbusUdp));
    assert!(tags.link().quirks.is_empty(), "only the seed's shelf PLC has length0 by default");
    assert_eq!((tags.id(), tags.poll()), ("d1", Duration::from_millis(200)));
}

#[test]
fn a_key_of_another_kind_is_refused_by_name() {
    // stride is a shelf setting: a crane is refused for having one, saying so, and a
    // crane's own checks never look at slots.
    let err = entry("crane", "stride = 1").unwrap_err().to_string();
    assert!(err.contains("`stride` is a key of shelf devices") && err.contains("d1"), "{err}");
    assert!(checked("crane", "").is_ok());
    let err = entry("shelf", "ack = \"echo\"").unwrap_err().to_string();
    assert!(err.contains("`ack`") && err.contains("crane"), "{err}");
    let err = entry("shelf", "[tags]\nx = \"4x1\"\n").unwrap_err().to_string();
    assert!(err.contains("`tags`"), "{err}");
    let err = entry("tags", "aisles = [1]\n[tags]\nx = \"4x1\"\n").unwrap_err().to_string();
    assert!(err.contains("`aisles`"), "{err}");
    let err = entry("crane", "lissen = 1").unwrap_err().to_string();
    assert!(err.contains("lissen"), "{err}");
}

#[test]
fn closed_sets_are_refused_when_read() {
    let err = entry("crane", "ack = \"maybe\"").unwrap_err().to_string();
    assert!(err.contains("maybe") && err.contains("handshake"), "{err}");
    let err = entry("shelf", "protocol = \"mc9\"").unwrap_err().to_string();
    assert!(err.contains("mc9"), "{err}");
    let err = entry("shelf", "quirks = [\"length1\"]").unwrap_err().to_string();
    assert!(err.contains("length1"), "{err}");
    let err = entry("shelf", "protocol = \"modbus-rtu\"\nserial = \"9600\"").unwrap_err().to_string();
    assert!(err.contains("serial") && err.contains("9600"), "{err}");
    let rtu = entry("shelf", "protocol = \"modbus-rtu\"\nserial = \"19200,8N1\"").unwrap();
    assert_eq!(rtu.link().serial.map(|s| s.baud), Some(19200));
    let alias = entry("crane", "protocol = \"mc3e-tcp\"").unwrap();
    assert_eq!(alias.link().protocol, Protocol::Mc3e);
}

#[test]
fn shared_checks() {
    let err = checked("shelf", "offline_after = 0").unwrap_err().to_string();
    assert!(err.contains("offline_after must be at least 1"), "{err}");
    let err = toml::from_str::<DeviceConfig>("id = \"a b\"\nkind = \"shelf\"\naddress = \"x:1\"\n")
        .unwrap()
        .check()
        .unwrap_err();
    assert!(matches!(*err.problem, Problem::Id), "{err}");
    let err = checked("shelf", "protocol = \"modbus-tcp\"\nquirks = [\"no-bcc\"]").unwrap_err().to_string();
    assert!(err.contains("no-bcc") && err.contains("modbus-tcp"), "{err}");
    let mut tcp = entry("shelf", "protocol = \"modbus-tcp\"\nquirks = [\"no-transaction-id\"]").unwrap();
    assert_eq!(tcp.link().quirks, [Quirk::NoTransactionId].into());
    tcp.link_mut().unit = 0;
    tcp.check().unwrap();
}

#[test]
fn capture_keys_default_turn_off_and_are_bounded() {
    let shelf = entry("shelf", "").unwrap();
    assert_eq!(shelf.link().capture, crate::capture::Limits { bytes: 4 << 20, seconds: 600 });
    assert!(shelf.link().capture_limits().is_some(), "on by default");
    let off = entry("crane", "capture_bytes = 0").unwrap();
    assert_eq!(off.link().capture_limits(), None);
    off.check().unwrap();
    let set = entry("tags", "capture_bytes = 1024\ncapture_seconds = 60\n[tags]\nx = \"4x1\"\n").unwrap();
    assert_eq!(set.link().capture_limits(), Some(crate::capture::Limits { bytes: 1024, seconds: 60 }));
    let err = checked("shelf", "capture_bytes = 268435457").unwrap_err();
    assert_eq!(err.problem.key(), "capture_bytes", "{err}");
    assert!(err.to_string().contains("256 MiB"), "{err}");
    for seconds in [0, 86_401] {
        let err = checked("shelf", &format!("capture_seconds = {seconds}")).unwrap_err();
        assert_eq!(err.problem.key(), "capture_seconds", "{err}");
    }
    checked("shelf", "capture_bytes = 268435456\ncapture_seconds = 86400").unwrap();
}
