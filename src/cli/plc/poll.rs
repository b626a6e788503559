//! What `rackd plc` prints, once or in a poll loop (`--interval`, `--count`).
//!
//! Decisions, after mbpoll's:
//! - One read prints `ADDRESS VALUE` lines, or with `--json` one array of
//!   `{"address", "value"}` (as before the poll loop existed).
//! - A poll loop prints `-- poll N at HH:MM:SS.mmm` and the lines of each poll; an item
//!   whose shown value differs from the previous successful poll's gets ` *` after it, and
//!   on a terminal (without `NO_COLOR`) its value is also bold yellow. With `--json`, each
//!   poll is one line: `{"poll", "time", "items": [{"address", "value", "changed"}]}`, or
//!   `{"poll", "time", "error"}` for a failed one.
//! - A failed poll prints its error (stderr in text mode, so stdout keeps only values) and
//!   the loop goes on. Polls start `--interval` apart; one that takes longer delays the
//!   next rather than piling up.
//! - Ctrl-C ends the loop, also in the middle of a request; the summary `-- N polls, M
//!   failed` goes to stderr. The exit status is a failure only if no poll succeeded.

use std::io::IsTerminal;
use std::time::Duration;

use anyhow::bail;
use serde_json::json;
use time::OffsetDateTime;

use super::item::{Item, Target};
use crate::protocols::PlcMemory;

/// How to print.
#[derive(Clone, Copy, Debug)]
pub struct Output {
    /// JSON instead of lines.
    pub json: bool,
    /// Highlight changes with colour (stdout is a terminal and NO_COLOR is unset).
    pub colour: bool,
}

impl Output {
    /// The output for `--json`, with colour only for a person at a terminal.
    pub fn new(json: bool) -> Output {
        let colour =
            std::io::stdout().is_terminal() && std::env::var_os("NO_COLOR").is_none_or(|v| v.is_empty());
        Output { json, colour }
    }

    /// The items of a single read or write.
    pub fn once(&self, items: &[Item]) {
        if self.json {
            let items: Vec<_> = items.iter().map(|(a, v)| json!({ "address": a, "value": v.json })).collect();
            crate::cli::say(serde_json::Value::Array(items));
        } else {
            for (address, value) in items {
                crate::cli::say(format!("{address} {}", value.text));
            }
        }
    }

    fn poll(&self, n: u64, items: &[Item], previous: Option<&[Item]>) {
        let changed =
            |i: usize| previous.is_some_and(|p| p.get(i).is_none_or(|(_, v)| v.text != items[i].1.text));
        if self.json {
            let items: Vec<_> = (0..items.len())
                .map(|i| json!({ "address": items[i].0, "value": items[i].1.json, "changed": changed(i) }))
                .collect();
            crate::cli::say(json!({ "poll": n, "time": rfc3339(), "items": items }));
            return;
        }
        crate::cli::say(format!("-- poll {n} at {}", clock()));
        for (i, (address, value)) in items.iter().enumerate() {
            match (changed(i), self.colour) {
                (false, _) => crate::cli::say(format!("{address} {}", value.text)),
                (true, false) => crate::cli::say(format!("{address} {} *", value.text)),
                (true, true) => crate::cli::say(format!("{address} \x1b[1;33m{}\x1b[0m *", value.text)),
            }
        }
    }

    fn failure(&self, n: u64, error: &anyhow::Error) {
        let text = crate::cli::describe(error);
        if self.json {
            crate::cli::say(json!({ "poll": n, "time": rfc3339(), "error": text }));
        } else {
            eprintln!("-- poll {n} at {} failed: {text}", clock());
        }
    }
}

fn clock() -> String {
    let format = time::macros::format_description!("[hour]:[minute]:[second].[subsecond digits:3]");
    OffsetDateTime::now_utc().format(format).unwrap_or_default()
}

fn rfc3339() -> String {
    OffsetDateTime::now_utc().format(&time::format_description::well_known::Rfc3339).unwrap_or_default()
}

/// Reads `count` items every `every` until `polls` polls are done (forever without) or
/// Ctrl-C.
pub async fn run(
    plc: &dyn PlcMemory,
    target: &Target,
    count: u16,
    every: Duration,
    polls: Option<u64>,
    out: Output,
) -> anyhow::Result<()> {
    let mut ticks = tokio::time::interval(every.max(Duration::from_millis(1)));
    ticks.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let ctrl_c = tokio::signal::ctrl_c();
    tokio::pin!(ctrl_c);
    let (mut done, mut failed) = (0u64, 0u64);
    let mut previous: Option<Vec<Item>> = None;
    while polls.is_none_or(|n| done < n) {
        tokio::select! {
            _ = ticks.tick() => {}
            _ = &mut ctrl_c => break,
        }
        let result = tokio::select! {
            result = target.read(plc, count) => result,
            _ = &mut ctrl_c => break,
        };
        done += 1;
        match result {
            Ok(items) => {
                out.poll(done, &items, previous.as_deref());
                previous = Some(items);
            }
            Err(e) => {
                failed += 1;
                out.failure(done, &e);
            }
        }
    }
    let polls = if done == 1 { "poll" } else { "polls" };
    eprintln!("-- {done} {polls}, {failed} failed");
    if done > 0 && failed == done {
        bail!("every poll failed");
    }
    Ok(())
}
