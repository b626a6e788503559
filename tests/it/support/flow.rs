//! A WMS that keeps sending jobs while the store fails under rackd (issue 53's PostgreSQL
//! restarts and failovers): [`Flow`] posts one job at a time, each with a reference, and
//! retries it every 20 ms while rackd answers 503 or cannot be reached, as a WMS would;
//! the reference makes a retry of a job already taken answer that job. It notes when
//! each job was accepted, which the tests time recovery with. Given several rackd nodes
//! (a cluster), it posts to each in turn, and to the next when one cannot be reached; a
//! node restarted on another port is pointed at again ([`Flow::point`]).
//!
//! The jobs go to the demo site's two machines in turn (three shelf jobs, then a crane
//! job): on each aisle a store into a place of its own, a light (shelf) or an empty travel
//! (crane), then the retrieve of the oldest box stored, so that the machines run real
//! transfers and every job can complete.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use serde_json::{Value, json};
use tokio::task::JoinHandle;

/// A job rackd accepted with a 2xx.
#[derive(Clone, Debug)]
pub struct Accepted {
    /// Its reference.
    pub reference: String,
    /// Its id as answered.
    pub id: i64,
    /// Its aisle: 1 the shelf's, 2 the crane's.
    pub aisle: u16,
    /// When the 2xx came.
    pub at: Instant,
    /// Whether it took a retry.
    pub retried: bool,
}

/// The poster, running until [`Flow::stop`].
pub struct Flow {
    urls: Arc<Mutex<Vec<String>>>,
    accepted: Arc<Mutex<Vec<Accepted>>>,
    stop: Arc<AtomicBool>,
    task: JoinHandle<()>,
}

impl Flow {
    /// Posts to the rackd nodes at `urls` in turn (the next one also when one does not
    /// answer), a job every `pace` once the last was accepted, references starting with
    /// `prefix`.
    pub fn start(urls: Vec<String>, pace: Duration, prefix: &str) -> Flow {
        let urls = Arc::new(Mutex::new(urls));
        let accepted = Arc::new(Mutex::new(Vec::new()));
        let stop = Arc::new(AtomicBool::new(false));
        let task =
            tokio::spawn(post_all(urls.clone(), pace, prefix.to_owned(), accepted.clone(), stop.clone()));
        Flow { urls, accepted, stop, task }
    }

    /// From now on posts to `url` in place of the `i`-th URL (a node started again, on a
    /// port of its own choosing).
    pub fn point(&self, i: usize, url: &str) {
        self.urls.lock().unwrap()[i] = url.to_owned();
    }

    /// How many were accepted so far.
    pub fn count(&self) -> usize {
        self.accepted.lock().unwrap().len()
    }

    /// The first job accepted at or after `since`, if any yet.
    pub fn first_after(&self, since: Instant) -> Option<Accepted> {
        self.accepted.lock().unwrap().iter().find(|a| a.at >= since).cloned()
    }

    /// Stops posting (the job in hand is posted until accepted first) and answers every
    /// job accepted.
    pub async fn stop(self) -> Vec<Accepted> {
        self.stop.store(true, Ordering::Relaxed);
        self.task.await.expect("the poster");
        std::mem::take(&mut *self.accepted.lock().unwrap())
    }
}

/// The poster's loop. Not `eventually`: a spawned future that calls an async closure
/// through `AsyncFnMut` is not known to be `Send`.
async fn post_all(
    urls: Arc<Mutex<Vec<String>>>,
    pace: Duration,
    prefix: String,
    accepted: Arc<Mutex<Vec<Accepted>>>,
    stop: Arc<AtomicBool>,
) {
    let http = reqwest::Client::builder().timeout(Duration::from_secs(10)).build().unwrap();
    let mut mix = Mix::default();
    let mut turn = 0usize;
    while !stop.load(Ordering::Relaxed) {
        let (aisle, mut job) = mix.next();
        let reference = format!("{prefix}-{}", mix.n);
        job["reference"] = json!(reference);
        let deadline = Instant::now() + Duration::from_secs(30);
        let mut tries = 0;
        let id = loop {
            let url = {
                let urls = urls.lock().unwrap();
                urls[turn % urls.len()].clone()
            };
            tries += 1;
            let answer = http.post(format!("{url}/api/v1/jobs")).json(&job).send().await;
            let last = match answer {
                Ok(r) => {
                    let status = r.status().as_u16();
                    let body: Value = r.json().await.unwrap_or_default();
                    match (status, body["id"].as_i64()) {
                        (200 | 201, Some(id)) => break id,
                        (503, _) => format!("{status} {body}"),
                        _ => panic!("{url} answered {reference} with {status} {body}"),
                    }
                }
                Err(e) => {
                    // Another node, if there is one.
                    turn += 1;
                    format!("{url}: {e}")
                }
            };
            assert!(Instant::now() < deadline, "{reference} not accepted within 30 s; last: {last}");
            tokio::time::sleep(Duration::from_millis(20)).await;
        };
        let at = Instant::now();
        turn += 1;
        accepted.lock().unwrap().push(Accepted { reference, id, aisle, at, retried: tries > 1 });
        tokio::time::sleep(pace).await;
    }
}

/// The jobs, in turn (see the module doc).
#[derive(Default)]
struct Mix {
    n: u32,
    k: [u16; 2],
    stored: [VecDeque<Value>; 2],
}

impl Mix {
    fn next(&mut self) -> (u16, Value) {
        self.n += 1;
        let aisle: u16 = if self.n.is_multiple_of(4) { 2 } else { 1 };
        let a = usize::from(aisle - 1);
        let k = self.k[a];
        self.k[a] += 1;
        // Each k < 300 its own place: row, bay, level (a box is taken out before its place
        // comes round again).
        let at = |level: u16| json!({"aisle": aisle, "row": 1 + k % 2, "bay": 1 + k / 2 % 10, "level": level, "position": 1});
        let stored = &mut self.stored[a];
        let job = match k % 3 {
            0 => {
                let to = at(1 + k / 20 % 5);
                stored.push_back(to.clone());
                json!({"kind": "store", "barcode": format!("BOX-{}", self.n), "to": to})
            }
            1 if aisle == 1 => {
                json!({"kind": "light", "location": at(6), "color": "green", "on": k.is_multiple_of(2)})
            }
            1 => json!({"kind": "travel", "to": at(8)}),
            _ => json!({"kind": "retrieve", "from": stored.pop_front().expect("stored two jobs ago")}),
        };
        (aisle, job)
    }
}
