//! `bench retention`: the store's size over a simulated year with `[retention]`. Seeds a
//! fresh store a day at a time (as `bench history` does, through `rackd::store::import`),
//! and after each day archives what the retention would (`store::archive`, the jobs that
//! ended more than `--keep` days before the day's end), printing every 30 days the jobs in
//! the store, its size (the file, and on SQLite the pages in use; the KPIs' rollups rebuilt
//! first, as the writer keeps them: the import does not) and the archive's; at the end it checks that every seeded job is in
//! the store or in the archive, once, and prints the size's spread once the retention has
//! started to delete (issue 39's goal: flat within 10%).

use std::collections::HashSet;
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::time::Instant;

use rackd::store::archive::{self, Delete};
use rackd::store::{Database, Pool, import};
use rand::SeedableRng;
use rand::rngs::StdRng;

use crate::history::{job, size};

const DAY: i64 = 86_400_000;

/// What to run.
#[derive(clap::Args, Debug)]
pub struct RetentionArgs {
    /// Ended jobs over the simulated period.
    #[arg(long, default_value_t = 1_000_000)]
    jobs: u64,
    /// Days simulated.
    #[arg(long, default_value_t = 365)]
    days: i64,
    /// Days of ended jobs the store keeps (`retention.jobs_days`).
    #[arg(long, default_value_t = 90)]
    keep: i64,
    /// `sqlite` (a file in a temporary folder), `postgres` (a fresh database of the tests'
    /// throwaway cluster) or a PostgreSQL URL (its database must be empty).
    #[arg(long, default_value = "sqlite")]
    database: String,
}

/// Runs the benchmark.
pub async fn run(args: RetentionArgs) -> anyhow::Result<()> {
    let dir = tempfile::tempdir()?;
    let database = match args.database.as_str() {
        "sqlite" => Database::Sqlite(dir.path().join("bench.db")),
        "postgres" => Database::Postgres(crate::postgres::database().await),
        url => Database::Postgres(url.to_owned()),
    };
    let folder = dir.path().join("archive");
    let pool = rackd::store::open(&database, std::time::Duration::from_secs(30)).await?;
    println!(
        "bench retention: {} jobs over {} days, {} kept, {}",
        args.jobs, args.days, args.keep, args.database
    );
    println!(
        "{:>5} {:>12} {:>12} {:>10} {:>14} {:>16}",
        "day", "jobs kept", "store MiB", "in use", "archive MiB", "archive of the day"
    );
    let now = rackd::domain::time::now_ms();
    let start = (now - args.days * DAY).div_euclid(DAY) * DAY;
    let per_day = (args.jobs as i64 / args.days).max(1);
    let mut rng = StdRng::seed_from_u64(39);
    let (mut id, mut sizes) = (1i64, Vec::new());
    for day in 0..args.days {
        let jobs: Vec<_> = (0..per_day)
            .map(|n| {
                let created = start + day * DAY + n * DAY / per_day;
                let j = job(&mut rng, id, created);
                id += 1;
                j
            })
            .collect();
        for page in jobs.chunks(5_000) {
            import::ended_jobs(&pool, page).await?;
        }
        let t = Instant::now();
        let mut archived = 0;
        if day + 1 > args.keep {
            let cut = start + (day + 1 - args.keep) * DAY;
            let before = time::OffsetDateTime::from_unix_timestamp(cut / 1000)?.date();
            archived = archive::archive(&pool, before, &folder, Delete::Direct).await?.jobs;
        }
        let took = t.elapsed();
        if (day + 1) % 30 == 0 || day + 1 == args.days {
            // The rollups, as the writer would have kept them (the import does not).
            rackd::store::rollups::rebuild::rebuild(&pool, |_, _| {}).await?;
            let kept = count(&pool).await?;
            let store = size(&database, dir.path()).await?;
            let used = in_use(&pool).await?.unwrap_or(store);
            let files = folder_size(&folder);
            println!(
                "{:>5} {:>12} {:>12.1} {:>10.1} {:>14.1} {:>9} in {:.2} s",
                day + 1,
                kept,
                mib(store),
                mib(used),
                mib(files),
                archived,
                took.as_secs_f64()
            );
            if day + 1 > args.keep {
                sizes.push(used);
            }
        }
    }
    let seeded = id - 1;
    let in_store: HashSet<i64> = ids(&pool).await?;
    let mut in_archive = 0u64;
    let mut twice = 0u64;
    for entry in std::fs::read_dir(&folder).into_iter().flatten().flatten() {
        let file = std::fs::File::open(entry.path())?;
        for line in BufReader::new(flate2::read::GzDecoder::new(file)).lines() {
            let v: serde_json::Value = serde_json::from_str(&line?)?;
            in_archive += 1;
            if in_store.contains(&v["job"]["id"].as_i64().unwrap_or(0)) {
                twice += 1;
            }
        }
    }
    println!(
        "seeded {seeded} jobs: {} in the store, {in_archive} in the archive, {twice} in both: {}",
        in_store.len(),
        if in_store.len() as u64 + in_archive - twice == seeded as u64 && twice == 0 {
            "none lost"
        } else {
            "MISMATCH"
        }
    );
    if let (Some(lo), Some(hi)) = (sizes.iter().min(), sizes.iter().max()) {
        println!(
            "store size in use once the retention deletes: {:.1} to {:.1} MiB, spread {:.1}%",
            mib(*lo),
            mib(*hi),
            (*hi as f64 / *lo as f64 - 1.0) * 100.0
        );
    }
    pool.close().await;
    Ok(())
}

fn mib(bytes: u64) -> f64 {
    bytes as f64 / 1_048_576.0
}

fn folder_size(dir: &Path) -> u64 {
    std::fs::read_dir(dir)
        .into_iter()
        .flatten()
        .flatten()
        .filter_map(|e| e.metadata().ok())
        .map(|m| m.len())
        .sum()
}

/// SQLite's pages in use (the file less its free pages: a rebuild's room, kept by the file
/// for the next); None on PostgreSQL.
async fn in_use(pool: &Pool) -> anyhow::Result<Option<u64>> {
    let Pool::Sqlite(p) = pool else { return Ok(None) };
    let (pages, free, size): (i64, i64, i64) = sqlx::query_as(
        "SELECT (SELECT page_count FROM pragma_page_count), (SELECT freelist_count FROM pragma_freelist_count), \
         (SELECT page_size FROM pragma_page_size)",
    )
    .fetch_one(p)
    .await?;
    Ok(Some(((pages - free) * size) as u64))
}

async fn count(pool: &Pool) -> anyhow::Result<i64> {
    Ok(match pool {
        Pool::Sqlite(p) => sqlx::query_scalar("SELECT COUNT(*) FROM jobs").fetch_one(p).await?,
        Pool::Postgres(p) => sqlx::query_scalar("SELECT COUNT(*) FROM jobs").fetch_one(p).await?,
    })
}

async fn ids(pool: &Pool) -> anyhow::Result<HashSet<i64>> {
    let ids: Vec<i64> = match pool {
        Pool::Sqlite(p) => sqlx::query_scalar("SELECT id FROM jobs").fetch_all(p).await?,
        Pool::Postgres(p) => sqlx::query_scalar("SELECT id FROM jobs").fetch_all(p).await?,
    };
    Ok(ids.into_iter().collect())
}
