//! Captures read back by Wireshark: frames built with rackd's own codecs, written as pcapng
//! by [`rackd::capture::write`], decoded by the real tshark with Wireshark's own Modbus
//! dissectors and the project's Lua dissectors (`contrib/wireshark`), and the decoded
//! fields compared with what was encoded. Each test writes one file and runs tshark once.
//!
//! tshark comes from Debian's `tshark` package (`cargo xtask test` installs it), or
//! `$TSHARK`; without it the tests fail and say how to install it. tshark runs with a
//! temporary `HOME`, so that neither a developer's Wireshark preferences nor dissectors they
//! installed from `contrib/wireshark` change what the tests see.
//!
//! [`replay`] records a real conversation between rackd and the crane simulator and plays
//! it back to a fresh rackd (`rackd sim replay`); it needs no tshark.

mod alarms;
mod downloads;
mod endpoint;
mod mc3e;
mod mewtocol;
mod modbus;
mod ppi;
mod recorded;
mod recorded_serial;
mod replay;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use rackd::capture::{Annotations, Direction, Frame, Link};

/// Expert info severity "error" (Wireshark's `PI_ERROR`), as `-T fields` prints it.
const SEVERITY_ERROR: &str = "8388608";

/// Fields every run prints besides the test's own.
const ALWAYS: [&str; 3] = ["frame.comment", "_ws.expert.severity", "_ws.expert.message"];

/// tshark: `$TSHARK`, or the first on the PATH; a test without it fails with what to do.
pub fn tshark() -> PathBuf {
    let found = match std::env::var_os("TSHARK") {
        Some(path) => Some(PathBuf::from(path)).filter(|p| p.is_file()),
        None => {
            let path = std::env::var_os("PATH").unwrap_or_default();
            std::env::split_paths(&path).map(|d| d.join("tshark")).find(|p| p.is_file())
        }
    };
    found.unwrap_or_else(|| {
        panic!(
            "the capture tests need tshark: run `cargo xtask test` (or `cargo xtask setup`), which installs \
             it, or `apt-get install tshark` (Debian/Ubuntu; answer no to capturing as non-root), or set \
             $TSHARK to one"
        )
    })
}

/// A Lua dissector of `contrib/wireshark`.
fn dissector(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("contrib/wireshark").join(name)
}

/// Frames one millisecond apart, built in order.
#[derive(Default)]
pub struct Frames(Vec<Frame>);

impl Frames {
    /// Adds a sent frame.
    pub fn sent(&mut self, bytes: Vec<u8>, annotations: Annotations) -> &mut Self {
        self.push(Direction::Sent, bytes, annotations)
    }

    /// Adds a received frame.
    pub fn received(&mut self, bytes: Vec<u8>, annotations: Annotations) -> &mut Self {
        self.push(Direction::Received, bytes, annotations)
    }

    fn push(&mut self, direction: Direction, bytes: Vec<u8>, annotations: Annotations) -> &mut Self {
        let time_us = 1_760_000_000_000_000 + 1000 * self.0.len() as u64;
        self.0.push(Frame::new(direction, time_us, bytes).with(annotations));
        self
    }
}

/// Annotations with a job and a verdict or note, as the recorder will set them.
pub fn job(job: i64) -> Annotations {
    Annotations { job: Some(job), ..Annotations::default() }
}

/// One packet's fields as tshark printed them: every occurrence of a field, in order.
pub struct Packet(BTreeMap<String, Vec<String>>);

impl Packet {
    /// The field's occurrences.
    pub fn all(&self, field: &str) -> Vec<&str> {
        self.0.get(field).map(|v| v.iter().map(String::as_str).collect()).unwrap_or_default()
    }

    /// The field's only (or first) occurrence; "" when absent.
    pub fn get(&self, field: &str) -> &str {
        self.0.get(field).and_then(|v| v.first()).map_or("", String::as_str)
    }
}

/// Writes `frames` on `link` to a pcapng file and decodes it with tshark (with the Lua
/// dissectors and `options`, e.g. `-d tcp.port==5020,mbtcp`), printing `fields`.
pub fn decode(link: &Link, frames: &Frames, options: &[&str], fields: &[&str]) -> Vec<Packet> {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("capture.pcapng");
    rackd::capture::write(std::fs::File::create(&file).unwrap(), link, &frames.0).unwrap();
    let mut command = Command::new(tshark());
    command.env("HOME", dir.path()).env_remove("XDG_CONFIG_HOME").arg("-r").arg(&file);
    for lua in ["mc3e.lua", "mewtocol.lua", "s7ppi.lua"] {
        command.arg("-X").arg(format!("lua_script:{}", dissector(lua).display()));
    }
    command.args(options).args(["-T", "fields", "-E", "occurrence=a", "-E", "aggregator=|"]);
    let all: Vec<&str> = ALWAYS.iter().chain(fields).copied().collect();
    for field in &all {
        command.args(["-e", field]);
    }
    let out = command.output().expect("tshark runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "tshark failed: {stderr}");
    let noise = |l: &&str| l.trim().is_empty() || l.starts_with("Running as user");
    assert!(stderr.lines().all(|l| noise(&l)), "tshark complained: {stderr}");
    let text = String::from_utf8(out.stdout).unwrap();
    let packets: Vec<Packet> = text
        .lines()
        .map(|line| {
            let values = line.split('\t');
            Packet(
                all.iter()
                    .zip(values)
                    .filter(|(_, v)| !v.is_empty())
                    .map(|(f, v)| (f.to_string(), v.split('|').map(str::to_owned).collect()))
                    .collect(),
            )
        })
        .collect();
    assert_eq!(packets.len(), frames.0.len(), "one packet per frame:\n{text}");
    packets
}

/// No packet has an expert error (malformed packets, exceptions in dissectors, bad checks)
/// but those listed, each of which has one whose message contains the text given.
pub fn assert_clean(packets: &[Packet], expected: &[(usize, &str)]) {
    for (i, p) in packets.iter().enumerate() {
        let severities = p.all("_ws.expert.severity");
        let messages = p.all("_ws.expert.message");
        let errors: Vec<&str> = severities
            .iter()
            .zip(messages.iter().chain(std::iter::repeat(&"")))
            .filter(|(s, _)| **s == SEVERITY_ERROR)
            .map(|(_, m)| *m)
            .collect();
        match expected.iter().find(|(n, _)| *n == i) {
            Some((_, text)) => assert!(errors.iter().any(|m| m.contains(text)), "packet {i}: {errors:?}"),
            None => assert!(errors.is_empty(), "packet {i} has expert errors: {errors:?} ({messages:?})"),
        }
    }
}

/// Every packet's comment is its frame's annotations.
pub fn assert_comments(packets: &[Packet], frames: &Frames) {
    for (p, f) in packets.iter().zip(&frames.0) {
        assert_eq!(p.get("frame.comment"), f.annotations.comment());
    }
}
