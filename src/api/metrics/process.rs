//! The standard process metrics (`process_cpu_seconds_total`, `process_resident_memory_bytes`,
//! `process_virtual_memory_bytes`, `process_open_fds`, `process_max_fds`,
//! `process_start_time_seconds`), read from `/proc` at each scrape.
//!
//! Why by hand: `/proc/self/stat`, `/proc/stat`, `/proc/self/fd` and `/proc/self/limits`
//! are a stable kernel interface, and the parsing is [`parse`] and [`max_fds`], some
//! twenty lines; the clock tick and page size come from `rustix` (the lints forbid
//! `unsafe`, so no `libc::sysconf`). The crates that could do it, and why none fits:
//! - **prometheus-client** (0.24.1 here, 0.26.0 the latest) has no process collector: its
//!   issue #29 asks for one and pull request #232 ("WIP: process collector") is still open.
//! - **kubert-prometheus-process 0.2.3** (Linkerd's collector for prometheus-client) is built
//!   on prometheus-client 0.23, whose `Registry` and `Collector` are other types than
//!   rackd's 0.24 ones (a second copy of the crate); it serves another set (its own help
//!   texts, `# UNIT` lines, and uptime, clock time, threads and network bytes besides),
//!   takes the start time from its own registration rather than from the kernel, and
//!   reads through procfs 0.17 and `libc::sysconf` in `unsafe`.
//! - **metrics-process 2.4.3** targets the `metrics` facade; without its default feature,
//!   `collector::collect()` hands over the figures, but the start time in whole seconds
//!   and an unlimited `max_fds` as 0 (both would change what is served), through procfs
//!   0.18 and once_cell.
//! - **prometheus 0.14.0** (tikv) has a `ProcessCollector` behind its `process` feature, for
//!   its own registry: a second metrics library, on procfs and libc.
//! - **procfs 0.18.0** alone (without default features) would replace [`parse`] and
//!   [`max_fds`] with the same figures, but it is some 14,500 lines for all of `/proc`:
//!   added to this build it took 8.6 s (procfs-core) then 12.6 s (procfs), one after the
//!   other, on the project's 2-core machine, and rebuilt rustix with two more features
//!   (`system`, `thread`), to save twenty lines.
//!
//! The names are the standard ones, without rackd's prefix, so that the dashboards and
//! alerts written for every other exporter work as they are. A value that cannot be read
//! is left out of the scrape (and logged at debug), never reported as zero.

use prometheus_client::collector::Collector;
use prometheus_client::encoding::{DescriptorEncoder, EncodeGaugeValue, NoLabelSet};
use prometheus_client::metrics::MetricType;

/// The process's own figures, as read from `/proc`.
#[derive(Debug, Default, PartialEq)]
pub struct Figures {
    /// User and system CPU time, in seconds.
    pub cpu_seconds: f64,
    /// Resident memory, in bytes.
    pub resident_bytes: u64,
    /// Virtual memory, in bytes.
    pub virtual_bytes: u64,
    /// Start time, in seconds since the Unix epoch.
    pub start_time_seconds: f64,
}

/// Figures from the text of `/proc/self/stat` and `/proc/stat`, given the clock tick rate
/// and the page size.
pub fn parse(stat: &str, system: &str, ticks: u64, page: u64) -> Option<Figures> {
    // The command name (field 2) is in parentheses and may hold spaces: fields are counted
    // after its closing one, from field 3 (state).
    let fields: Vec<&str> = stat.get(stat.rfind(')')? + 1..)?.split_whitespace().collect();
    let field = |n: usize| fields.get(n - 3).and_then(|f| f.parse::<u64>().ok());
    let boot = system.lines().find_map(|l| l.strip_prefix("btime "))?.trim().parse::<u64>().ok()?;
    let ticks = ticks.max(1) as f64;
    Some(Figures {
        cpu_seconds: (field(14)? + field(15)?) as f64 / ticks,
        start_time_seconds: boot as f64 + field(22)? as f64 / ticks,
        virtual_bytes: field(23)?,
        resident_bytes: field(24)?.saturating_mul(page),
    })
}

/// The soft limit on open files from the text of `/proc/self/limits` (none: unlimited).
pub fn max_fds(limits: &str) -> Option<u64> {
    let line = limits.lines().find(|l| l.starts_with("Max open files"))?;
    line["Max open files".len()..].split_whitespace().next()?.parse().ok()
}

/// Reads the process metrics at each scrape.
#[derive(Debug, Default)]
pub struct Process;

fn gauge(e: &mut DescriptorEncoder, name: &str, help: &str, v: impl EncodeGaugeValue) -> std::fmt::Result {
    e.encode_descriptor(name, help, None, MetricType::Gauge)?.encode_gauge(&v)
}

fn read(path: &str) -> Option<String> {
    std::fs::read_to_string(path).map_err(|e| tracing::debug!(path, error = %e, "process metrics")).ok()
}

impl Collector for Process {
    fn encode(&self, mut e: DescriptorEncoder) -> std::fmt::Result {
        let ticks = rustix::param::clock_ticks_per_second();
        let page = rustix::param::page_size() as u64;
        if let Some(f) =
            read("/proc/self/stat").zip(read("/proc/stat")).and_then(|(s, sys)| parse(&s, &sys, ticks, page))
        {
            e.encode_descriptor(
                "process_cpu_seconds",
                "Total user and system CPU time spent in seconds.",
                None,
                MetricType::Counter,
            )?
            .encode_counter::<NoLabelSet, _, u64>(&f.cpu_seconds, None)?;
            gauge(
                &mut e,
                "process_resident_memory_bytes",
                "Resident memory size in bytes.",
                f.resident_bytes as i64,
            )?;
            gauge(
                &mut e,
                "process_virtual_memory_bytes",
                "Virtual memory size in bytes.",
                f.virtual_bytes as i64,
            )?;
            gauge(
                &mut e,
                "process_start_time_seconds",
                "Start time of the process since unix epoch in seconds.",
                f.start_time_seconds,
            )?;
        }
        match std::fs::read_dir("/proc/self/fd") {
            Ok(dir) => {
                gauge(&mut e, "process_open_fds", "Number of open file descriptors.", dir.count() as i64)?
            }
            Err(err) => tracing::debug!(error = %err, "process metrics: /proc/self/fd"),
        }
        if let Some(max) = read("/proc/self/limits").as_deref().and_then(max_fds) {
            gauge(&mut e, "process_max_fds", "Maximum number of open file descriptors.", max as i64)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn figures_from_proc_text() {
        // A real line, with a command name holding a space and a parenthesis.
        let stat = "4242 (rackd (x) y) S 1 4242 4242 0 -1 4194560 1200 0 0 0 250 50 0 0 20 0 9 0 \
                    123400 987654321 2048 18446744073709551615 1 1 0 0 0 0 0 0 0 0 0 0 17 1 0 0 0 0 0";
        let system = "cpu  1 2 3\nbtime 1700000000\nprocesses 10\n";
        let f = parse(stat, system, 100, 4096).unwrap();
        assert_eq!(f.cpu_seconds, 3.0, "(250 + 50) ticks at 100 a second");
        assert_eq!(f.start_time_seconds, 1_700_001_234.0, "boot + 123400 ticks");
        assert_eq!(f.virtual_bytes, 987_654_321);
        assert_eq!(f.resident_bytes, 2048 * 4096);
        assert_eq!(parse("4242 (short) S 1", system, 100, 4096), None, "too few fields");
        assert_eq!(parse(stat, "cpu 1\n", 100, 4096), None, "no boot time");
    }

    #[test]
    fn the_soft_limit_on_open_files() {
        let limits = "Limit                     Soft Limit           Hard Limit           Units     \n\
                      Max cpu time              unlimited            unlimited            seconds   \n\
                      Max open files            1024                 524288               files     \n";
        assert_eq!(max_fds(limits), Some(1024));
        assert_eq!(
            max_fds("Max open files            unlimited            unlimited            files\n"),
            None
        );
    }

    #[test]
    fn this_process_can_be_read() {
        let stat = std::fs::read_to_string("/proc/self/stat").unwrap();
        let system = std::fs::read_to_string("/proc/stat").unwrap();
        let f =
            parse(&stat, &system, rustix::param::clock_ticks_per_second(), rustix::param::page_size() as u64);
        let f = f.expect("this kernel's /proc/self/stat parses");
        assert!(f.resident_bytes > 0 && f.virtual_bytes >= f.resident_bytes, "{f:?}");
        assert!(f.start_time_seconds > 1_600_000_000.0, "{f:?}");
    }
}
