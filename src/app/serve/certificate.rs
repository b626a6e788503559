//! The certificate served over HTTPS, watched: one that expires within
//! [`EXPIRING_WITHIN`], or files that changed but do not load, is the `certificate` alarm,
//! and `/metrics` shows both (`rackd_tls_certificate_expiry_timestamp_seconds`,
//! `rackd_tls_certificate_reload_failing`), rather than a log line alone.
//!
//! Decisions:
//! - **Two alarms on device `tls`** (`tls:NODE` in a cluster: each node serves its own
//!   certificate and raises its own, through its own writer, standby or not), class
//!   `link` (clients cannot reach rackd): code 0, the certificate served expires within
//!   14 days or has expired, its text naming the date (a new certificate that expires soon
//!   too clears it and raises it again with its own date); code 1, the files changed but
//!   do not load and the previous certificate is still served. Each clears once it no longer
//!   holds: a renewed certificate served, files that load (or are back as they were).
//! - **14 days**: the usual renewal leaves 30 (Let's Encrypt, most ACME clients), so a
//!   certificate this close to its end was not renewed, and two weeks is time enough for a
//!   site whose certificates come from a ticket to another team.
//! - **Checked when what is served changes, and at least hourly**: the 14 days arrive with
//!   no change of the files. The end itself is a change of the alarm too: raised again,
//!   its text saying the certificate expired.
//! - **The validity is read from the certificate's DER by hand** ([`not_after`], a walk over
//!   five fields): rustls does not expose it, and x509-parser would bring nom, asn1-rs,
//!   der-parser and oid-registry into the binary for one date. A certificate whose date
//!   does not read (rustls accepted it, so this should not happen) has no expiry alarm and
//!   no expiry sample.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use time::OffsetDateTime;
use tokio::sync::watch;

use crate::api::metrics::Metrics;
use crate::api::metrics::scrape::CertificateSample;
use crate::config::tls::{EXPIRING_ACTION, REFUSED_ACTION};
use crate::domain::AlarmKind;
use crate::store::alarms::NewAlarm;
use crate::store::writer::{Record, WriteError, Writer};

/// How close to its end a served certificate raises the alarm.
pub(crate) const EXPIRING_WITHIN: time::Duration = time::Duration::days(14);

/// The longest the watch sleeps between two looks at the clock.
const LOOK_EVERY: Duration = Duration::from_secs(3600);

/// What is served, as the watch of the files tells it.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Served {
    /// When the certificate being served expires; None if its date does not read.
    pub(crate) expires: Option<OffsetDateTime>,
    /// While the files as they are now do not load: why (the previous certificate is
    /// served meanwhile).
    pub(crate) refused: Option<String>,
}

/// The device the alarms are raised on: `tls`, or `tls:NODE` on a cluster's node.
pub(crate) fn device(node: Option<&str>) -> String {
    match node {
        Some(node) => format!("tls:{node}"),
        None => "tls".into(),
    }
}

/// Raises and clears the `certificate` alarms of `served` (the certificate of `cert_file`)
/// on `device`, and keeps `/metrics`' figures, until the writer closes.
pub(crate) async fn watch(
    mut served: watch::Receiver<Served>,
    cert_file: PathBuf,
    device: String,
    writer: Writer,
    metrics: Arc<Metrics>,
) {
    // What the store has, as far as this task knows: unknown at first, so both are written
    // once (a clear of an alarm left from before a restart, whose files are fine now).
    // The expiry alarm as written: the date it names, and whether it said "expired".
    let mut expiring: Option<Option<(OffsetDateTime, bool)>> = None;
    let mut refused: Option<bool> = None;
    loop {
        let now = served.borrow_and_update().clone();
        metrics.set_certificate(CertificateSample {
            expires_at: now.expires.map(OffsetDateTime::unix_timestamp),
            reload_failing: now.refused.is_some(),
        });
        let clock = OffsetDateTime::now_utc();
        let soon = now.expires.filter(|at| *at - clock <= EXPIRING_WITHIN).map(|at| (at, at <= clock));
        if expiring != Some(soon) {
            let mut records = Vec::new();
            // Another certificate's alarm (or this one's before it expired) goes first; one
            // found active at a start is kept.
            if expiring.is_some_and(|was| was.is_some()) || (expiring.is_none() && soon.is_none()) {
                records
                    .push(Record::AlarmCleared { device: device.clone(), key: (AlarmKind::Certificate, 0) });
            }
            if let Some((at, expired)) = soon {
                records.push(raise(&device, 0, expiry_text(&cert_file, at, expired), EXPIRING_ACTION));
            }
            match write(&writer, records).await {
                None => return,
                Some(true) => expiring = Some(soon),
                Some(false) => {}
            }
        }
        if refused != Some(now.refused.is_some()) {
            let record = match &now.refused {
                Some(why) => {
                    let text = format!(
                        "the HTTPS certificate files changed but do not load ({why}); rackd still serves \
                         the previous certificate"
                    );
                    raise(&device, 1, text, REFUSED_ACTION)
                }
                None => Record::AlarmCleared { device: device.clone(), key: (AlarmKind::Certificate, 1) },
            };
            match write(&writer, vec![record]).await {
                None => return,
                Some(true) => refused = Some(now.refused.is_some()),
                Some(false) => {}
            }
        }
        // The next change of the alarm the clock alone makes: 14 days before the end, then
        // the end.
        let until_due = now
            .expires
            .map(|at| {
                let clock = OffsetDateTime::now_utc();
                if at - clock > EXPIRING_WITHIN { at - EXPIRING_WITHIN - clock } else { at - clock }
            })
            .and_then(|left| Duration::try_from(left).ok())
            .unwrap_or(LOOK_EVERY);
        // A record the store refused is tried again within a second.
        let pause = if expiring.is_none() || refused.is_none() { Duration::from_secs(1) } else { LOOK_EVERY };
        tokio::select! {
            changed = served.changed() => if changed.is_err() { return },
            () = tokio::time::sleep(until_due.min(pause).max(Duration::from_millis(10))) => {}
        }
    }
}

/// Writes `records` in order: Some(true) when all went, Some(false) when the store refused
/// one (logged), None when the writer is gone.
async fn write(writer: &Writer, records: Vec<Record>) -> Option<bool> {
    for record in records {
        match writer.record(record).await {
            Ok(()) => {}
            Err(WriteError::Closed | WriteError::Fenced(_)) => return None,
            Err(e) => {
                tracing::warn!(error = %e, "the certificate alarm could not be recorded");
                return Some(false);
            }
        }
    }
    Some(true)
}

fn raise(device: &str, code: u16, text: String, action: &str) -> Record {
    Record::AlarmRaised(NewAlarm {
        device: device.to_owned(),
        kind: AlarmKind::Certificate,
        code,
        class: AlarmKind::Certificate.class(),
        text,
        detail: None,
        action: Some(action.to_owned()),
    })
}

/// The alarm's text for a certificate that expires (or `expired`) at `at`.
fn expiry_text(cert_file: &std::path::Path, at: OffsetDateTime, expired: bool) -> String {
    let date = at.date();
    let file = cert_file.display();
    let left = at - OffsetDateTime::now_utc();
    if expired {
        format!("the HTTPS certificate in {file} expired on {date} (UTC): clients refuse rackd")
    } else {
        let days = left.whole_days();
        format!(
            "the HTTPS certificate in {file} expires on {date} (UTC), in {days} days: clients will refuse \
             rackd from then on"
        )
    }
}

/// The end of a certificate's validity (its `notAfter`), read from its DER: the
/// certificate, its `tbsCertificate`, then past the version (when present), the serial
/// number, the signature's algorithm and the issuer, to the validity's second time. None
/// for anything that is not so.
pub(crate) fn not_after(der: &[u8]) -> Option<OffsetDateTime> {
    let (_, certificate, _) = element(der)?;
    let (_, tbs, _) = element(certificate)?;
    let (tag, _, after_version) = element(tbs)?;
    let mut rest = if tag == 0xa0 { after_version } else { tbs };
    for _ in 0..3 {
        rest = element(rest)?.2;
    }
    let (_, validity, _) = element(rest)?;
    let (_, _, after_not_before) = element(validity)?;
    let (tag, time, _) = element(after_not_before)?;
    der_time(tag, time)
}

/// One DER element of `input`: its tag, its contents, and what follows it.
fn element(input: &[u8]) -> Option<(u8, &[u8], &[u8])> {
    let (&tag, rest) = input.split_first()?;
    let (&first, rest) = rest.split_first()?;
    let (length, rest) = match first {
        0..=0x7f => (usize::from(first), rest),
        0x81..=0x84 => {
            let n = usize::from(first & 0x7f);
            let bytes = rest.get(..n)?;
            (bytes.iter().fold(0usize, |a, &b| a << 8 | usize::from(b)), &rest[n..])
        }
        _ => return None,
    };
    let contents = rest.get(..length)?;
    Some((tag, contents, &rest[length..]))
}

/// A UTCTime (tag 0x17, `YYMMDDHHMMSSZ`, years 1950 to 2049) or GeneralizedTime (0x18,
/// `YYYYMMDDHHMMSSZ`), as RFC 5280 writes a validity's times.
fn der_time(tag: u8, contents: &[u8]) -> Option<OffsetDateTime> {
    let digits = contents.strip_suffix(b"Z")?;
    if !digits.iter().all(u8::is_ascii_digit) {
        return None;
    }
    let number = |d: &[u8]| d.iter().fold(0i32, |n, &b| n * 10 + i32::from(b - b'0'));
    let (year, rest) = match (tag, digits.len()) {
        (0x17, 12) => {
            let yy = number(&digits[..2]);
            (if yy >= 50 { 1900 + yy } else { 2000 + yy }, &digits[2..])
        }
        (0x18, 14) => (number(&digits[..4]), &digits[4..]),
        _ => return None,
    };
    let two = |i: usize| u8::try_from(number(&rest[i..i + 2])).ok();
    let month = time::Month::try_from(two(0)?).ok()?;
    let date = time::Date::from_calendar_date(year, month, two(2)?).ok()?;
    let at = time::Time::from_hms(two(4)?, two(6)?, two(8)?).ok()?;
    Some(date.with_time(at).assume_utc())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn certificate(not_after: OffsetDateTime) -> Vec<u8> {
        let mut params = rcgen::CertificateParams::new(vec!["localhost".into()]).unwrap();
        params.not_after = not_after;
        let key = rcgen::KeyPair::generate().unwrap();
        params.self_signed(&key).unwrap().der().to_vec()
    }

    #[test]
    fn the_end_of_validity_reads_in_both_time_forms() {
        // rcgen writes UTCTime up to 2049 and GeneralizedTime from 2050, as RFC 5280 says.
        for at in [
            time::macros::datetime!(2031-02-28 13:45:07 UTC),
            time::macros::datetime!(2049-12-31 23:59:59 UTC),
            time::macros::datetime!(2050-01-01 00:00:00 UTC),
            time::macros::datetime!(4096-01-01 00:00:00 UTC),
        ] {
            assert_eq!(not_after(&certificate(at)), Some(at), "{at}");
        }
    }

    #[test]
    fn anything_short_of_a_whole_certificate_reads_as_none() {
        let der = certificate(time::macros::datetime!(2031-02-28 13:45:07 UTC));
        for end in 0..der.len() {
            assert_eq!(not_after(&der[..end]), None, "the first {end} bytes");
        }
        assert_eq!(der_time(0x17, b"3102281345Z"), None);
        assert_eq!(der_time(0x17, b"31022813450+Z"), None);
        assert_eq!(der_time(0x18, b"20311302134507Z"), None, "month 13");
        assert_eq!(der_time(0x17, b"991231235959Z"), Some(time::macros::datetime!(1999-12-31 23:59:59 UTC)));
    }

    #[test]
    fn the_alarm_says_when_and_whether_it_is_too_late() {
        let file = std::path::Path::new("/etc/rackd/tls/server.crt");
        let at = OffsetDateTime::now_utc() + time::Duration::days(10) + time::Duration::hours(1);
        let text = expiry_text(file, at, false);
        assert!(text.contains(&format!("expires on {}", at.date())) && text.contains("in 10 days"), "{text}");
        assert!(text.contains("/etc/rackd/tls/server.crt"), "{text}");
        let at = OffsetDateTime::now_utc() - time::Duration::days(2);
        let text = expiry_text(file, at, true);
        assert!(text.contains(&format!("expired on {}", at.date())), "{text}");
    }

    proptest::proptest! {
        #[test]
        fn random_bytes_never_panic(bytes in proptest::collection::vec(proptest::num::u8::ANY, 0..300)) {
            let _ = not_after(&bytes);
        }
    }
}
