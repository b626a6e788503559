//! `rackd sim ... --preset FILE --control ADDR`: each memory simulator started with the
//! preset shipped in `config/sim/` answers the real rackd client with the preset's values,
//! refuses a master's write into a read-only range with its protocol's own code, and its
//! control surface reads and writes values while the client reads them.

use std::path::PathBuf;
use std::time::Duration;

use rackd::cli::sim::bench::PresetArgs;
use rackd::cli::sim::faults::FaultArgs;
use rackd::cli::sim::{line as sim_line, mc3e as sim_mc3e, modbus as sim_modbus};
use rackd::protocols::link::{LinkConfig, connect};
use rackd::protocols::{DeviceCode, PlcError, PlcMemory, Protocol, mc3e, mewtocol, modbus, ppi};
use serde_json::json;

/// A started simulator: where its server and control surface listen, and what keeps
/// them running.
struct Bench {
    server: String,
    control: String,
    _running: Box<dyn std::any::Any>,
}

fn bench_args(file: &str) -> PresetArgs {
    PresetArgs {
        preset: Some(PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("config/sim").join(file)),
        control: Some("127.0.0.1:0".parse().unwrap()),
    }
}

async fn start(protocol: Protocol) -> Bench {
    let (server, control, running): (_, _, Box<dyn std::any::Any>) = match protocol {
        Protocol::ModbusTcp => {
            let args = sim_modbus::SimModbusArgs {
                listen: "127.0.0.1:0".into(),
                transport: sim_modbus::SimTransport::Tcp,
                unit: 1,
                quirk: vec![],
                serial: "9600,8E1".parse().unwrap(),
                faults: FaultArgs::default(),
                bench: bench_args("modbus.json"),
            };
            let r = sim_modbus::start(&args).await.unwrap();
            (r.server.local_addr().unwrap(), r.control.as_ref().unwrap().local_addr(), Box::new(r))
        }
        Protocol::Mc3e => {
            let args = sim_mc3e::SimMc3eArgs {
                listen: "127.0.0.1:0".parse().unwrap(),
                transport: sim_mc3e::SimTransport::Tcp,
                faults: FaultArgs::default(),
                cpu: Default::default(),
                bench: bench_args("mc3e.json"),
            };
            let r = sim_mc3e::start(&args).await.unwrap();
            (r.server.local_addr(), r.control.as_ref().unwrap().local_addr(), Box::new(r))
        }
        Protocol::MewtocolTcp | Protocol::PpiTcp => {
            let file = if protocol == Protocol::PpiTcp { "ppi.json" } else { "mewtocol.json" };
            let args = sim_line::SimLineArgs {
                listen: "127.0.0.1:0".into(),
                serial: None,
                station: None,
                faults: FaultArgs::default(),
                bench: bench_args(file),
            };
            let r = match protocol {
                Protocol::PpiTcp => sim_line::start_ppi(&args).await.unwrap(),
                _ => sim_line::start_mewtocol(&args).await.unwrap(),
            };
            (r.server.local_addr().unwrap(), r.control.as_ref().unwrap().local_addr(), Box::new(r))
        }
        other => unreachable!("{other}"),
    };
    Bench { server: server.to_string(), control: format!("http://{control}"), _running: running }
}

async fn client(protocol: Protocol, bench: &Bench) -> std::sync::Arc<dyn PlcMemory> {
    let mut link = LinkConfig::new(protocol, bench.server.clone());
    // A fixed 2 s timeout, no retry: these tests read presets, not the adaptive timer, whose
    // 2 ms floor a loaded machine can overshoot.
    (link.timeout, link.retries, link.tuning.min_timeout) =
        (Duration::from_secs(2), 0, Duration::from_secs(2));
    connect(&link).await.unwrap()
}

async fn words(plc: &dyn PlcMemory, address: &str, count: u16) -> Vec<u16> {
    plc.read_words(&plc.parse_address(address).unwrap(), count).await.unwrap()
}

async fn bits(plc: &dyn PlcMemory, address: &str, count: u16) -> Vec<bool> {
    plc.read_bits(&plc.parse_address(address).unwrap(), count).await.unwrap()
}

/// The device's own code of a refused write.
async fn refusal(plc: &dyn PlcMemory, address: &str, values: &[u16]) -> DeviceCode {
    match plc.write_words(&plc.parse_address(address).unwrap(), values).await {
        Err(PlcError::Device(code)) => code,
        other => panic!("write into {address}: {other:?}"),
    }
}

// 3.5 is 0x40600000; -70000 is 0xFFFEEE90.
const F32_HIGH: u16 = 0x4060;
const I32: [u16; 2] = [0xFFFE, 0xEE90];

#[tokio::test]
async fn modbus_serves_the_preset_and_refuses_read_only_writes_with_exception_02() {
    let bench = start(Protocol::ModbusTcp).await;
    let plc = client(Protocol::ModbusTcp, &bench).await;
    let plc = plc.as_ref();
    assert_eq!(words(plc, "4x100", 4).await, [0, F32_HIGH, 0x0001, 0x86A0], "f32 CDAB, u32 ABCD");
    assert_eq!(words(plc, "4x110", 4).await, [0x5241, 0x434B, 0x2D30, 0x3100], "RACK-01");
    assert_eq!(words(plc, "4x200", 3).await, [0xFFFB, 0, 5]);
    assert_eq!(words(plc, "4x300", 1).await, [1]);
    assert_eq!(bits(plc, "0x10", 3).await, [true, false, true]);
    assert_eq!(bits(plc, "1x0", 3).await, [true, true, false]);
    assert_eq!(words(plc, "3x0", 1).await, [215]);

    assert_eq!(refusal(plc, "4x103", &[1, 2]).await, DeviceCode::Modbus(modbus::Exception(2)));
    let coil = plc.write_bits(&plc.parse_address("0x12").unwrap(), &[false]).await;
    assert!(matches!(coil, Err(PlcError::Device(DeviceCode::Modbus(modbus::Exception(2))))), "{coil:?}");
    plc.write_words(&plc.parse_address("4x104").unwrap(), &[9]).await.unwrap();
    assert_eq!(words(plc, "4x102", 3).await, [0x0001, 0x86A0, 9], "nothing of the refused write landed");
    assert_eq!(bits(plc, "0x12", 1).await, [true]);
}

#[tokio::test]
async fn mc3e_serves_the_preset_and_refuses_read_only_writes_with_c05b() {
    let bench = start(Protocol::Mc3e).await;
    let plc = client(Protocol::Mc3e, &bench).await;
    let plc = plc.as_ref();
    assert_eq!(words(plc, "D100", 4).await, [0, F32_HIGH, I32[1], I32[0]], "MC: low word first");
    assert_eq!(words(plc, "D110", 4).await, [0x4152, 0x4B43, 0x302D, 0x0031], "RACK-01, low byte first");
    assert_eq!(words(plc, "D200", 3).await, [1, 2, 3]);
    assert_eq!(bits(plc, "M10", 3).await, [true, false, true]);
    assert_eq!(bits(plc, "X19", 3).await, [false, true, false]);

    assert_eq!(refusal(plc, "D103", &[1]).await, DeviceCode::Mc3e(mc3e::EndCode(0xC05B)));
    let x = plc.write_bits(&plc.parse_address("X3F").unwrap(), &[true]).await;
    assert!(matches!(x, Err(PlcError::Device(DeviceCode::Mc3e(mc3e::EndCode(0xC05B))))), "{x:?}");
    plc.write_bits(&plc.parse_address("X40").unwrap(), &[true]).await.unwrap();
    assert_eq!(words(plc, "D103", 1).await, [I32[0]]);
}

#[tokio::test]
async fn mewtocol_serves_the_preset_and_refuses_read_only_writes_with_error_65() {
    let bench = start(Protocol::MewtocolTcp).await;
    let plc = client(Protocol::MewtocolTcp, &bench).await;
    let plc = plc.as_ref();
    assert_eq!(words(plc, "DT100", 4).await, [0, F32_HIGH, I32[1], I32[0]], "MEWTOCOL: low word first");
    assert_eq!(words(plc, "DT110", 3).await, [0x5046, 0x582D, 0], "FP-X, low byte first");
    assert_eq!(words(plc, "WR0", 1).await, [4660]);
    assert_eq!(bits(plc, "Y1A", 1).await, [true]);
    assert_eq!(words(plc, "WX0", 1).await, [0x0008], "X3");

    assert_eq!(refusal(plc, "DT102", &[1]).await, DeviceCode::Mewtocol(mewtocol::ErrorCode(65)));
    let x = plc.write_bits(&plc.parse_address("X3").unwrap(), &[false]).await;
    assert!(matches!(x, Err(PlcError::Device(DeviceCode::Mewtocol(mewtocol::ErrorCode(65))))), "{x:?}");
    assert_eq!(refusal(plc, "WX3", &[1]).await, DeviceCode::Mewtocol(mewtocol::ErrorCode(65)));
    plc.write_words(&plc.parse_address("WX4").unwrap(), &[1]).await.unwrap();
    assert_eq!(words(plc, "DT102", 2).await, [I32[1], I32[0]]);
}

#[tokio::test]
async fn ppi_serves_the_preset_and_refuses_read_only_writes_with_item_code_03() {
    let bench = start(Protocol::PpiTcp).await;
    let plc = client(Protocol::PpiTcp, &bench).await;
    let plc = plc.as_ref();
    assert_eq!(words(plc, "VD4", 4).await, [F32_HIGH, 0, I32[0], I32[1]], "S7: high word first");
    assert_eq!(words(plc, "VW200", 3).await, [0x5337, 0x2D32, 0x3030], "S7-200");
    assert_eq!(words(plc, "VW100", 2).await, [0xFFFF, 2]);
    assert_eq!(bits(plc, "Q0.1", 1).await, [true]);
    assert_eq!(bits(plc, "I0.3", 1).await, [true]);

    assert_eq!(refusal(plc, "VW10", &[1]).await, DeviceCode::Ppi(ppi::ReturnCode::Item(0x03)));
    let i = plc.write_bits(&plc.parse_address("I1.7").unwrap(), &[true]).await;
    assert!(matches!(i, Err(PlcError::Device(DeviceCode::Ppi(ppi::ReturnCode::Item(3))))), "{i:?}");
    plc.write_bits(&plc.parse_address("I2.0").unwrap(), &[true]).await.unwrap();
    assert_eq!(words(plc, "VW10", 1).await, [I32[1]]);
}

async fn get(bench: &Bench, path: &str) -> serde_json::Value {
    let response = reqwest::get(format!("{}{path}", bench.control)).await.unwrap();
    assert!(response.status().is_success(), "GET {path}: {}", response.status());
    response.json().await.unwrap()
}

async fn put(bench: &Bench, body: serde_json::Value) -> (u16, serde_json::Value) {
    let response =
        reqwest::Client::new().put(format!("{}/values", bench.control)).json(&body).send().await.unwrap();
    (response.status().as_u16(), response.json().await.unwrap())
}

#[tokio::test]
async fn the_control_surface_plays_the_field_while_a_master_reads() {
    let bench = start(Protocol::ModbusTcp).await;
    let plc = client(Protocol::ModbusTcp, &bench).await;
    let plc = plc.as_ref();
    let f32_at = "/values?address=4x100&type=f32&word_order=cdab";
    assert_eq!(get(&bench, f32_at).await["value"], json!(3.5));
    assert_eq!(get(&bench, "/values?address=4x110&type=string&length=8").await["value"], json!("RACK-01"));
    assert_eq!(get(&bench, "/values?address=0x10&count=3").await["values"], json!([true, false, true]));

    // Into a read-only range: the field may, the master may not.
    let (status, _) =
        put(&bench, json!({"address": "4x100", "type": "f32", "word_order": "cdab", "value": -1.25})).await;
    assert_eq!(status, 200);
    assert_eq!(words(plc, "4x100", 2).await, [0, 0xBFA0], "-1.25 CDAB");
    assert_eq!(refusal(plc, "4x100", &[1]).await, DeviceCode::Modbus(modbus::Exception(2)));
    plc.write_words(&plc.parse_address("4x200").unwrap(), &[0xFFFF]).await.unwrap();
    assert_eq!(get(&bench, "/values?address=4x200&type=i16").await["value"], json!(-1));

    let (status, _) = put(&bench, json!({"address": "1x5", "value": true, "read_only": true})).await;
    assert_eq!(status, 200);
    assert_eq!(bits(plc, "1x5", 1).await, [true]);
    let listed = get(&bench, "/read-only").await;
    assert_eq!(
        listed,
        json!([{"address": "4x100", "count": 4}, {"address": "0x10", "count": 3}, {"address": "1x5", "count": 1}])
    );

    let (status, body) = put(&bench, json!({"address": "4x101", "value": 1, "read_only": true})).await;
    assert_eq!(status, 400);
    assert!(
        body["error"]["message"].as_str().unwrap().contains("overlaps the read-only range 4x100"),
        "{body}"
    );
    let (status, body) = put(&bench, json!({"address": "D1", "value": 1})).await;
    assert_eq!(status, 400);
    assert!(body["error"]["message"].as_str().unwrap().contains("D1"), "{body}");
    for query in ["address=4x1&type=f64", "address=4x0&type=u32&count=40000", "address=4x1&type=string"] {
        let reply = reqwest::get(format!("{}/values?{query}", bench.control)).await.unwrap();
        assert_eq!(reply.status().as_u16(), 400, "{query}");
    }

    // The master's requests: two reads, two writes (one refused).
    assert_eq!(get(&bench, "/counters").await, json!({"requests": 4, "refused": 1}));
}

#[tokio::test]
async fn every_simulator_has_the_same_control_surface() {
    for (protocol, address, order, before, after) in [
        (Protocol::Mc3e, "D100", "low-first", [0, F32_HIGH], [0, 0xBFA0]),
        (Protocol::MewtocolTcp, "DT100", "cdab", [0, F32_HIGH], [0, 0xBFA0]),
        (Protocol::PpiTcp, "VD4", "abcd", [F32_HIGH, 0], [0xBFA0, 0]),
    ] {
        let bench = start(protocol).await;
        let plc = client(protocol, &bench).await;
        let query = format!("/values?address={address}&type=f32&word_order={order}");
        assert_eq!(get(&bench, &query).await["value"], json!(3.5), "{protocol}");
        assert_eq!(words(plc.as_ref(), address, 2).await, before, "{protocol}");
        let body = json!({"address": address, "type": "f32", "word_order": order, "value": -1.25});
        assert_eq!(put(&bench, body).await.0, 200, "{protocol}");
        assert_eq!(words(plc.as_ref(), address, 2).await, after, "{protocol}");
        refusal(plc.as_ref(), address, &[1, 2]).await;
        assert_eq!(get(&bench, "/counters").await["refused"], json!(1), "{protocol}");
    }
}

#[test]
fn a_bad_preset_stops_the_simulator_before_it_serves() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("bench.json");
    std::fs::write(&file, r#"{"values": [{"address": "4x1", "value": 1}, {"address": "VW4", "value": 2}]}"#)
        .unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_rackd"))
        .args(["sim", "modbus", "--listen", "127.0.0.1:0", "--transport", "tcp", "--preset"])
        .arg(&file)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(err.contains("bench.json: values[1] (VW4): ") && !err.contains("serving"), "{err}");
}

#[tokio::test]
async fn the_binary_takes_preset_and_control_flags() {
    use tokio::io::{AsyncBufReadExt, BufReader};
    let preset = concat!(env!("CARGO_MANIFEST_DIR"), "/config/sim/ppi.json");
    let mut child = tokio::process::Command::new(env!("CARGO_BIN_EXE_rackd"))
        .args(["sim", "ppi", "--listen", "127.0.0.1:0", "--preset", preset, "--control", "127.0.0.1:0"])
        .stderr(std::process::Stdio::piped())
        .kill_on_drop(true)
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(child.stderr.take().unwrap()).lines();
    let (mut control, mut server) = (None, None);
    while control.is_none() || server.is_none() {
        let line = lines.next_line().await.unwrap().expect("the simulator printed its addresses");
        if let Some(at) = line.strip_prefix("control surface on ") {
            control = Some(at.to_owned());
        } else if let Some(rest) = line.strip_prefix("PPI simulator on ") {
            server = rest.split(';').next().map(str::to_owned);
        }
    }
    let bench = Bench { server: server.unwrap(), control: control.unwrap(), _running: Box::new(()) };
    assert_eq!(get(&bench, "/values?address=VB200&type=string&length=6").await["value"], json!("S7-200"));
    let plc = client(Protocol::PpiTcp, &bench).await;
    assert_eq!(words(plc.as_ref(), "VD8", 2).await, I32);
    child.kill().await.unwrap();
}
