//! 500 mixed jobs: all complete, and rackd's inventory and lights equal the simulator's.

use std::collections::BTreeMap;

use rackd::domain::Location;
use rackd::wire::task_id_for;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use serde_json::{Value, json};

use super::{shelf_app, sim};
use crate::support::*;

/// What the store should look like after the jobs, applied in order.
#[derive(Default)]
pub struct Model {
    pub boxes: BTreeMap<Location, String>,
    pub lights: BTreeMap<(Location, &'static str), bool>,
}

fn all_locations() -> Vec<Location> {
    let mut v = Vec::new();
    for row in 1..=2 {
        for bay in 1..=10 {
            for level in 1..=6 {
                for position in 1..=4 {
                    v.push(Location { aisle: 1, row, bay, level, position });
                }
            }
        }
    }
    v
}

fn js(l: Location) -> Value {
    serde_json::to_value(l).unwrap()
}

/// `n` jobs, each valid against the store as the jobs before it leave it.
pub fn mixed_jobs(n: usize, seed: u64, model: &mut Model) -> Vec<Value> {
    let mut rng = StdRng::seed_from_u64(seed);
    let all = all_locations();
    let mut jobs = Vec::new();
    for i in 0..n {
        let occupied: Vec<Location> = model.boxes.keys().copied().collect();
        let empty: Vec<Location> = all.iter().copied().filter(|l| !model.boxes.contains_key(l)).collect();
        let pick = |rng: &mut StdRng, v: &[Location]| v[rng.random_range(0..v.len())];
        let choice = if occupied.len() < 3 { 0 } else { rng.random_range(0..5) };
        let job = match choice {
            1 => {
                let from = pick(&mut rng, &occupied);
                model.boxes.remove(&from);
                json!({"kind": "retrieve", "from": js(from)})
            }
            2 => {
                let (from, to) = (pick(&mut rng, &occupied), pick(&mut rng, &empty));
                let b = model.boxes.remove(&from).unwrap();
                model.boxes.insert(to, b);
                json!({"kind": "move", "from": js(from), "to": js(to)})
            }
            3 => {
                let at = pick(&mut rng, &all);
                model.boxes.remove(&at);
                json!({"kind": "clear", "location": js(at)})
            }
            4 => {
                let at = pick(&mut rng, &all);
                let color = if rng.random_bool(0.5) { "red" } else { "green" };
                let on = rng.random_bool(0.6);
                model.lights.insert((at, color), on);
                json!({"kind": "light", "location": js(at), "color": color, "on": on})
            }
            _ => {
                let to = pick(&mut rng, &empty);
                let barcode = format!("BOX-{seed}-{i}");
                model.boxes.insert(to, barcode.clone());
                json!({"kind": "store", "to": js(to), "barcode": barcode})
            }
        };
        jobs.push(job);
    }
    jobs
}

/// Posts jobs in batches of 100.
pub async fn submit(app: &TestApp, jobs: &[Value]) {
    for chunk in jobs.chunks(100) {
        let (status, body) = app.post("/api/v1/jobs/batch", &json!({"jobs": chunk})).await;
        assert_eq!(status, 201, "{body}");
    }
}

/// rackd's locations as (boxes with barcodes, lights on).
pub async fn rackd_store(app: &TestApp) -> (BTreeMap<Location, String>, Vec<(Location, &'static str)>) {
    let (_, locations) = app.get("/api/v1/locations").await;
    let mut boxes = BTreeMap::new();
    let mut lights = Vec::new();
    for l in locations.as_array().unwrap() {
        let at: Location = serde_json::from_value(json!({
            "aisle": l["aisle"], "row": l["row"], "bay": l["bay"], "level": l["level"], "position": l["position"]
        }))
        .unwrap();
        if l["occupied"] == true {
            boxes.insert(at, l["barcode"].as_str().unwrap_or("").to_owned());
        }
        for color in ["green", "red"] {
            if l[color] == true {
                lights.push((at, color));
            }
        }
        assert!(l["reserved_by"].is_null(), "a reservation outlived its job: {l}");
    }
    (boxes, lights)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn five_hundred_mixed_jobs_complete_and_inventories_agree() {
    let (app, sim) = shelf_app(sim(0), |_| {}).await;
    let mut model = Model::default();
    let jobs = mixed_jobs(500, 7, &mut model);
    submit(&app, &jobs).await;
    let done = wait_ended(&app, 500, 120).await;
    for j in &done {
        assert_eq!(j["state"], "completed", "{j}");
        assert_eq!(
            sim.received(task_id_for(j["id"].as_i64().unwrap())),
            1,
            "task of job {} sent once",
            j["id"]
        );
    }
    let (boxes, mut lights) = rackd_store(&app).await;
    assert_eq!(boxes, sim.inventory(), "rackd's inventory equals the PLC's");
    assert_eq!(boxes, model.boxes, "and the model's");
    let mut sim_lights = sim.lights_on();
    lights.sort();
    sim_lights.sort();
    assert_eq!(lights, sim_lights, "lights agree");
    let model_on: Vec<_> = model.lights.iter().filter(|(_, on)| **on).map(|(k, _)| *k).collect();
    assert_eq!(lights, model_on, "and with the model");
    assert_eq!(sim.violations(), 0, "no write into a busy slot");
}
