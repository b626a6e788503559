//! The poll loop and the hints in errors, over sockets.

use std::io::{BufRead, BufReader};
use std::process::Command;

use super::{ok, plc, sim, spawn, stderr_of};

#[test]
fn a_poll_loop_marks_a_change_and_ctrl_c_ends_it_with_a_summary() {
    let modbus = sim(&["modbus", "--transport", "tcp"]);
    ok("modbus-tcp", &modbus.address, &["write", "4x7", "1", "2"]);
    let mut poller =
        spawn("modbus-tcp", &modbus.address, &["read", "4x7", "2", "--interval", "50", "--count", "400"]);
    let mut lines = BufReader::new(poller.stdout.take().unwrap()).lines().map_while(Result::ok);
    assert!(lines.next().unwrap().starts_with("-- poll 1 at "));
    assert_eq!((lines.next().unwrap(), lines.next().unwrap()), ("4x7 1".into(), "4x8 2".into()));
    ok("modbus-tcp", &modbus.address, &["write", "4x8", "5"]);
    let mut seen = Vec::new();
    for line in lines.by_ref() {
        let changed = line == "4x8 5 *";
        seen.push(line);
        if changed {
            break;
        }
    }
    assert!(
        seen.iter().all(|l| l.starts_with("-- poll ") || l == "4x7 1" || l == "4x8 2" || l == "4x8 5 *"),
        "{seen:?}"
    );
    assert!(seen.contains(&"4x7 1".to_owned()), "the unchanged register has no marker: {seen:?}");
    let next: Vec<_> = lines.by_ref().take(3).collect();
    assert_eq!(next[1..], ["4x7 1".to_owned(), "4x8 5".to_owned()], "marked once, at the poll that saw it");
    let status = Command::new("kill").args(["-INT", &poller.id().to_string()]).status().unwrap();
    assert!(status.success());
    let err = stderr_of(&mut poller);
    assert!(poller.wait().unwrap().success(), "Ctrl-C ends the loop cleanly: {err}");
    assert!(err.contains(" polls, 0 failed"), "{err}");
}

#[test]
fn count_ends_the_loop_and_a_failed_poll_does_not() {
    let modbus = sim(&["modbus", "--transport", "udp"]);
    let (ok, out, err) =
        plc("modbus-udp", &modbus.address, &["read", "4x0", "--count", "3", "--interval", "50", "--json"]);
    assert!(ok, "{err}");
    let polls: Vec<serde_json::Value> = out.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(polls.len(), 3, "{out}");
    assert_eq!(polls[2]["poll"], 3);
    assert_eq!(polls[2]["items"][0], serde_json::json!({"address": "4x0", "value": 0, "changed": false}));
    assert!(err.contains("-- 3 polls, 0 failed"), "{err}");

    let tcp = sim(&["modbus", "--transport", "tcp"]);
    let args = ["read", "4x0", "--count", "4", "--interval", "400", "--timeout-ms", "100", "--retries", "0"];
    let mut poller = spawn("modbus-tcp", &tcp.address, &args);
    let mut lines = BufReader::new(poller.stdout.take().unwrap()).lines().map_while(Result::ok);
    assert!(lines.next().unwrap().starts_with("-- poll 1"));
    drop(tcp); // the PLC goes away: the polls after fail, and the loop goes on
    let rest: Vec<_> = lines.collect();
    let err = stderr_of(&mut poller);
    assert!(poller.wait().unwrap().success(), "one poll succeeded: {err}");
    assert_eq!(rest, ["4x0 0"], "{err}");
    assert!(err.contains("-- poll 4 at ") && err.contains("-- 4 polls, 3 failed"), "{err}");
}

#[test]
fn errors_say_which_flag_to_try() {
    let zero_tid = sim(&["modbus", "--transport", "udp", "--quirk", "zero-tid"]);
    let quick = ["--timeout-ms", "100", "--retries", "1", "read", "4x1"];
    let (ok, _, err) = plc("modbus-udp", &zero_tid.address, &quick);
    assert!(
        !ok && err.contains("another transaction id") && err.contains("try --ignore-transaction-id"),
        "{err}"
    );
    let (ok, _, err) =
        plc("modbus-udp", &zero_tid.address, &[&quick[..], &["--ignore-transaction-id"]].concat());
    assert!(ok, "{err}");

    let length0 = sim(&["modbus", "--transport", "udp", "--quirk", "length0"]);
    let (ok, _, err) = plc("modbus-udp", &length0.address, &quick);
    assert!(!ok && err.contains("try --length0"), "{err}");

    let silent = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let (ok, _, err) =
        plc("ppi-tcp", &silent.local_addr().unwrap().to_string(), &["--timeout-ms", "100", "read", "VW0"]);
    assert!(!ok && err.contains("gateway's serial settings (baud rate, parity)"), "{err}");
    // A port held without listening: the connection is refused, and nothing takes the port.
    let refusing = crate::support::held::HeldPort::new();
    let free = refusing.addr().to_string();
    let (ok, _, err) = plc("mc3e", &free, &["--timeout-ms", "100", "--retries", "0", "read", "D0"]);
    assert!(!ok && err.contains("nothing listens"), "{err}");
    let (ok, _, err) = plc("mc3e", "127.0.0.1", &["read", "D0"]);
    assert!(!ok && err.contains("MC protocol has none of its own"), "{err}");

    let refusing = sim(&["modbus", "--transport", "tcp", "--device-error", "2"]);
    let (ok, _, err) = plc("modbus-tcp", &refusing.address, &["read", "40001"]);
    assert!(!ok && err.contains("exception 02 \"illegal data address\": ") && err.contains("40101"), "{err}");
}

#[tokio::test]
async fn silence_on_a_serial_line_names_unit_baud_parity_and_wiring() {
    use tokio_serial::SerialPort;
    // A pty pair whose far end never answers: a PLC that is not there, or set differently.
    let (_far, near) = tokio_serial::SerialStream::pair().expect("pty pair");
    let path = near.name().expect("the pty's device path");
    drop(near);
    let args = ["--timeout-ms", "100", "--retries", "0", "read", "4x0"];
    let (ok, _, err) = tokio::task::spawn_blocking(move || plc("modbus-rtu", &path, &args)).await.unwrap();
    assert!(!ok && err.contains("timeout"), "{err}");
    assert!(
        err.contains("check the unit (--unit), the baud rate and parity (--serial), and the wiring"),
        "{err}"
    );
}

/// The replies a late PLC still sends to the attempts of an earlier poll are late answers
/// to rackd's own requests: a capture marks them `stale`, never `foreign` (which would send
/// an engineer looking for another master on the network).
#[test]
fn late_replies_to_an_earlier_poll_are_stale_not_foreign() {
    use rackd::capture::{Direction, Verdict, read_file};

    let late = sim(&["modbus", "--transport", "udp", "--late-ms", "250"]);
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("late.pcapng");
    let name = file.to_str().unwrap();
    let args = ["read", "4x0", "--count", "3", "--interval", "100", "--timeout-ms", "100", "--capture", name];
    let (ok, _, err) = plc("modbus-udp", &late.address, &args);
    assert!(ok, "{err}");
    let capture = read_file(&file).unwrap();
    let verdicts: Vec<Option<Verdict>> = capture
        .frames
        .iter()
        .filter(|f| f.direction == Direction::Received)
        .map(|f| f.annotations.verdict)
        .collect();
    assert!(verdicts.contains(&Some(Verdict::StaleReply)), "{verdicts:?}");
    assert!(!verdicts.contains(&Some(Verdict::ForeignReply)), "{verdicts:?}");
}
