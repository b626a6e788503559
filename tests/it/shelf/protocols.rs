//! One task-slot interface, many protocols: the same workload through the real rackd over
//! Modbus RTU on a pty pair (the S7-1200-like RTU slave), PPI and MEWTOCOL (pty and TCP)
//! ends exactly as it does over the seed's Modbus UDP: the same job results, the same
//! failure kinds, the same inventory and lights on the simulated shelf.

use std::collections::BTreeMap;
use std::time::Duration;

use rackd::config::devices::ShelfConfig;
use rackd::domain::Location;
use rackd::protocols::faults::Faults;
use rackd::sim::shelf::{ShelfProtocol, ShelfSim, ShelfSimOptions};
use rackd::store::Engine;
use serde_json::{Value, json};

use super::workload::rackd_store;
use crate::support::*;

/// What a run left behind: each job's (kind, state, failure kind, failure code) in
/// submission order, the PLC's inventory and the lights it has on.
#[derive(Debug, PartialEq)]
struct Outcome {
    jobs: Vec<(String, String, Value, Value)>,
    inventory: BTreeMap<Location, String>,
    lights: Vec<(Location, &'static str)>,
}

/// Stores, retrieves, a move, a clear, a light, and a retrieve from a place the PLC knows
/// is empty (rejected, kind 2). Jobs on the same place run in order: rackd holds a later
/// job while an earlier one reserves its location.
fn workload() -> Vec<Value> {
    vec![
        json!({"kind": "store", "barcode": "BOX-A", "to": loc(1, 1, 1, 1)}),
        json!({"kind": "store", "barcode": "BOX-B", "to": loc(1, 1, 1, 2)}),
        json!({"kind": "store", "to": loc(2, 3, 2, 1)}),
        json!({"kind": "store", "barcode": "BOX-D", "to": loc(2, 5, 6, 4)}),
        json!({"kind": "retrieve", "from": loc(1, 1, 1, 1)}),
        json!({"kind": "move", "from": loc(1, 1, 1, 2), "to": loc(1, 2, 3, 3)}),
        json!({"kind": "clear", "location": loc(2, 3, 2, 1)}),
        json!({"kind": "light", "location": loc(2, 5, 6, 4), "color": "red", "on": true}),
        json!({"kind": "retrieve", "from": loc(2, 9, 6, 4)}),
    ]
}

fn options(protocol: ShelfProtocol) -> ShelfSimOptions {
    ShelfSimOptions { task_time: Duration::from_millis(5), ..ShelfSimOptions::for_protocol(protocol) }
}

/// Runs the workload through a real rackd driving `sim` at `address` (device settings
/// changed by `edit`), and checks that rackd's store agrees with the PLC's and that rule 1
/// was kept.
async fn run(sim: &ShelfSim, address: &str, edit: impl FnOnce(&mut ShelfConfig)) -> Outcome {
    let mut device = rackd::cli::demo::shelf_device(sim, "shelf1", address, vec![1]);
    (device.poll_ms, device.link.timeout, device.link.retries) = (20, Duration::from_millis(200), 3);
    edit(&mut device);
    let app = spawn_with(Engine::Sqlite, |c| c.devices = vec![device.into()]).await;
    let jobs = workload();
    let (status, body) = app.post("/api/v1/jobs/batch", &json!({"jobs": jobs})).await;
    assert_eq!(status, 201, "{body}");
    let mut done = wait_ended(&app, jobs.len(), 60).await;
    done.sort_by_key(|j| j["id"].as_i64());
    let (boxes, mut lights) = rackd_store(&app).await;
    let what = sim.protocol();
    assert_eq!(boxes, sim.inventory(), "{what}: rackd's inventory equals the PLC's");
    let mut sim_lights = sim.lights_on();
    lights.sort();
    sim_lights.sort();
    assert_eq!(lights, sim_lights, "{what}: lights agree");
    assert_eq!(sim.violations(), 0, "{what}: no write into a busy slot");
    app.stop().await;
    Outcome {
        jobs: done
            .iter()
            .map(|j| {
                let s = |v: &Value| v.as_str().unwrap_or_default().to_owned();
                (s(&j["kind"]), s(&j["state"]), j["failure"]["kind"].clone(), j["failure"]["code"].clone())
            })
            .collect(),
        inventory: sim.inventory(),
        lights: sim_lights,
    }
}

/// The workload over the seed's transport, checked against what it must give.
async fn over_udp() -> Outcome {
    let sim = ShelfSim::start("127.0.0.1:0", options(ShelfProtocol::ModbusUdp)).await.unwrap();
    let outcome = run(&sim, &sim.local_addr().unwrap().to_string(), |_| {}).await;
    let states: Vec<_> = outcome.jobs.iter().map(|j| j.1.as_str()).collect();
    assert_eq!(states, ["completed"; 8].iter().copied().chain(["failed"]).collect::<Vec<_>>());
    assert_eq!(outcome.jobs[8].2, "rejected");
    assert_eq!(outcome.jobs[8].3, 2);
    let at = |row, bay, level, position| Location { aisle: 1, row, bay, level, position };
    let expected: BTreeMap<_, _> =
        [(at(1, 2, 3, 3), "BOX-B".to_owned()), (at(2, 5, 6, 4), "BOX-D".to_owned())].into();
    assert_eq!(outcome.inventory, expected);
    assert_eq!(outcome.lights, vec![(at(2, 5, 6, 4), "red")]);
    sim.shutdown().await;
    outcome
}

/// The workload over a serial protocol: the simulator on one end of a pty pair, rackd
/// opening the other end by its path, as it opens /dev/ttyUSB0 on a site.
async fn over_pty(protocol: ShelfProtocol) -> Outcome {
    let (sim_end, rackd_end) = tokio_serial::SerialStream::pair().expect("pty pair");
    let path = tokio_serial::SerialPort::name(&rackd_end).expect("a pty's far end has a path");
    let sim = ShelfSim::serve_stream(sim_end, options(protocol)).await.unwrap();
    let outcome = run(&sim, &path, |_| {}).await;
    sim.shutdown().await;
    // Held open until here: were the last descriptor of the far end closed, reading the
    // simulator's end would fail.
    drop(rackd_end);
    outcome
}

async fn over_tcp(protocol: ShelfProtocol) -> Outcome {
    let sim = ShelfSim::start("127.0.0.1:0", options(protocol)).await.unwrap();
    let outcome = run(&sim, &sim.local_addr().unwrap().to_string(), |_| {}).await;
    sim.shutdown().await;
    outcome
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn lossy_ppi_and_mewtocol_lines_still_end_as_over_udp() {
    let udp = over_udp().await;
    for protocol in [ShelfProtocol::PpiTcp, ShelfProtocol::MewtocolTcp] {
        let mut lossy = options(protocol);
        lossy.faults = Faults {
            drop_rate: 0.2,
            garbage_rate: 0.1,
            delay: Duration::from_millis(1),
            ..Faults::default()
        };
        let sim = ShelfSim::start("127.0.0.1:0", lossy).await.unwrap();
        // Lost requests and responses, noise and late replies: rackd's retries must still
        // hand each task over once, and never write into a busy slot (run checks it).
        let outcome = run(&sim, &sim.local_addr().unwrap().to_string(), |d| {
            (d.link.timeout, d.link.retries, d.offline_after) = (Duration::from_millis(40), 8, 20);
        })
        .await;
        assert_eq!(outcome, udp, "{protocol}");
        sim.shutdown().await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn modbus_rtu_on_a_pty_against_an_s7_1200_ends_as_over_udp() {
    let udp = over_udp().await;
    assert_eq!(over_pty(ShelfProtocol::ModbusRtu).await, udp);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn ppi_on_a_pty_and_over_tcp_ends_as_over_udp() {
    let udp = over_udp().await;
    assert_eq!(over_pty(ShelfProtocol::Ppi).await, udp);
    assert_eq!(over_tcp(ShelfProtocol::PpiTcp).await, udp);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn mewtocol_on_a_pty_and_over_tcp_ends_as_over_udp() {
    let udp = over_udp().await;
    assert_eq!(over_pty(ShelfProtocol::Mewtocol).await, udp);
    assert_eq!(over_tcp(ShelfProtocol::MewtocolTcp).await, udp);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn modbus_tcp_and_rtu_over_tcp_end_as_over_udp() {
    let udp = over_udp().await;
    assert_eq!(over_tcp(ShelfProtocol::ModbusTcp).await, udp);
    assert_eq!(over_tcp(ShelfProtocol::ModbusRtuTcp).await, udp);
}
