//! `bench history`: what a year of history costs the reads. Seeds a store with N ended jobs
//! spread over a year (through `rackd::store::import`, the store's own statements, at full
//! speed: not by replaying the API), rebuilds the KPIs' rollups from it (timed), starts `rackd serve` on it as a child process, and
//! prints each call beside the same call on an empty store in the same run, with the
//! ratio: the time to ready, single-POST latency (the first calls, on each store: the
//! fresh store then holds those 200 jobs), the KPI and list reads, `/metrics`, resident
//! memory, the database's size, and the prune of the oldest day (`store::archive`, as the
//! retention runs it) with the p99 of single POSTs sent meanwhile, beside their p99 on the
//! same store without a prune.
//!
//! The seeded site is the demo's (shelf aisle 1, crane aisle 2), its devices configured but
//! not running (no simulator answers: they are offline, as a site's at night, and cost the
//! reads nothing). Jobs: 45% store, 40% retrieve, 10% move, 5% light; 96% completed, 3%
//! failed, 1% cancelled; each with the history a job leaves (queued, dispatched, running,
//! ended: 4 rows), a few seconds to a minute long, uniformly over `--days` up to an hour
//! ago, so that the last hour of the store is as quiet as an empty one's.

use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::Context;
use rackd::config::Config;
use rackd::domain::{Failure, FailureKind, JobSpec, JobState, LightColor, Location, NewJob, Priority};
use rackd::store::import::{self, Ended};
use rackd::store::{Database, Pool};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

use crate::child::Server;

/// Jobs written per transaction.
const PAGE: usize = 5_000;
/// Each read is timed this many times; the median is printed.
const TIMES: usize = 7;
/// Single POSTs timed, one after the other.
const POSTS: usize = 200;

/// What to run.
#[derive(clap::Args, Debug)]
pub struct HistoryArgs {
    /// Ended jobs to seed.
    #[arg(long, default_value_t = 10_000_000)]
    jobs: u64,
    /// Over how many days back they are spread.
    #[arg(long, default_value_t = 365)]
    days: u64,
    /// `sqlite` (a file in a temporary folder), `postgres` (a fresh database of the tests'
    /// throwaway cluster) or a PostgreSQL URL (its database must be empty).
    #[arg(long, default_value = "sqlite")]
    database: String,
}

/// The figures of one store.
struct Figures {
    ready: Duration,
    reads: Vec<(String, Result<Duration, String>)>,
    post_p50: Duration,
    post_p99: Duration,
    rss_kib: u64,
    size_bytes: u64,
    /// The prune of the oldest day: jobs archived, how long it took, and the p99 of the
    /// single POSTs sent meanwhile (None when none was).
    prune: (u64, Duration, Option<Duration>),
}

/// Runs the benchmark.
pub async fn run(args: HistoryArgs) -> anyhow::Result<()> {
    println!(
        "bench history: {} ended jobs over {} days, {}, {} cores",
        args.jobs,
        args.days,
        args.database,
        std::thread::available_parallelism().map_or(1, |n| n.get())
    );
    let empty = measure(&args, 0).await?;
    let full = measure(&args, args.jobs).await?;
    print(&args, &empty, &full);
    Ok(())
}

/// Seeds a store with `jobs` jobs, serves it, and measures.
async fn measure(args: &HistoryArgs, jobs: u64) -> anyhow::Result<Figures> {
    let dir = tempfile::tempdir()?;
    let database = match args.database.as_str() {
        "sqlite" => Database::Sqlite(dir.path().join("bench.db")),
        "postgres" => Database::Postgres(crate::postgres::database().await),
        url => Database::Postgres(url.to_owned()),
    };
    let pool = rackd::store::open(&database, Duration::from_secs(30)).await?;
    let seeded = Instant::now();
    let ids = seed(&pool, jobs, args.days).await?;
    if jobs > 0 {
        let secs = seeded.elapsed().as_secs_f64();
        println!("seeded {jobs} jobs in {secs:.0} s ({:.0} jobs/s)", jobs as f64 / secs);
        // Loaded by another tool than the writer: the KPIs' rollups are rebuilt from the
        // history, as `rackd db rollups --rebuild` does.
        let t = Instant::now();
        let done = rackd::store::rollups::rebuild::rebuild(&pool, |_, _| {}).await?;
        let secs = t.elapsed().as_secs_f64();
        println!(
            "rebuilt the rollups from {} history entries in {secs:.0} s ({:.0} entries/s): {} rows, \
             the last transaction (the swap) {:.2} s",
            done.entries,
            done.entries as f64 / secs,
            done.rows,
            done.swap.as_secs_f64()
        );
    }
    pool.close().await;

    let mut config = Config::demo();
    // The seeded year stays: the prune is measured on its own (below).
    config.retention.jobs_days = 36_500;
    if let Database::Postgres(url) = &database {
        config.database.url = Some(url.clone());
    }
    let file = dir.path().join("bench.toml");
    std::fs::write(&file, toml::to_string(&config).context("the demo configuration as TOML")?)?;
    let started = Instant::now();
    let server = Server::start(&file, dir.path()).await?;
    let ready = started.elapsed();
    let base = format!("http://{}", server.addr);
    let client = reqwest::Client::new();

    let mut posts = Vec::with_capacity(POSTS);
    for n in 0..POSTS {
        let body = serde_json::json!({"kind": "light", "reference": format!("bench-post-{n}"),
            "location": {"aisle": 1, "row": 1, "bay": 1, "level": 1, "position": 1}, "color": "green", "on": true});
        let t = Instant::now();
        let r = client.post(format!("{base}/api/v1/jobs")).json(&body).send().await?;
        anyhow::ensure!(r.status() == 201, "POST /api/v1/jobs answered {}", r.status());
        posts.push(t.elapsed());
    }
    posts.sort();
    // The middle of the seeded jobs; on the fresh store, a posted one.
    let one = ids.map_or(1, |(first, last)| (first + last) / 2);
    let calls = [
        ("GET /api/v1/stats?since=30d".to_owned(), "/api/v1/stats?since=30d".to_owned()),
        ("GET /api/v1/stats?since=365d".to_owned(), "/api/v1/stats?since=365d".to_owned()),
        ("GET /api/v1/stats?since=8h".to_owned(), "/api/v1/stats?since=8h".to_owned()),
        ("GET /metrics".to_owned(), "/metrics".to_owned()),
        (
            "GET /api/v1/jobs?state=completed&limit=50".to_owned(),
            "/api/v1/jobs?state=completed&limit=50".to_owned(),
        ),
        ("GET /api/v1/jobs?limit=50".to_owned(), "/api/v1/jobs?limit=50".to_owned()),
        ("GET /api/v1/jobs?kind=light&limit=50".to_owned(), "/api/v1/jobs?kind=light&limit=50".to_owned()),
        (
            "GET /api/v1/jobs?device=crane1&limit=50".to_owned(),
            "/api/v1/jobs?device=crane1&limit=50".to_owned(),
        ),
        ("GET /api/v1/jobs/{id} (one job)".to_owned(), format!("/api/v1/jobs/{one}")),
        ("GET /api/v1/health".to_owned(), "/api/v1/health".to_owned()),
    ];
    let mut reads = Vec::new();
    for (name, path) in calls {
        reads.push((name, time_read(&client, &format!("{base}{path}")).await));
    }
    let rss_kib = rss_kib(server.pid)?;
    let prune = prune_a_day(&database, dir.path(), &client, &base).await?;
    server.stop().await;
    let size_bytes = size(&database, dir.path()).await?;
    Ok(Figures {
        ready,
        reads,
        post_p50: posts[POSTS / 2],
        post_p99: posts[POSTS * 99 / 100],
        rss_kib,
        size_bytes,
        prune,
    })
}

/// Archives the oldest day of the store (`store::archive`, as the retention does) while
/// single POSTs go on, one after the other: the jobs archived, the time, the POSTs' p99.
async fn prune_a_day(
    database: &Database,
    dir: &Path,
    client: &reqwest::Client,
    base: &str,
) -> anyhow::Result<(u64, Duration, Option<Duration>)> {
    let pool = rackd::store::open(database, Duration::from_secs(30)).await?;
    let first: Option<i64> = match &pool {
        Pool::Sqlite(p) => sqlx::query_scalar("SELECT MIN(updated_at) FROM jobs").fetch_one(p).await?,
        Pool::Postgres(p) => sqlx::query_scalar("SELECT MIN(updated_at) FROM jobs").fetch_one(p).await?,
    };
    let day = first.map_or(time::OffsetDateTime::now_utc(), rackd::domain::time::from_ms).date();
    let before = day.next_day().unwrap_or(day);
    let started = Instant::now();
    let folder = dir.join("archive");
    let archive = tokio::spawn(async move {
        let done =
            rackd::store::archive::archive(&pool, before, &folder, rackd::store::archive::Delete::Direct)
                .await;
        pool.close().await;
        done
    });
    let mut posts = Vec::new();
    while !archive.is_finished() {
        let body = serde_json::json!({"kind": "light", "reference": format!("bench-prune-{}", posts.len()),
            "location": {"aisle": 1, "row": 1, "bay": 2, "level": 1, "position": 1}, "color": "red", "on": true});
        let t = Instant::now();
        client.post(format!("{base}/api/v1/jobs")).json(&body).send().await?;
        posts.push(t.elapsed());
    }
    let done = archive.await??;
    let took = started.elapsed();
    posts.sort();
    let p99 = posts.get((posts.len() * 99 / 100).min(posts.len().saturating_sub(1))).copied();
    Ok((done.jobs, took, p99.filter(|_| !posts.is_empty())))
}

/// The median of [`TIMES`] calls of `url`, or what it answered instead of 200.
async fn time_read(client: &reqwest::Client, url: &str) -> Result<Duration, String> {
    let mut times = Vec::with_capacity(TIMES);
    for _ in 0..TIMES {
        let t = Instant::now();
        let r = client.get(url).send().await.map_err(|e| e.to_string())?;
        let status = r.status();
        let body = r.bytes().await.map_err(|e| e.to_string())?;
        if status != 200 {
            let code = serde_json::from_slice::<serde_json::Value>(&body)
                .ok()
                .and_then(|v| v["error"]["code"].as_str().map(str::to_owned))
                .unwrap_or_default();
            return Err(format!("{} {code}", status.as_u16()));
        }
        times.push(t.elapsed());
    }
    times.sort();
    Ok(times[TIMES / 2])
}

/// Writes `n` ended jobs over the last `days` days; the first and last id.
async fn seed(pool: &Pool, n: u64, days: u64) -> anyhow::Result<Option<(i64, i64)>> {
    if n == 0 {
        return Ok(None);
    }
    let mut rng = StdRng::seed_from_u64(39);
    let now = rackd::domain::time::now_ms();
    let (from, to) = (now - days as i64 * 86_400_000, now - 3_600_000);
    let mut id = 1i64;
    let mut page = Vec::with_capacity(PAGE);
    let mut last_report = Instant::now();
    while (id as u64) <= n {
        // Ids in the order of their creation time, as the writer gives them.
        let created = from + ((to - from) as f64 * (id - 1) as f64 / n as f64) as i64;
        page.push(job(&mut rng, id, created));
        id += 1;
        if page.len() == PAGE || id as u64 > n {
            import::ended_jobs(pool, &page).await?;
            page.clear();
            if last_report.elapsed() > Duration::from_secs(10) {
                println!("  {} of {n} jobs seeded", id - 1);
                last_report = Instant::now();
            }
        }
    }
    Ok(Some((1, n as i64)))
}

/// One ended job, created at `created` (Unix ms).
pub(crate) fn job(rng: &mut StdRng, id: i64, created: i64) -> Ended {
    let crane = rng.random_bool(0.5);
    let (aisle, bays, levels, positions) = if crane { (2, 20, 8, 2) } else { (1, 10, 6, 4) };
    let place = |rng: &mut StdRng| Location {
        aisle,
        row: rng.random_range(1..=2),
        bay: rng.random_range(1..=bays),
        level: rng.random_range(1..=levels),
        position: rng.random_range(1..=positions),
    };
    let roll: f64 = rng.random();
    let spec = if roll < 0.45 {
        JobSpec::Store { to: place(rng) }
    } else if roll < 0.85 {
        JobSpec::Retrieve { from: place(rng) }
    } else if roll < 0.95 {
        JobSpec::Move { from: place(rng), to: place(rng) }
    } else {
        JobSpec::Light { location: place(rng), color: LightColor::Green, on: true }
    };
    let device = if crane && !matches!(spec, JobSpec::Light { .. }) { "crane1" } else { "shelf1" };
    let new = NewJob {
        spec,
        reference: Some(format!("h{id}")),
        priority: Priority::DEFAULT,
        barcode: None,
        device: None,
        serves: None,
        terms: Default::default(),
    };
    let mut job = new.accepted(id, created);
    let dispatched = created + rng.random_range(100..30_000);
    let running = dispatched + rng.random_range(100..1_000);
    let took = if crane { rng.random_range(20_000..90_000) } else { rng.random_range(5_000..20_000) };
    let ended = running + took;
    let roll: f64 = rng.random();
    let (state, cause) = if roll < 0.96 {
        (JobState::Completed, "the device reported it done")
    } else if roll < 0.99 {
        (JobState::Failed, "the device reported a fault")
    } else {
        (JobState::Cancelled, "cancelled by wms")
    };
    if state == JobState::Failed {
        job.failure =
            Some(Failure { kind: FailureKind::DeviceFault, code: Some(7), text: "fault 7".to_owned() });
    }
    job.device = Some(device.to_owned());
    job.state = state;
    job.updated_at = rackd::domain::time::from_ms(ended);
    let history = vec![
        (JobState::Queued, "accepted".to_owned(), created),
        (JobState::Dispatched, format!("handed to {device}"), dispatched),
        (JobState::Running, "the device started it".to_owned(), running),
        (state, cause.to_owned(), ended),
    ];
    Ended { request: new.canonical(), job, history }
}

/// The resident memory of process `pid`, KiB.
fn rss_kib(pid: u32) -> anyhow::Result<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status"))?;
    let line = status.lines().find(|l| l.starts_with("VmRSS:")).context("no VmRSS")?;
    Ok(line.split_whitespace().nth(1).and_then(|v| v.parse().ok()).unwrap_or(0))
}

/// The database's size on disk: SQLite's file and its WAL, or PostgreSQL's database.
pub(crate) async fn size(database: &Database, dir: &Path) -> anyhow::Result<u64> {
    Ok(match database {
        Database::Sqlite(_) => ["bench.db", "bench.db-wal"]
            .iter()
            .filter_map(|f| std::fs::metadata(dir.join(f)).ok())
            .map(|m| m.len())
            .sum(),
        Database::Postgres(url) => {
            let pool = sqlx::PgPool::connect(url).await?;
            let bytes: i64 =
                sqlx::query_scalar("SELECT pg_database_size(current_database())").fetch_one(&pool).await?;
            pool.close().await;
            bytes as u64
        }
    })
}

fn print(args: &HistoryArgs, empty: &Figures, full: &Figures) {
    println!("{:<48} {:>14} {:>14} {:>8}", "", "fresh store", format!("{} jobs", args.jobs), "ratio");
    let row = |name: &str, a: String, b: String, r: String| println!("{name:<48} {a:>14} {b:>14} {r:>8}");
    // A figure of both stores, shown by `show`, and their ratio.
    let pair = |name: &str, a: f64, b: f64, show: &dyn Fn(f64) -> String| {
        let ratio = if a > 0.0 { format!("{:.1}x", b / a) } else { "-".to_owned() };
        row(name, show(a), show(b), ratio);
    };
    let ms = |secs: f64| format!("{:.2} ms", secs * 1000.0);
    let secs = |d: Duration| d.as_secs_f64();
    pair("start-up to ready", secs(empty.ready), secs(full.ready), &ms);
    for ((name, a), (_, b)) in empty.reads.iter().zip(&full.reads) {
        match (a, b) {
            (Ok(a), Ok(b)) => pair(name, secs(*a), secs(*b), &ms),
            _ => {
                let show =
                    |x: &Result<Duration, String>| x.as_ref().map_or_else(|e| e.clone(), |d| ms(secs(*d)));
                row(name, show(a), show(b), "-".to_owned());
            }
        }
    }
    pair("POST /api/v1/jobs, p50", secs(empty.post_p50), secs(full.post_p50), &ms);
    pair("POST /api/v1/jobs, p99", secs(empty.post_p99), secs(full.post_p99), &ms);
    let mib = |kib: f64| format!("{:.0} MiB", kib / 1024.0);
    pair("resident memory after the reads", empty.rss_kib as f64, full.rss_kib as f64, &mib);
    let size = |bytes: f64| format!("{:.1} MiB", bytes / 1_048_576.0);
    pair("database size", empty.size_bytes as f64, full.size_bytes as f64, &size);
    let (jobs, took) = (full.prune.0, full.prune.1);
    row(
        &format!("prune of the oldest day ({jobs} jobs)"),
        ms(secs(empty.prune.1)),
        ms(secs(took)),
        "-".to_owned(),
    );
    if let Some(during) = full.prune.2 {
        let (without, during) = (secs(full.post_p99), secs(during));
        println!(
            "single POSTs on the {} jobs, p99: {} without a prune, {} during it ({:.1}x)",
            args.jobs,
            ms(without),
            ms(during),
            during / without
        );
    }
}
