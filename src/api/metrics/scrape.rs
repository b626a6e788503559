//! What `/metrics` reads at scrape time rather than counting as it happens: each device's
//! status (the snapshot `/api/v1/devices` serves, its link counters and round trips
//! included), the counts of jobs and active alarms as kept in memory (see [`super`]), and
//! on the node that delivers webhooks each subscription's figures as its deliverer keeps
//! them ([`crate::service::webhooks::Live`]): nothing is read from the store.
//!
//! Decisions:
//! - **No second bookkeeping.** The link's counters are totals since rackd started and only
//!   grow, so they are served as counters straight from the status; the gauges are the
//!   status itself. Nothing is copied into the registry between scrapes.
//! - **Small, fixed label sets.** Every device family has the one label `device`; its kind,
//!   protocol and address are on `rackd_device_info` (join on `device` when needed). Jobs
//!   have `device` and `state`, alarms `device` and `class`; every configured device gets a
//!   sample for each state and class, zero included, so an alert never waits for a first
//!   occurrence to have a series.
//! - **A device never heard from** counts its seconds since contact from rackd's start: it
//!   has been silent at least that long, and an alert on the age fires for it too.
//! - **Webhooks only where they are delivered.** The figures live in the deliverers, which
//!   run on the node that drives the machines: a standby (or a node with no `[[webhooks]]`)
//!   has no `rackd_webhook_*` family at all, rather than zeros that would read as caught up.
//!   Each subscription has the one label `webhook` (its name), and its deliveries one more,
//!   `outcome`, with a sample for each outcome from the start, zero included.

use std::collections::BTreeMap;

use prometheus_client::collector::Collector;
use prometheus_client::encoding::{
    DescriptorEncoder, EncodeGaugeValue, EncodeLabelSet, EncodeLabelValue, LabelValueEncoder, NoLabelSet,
};
use prometheus_client::metrics::MetricType;
use time::OffsetDateTime;

use crate::devices::DeviceStatus;
use crate::domain::{AlarmClass, JobState};
use crate::protocols::transport::ROUND_TRIP_BOUNDS;
use crate::service::webhooks::{Live, OUTCOMES};
use crate::store::counts::Counts;

/// A label value from outside the code (a device id, an address): escaped as both text
/// formats want (prometheus-client 0.24 writes label values as they are; 0.25.2 and later
/// escape them, and this must go with that upgrade: see [`super::format`]).
#[derive(Clone, Debug, Hash, PartialEq, Eq)]
pub struct Text(pub String);

impl EncodeLabelValue for Text {
    fn encode(&self, encoder: &mut LabelValueEncoder) -> Result {
        use std::fmt::Write;
        for c in self.0.chars() {
            match c {
                '\\' => encoder.write_str("\\\\")?,
                '"' => encoder.write_str("\\\"")?,
                '\n' => encoder.write_str("\\n")?,
                c => encoder.write_char(c)?,
            }
        }
        Ok(())
    }
}

#[derive(EncodeLabelSet, Debug, Clone, PartialEq, Eq, Hash)]
struct Device {
    device: Text,
}

#[derive(EncodeLabelSet, Debug, Clone, PartialEq, Eq, Hash)]
struct DeviceInfo {
    device: Text,
    kind: &'static str,
    protocol: Text,
    address: Text,
}

#[derive(EncodeLabelSet, Debug, Clone, PartialEq, Eq, Hash)]
struct Dropped {
    device: Text,
    reason: &'static str,
}

#[derive(EncodeLabelSet, Debug, Clone, PartialEq, Eq, Hash)]
struct JobCount {
    device: Text,
    state: Text,
}

#[derive(EncodeLabelSet, Debug, Clone, PartialEq, Eq, Hash)]
struct AlarmCount {
    device: Text,
    class: Text,
}

/// One scrape's worth of state, encoded as rackd's scrape-time families.
#[derive(Debug)]
pub struct Scrape {
    /// Every device's status, as the API shows it.
    pub devices: Vec<DeviceStatus>,
    /// Jobs by (device, state) and active alarms by (device, class), as committed.
    pub counts: Counts,
    /// Now.
    pub now: OffsetDateTime,
    /// When rackd started (the age of a device never heard from).
    pub started: OffsetDateTime,
    /// In a cluster: this node's name, whether it is active, and its takeovers.
    pub cluster: Option<ClusterSample>,
    /// On the node that delivers webhooks, each running subscription; empty elsewhere.
    pub webhooks: Vec<WebhookSample>,
    /// With `[server.tls]`: the certificate served.
    pub certificate: Option<CertificateSample>,
    /// On the node that drives the machines: deadlines and sequences.
    pub orders: Option<crate::service::dispatch::gate::Orders>,
}

#[derive(EncodeLabelSet, Debug, Clone, PartialEq, Eq, Hash)]
struct StationLabel {
    station: u16,
}

/// The certificate served over HTTPS, as the watch of its files tells it
/// (`app::serve::certificate`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CertificateSample {
    /// When it expires (its `notAfter`), in Unix seconds; None if that does not read.
    pub expires_at: Option<i64>,
    /// Whether the files as they are now do not load (the previous certificate is served).
    pub reload_failing: bool,
}

/// A webhook subscription's figures, as its deliverer keeps them.
#[derive(Debug)]
pub struct WebhookSample {
    /// The subscription's name.
    pub name: String,
    /// The newest event seq published (on disk): what its cursor is behind of.
    pub published: i64,
    /// What its deliverer counts.
    pub live: Live,
}

/// A cluster node's figures.
#[derive(Debug)]
pub struct ClusterSample {
    /// The node's name.
    pub node: String,
    /// Whether it drives the machines now.
    pub active: bool,
    /// The epoch it drives under (0 on a standby).
    pub epoch: i64,
    /// Times its process took over.
    pub takeovers: u64,
}

#[derive(EncodeLabelSet, Debug, Clone, PartialEq, Eq, Hash)]
struct NodeLabel {
    node: Text,
}

#[derive(EncodeLabelSet, Debug, Clone, PartialEq, Eq, Hash)]
struct WebhookLabel {
    webhook: Text,
}

#[derive(EncodeLabelSet, Debug, Clone, PartialEq, Eq, Hash)]
struct WebhookOutcome {
    webhook: Text,
    outcome: &'static str,
}

type Result = std::result::Result<(), std::fmt::Error>;

fn gauge<L: EncodeLabelSet, V: EncodeGaugeValue>(
    e: &mut DescriptorEncoder,
    name: &str,
    help: &str,
    samples: impl IntoIterator<Item = (L, V)>,
) -> Result {
    let mut m = e.encode_descriptor(name, help, None, MetricType::Gauge)?;
    for (labels, v) in samples {
        m.encode_family(&labels)?.encode_gauge(&v)?;
    }
    Ok(())
}

/// A gauge of one sample, without labels.
fn one(e: &mut DescriptorEncoder, name: &str, help: &str, value: i64) -> Result {
    e.encode_descriptor(name, help, None, MetricType::Gauge)?.encode_gauge(&value)
}

fn counter<L: EncodeLabelSet>(
    e: &mut DescriptorEncoder,
    name: &str,
    help: &str,
    samples: impl IntoIterator<Item = (L, u64)>,
) -> Result {
    let mut m = e.encode_descriptor(name, help, None, MetricType::Counter)?;
    for (labels, v) in samples {
        m.encode_family(&labels)?.encode_counter::<NoLabelSet, _, u64>(&v, None)?;
    }
    Ok(())
}

/// `counted`, with a zero for each configured device and each of `all` not counted.
fn counts(
    counted: &BTreeMap<(String, String), i64>,
    devices: &[DeviceStatus],
    all: &[&str],
) -> BTreeMap<(String, String), i64> {
    let mut map = counted.clone();
    for d in devices {
        for a in all {
            map.entry((d.id.clone(), (*a).to_owned())).or_insert(0);
        }
    }
    map
}

impl Scrape {
    fn each<L, V>(&self, f: impl Fn(&DeviceStatus) -> (L, V)) -> Vec<(L, V)> {
        self.devices.iter().map(f).collect()
    }

    fn devices(&self, e: &mut DescriptorEncoder) -> Result {
        let id = |s: &DeviceStatus| Device { device: Text(s.id.clone()) };
        let flag = |b: bool| i64::from(b);
        let mut m = e.encode_descriptor(
            "device",
            "A configured device: its kind, protocol and address.",
            None,
            MetricType::Info,
        )?;
        for s in &self.devices {
            let info = DeviceInfo {
                device: Text(s.id.clone()),
                kind: s.kind.as_str(),
                protocol: Text(s.protocol.clone()),
                address: Text(s.address.clone()),
            };
            m.encode_info(&info)?;
        }
        gauge(
            e,
            "device_online",
            "1 while the device answers, 0 while it is offline.",
            self.each(|s| (id(s), flag(s.online))),
        )?;
        gauge(
            e,
            "device_degraded",
            "1 while the device's link needs too many retries (a warning).",
            self.each(|s| (id(s), flag(s.link.degraded))),
        )?;
        gauge(
            e,
            "device_paused",
            "1 while an operator has paused the device (or all its aisles).",
            self.each(|s| (id(s), flag(s.paused))),
        )?;
        let age =
            |s: &DeviceStatus| (self.now - s.last_contact.unwrap_or(self.started)).as_seconds_f64().max(0.0);
        gauge(
            e,
            "device_seconds_since_contact",
            "Seconds since the device last answered (since rackd started if it never did).",
            self.each(|s| (id(s), age(s))),
        )?;
        counter(
            e,
            "device_link_requests",
            "Requests rackd asked of the device's link.",
            self.each(|s| (id(s), s.link.requests)),
        )?;
        counter(
            e,
            "device_link_retries",
            "Requests sent again after a timeout or a bad reply.",
            self.each(|s| (id(s), s.link.retries)),
        )?;
        counter(
            e,
            "device_link_timeouts",
            "Attempts that got no reply in time.",
            self.each(|s| (id(s), s.link.timeouts)),
        )?;
        let dropped = self.devices.iter().flat_map(|s| {
            [("stale", s.link.stale), ("foreign", s.link.foreign), ("malformed", s.link.malformed)]
                .map(|(reason, n)| (Dropped { device: Text(s.id.clone()), reason }, n))
        });
        counter(
            e,
            "device_link_dropped_replies",
            "Replies dropped: stale (late or for another request), foreign (another id or unit) or malformed.",
            dropped,
        )?;
        let mut m = e.encode_descriptor(
            "device_link_round_trip_seconds",
            "Round trips of the device's clean replies (those the adaptive timeout learns from).",
            None,
            MetricType::Histogram,
        )?;
        for s in &self.devices {
            let r = &s.link.round_trips;
            let buckets: Vec<(f64, u64)> =
                ROUND_TRIP_BOUNDS.iter().copied().chain([f64::MAX]).zip(r.counts).collect();
            m.encode_family(&id(s))?.encode_histogram::<NoLabelSet>(
                r.sum_seconds,
                r.count(),
                &buckets,
                None,
            )?;
        }
        Ok(())
    }

    fn webhooks(&self, e: &mut DescriptorEncoder) -> Result {
        if self.webhooks.is_empty() {
            return Ok(());
        }
        let name = |w: &WebhookSample| WebhookLabel { webhook: Text(w.name.clone()) };
        // A deliverer shows its row as soon as its task first runs. Before that its cursor
        // and pause are unknown, so those gauges have no sample for it rather than a wrong one.
        let shown = || self.webhooks.iter().filter(|w| !w.live.row.name.is_empty());
        let now_ms = (self.now.unix_timestamp_nanos() / 1_000_000) as i64;
        let behind = |w: &WebhookSample| (w.published - w.live.row.cursor).max(0);
        gauge(
            e,
            "webhook_events_behind",
            "Events published that the subscription is not done with (acknowledged, or not of its types).",
            shown().map(|w| (name(w), behind(w))),
        )?;
        let seconds = |w: &WebhookSample| match w.live.oldest_pending_at {
            Some(at) => (now_ms - at).max(0) as f64 / 1000.0,
            None => 0.0,
        };
        gauge(
            e,
            "webhook_seconds_behind",
            "Age of the event being delivered (since its commit); 0 when caught up or paused.",
            shown().map(|w| (name(w), seconds(w))),
        )?;
        let outcomes = self.webhooks.iter().flat_map(|w| {
            OUTCOMES.map(|outcome| {
                let n = w.live.outcomes.get(outcome).copied().unwrap_or(0);
                (WebhookOutcome { webhook: Text(w.name.clone()), outcome }, n)
            })
        });
        counter(
            e,
            "webhook_deliveries",
            "Tries to deliver an event: delivered (2xx), failed (another status, or none), gone (410).",
            outcomes,
        )?;
        counter(
            e,
            "webhook_retries",
            "Tries that were a retry of an event already tried.",
            self.webhooks.iter().map(|w| (name(w), w.live.retries)),
        )?;
        gauge(
            e,
            "webhook_paused",
            "1 while the subscription is paused (by an operator, or by the receiver's 410 Gone).",
            shown().map(|w| (name(w), i64::from(w.live.row.paused != 0))),
        )
    }
}

impl Collector for Scrape {
    fn encode(&self, mut e: DescriptorEncoder) -> Result {
        self.devices(&mut e)?;
        let states: Vec<&str> = JobState::ALL.iter().map(|s| s.as_str()).collect();
        let jobs = counts(&self.counts.jobs, &self.devices, &states);
        let jobs = jobs.into_iter().map(|((d, s), n)| (JobCount { device: Text(d), state: Text(s) }, n));
        gauge(&mut e, "jobs", "Jobs in the store by device and state.", jobs)?;
        let classes: Vec<&str> = AlarmClass::ALL.iter().map(|c| c.as_str()).collect();
        let alarms = counts(&self.counts.alarms, &self.devices, &classes);
        let alarms =
            alarms.into_iter().map(|((d, c), n)| (AlarmCount { device: Text(d), class: Text(c) }, n));
        gauge(
            &mut e,
            "alarms_active",
            "Active alarms by device and class (business, hardware, link).",
            alarms,
        )?;
        if let Some(c) = &self.cluster {
            let node = || NodeLabel { node: Text(c.node.clone()) };
            let help =
                "1 while this node drives the machines (the active node of its cluster), 0 on a standby.";
            gauge(&mut e, "cluster_active", help, [(node(), i64::from(c.active))])?;
            let help = "The epoch (fencing token) this node drives under; 0 on a standby.";
            gauge(&mut e, "cluster_epoch", help, [(node(), c.epoch)])?;
            let help = "Times this node's process became the active node.";
            counter(&mut e, "cluster_takeovers", help, [(node(), c.takeovers)])?;
        }
        if let Some(c) = &self.certificate {
            let help = "When the certificate served over HTTPS expires (its notAfter), in Unix seconds.";
            if let Some(at) = c.expires_at {
                one(&mut e, "tls_certificate_expiry_timestamp_seconds", help, at)?;
            }
            let help = "1 while the certificate files changed but do not load (the previous certificate is still served).";
            one(&mut e, "tls_certificate_reload_failing", help, i64::from(c.reload_failing))?;
        }
        if let Some(o) = &self.orders {
            one(&mut e, "jobs_late", "Unfinished jobs past their deadline.", o.late as i64)?;
            let help = "Jobs that ended after their deadline, since rackd started.";
            e.encode_descriptor("jobs_ended_late", help, None, MetricType::Counter)?
                .encode_counter::<NoLabelSet, _, u64>(&o.ended_late, None)?;
            if let Some(slack) = o.slack {
                let help = "Seconds to the nearest deadline of an unfinished job (negative once passed).";
                e.encode_descriptor("deadline_slack_seconds", help, None, MetricType::Gauge)?
                    .encode_gauge(&slack)?;
            }
            let help = "Sequence members delivered out of order (a position ahead of an earlier one, or due at \
                        the station before it), by station (0: a sequence without one), since rackd started.";
            let mut inversions = o.inversions.clone();
            inversions.entry(0).or_default();
            counter(
                &mut e,
                "sequence_inversions",
                help,
                inversions.into_iter().map(|(s, n)| (StationLabel { station: s }, n)),
            )?;
        }
        self.webhooks(&mut e)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::store::webhooks::Row;

    fn text(webhooks: Vec<WebhookSample>, now: OffsetDateTime) -> String {
        let scrape = Scrape {
            devices: Vec::new(),
            counts: Counts::default(),
            now,
            started: now,
            cluster: None,
            webhooks,
            certificate: None,
            orders: None,
        };
        let mut registry = prometheus_client::registry::Registry::with_prefix("rackd");
        registry.register_collector(Box::new(scrape));
        let mut out = String::new();
        prometheus_client::encoding::text::encode(&mut out, &registry).unwrap();
        out
    }

    fn sample(name: &str, published: i64, row: Row, oldest_pending_at: Option<i64>) -> WebhookSample {
        let live = Live { row, oldest_pending_at, ..Live::default() };
        WebhookSample { name: name.into(), published, live }
    }

    #[test]
    fn webhooks_show_their_lag_pause_and_every_outcome_from_zero() {
        let now = OffsetDateTime::from_unix_timestamp(1_700_000_000).unwrap();
        let now_ms = 1_700_000_000_000;
        let row = |name: &str, cursor, paused| Row { name: name.into(), cursor, paused, ..Row::default() };
        let mut failing = sample("wms", 10, row("wms", 4, 0), Some(now_ms - 90_500));
        failing.live.outcomes.insert("delivered", 4);
        failing.live.outcomes.insert("failed", 7);
        failing.live.retries = 6;
        let paused = sample("erp", 10, row("erp", 2, 1), None);
        // A cursor ahead of what this node has published yet (a new node's hub): not behind.
        let ahead = sample("ahead", 10, row("ahead", 12, 0), None);
        // A deliverer whose task has not run yet: counters only.
        let unstarted = sample("new\"one", 10, Row::default(), None);
        let out = text(vec![failing, paused, ahead, unstarted], now);
        for line in [
            "rackd_webhook_events_behind{webhook=\"wms\"} 6\n",
            "rackd_webhook_events_behind{webhook=\"erp\"} 8\n",
            "rackd_webhook_events_behind{webhook=\"ahead\"} 0\n",
            "rackd_webhook_seconds_behind{webhook=\"wms\"} 90.5\n",
            "rackd_webhook_seconds_behind{webhook=\"erp\"} 0.0\n",
            "rackd_webhook_deliveries_total{webhook=\"wms\",outcome=\"delivered\"} 4\n",
            "rackd_webhook_deliveries_total{webhook=\"wms\",outcome=\"failed\"} 7\n",
            "rackd_webhook_deliveries_total{webhook=\"wms\",outcome=\"gone\"} 0\n",
            "rackd_webhook_deliveries_total{webhook=\"erp\",outcome=\"gone\"} 0\n",
            "rackd_webhook_deliveries_total{webhook=\"new\\\"one\",outcome=\"failed\"} 0\n",
            "rackd_webhook_retries_total{webhook=\"wms\"} 6\n",
            "rackd_webhook_retries_total{webhook=\"new\\\"one\"} 0\n",
            "rackd_webhook_paused{webhook=\"wms\"} 0\n",
            "rackd_webhook_paused{webhook=\"erp\"} 1\n",
        ] {
            assert!(out.contains(line), "{line}{out}");
        }
        let unstarted_gauges = out.lines().filter(|l| l.contains("new\\\"one") && !l.contains("_total{"));
        assert_eq!(unstarted_gauges.count(), 0, "{out}");
    }

    #[test]
    fn no_webhook_family_where_none_is_delivered() {
        let out = text(Vec::new(), OffsetDateTime::now_utc());
        assert!(!out.contains("webhook"), "{out}");
    }
}
