//! Issue 51, "files rackd writes are its own": the archive's days (`rackd db archive`),
//! `rackd plc --capture` and alarm captures are created without following a link planted
//! in their folder, never over a file that is there, and readable by their owner alone, as
//! is a new SQLite database (`src/files.rs`). The real binary and the real server.

use std::os::unix::fs::PermissionsExt;
use std::path::Path;
use std::process::Command;
use std::time::Duration;

use rackd::domain::time::from_ms;
use rackd::domain::{JobSpec, JobState, LightColor, Location, NewJob, Priority};
use rackd::protocols::faults::Faults;
use rackd::sim::shelf::ShelfSim;
use rackd::store::import::{self, Ended};
use rackd::store::{self, Database, Engine};

use crate::shelf::{device_for, sim};
use crate::support::{eventually, spawn_with};

/// 2026-01-01, midnight UTC, in Unix ms.
const DAY0: i64 = 1_767_225_600_000;

const VICTIM: &str = "another user's file\n";

fn mode(path: &Path) -> u32 {
    std::fs::metadata(path).unwrap().permissions().mode() & 0o777
}

/// Asserts `file` still holds [`VICTIM`] (a binary capture or archive is not printed).
#[track_caller]
fn assert_untouched(file: &Path, why: &str) {
    let now = std::fs::read(file).unwrap();
    assert!(now == VICTIM.as_bytes(), "{why}: {} now holds {} bytes", file.display(), now.len());
}

fn rackd(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_rackd")).args(args).output().unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into(),
        String::from_utf8_lossy(&out.stderr).into(),
    )
}

/// A SQLite store in `dir` with three light jobs that completed on 2026-01-01.
async fn store_with_ended_jobs(dir: &Path) -> String {
    let path = dir.join("rackd.db");
    let pool = store::open(&Database::Sqlite(path.clone()), Duration::from_secs(5)).await.unwrap();
    let jobs: Vec<Ended> = (1..=3)
        .map(|id| {
            let new = NewJob {
                spec: JobSpec::Light {
                    location: Location { aisle: 1, row: 1, bay: id as u16, level: 1, position: 1 },
                    color: LightColor::Green,
                    on: true,
                },
                reference: Some(format!("A-{id}")),
                priority: Priority::default(),
                barcode: None,
                device: None,
                serves: None,
                terms: Default::default(),
            };
            let end = DAY0 + 43_200_000 + id;
            let mut job = new.accepted(id, end - 60_000);
            job.state = JobState::Completed;
            job.updated_at = from_ms(end);
            let history = vec![
                (JobState::Queued, "accepted".into(), end - 60_000),
                (JobState::Completed, "done".into(), end),
            ];
            Ended { request: new.canonical(), job, history }
        })
        .collect();
    import::ended_jobs(&pool, &jobs).await.unwrap();
    pool.close().await;
    format!("sqlite:{}", path.display())
}

#[tokio::test]
async fn the_archive_follows_no_link_replaces_no_file_and_is_its_owners() {
    let dir = tempfile::tempdir().unwrap();
    let database = store_with_ended_jobs(dir.path()).await;
    let archive = dir.path().join("archive");
    std::fs::create_dir(&archive).unwrap();
    // Planted by another local user: a link where the archive would write its temporary
    // file, to a file of theirs; a link where the day's file goes, to nowhere.
    let victim = dir.path().join("victim");
    std::fs::write(&victim, VICTIM).unwrap();
    std::os::unix::fs::symlink(&victim, archive.join("jobs-2026-01-01.jsonl.gz.tmp")).unwrap();
    let day = archive.join("jobs-2026-01-01.jsonl.gz");
    std::os::unix::fs::symlink(dir.path().join("nowhere"), &day).unwrap();

    let (ok, out, err) = rackd(&[
        "db",
        "archive",
        "--database",
        &database,
        "--before",
        "2026-01-02",
        "--to",
        archive.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    assert!(out.contains("archived 3 jobs to 1 files"), "{out}");
    assert_untouched(&victim, "the archive wrote through a planted link");
    assert!(std::fs::symlink_metadata(&day).unwrap().file_type().is_symlink(), "the day's name was replaced");
    let written = archive.join("jobs-2026-01-01.2.jsonl.gz");
    let meta =
        std::fs::symlink_metadata(&written).unwrap_or_else(|e| panic!("{}: {e}; {out}", written.display()));
    assert!(meta.file_type().is_file());
    assert_eq!(mode(&written) & 0o077, 0, "the archive is its owner's alone: {:o}", mode(&written));
    assert!(!dir.path().join("nowhere").exists());
}

#[test]
fn a_plc_capture_follows_no_link_and_replaces_no_file() {
    let dir = tempfile::tempdir().unwrap();
    let victim = dir.path().join("victim");
    std::fs::write(&victim, VICTIM).unwrap();
    let link = dir.path().join("plc.pcapng");
    std::os::unix::fs::symlink(&victim, &link).unwrap();
    // MC without a port: refused before a link opens, as early as can be.
    let (ok, _, err) = rackd(&[
        "plc",
        "--protocol",
        "mc3e",
        "--address",
        "127.0.0.1",
        "read",
        "D0",
        "--capture",
        link.to_str().unwrap(),
    ]);
    assert!(!ok);
    assert_untouched(&victim, &format!("the capture wrote through a planted link: {err}"));
    assert!(
        std::fs::symlink_metadata(&link).is_ok_and(|m| m.file_type().is_symlink()),
        "the link was removed: {err}"
    );
    assert!(err.contains("exists"), "{err}");

    // A file that is there is not replaced either.
    std::fs::remove_file(&link).unwrap();
    std::fs::write(&link, VICTIM).unwrap();
    let (ok, _, err) = rackd(&[
        "plc",
        "--protocol",
        "mc3e",
        "--address",
        "127.0.0.1",
        "read",
        "D0",
        "--capture",
        link.to_str().unwrap(),
    ]);
    assert!(!ok && err.contains("exists"), "{err}");
    assert_untouched(&link, "a file there was replaced");

    // A new one is its owner's alone.
    let modbus = crate::plc::sim(&["modbus", "--transport", "tcp"]);
    let file = dir.path().join("new.pcapng");
    let (ok, _, err) =
        crate::plc::plc("modbus-tcp", &modbus.address, &["read", "4x0", "--capture", file.to_str().unwrap()]);
    assert!(ok, "{err}");
    assert_eq!(mode(&file) & 0o077, 0, "{:o}", mode(&file));
}

#[tokio::test]
async fn an_alarm_capture_follows_no_link_and_is_its_owners() {
    let captures = tempfile::tempdir().unwrap();
    let victim = captures.path().join("victim");
    std::fs::write(&victim, VICTIM).unwrap();
    // Where the first alarms' captures were written before their rename.
    for id in 1..=3 {
        std::os::unix::fs::symlink(&victim, captures.path().join(format!("alarm-{id}.pcapng.part"))).unwrap();
    }
    let shelf = ShelfSim::start("127.0.0.1:0", sim(50)).await.unwrap();
    let device = device_for(&shelf, |d| d.link.retries = 1);
    let folder = captures.path().to_owned();
    let app = spawn_with(Engine::Sqlite, |c| {
        c.devices = vec![device.into()];
        c.retention.alarm_capture_seconds = 30;
        c.retention.captures_dir = Some(folder);
    })
    .await;
    shelf.set_faults(Faults { drop_rate: 1.0, ..Faults::default() });
    let kept = eventually("an alarm capture in the folder", Duration::from_secs(20), async || {
        let files: Vec<_> = std::fs::read_dir(captures.path())
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|e| e == "pcapng"))
            .collect();
        files.into_iter().next().ok_or("none yet")
    })
    .await;
    assert_untouched(&victim, "the capture wrote through a planted link");
    assert!(std::fs::symlink_metadata(&kept).unwrap().file_type().is_file(), "{}", kept.display());
    assert_eq!(mode(&kept) & 0o077, 0, "{}: {:o}", kept.display(), mode(&kept));
    // The database it made, and its WAL, are its own too.
    let Database::Sqlite(db) = &app.db else { unreachable!() };
    let wal = db.with_extension("db-wal");
    for file in [db, &wal] {
        assert_eq!(mode(file) & 0o077, 0, "{}: {:o}", file.display(), mode(file));
    }
    app.stop().await;
}
