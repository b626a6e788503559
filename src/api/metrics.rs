//! Prometheus metrics: HTTP requests by route and status, jobs by state, intake latency,
//! live event subscribers.

use prometheus_client::encoding::EncodeLabelSet;
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::metrics::histogram::{Histogram, exponential_buckets};
use prometheus_client::registry::Registry;

use crate::domain::JobState;

/// Labels of the request counter.
#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
pub struct RequestLabels {
    method: String,
    route: String,
    status: u16,
}

/// Labels of the jobs gauge.
#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
pub struct StateLabels {
    state: &'static str,
}

/// The service's metrics.
pub struct Metrics {
    registry: Registry,
    requests: Family<RequestLabels, Counter>,
    jobs: Family<StateLabels, Gauge>,
    subscribers: Gauge,
    /// Seconds from a submission reaching the writer to its commit.
    pub intake_seconds: Histogram,
}

impl Default for Metrics {
    fn default() -> Self {
        let mut registry = Registry::with_prefix("rackd");
        let requests = Family::<RequestLabels, Counter>::default();
        let jobs = Family::<StateLabels, Gauge>::default();
        let intake_seconds = Histogram::new(exponential_buckets(0.0001, 2.0, 16));
        registry.register("http_requests", "HTTP requests by method, route and status", requests.clone());
        registry.register("jobs", "Jobs by state", jobs.clone());
        registry.register("intake_seconds", "Time from submission to durable commit", intake_seconds.clone());
        let subscribers = Gauge::default();
        registry.register("ws_subscribers", "WebSocket subscribers to live events", subscribers.clone());
        Metrics { registry, requests, jobs, subscribers, intake_seconds }
    }
}

impl Metrics {
    /// Counts one answered request.
    pub fn count_request(&self, method: String, route: String, status: u16) {
        self.requests.get_or_create(&RequestLabels { method, route, status }).inc();
    }

    /// Prometheus text, with the job counts by state (as the store counts them) and the
    /// number of live event subscribers set first.
    pub fn encode(&self, counts: &[(String, i64)], subscribers: usize) -> Result<String, std::fmt::Error> {
        for state in JobState::ALL {
            let n = counts.iter().find(|(s, _)| s == state.as_str()).map_or(0, |(_, n)| *n);
            self.jobs.get_or_create(&StateLabels { state: state.as_str() }).set(n);
        }
        self.subscribers.set(subscribers as i64);
        let mut text = String::new();
        prometheus_client::encoding::text::encode(&mut text, &self.registry)?;
        Ok(text)
    }
}
