//! One frame as the flight recorder keeps it: which way it went, when, its bytes, and what
//! rackd made of it (the annotations that become the packet's comment in a capture).

/// Which way a frame went, seen from rackd.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Direction {
    /// rackd sent it to the device.
    Sent,
    /// rackd received it from the device.
    Received,
}

/// What rackd made of a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Verdict {
    /// Taken as the answer (or sent and answered).
    Ok,
    /// Sent again after an attempt failed.
    Retry,
    /// No answer came in time.
    Timeout,
    /// Dropped without a reading (a frame nobody waited for, a garbled byte run).
    Dropped,
    /// A late answer to an earlier attempt, kept out of the current request.
    StaleReply,
    /// An answer to a request rackd did not send (another master on the line).
    ForeignReply,
    /// An answer from another unit or station than the one asked.
    WrongUnit,
    /// The frame's check (CRC, BCC, FCS) did not match.
    CrcError,
    /// The bytes are not a frame of the protocol.
    Malformed,
}

impl Verdict {
    /// The verdict in plain words, as the capture's comment shows it.
    pub fn name(self) -> &'static str {
        match self {
            Verdict::Ok => "ok",
            Verdict::Retry => "retry",
            Verdict::Timeout => "timeout",
            Verdict::Dropped => "dropped",
            Verdict::StaleReply => "stale reply",
            Verdict::ForeignReply => "foreign reply",
            Verdict::WrongUnit => "wrong unit",
            Verdict::CrcError => "CRC error",
            Verdict::Malformed => "malformed",
        }
    }
}

impl Verdict {
    /// The verdict of a plain name, as [`Verdict::name`] gives it.
    pub fn from_name(name: &str) -> Option<Verdict> {
        ALL_VERDICTS.into_iter().find(|v| v.name() == name)
    }
}

/// Every verdict. The flight recorder keeps a verdict as its place here: append only.
pub(super) const ALL_VERDICTS: [Verdict; 9] = [
    Verdict::Ok,
    Verdict::Retry,
    Verdict::Timeout,
    Verdict::Dropped,
    Verdict::StaleReply,
    Verdict::ForeignReply,
    Verdict::WrongUnit,
    Verdict::CrcError,
    Verdict::Malformed,
];

impl std::fmt::Display for Verdict {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// What rackd knew about a frame when it sent or read it.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Annotations {
    /// The job the exchange served, if any.
    pub job: Option<i64>,
    /// The device's task number (a crane's D8, a shelf slot's task word), if any.
    pub task: Option<u32>,
    /// Which retry this attempt is: 0 for the first attempt.
    pub retry: u32,
    /// What rackd made of the frame; None when it judged nothing (most requests).
    pub verdict: Option<Verdict>,
    /// Free text (a driver's own words); empty for none.
    pub note: String,
}

impl Annotations {
    /// The packet comment: the annotations that are set, in a fixed order, as
    /// `job 17, task 4, retry 1, verdict: stale reply, note`. A first attempt (retry 0)
    /// says nothing of retries. Empty when nothing is set.
    pub fn comment(&self) -> String {
        let mut parts = Vec::new();
        if let Some(job) = self.job {
            parts.push(format!("job {job}"));
        }
        if let Some(task) = self.task {
            parts.push(format!("task {task}"));
        }
        if self.retry > 0 {
            parts.push(format!("retry {}", self.retry));
        }
        if let Some(verdict) = self.verdict {
            parts.push(format!("verdict: {verdict}"));
        }
        if !self.note.is_empty() {
            parts.push(self.note.clone());
        }
        parts.join(", ")
    }

    /// Reads a [`comment`](Annotations::comment) back: its leading `job`, `task`, `retry`
    /// and `verdict:` parts in their order, the rest as the note. A comment that is not
    /// rackd's (a person's, in Wireshark) is all note.
    pub fn parse(comment: &str) -> Annotations {
        let mut a = Annotations::default();
        let mut rest = comment;
        let mut stage = 0;
        while !rest.is_empty() {
            let (part, tail) = rest.split_once(", ").unwrap_or((rest, ""));
            let number = |prefix: &str| part.strip_prefix(prefix).and_then(|n| n.parse::<u64>().ok());
            let verdict = part.strip_prefix("verdict: ").and_then(Verdict::from_name);
            match () {
                _ if stage < 1 && number("job ").is_some() => {
                    (a.job, stage) = (part[4..].parse().ok(), 1);
                }
                _ if stage < 2 && number("task ").is_some_and(|n| n <= u64::from(u32::MAX)) => {
                    (a.task, stage) = (part[5..].parse().ok(), 2);
                }
                _ if stage < 3
                    && number("retry ").is_some_and(|n| (1..=u64::from(u32::MAX)).contains(&n)) =>
                {
                    (a.retry, stage) = (part[6..].parse().unwrap_or(0), 3);
                }
                _ if stage < 4 && verdict.is_some() => (a.verdict, stage) = (verdict, 4),
                _ => break,
            }
            rest = tail;
        }
        a.note = rest.to_owned();
        a
    }
}

/// One frame on a link.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Frame {
    /// Which way it went.
    pub direction: Direction,
    /// When, in microseconds since the Unix epoch.
    pub time_us: u64,
    /// The frame's bytes, exactly as sent or read.
    pub bytes: bytes::Bytes,
    /// What rackd made of it.
    pub annotations: Annotations,
}

impl Frame {
    /// A frame without annotations.
    pub fn new(direction: Direction, time_us: u64, bytes: impl Into<bytes::Bytes>) -> Frame {
        Frame { direction, time_us, bytes: bytes.into(), annotations: Annotations::default() }
    }

    /// The same frame with these annotations.
    pub fn with(mut self, annotations: Annotations) -> Frame {
        self.annotations = annotations;
        self
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_comment_lists_what_is_set_in_order() {
        assert_eq!(Annotations::default().comment(), "");
        let a = Annotations {
            job: Some(17),
            task: Some(4),
            retry: 1,
            verdict: Some(Verdict::StaleReply),
            note: "transaction 9 expected".into(),
        };
        assert_eq!(a.comment(), "job 17, task 4, retry 1, verdict: stale reply, transaction 9 expected");
        let b = Annotations { retry: 0, verdict: Some(Verdict::CrcError), ..Annotations::default() };
        assert_eq!(b.comment(), "verdict: CRC error");
    }

    #[test]
    fn a_comment_reads_back_as_its_annotations() {
        let a = Annotations {
            job: Some(17),
            task: Some(4),
            retry: 1,
            verdict: Some(Verdict::StaleReply),
            note: "transaction 9 expected, then 10".into(),
        };
        assert_eq!(Annotations::parse(&a.comment()), a);
        for v in ALL_VERDICTS {
            let b = Annotations { verdict: Some(v), ..Annotations::default() };
            assert_eq!(Annotations::parse(&b.comment()), b);
        }
        assert_eq!(Annotations::parse(""), Annotations::default());
        let person = Annotations::parse("retry 0 looks odd, job x");
        assert_eq!(person, Annotations { note: "retry 0 looks odd, job x".into(), ..Annotations::default() });
        assert_eq!(Annotations::parse("task 3, job 2").note, "job 2", "out of order: the rest is the note");
    }

    #[test]
    fn every_verdict_has_a_plain_name() {
        let names: Vec<&str> = ALL_VERDICTS.iter().map(|v| v.name()).collect();
        assert_eq!(
            names,
            [
                "ok",
                "retry",
                "timeout",
                "dropped",
                "stale reply",
                "foreign reply",
                "wrong unit",
                "CRC error",
                "malformed"
            ]
        );
    }
}
