//! The limiter's lines, captured from a real subscriber, on paused time.

use std::io::Write;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use super::Repeats;

/// Log output collected in memory.
#[derive(Clone, Default)]
struct Captured(Arc<Mutex<Vec<u8>>>);

impl Write for Captured {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.lock().unwrap().extend_from_slice(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl Captured {
    fn lines(&self) -> Vec<String> {
        String::from_utf8(self.0.lock().unwrap().clone()).unwrap().lines().map(str::to_owned).collect()
    }
}

/// Runs `f` with every line at DEBUG and above written to the returned capture.
fn capture(f: impl FnOnce()) -> Vec<String> {
    let out = Captured::default();
    let writer = out.clone();
    let subscriber = tracing_subscriber::fmt()
        .with_max_level(tracing::Level::DEBUG)
        .with_ansi(false)
        .without_time()
        .with_writer(move || writer.clone())
        .finish();
    tracing::subscriber::with_default(subscriber, f);
    out.lines()
}

fn timeout() -> std::io::Error {
    std::io::Error::new(std::io::ErrorKind::TimedOut, "no reply in 100 ms")
}

#[tokio::test(start_paused = true)]
async fn an_outage_logs_its_start_one_summary_per_interval_and_its_end() {
    let mut repeats = Repeats::every(Duration::from_secs(60));
    let mut lines = Vec::new();
    // Five polls a second for three and a half minutes.
    for _ in 0..(5 * 210) {
        lines.extend(capture(|| repeats.failed("poll failed", &timeout())));
        tokio::time::advance(Duration::from_millis(200)).await;
    }
    lines.extend(capture(|| repeats.recovered()));
    assert_eq!(lines.len(), 5, "{lines:#?}");
    assert!(
        lines[0].contains("WARN") && lines[0].contains("poll failed error=no reply in 100 ms"),
        "{}",
        lines[0]
    );
    for summary in &lines[1..4] {
        assert!(summary.contains("still failing: 300 more failures in the last 60 s"), "{summary}");
        assert!(summary.contains("last_error=poll failed: no reply in 100 ms"), "{summary}");
    }
    assert!(lines[4].contains("INFO"), "{}", lines[4]);
    assert!(lines[4].contains("working again after 1050 failures over 210.0 s"), "{}", lines[4]);
    assert!(!repeats.failing());
}

#[tokio::test(start_paused = true)]
async fn a_flapping_device_writes_at_most_one_warning_per_interval() {
    let mut repeats = Repeats::every(Duration::from_secs(60));
    let mut lines = Vec::new();
    // Fails twice, answers once, every second, for two minutes.
    for _ in 0..120 {
        lines.extend(capture(|| {
            repeats.failed("poll failed", &timeout());
            repeats.failed("poll failed", &timeout());
        }));
        tokio::time::advance(Duration::from_millis(500)).await;
        lines.extend(capture(|| repeats.recovered()));
        tokio::time::advance(Duration::from_millis(500)).await;
    }
    let warnings: Vec<_> = lines.iter().filter(|l| l.contains("WARN")).collect();
    let infos: Vec<_> = lines.iter().filter(|l| l.contains("INFO")).collect();
    assert_eq!(warnings.len(), 2, "{lines:#?}");
    assert_eq!(infos.len(), 2, "{lines:#?}");
    // The second outage is announced with the failures of the flaps in between.
    assert!(warnings[1].contains("earlier_failures=120"), "{}", warnings[1]);
    let debug = lines.iter().filter(|l| l.contains("DEBUG")).count();
    assert_eq!(debug, 118, "the short outages in between end at DEBUG");
}

#[tokio::test(start_paused = true)]
async fn a_device_that_never_fails_logs_nothing() {
    let mut repeats = Repeats::default();
    let lines = capture(|| {
        for _ in 0..100 {
            repeats.recovered();
        }
    });
    assert!(lines.is_empty(), "{lines:#?}");
}
