//! The two text formats `/metrics` speaks, which one a scraper asked for, and the
//! conversion from OpenMetrics (what prometheus-client writes) to Prometheus text 0.0.4.
//!
//! Why a converter and not a second encoder: prometheus-client 0.24 writes OpenMetrics
//! only, and for the metric types rackd uses the two formats differ in a few metadata lines,
//! never in samples:
//! - a counter's `# HELP` and `# TYPE` name its family (`x`) in OpenMetrics and the sample
//!   (`x_total`) in 0.0.4;
//! - an `info` family `x` (sample `x_info ... 1`) is a gauge named `x_info` in 0.0.4;
//! - `unknown` is `untyped`; `# UNIT` lines and the closing `# EOF` do not exist in 0.0.4;
//! - histograms, gauges, label escaping and sample lines are the same.
//!
//! Rewriting those lines keeps one registry and one set of collectors for both formats. The
//! converter refuses what it does not know how to convert (`stateset`, `gaugehistogram`,
//! `summary`, exemplars) rather than pass on text a 0.0.4 parser would misread; rackd
//! registers none of them, and a unit test converts the whole registry's output.
//!
//! The crates that could do this instead, and why none does yet:
//! - **prometheus-client 0.26.0** adds `encoding::prometheus_text::encode`, a 0.0.4 encoder
//!   over the same registry and collectors: the right replacement, but not byte for byte.
//!   It writes bucket bounds as Go does (`le="1"`, `le="3600"`) where OpenMetrics, and so
//!   today's 0.0.4, has `le="1.0"`, `le="3600.0"` (its own tests show both), so every
//!   integer bound of rackd's histograms (`writer_group_size`, `job_dispatch_seconds`,
//!   `job_duration_seconds`, ...) would change label value: new series for a scraper that
//!   stores them as they come (Prometheus 2.x). The same upgrade escapes label values
//!   itself (0.25.2), so [`super::scrape::Text`]'s escaping must go in the same change.
//!   Moving to it, once a change of `le` in 0.0.4 is accepted, deletes [`to_prometheus`]
//!   and that escaping.
//! - **prometheus 0.14.0** (tikv): its `TextEncoder` writes 0.0.4 from the crate's own
//!   protobuf-shaped `MetricFamily`s and reads no text, so it would need an OpenMetrics
//!   parser in front of it, and a second metrics library.
//! - **prometheus-parse 0.2.5**: reads 0.0.4 text into samples; no OpenMetrics, no writer.
//! - **openmetrics-parser 0.5.1**: reads either format into its own model
//!   (`OpenMetricsType`, `PrometheusType`) and prints it back in the same format, with no
//!   conversion between the two; LGPL-3.0, with pest and pest_derive to compile.
//!
//! Content negotiation stays here in any case: prometheus-client reads no `Accept` header
//! (0.26.0 has the 0.0.4 content type as a constant, nothing more).

use axum::http::HeaderValue;

/// The content type of OpenMetrics text.
pub const OPENMETRICS: &str = "application/openmetrics-text; version=1.0.0; charset=utf-8";
/// The content type of Prometheus text 0.0.4.
pub const PROMETHEUS: &str = "text/plain; version=0.0.4; charset=utf-8";

/// The formats `/metrics` answers in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// OpenMetrics 1.0 text, ending in `# EOF`.
    OpenMetrics,
    /// Prometheus text format 0.0.4: the default.
    Prometheus,
}

impl Format {
    /// The format an `Accept` header asks for: OpenMetrics when it lists
    /// `application/openmetrics-text` (any version) with a weight above zero and at least
    /// that of `text/plain`; Prometheus text otherwise, and without the header.
    pub fn negotiate(accept: Option<&HeaderValue>) -> Format {
        let Some(accept) = accept.and_then(|a| a.to_str().ok()) else { return Format::Prometheus };
        let (mut openmetrics, mut text) = (0.0_f64, 0.0_f64);
        for range in accept.split(',') {
            let mut parts = range.split(';');
            let media = parts.next().unwrap_or("").trim().to_ascii_lowercase();
            let q = parts
                .filter_map(|p| p.trim().strip_prefix("q="))
                .find_map(|q| q.trim().parse::<f64>().ok())
                .unwrap_or(1.0);
            match media.as_str() {
                "application/openmetrics-text" => openmetrics = openmetrics.max(q),
                "text/plain" => text = text.max(q),
                _ => {}
            }
        }
        if openmetrics > 0.0 && openmetrics >= text { Format::OpenMetrics } else { Format::Prometheus }
    }

    /// The `Content-Type` of an answer in this format.
    pub fn content_type(self) -> &'static str {
        match self {
            Format::OpenMetrics => OPENMETRICS,
            Format::Prometheus => PROMETHEUS,
        }
    }
}

/// What the converter could not turn into 0.0.4.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum ConvertError {
    /// A metric type 0.0.4 has no equivalent for.
    #[error("metric type {0:?} has no Prometheus 0.0.4 equivalent")]
    Type(String),
    /// A sample carries an exemplar, which 0.0.4 cannot hold.
    #[error("exemplars have no Prometheus 0.0.4 form")]
    Exemplar,
}

/// Prometheus text 0.0.4 from OpenMetrics text (see the module doc).
pub fn to_prometheus(openmetrics: &str) -> Result<String, ConvertError> {
    let mut out = String::with_capacity(openmetrics.len());
    // `# HELP` comes before `# TYPE`, and only the type says what the name becomes.
    let mut help: Option<(&str, &str)> = None;
    for line in openmetrics.lines() {
        if line == "# EOF" || line.starts_with("# UNIT ") {
            continue;
        }
        if let Some(rest) = line.strip_prefix("# HELP ") {
            let (name, text) = rest.split_once(' ').unwrap_or((rest, ""));
            help = Some((name, text));
            continue;
        }
        if let Some(rest) = line.strip_prefix("# TYPE ") {
            let (name, kind) = rest.split_once(' ').unwrap_or((rest, "unknown"));
            let (name, kind) = match kind {
                "counter" => (format!("{name}_total"), "counter"),
                "info" => (format!("{name}_info"), "gauge"),
                "unknown" => (name.to_owned(), "untyped"),
                "gauge" | "histogram" => (name.to_owned(), kind),
                other => return Err(ConvertError::Type(other.to_owned())),
            };
            if let Some((_, text)) = help.take() {
                out.push_str(&format!("# HELP {name} {text}\n"));
            }
            out.push_str(&format!("# TYPE {name} {kind}\n"));
            continue;
        }
        if let Some((name, text)) = help.take() {
            // A family with help and no type: untyped in both formats.
            out.push_str(&format!("# HELP {name} {text}\n"));
        }
        if line.contains(" # {") {
            return Err(ConvertError::Exemplar);
        }
        out.push_str(line);
        out.push('\n');
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn accept(value: &str) -> Format {
        Format::negotiate(Some(&HeaderValue::from_str(value).unwrap()))
    }

    #[test]
    fn openmetrics_only_when_asked_for() {
        assert_eq!(Format::negotiate(None), Format::Prometheus);
        assert_eq!(accept("*/*"), Format::Prometheus);
        assert_eq!(accept("text/plain"), Format::Prometheus);
        assert_eq!(accept("application/openmetrics-text; version=1.0.0"), Format::OpenMetrics);
        assert_eq!(accept("application/openmetrics-text;version=0.0.1"), Format::OpenMetrics);
        // What Prometheus 2.x sends.
        let prometheus = "application/openmetrics-text;version=1.0.0;q=0.5,application/openmetrics-text;\
                          version=0.0.1;q=0.4,text/plain;version=0.0.4;q=0.3,*/*;q=0.2";
        assert_eq!(accept(prometheus), Format::OpenMetrics);
        assert_eq!(accept("application/openmetrics-text;q=0.2, text/plain;q=0.9"), Format::Prometheus);
        assert_eq!(accept("application/openmetrics-text;q=0"), Format::Prometheus);
        assert_eq!(accept("Application/OpenMetrics-Text"), Format::OpenMetrics);
    }

    #[test]
    fn counters_and_infos_are_renamed_units_and_eof_dropped() {
        let openmetrics = "# HELP rackd_requests Requests.\n# TYPE rackd_requests counter\n\
                           rackd_requests_total{route=\"/a\"} 3\n\
                           # HELP rackd_build Build.\n# TYPE rackd_build info\nrackd_build_info{version=\"1\"} 1\n\
                           # HELP rackd_wait_seconds Wait.\n# TYPE rackd_wait_seconds histogram\n\
                           # UNIT rackd_wait_seconds seconds\n\
                           rackd_wait_seconds_sum 0.5\nrackd_wait_seconds_count 1\n\
                           rackd_wait_seconds_bucket{le=\"+Inf\"} 1\n\
                           # HELP rackd_odd Odd.\n# TYPE rackd_odd unknown\nrackd_odd 1\n# EOF\n";
        let expected = "# HELP rackd_requests_total Requests.\n# TYPE rackd_requests_total counter\n\
                        rackd_requests_total{route=\"/a\"} 3\n\
                        # HELP rackd_build_info Build.\n# TYPE rackd_build_info gauge\nrackd_build_info{version=\"1\"} 1\n\
                        # HELP rackd_wait_seconds Wait.\n# TYPE rackd_wait_seconds histogram\n\
                        rackd_wait_seconds_sum 0.5\nrackd_wait_seconds_count 1\n\
                        rackd_wait_seconds_bucket{le=\"+Inf\"} 1\n\
                        # HELP rackd_odd Odd.\n# TYPE rackd_odd untyped\nrackd_odd 1\n";
        assert_eq!(to_prometheus(openmetrics).unwrap(), expected);
    }

    #[test]
    fn what_has_no_0_0_4_form_is_refused() {
        let stateset = "# TYPE x stateset\nx{x=\"a\"} 1\n# EOF\n";
        assert_eq!(to_prometheus(stateset), Err(ConvertError::Type("stateset".into())));
        let exemplar = "# TYPE x counter\nx_total 1 # {trace=\"a\"} 1\n# EOF\n";
        assert_eq!(to_prometheus(exemplar), Err(ConvertError::Exemplar));
    }
}
