//! `/metrics`: what a site's monitoring scrapes and alerts on, in the Prometheus conventions
//! (a `rackd_` prefix, `_total` counters, base units in the name, help on every family).
//!
//! Two kinds of figures:
//! - **counted as they happen** (this module's [`Metrics`]): HTTP requests, intake latency,
//!   WebSocket subscribers, resyncs and snapshots, the job writer's group size and commit
//!   time, and the dispatch latency and duration of jobs, observed by the writer when it
//!   commits the transition ([`crate::store::writer::JobTiming`]);
//! - **kept as they change** (this module's counts): jobs by device and state and active
//!   alarms by device and class, as committed ([`crate::store::counts`]): loaded at start
//!   (a few dozen rows), then changed by each commit of the writer once it is on disk, or
//!   on a node of a cluster read again after each commit it follows; a scrape reads no
//!   table, so it costs the same whatever the history holds;
//! - **read at scrape time** ([`scrape`]): each device's status and link counters, each
//!   webhook subscription's lag and tries (on the node that delivers them), and the process
//!   figures ([`process`]).
//!
//! Content negotiation ([`format`](mod@format)): OpenMetrics when the scraper's `Accept` asks for it,
//! Prometheus text 0.0.4 otherwise; each is served exactly, with its own content type.
//!
//! The full list of families is in docs/operations/metrics.md.

pub mod format;
#[cfg(target_os = "linux")]
pub mod process;
pub mod scrape;

use std::sync::Arc;

use prometheus_client::encoding::EncodeLabelSet;
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::metrics::histogram::{Histogram, exponential_buckets};
use prometheus_client::metrics::info::Info;
use prometheus_client::registry::Registry;
use time::OffsetDateTime;

use super::error::ApiError;
use crate::store::counts::Counts;
use crate::store::writer::{GroupStats, JobTiming, Observe};
use format::Format;

/// Labels of the request counter.
#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
pub struct RequestLabels {
    /// A standard method or `other` (see [`super::ops::method_label`]).
    method: &'static str,
    route: String,
    status: u16,
}

/// Labels of the job dispatch histogram.
#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct KindLabels {
    kind: &'static str,
}

/// Labels of the job duration histogram.
#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct EndLabels {
    kind: &'static str,
    state: &'static str,
}

/// Labels of the store's failed commits.
#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct CauseLabels {
    cause: &'static str,
}

/// Labels of the settled commits whose answer was lost.
#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct LandedLabels {
    landed: &'static str,
}

/// Labels of the snapshot counter.
#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct ReasonLabels {
    reason: &'static str,
}

type Histograms<L> = Family<L, Histogram, fn() -> Histogram>;

/// From 10 ms to an hour: a job waits for a free device as long as the site is busy.
fn dispatch_buckets() -> Histogram {
    Histogram::new([0.01, 0.05, 0.1, 0.5, 1.0, 5.0, 10.0, 30.0, 60.0, 300.0, 900.0, 3600.0])
}

/// From 100 ms (a light) to an hour (a crane's long move behind a relocation).
fn duration_buckets() -> Histogram {
    Histogram::new([0.1, 0.5, 1.0, 2.0, 5.0, 10.0, 30.0, 60.0, 120.0, 300.0, 600.0, 1800.0, 3600.0])
}

/// The service's metrics counted as they happen, and the registry they are served from.
pub struct Metrics {
    registry: Registry,
    requests: Family<RequestLabels, Counter>,
    subscribers: Gauge,
    ws_resyncs: Counter,
    ws_snapshots: Family<ReasonLabels, Counter>,
    store_failures: Family<CauseLabels, Counter>,
    unsure_commits: Family<LandedLabels, Counter>,
    group_size: Histogram,
    commit_seconds: Histogram,
    dispatch_seconds: Histograms<KindLabels>,
    job_seconds: Histograms<EndLabels>,
    started: OffsetDateTime,
    /// Jobs by device and state, active alarms by device and class, as committed.
    counts: std::sync::Mutex<Counts>,
    /// The certificate served over HTTPS, once told.
    certificate: std::sync::Mutex<Option<scrape::CertificateSample>>,
    /// Seconds from a submission reaching the writer to its commit.
    pub intake_seconds: Histogram,
}

impl Default for Metrics {
    fn default() -> Self {
        let mut registry = Registry::default();
        #[cfg(target_os = "linux")]
        registry.register_collector(Box::new(process::Process));
        let r = registry.sub_registry_with_prefix("rackd");
        let version = [
            ("version".to_owned(), env!("CARGO_PKG_VERSION").to_owned()),
            ("os".to_owned(), std::env::consts::OS.to_owned()),
            ("arch".to_owned(), std::env::consts::ARCH.to_owned()),
        ];
        r.register(
            "build",
            "The running rackd: version, operating system and architecture",
            Info::new(version),
        );
        let requests = Family::<RequestLabels, Counter>::default();
        r.register("http_requests", "HTTP requests by method, route and status", requests.clone());
        let intake_seconds = Histogram::new(exponential_buckets(0.0001, 2.0, 16));
        r.register("intake_seconds", "Time from submission to durable commit", intake_seconds.clone());
        let subscribers = Gauge::default();
        r.register("ws_subscribers", "WebSocket subscribers to live events", subscribers.clone());
        let ws_resyncs = Counter::default();
        r.register(
            "ws_resyncs",
            "WebSocket subscribers that fell too far behind and were told to resync",
            ws_resyncs.clone(),
        );
        let ws_snapshots = Family::<ReasonLabels, Counter>::default();
        // Each reason's series from the start, at zero, for `rate()` and alerts.
        for reason in ["requested", "since_expired", "since_unknown"] {
            ws_snapshots.get_or_create(&ReasonLabels { reason }).inc_by(0);
        }
        r.register(
            "ws_snapshots",
            "Snapshots sent to WebSocket subscribers, by reason (requested, since_expired, since_unknown)",
            ws_snapshots.clone(),
        );
        let store_failures = Family::<CauseLabels, Counter>::default();
        for cause in crate::store::fault::Cause::ALL {
            store_failures.get_or_create(&CauseLabels { cause: cause.as_str() }).inc_by(0);
        }
        r.register(
            "store_commit_failures",
            "Groups of the job writer that failed for the store's own cause (full, read_only, io_error, unreachable)",
            store_failures.clone(),
        );
        let unsure_commits = Family::<LandedLabels, Counter>::default();
        for landed in ["true", "false"] {
            unsure_commits.get_or_create(&LandedLabels { landed }).inc_by(0);
        }
        r.register(
            "store_unsure_commits",
            "Groups whose COMMIT's answer was lost (PostgreSQL), by whether the database then showed them landed",
            unsure_commits.clone(),
        );
        let group_size = Histogram::new(exponential_buckets(1.0, 2.0, 12));
        r.register(
            "writer_group_size",
            "Commands the job writer committed together in one transaction",
            group_size.clone(),
        );
        let commit_seconds = Histogram::new(exponential_buckets(0.0001, 2.0, 16));
        r.register(
            "writer_commit_seconds",
            "Time the job writer took to apply and commit one group",
            commit_seconds.clone(),
        );
        let dispatch_seconds: Histograms<KindLabels> = Family::new_with_constructor(dispatch_buckets);
        r.register(
            "job_dispatch_seconds",
            "Time jobs waited from queued to dispatched, by kind",
            dispatch_seconds.clone(),
        );
        let job_seconds: Histograms<EndLabels> = Family::new_with_constructor(duration_buckets);
        r.register(
            "job_duration_seconds",
            "Time from dispatched (or queued, if never dispatched) to the end, by kind and final state",
            job_seconds.clone(),
        );
        Metrics {
            registry,
            requests,
            subscribers,
            ws_resyncs,
            ws_snapshots,
            store_failures,
            unsure_commits,
            group_size,
            commit_seconds,
            dispatch_seconds,
            job_seconds,
            started: crate::domain::time::now(),
            counts: std::sync::Mutex::default(),
            certificate: std::sync::Mutex::default(),
            intake_seconds,
        }
    }
}

impl Metrics {
    /// Counts one answered request.
    pub fn count_request(&self, method: &'static str, route: String, status: u16) {
        self.requests.get_or_create(&RequestLabels { method, route, status }).inc();
    }

    /// Counts a WebSocket subscriber told to resync.
    pub fn count_resync(&self) {
        self.ws_resyncs.inc();
    }

    /// Counts a group of the writer that failed for the store's own `cause`.
    pub fn count_store_failure(&self, cause: crate::store::fault::Cause) {
        self.store_failures.get_or_create(&CauseLabels { cause: cause.as_str() }).inc();
    }

    /// Counts a group whose `COMMIT`'s answer was lost, by whether it `landed`.
    pub fn count_unsure_commit(&self, landed: bool) {
        let landed = if landed { "true" } else { "false" };
        self.unsure_commits.get_or_create(&LandedLabels { landed }).inc();
    }

    /// Counts a snapshot sent to a WebSocket subscriber, by its `reason`.
    pub fn count_snapshot(&self, reason: &'static str) {
        self.ws_snapshots.get_or_create(&ReasonLabels { reason }).inc();
    }

    /// The job writer's hook: group size, commit time and timed transitions, and with
    /// `counting` what each commit changed in the counts of jobs and alarms (a node of its
    /// own; a node of a cluster reads them again instead, see [`Metrics::set_counts`]).
    pub fn writer_hook(self: &Arc<Self>, counting: bool) -> Observe {
        let metrics = Arc::clone(self);
        Arc::new(move |group: &GroupStats<'_>| metrics.observe_group(group, counting))
    }

    /// Sets the counts of jobs and alarms to `counts`, as read from the store (at start,
    /// and on a node of a cluster after each commit it follows).
    pub fn set_counts(&self, counts: Counts) {
        *self.counts.lock().unwrap_or_else(|p| p.into_inner()) = counts;
    }

    /// The certificate served over HTTPS is `sample` from now on (`app::serve::certificate`).
    pub fn set_certificate(&self, sample: scrape::CertificateSample) {
        *self.certificate.lock().unwrap_or_else(|p| p.into_inner()) = Some(sample);
    }

    /// The certificate served over HTTPS, as last told; None without `[server.tls]`.
    pub fn certificate(&self) -> Option<scrape::CertificateSample> {
        *self.certificate.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// The counts of jobs and alarms now.
    pub fn counts(&self) -> Counts {
        self.counts.lock().unwrap_or_else(|p| p.into_inner()).clone()
    }

    fn observe_group(&self, group: &GroupStats<'_>, counting: bool) {
        if counting && !group.counts.is_empty() {
            self.counts.lock().unwrap_or_else(|p| p.into_inner()).add(group.counts);
        }
        self.group_size.observe(group.commands as f64);
        self.commit_seconds.observe(group.took.as_secs_f64());
        for timing in group.jobs {
            match *timing {
                JobTiming::Dispatched { kind, waited } => self
                    .dispatch_seconds
                    .get_or_create(&KindLabels { kind: kind.as_str() })
                    .observe(waited.as_secs_f64()),
                JobTiming::Ended { kind, state, took } => self
                    .job_seconds
                    .get_or_create(&EndLabels { kind: kind.as_str(), state: state.as_str() })
                    .observe(took.as_secs_f64()),
            }
        }
    }

    /// OpenMetrics text of everything: the counted families, then `scrape`'s.
    pub fn encode(&self, scrape: scrape::Scrape, subscribers: usize) -> Result<String, std::fmt::Error> {
        use prometheus_client::encoding::text;
        self.subscribers.set(subscribers as i64);
        let mut now = Registry::with_prefix("rackd");
        now.register_collector(Box::new(scrape));
        let mut out = String::with_capacity(16 * 1024);
        text::encode_registry(&mut out, &self.registry)?;
        text::encode_registry(&mut out, &now)?;
        text::encode_eof(&mut out)?;
        Ok(out)
    }

    /// When rackd started (the age of a device never heard from).
    pub fn started(&self) -> OffsetDateTime {
        self.started
    }

    /// The body of `GET /metrics` in `format`: the counted families, then `scrape`'s.
    pub fn render(
        &self,
        scrape: scrape::Scrape,
        subscribers: usize,
        format: Format,
    ) -> Result<String, ApiError> {
        let failed = |e: &dyn std::fmt::Display| {
            tracing::error!(error = %e, "encoding metrics");
            ApiError::unavailable("the metrics could not be encoded")
        };
        let openmetrics = self.encode(scrape, subscribers).map_err(|e| failed(&e))?;
        match format {
            Format::OpenMetrics => Ok(openmetrics),
            Format::Prometheus => format::to_prometheus(&openmetrics).map_err(|e| failed(&e)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_family_converts_to_0_0_4() {
        let metrics = Arc::new(Metrics::default());
        metrics.count_request("GET", "/x".into(), 200);
        metrics.count_resync();
        metrics.count_snapshot("requested");
        let kind = crate::domain::JobKind::Store;
        let jobs = [
            JobTiming::Dispatched { kind, waited: std::time::Duration::from_millis(30) },
            JobTiming::Ended {
                kind,
                state: crate::domain::JobState::Completed,
                took: std::time::Duration::from_secs(2),
            },
        ];
        let mut counts = Counts::default();
        counts.job(Some("shelf1"), crate::domain::JobState::Completed, 1);
        (metrics.writer_hook(true))(&GroupStats {
            statements: 5,
            commands: 3,
            took: std::time::Duration::from_millis(2),
            jobs: &jobs,
            counts: &counts,
        });
        let now = OffsetDateTime::now_utc();
        let live = crate::service::webhooks::Live {
            row: crate::store::webhooks::Row { name: "wms".into(), cursor: 4, ..Default::default() },
            outcomes: [("failed", 3)].into(),
            retries: 2,
            ..Default::default()
        };
        let scrape = scrape::Scrape {
            devices: Vec::new(),
            counts: metrics.counts(),
            now,
            started: now,
            cluster: None,
            webhooks: vec![scrape::WebhookSample { name: "wms".into(), published: 7, live }],
            certificate: Some(scrape::CertificateSample {
                expires_at: Some(1_900_000_000),
                reload_failing: true,
            }),
            orders: Some(crate::service::dispatch::gate::Orders {
                late: 2,
                ended_late: 5,
                slack: Some(-12.5),
                inversions: [(3, 1)].into(),
            }),
        };
        let text = metrics.encode(scrape, 2).unwrap();
        assert!(text.ends_with("# EOF\n"), "{text}");
        assert!(text.contains("rackd_build_info{version=\""), "{text}");
        assert!(text.contains("rackd_job_dispatch_seconds_count{kind=\"store\"} 1"), "{text}");
        assert!(
            text.contains("rackd_job_duration_seconds_count{kind=\"store\",state=\"completed\"} 1"),
            "{text}"
        );
        assert!(text.contains("rackd_writer_group_size_count 1"), "{text}");
        assert!(text.contains("rackd_jobs{device=\"shelf1\",state=\"completed\"} 1"), "{text}");
        let old = format::to_prometheus(&text).unwrap();
        assert!(!old.contains("# EOF") && !old.contains(" info\n"), "{old}");
        assert!(old.contains("# TYPE rackd_ws_resyncs_total counter\nrackd_ws_resyncs_total 1\n"), "{old}");
        assert!(old.contains("# TYPE rackd_build_info gauge\n"), "{old}");
        assert!(
            old.contains(
                "# TYPE rackd_webhook_deliveries_total counter\n\
                 rackd_webhook_deliveries_total{webhook=\"wms\",outcome=\"delivered\"} 0\n\
                 rackd_webhook_deliveries_total{webhook=\"wms\",outcome=\"failed\"} 3\n"
            ),
            "{old}"
        );
        assert!(old.contains("rackd_webhook_retries_total{webhook=\"wms\"} 2\n"), "{old}");
        assert!(old.contains("# TYPE rackd_webhook_events_behind gauge\n"), "{old}");
        assert!(old.contains("\nrackd_tls_certificate_expiry_timestamp_seconds 1900000000\n"), "{old}");
        assert!(old.contains("\nrackd_tls_certificate_reload_failing 1\n"), "{old}");
        assert!(old.contains("\nrackd_jobs_late 2\n"), "{old}");
        assert!(old.contains("\nrackd_jobs_ended_late_total 5\n"), "{old}");
        assert!(old.contains("\nrackd_deadline_slack_seconds -12.5\n"), "{old}");
        assert!(old.contains("rackd_sequence_inversions_total{station=\"0\"} 0\nrackd_sequence_inversions_total{station=\"3\"} 1\n"), "{old}");
    }
}
