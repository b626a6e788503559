//! Where a child process listens, as it says itself. A test gives the child port 0 and reads
//! the address from its log ("rackd listening addr=...", chromedriver's "started
//! successfully on port N"), never a port picked beforehand: a port the test let go of can
//! be taken before the child binds it (by another test's server, or as the local port of
//! any outgoing connection), and the child then fails with "Address already in use".
//! [`super::node::Node`] does the same for the nodes a test kills and starts again.

use std::net::SocketAddr;
use std::path::Path;
use std::process::Child;
use std::time::Duration;

/// How long a child may take to say where it listens (a loaded machine, a cold binary).
const WITHIN: Duration = Duration::from_secs(30);

/// The address of a "rackd listening" line of rackd's log, text (`addr=HOST:PORT`) or
/// JSON (the `addr` field).
pub fn rackd_line(line: &str) -> Option<SocketAddr> {
    if !line.contains("rackd listening") {
        return None;
    }
    if line.starts_with('{') {
        let value: serde_json::Value = serde_json::from_str(line).ok()?;
        return value["fields"]["addr"].as_str()?.parse().ok();
    }
    let at = line.split_whitespace().find_map(|w| w.strip_prefix("addr="))?;
    at.trim_matches('"').parse().ok()
}

/// Waits until the log of `child` (its output, written to `log`) has a line `find` takes an
/// address from; fails with the log if the child exits first, or after 30 s.
pub async fn announced(
    log: &Path,
    child: &mut Child,
    find: impl Fn(&str) -> Option<SocketAddr>,
) -> SocketAddr {
    super::eventually(format!("{} to say where it listens", log.display()), WITHIN, async || {
        look(log, child, &find)
    })
    .await
}

/// As [`announced`], for a test without a runtime.
pub fn announced_blocking(
    log: &Path,
    child: &mut Child,
    find: impl Fn(&str) -> Option<SocketAddr>,
) -> SocketAddr {
    super::eventually_blocking(format!("{} to say where it listens", log.display()), WITHIN, || {
        look(log, child, &find)
    })
}

/// Where a `rackd serve` child whose log goes to `log` listens.
pub async fn rackd(log: &Path, child: &mut Child) -> SocketAddr {
    announced(log, child, rackd_line).await
}

/// As [`rackd`], for a test without a runtime.
pub fn rackd_blocking(log: &Path, child: &mut Child) -> SocketAddr {
    announced_blocking(log, child, rackd_line)
}

fn look(
    log: &Path,
    child: &mut Child,
    find: &impl Fn(&str) -> Option<SocketAddr>,
) -> Result<SocketAddr, String> {
    let text = std::fs::read_to_string(log).unwrap_or_default();
    if let Some(addr) = text.lines().find_map(find) {
        return Ok(addr);
    }
    if let Ok(Some(status)) = child.try_wait() {
        panic!("the child ended ({status}) before it said where it listens; its log:\n{text}");
    }
    Err(text)
}
