//! The WMS's side of a run: it posts the stream in order, a sequence as one batch, keeping
//! at most `--backlog` jobs per aisle open over the site, and learns of each job's end
//! from rackd's live events (`GET /api/v1/ws?topics=jobs`), as a WMS would.
//!
//! A deadline is set as the job is posted: the post's simulated instant plus the job's
//! allowance. rackd reads deadlines on the wall clock while the cranes run `--time-scale`
//! times faster, so the deadline sent is the post's wall-clock time plus the allowance
//! divided by the time scale.

use std::collections::HashMap;
use std::time::{Duration, Instant};

use anyhow::{Context, bail, ensure};
use futures::StreamExt;
use serde_json::{Value, json};
use time::OffsetDateTime;
use time::format_description::well_known::Rfc3339;
use tokio::sync::mpsc;
use tokio_tungstenite::tungstenite::Message;

use super::Mode;
use super::workload::{Job, Kind, Post, Workload};

/// Longest wait for any job to end before the run is given up.
const STALL: Duration = Duration::from_secs(120);

/// What became of one job.
#[derive(Clone, Debug)]
pub struct Posted {
    /// rackd's id.
    pub id: i64,
    /// When rackd answered (the job committed).
    pub answered: Instant,
    /// Its deadline in simulated seconds from the start, if the workload gives it one.
    pub deadline: Option<f64>,
    /// Its end state (`completed`, `failed`, `cancelled`).
    pub ended: String,
}

/// How the run is clocked: its start on both clocks, and the time scale.
#[derive(Clone, Copy, Debug)]
pub struct Clock {
    /// The start of the workload.
    pub start: Instant,
    /// The same instant on the wall clock.
    pub wall: OffsetDateTime,
    /// Simulated seconds per real second.
    pub scale: f64,
}

impl Clock {
    /// Simulated seconds from the start to `at`.
    pub fn sim(&self, at: Instant) -> f64 {
        at.saturating_duration_since(self.start).as_secs_f64() * self.scale
    }

    /// The wall-clock time of simulated second `secs`.
    fn wall_at(&self, secs: f64) -> OffsetDateTime {
        self.wall + Duration::from_secs_f64(secs.max(0.0) / self.scale)
    }
}

/// Runs the stream against rackd at `base` (`http://ADDR`); one entry per job.
pub async fn run(
    base: String,
    workload: &Workload,
    mode: Mode,
    backlog: usize,
    clock: Clock,
) -> anyhow::Result<Vec<Posted>> {
    let (ends, mut ended) = mpsc::unbounded_channel();
    let url = format!("{}/api/v1/ws?topics=jobs", base.replace("http://", "ws://"));
    let (mut socket, _) = tokio_tungstenite::connect_async(url).await.context("the WMS's live events")?;
    let first = socket.next().await.context("no snapshot")??;
    ensure!(matches!(first, Message::Text(_)), "the live events began with {first:?}");
    let reader = tokio::spawn(async move {
        while let Some(Ok(message)) = socket.next().await {
            let Message::Text(text) = message else { continue };
            let event: Value = serde_json::from_str(&text).unwrap_or_default();
            let data = &event["data"];
            let state = data["state"].as_str().unwrap_or_default();
            if event["type"] == "job.updated" && ["completed", "failed", "cancelled"].contains(&state) {
                let index = data["reference"].as_str().and_then(|r| r.strip_prefix('J')?.parse().ok());
                if let Some(index) = index {
                    let _ = ends.send((index, state.to_owned()));
                }
            }
        }
    });
    let client = reqwest::Client::new();
    let cap = backlog * usize::from(workload.aisles);
    let mut posted: Vec<Option<Posted>> = vec![None; workload.jobs.len()];
    let mut done: HashMap<usize, String> = HashMap::new();
    let mut open = 0usize;
    for post in &workload.posts {
        let members = match *post {
            Post::Job(j) => vec![j],
            Post::Sequence(s) => workload.sequences[s].members.clone(),
        };
        while open > 0 && open + members.len() > cap {
            let (index, state) = next_end(&mut ended, &done).await?;
            done.insert(index, state);
            open -= 1;
        }
        let sent = Instant::now();
        let deadline = |j: &Job| j.deadline.map(|d| clock.sim(sent) + d.allowance);
        let bodies: Vec<Value> = members
            .iter()
            .map(|&j| request(workload, j, mode, deadline(&workload.jobs[j]).map(|s| clock.wall_at(s))))
            .collect();
        let ids = if let [body] = bodies.as_slice() {
            let r = client.post(format!("{base}/api/v1/jobs")).json(body).send().await?;
            ensure!(r.status() == 201, "POST {body}: {} {}", r.status(), r.text().await?);
            vec![r.json::<Value>().await?["id"].as_i64().context("a job id")?]
        } else {
            let r = client
                .post(format!("{base}/api/v1/jobs/batch"))
                .json(&json!({"jobs": bodies}))
                .send()
                .await?;
            ensure!(r.status() == 201, "POST batch {bodies:?}: {} {}", r.status(), r.text().await?);
            let answer: Value = r.json().await?;
            let jobs = answer["jobs"].as_array().context("a batch's jobs")?;
            jobs.iter().map(|j| j["id"].as_i64().context("a job id")).collect::<anyhow::Result<_>>()?
        };
        let answered = Instant::now();
        for (&j, id) in members.iter().zip(ids) {
            let deadline = deadline(&workload.jobs[j]);
            posted[j] = Some(Posted { id, answered, deadline, ended: String::new() });
        }
        open += members.len();
    }
    while open > 0 {
        let (index, state) = next_end(&mut ended, &done).await?;
        done.insert(index, state);
        open -= 1;
    }
    reader.abort();
    posted
        .into_iter()
        .enumerate()
        .map(|(j, p)| {
            let mut p = p.with_context(|| format!("job J{j} was never posted"))?;
            p.ended = done.remove(&j).unwrap_or_default();
            Ok(p)
        })
        .collect()
}

/// The next job to end that had not ended before (an end is told once per job, but a
/// state after `completed` would be a second one).
async fn next_end(
    ended: &mut mpsc::UnboundedReceiver<(usize, String)>,
    done: &HashMap<usize, String>,
) -> anyhow::Result<(usize, String)> {
    loop {
        match tokio::time::timeout(STALL, ended.recv()).await {
            Ok(Some(end)) if !done.contains_key(&end.0) => return Ok(end),
            Ok(Some(_)) => {}
            Ok(None) => bail!("rackd's live events ended"),
            Err(_) => bail!("no job ended in {STALL:?}"),
        }
    }
}

/// Job `j` as the WMS posts it in `mode`: with its sequence and deadline when the mode
/// posts them.
fn request(workload: &Workload, j: usize, mode: Mode, deadline: Option<OffsetDateTime>) -> Value {
    let job = &workload.jobs[j];
    let at = |[row, bay, level, side]: [u16; 4]| json!({"aisle": job.aisle, "row": row, "bay": bay, "level": level, "position": side});
    let mut body = match job.kind {
        Kind::Store(cell) => json!({"kind": "store", "to": at(cell)}),
        Kind::Retrieve(cell) => json!({"kind": "retrieve", "from": at(cell)}),
    };
    body["reference"] = json!(format!("J{j}"));
    body["barcode"] = json!(job.barcode);
    if let (Some(d), Some(at)) = (job.deadline, deadline)
        && mode.posts(&d)
    {
        body["deadline"] = json!(at.format(&Rfc3339).expect("a formattable time"));
    }
    if let Some(m) = job.member.filter(|_| mode == Mode::Orders) {
        let sequence = &workload.sequences[m.sequence];
        body["sequence"] = json!({
            "name": format!("SEQ-{}", m.sequence),
            "position": m.position,
            "station": sequence.station,
            "last": m.position as usize == sequence.members.len(),
        });
    }
    body
}
