//! `rackd plc --capture FILE`: the file holds the command's frames after a read, after a
//! failed read, and after Ctrl-C ends a poll (none is left when no link opened); tshark
//! decodes the read's request and reply.

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::Command;

use rackd::capture::{Direction, Link, Transport, read_file};

use super::{ok, plc, sim, spawn, stderr_of};

fn path_of(dir: &tempfile::TempDir) -> (std::path::PathBuf, String) {
    let file = dir.path().join("plc.pcapng");
    let text = file.to_str().unwrap().to_owned();
    (file, text)
}

/// `modbus.func_code`, `modbus.reference_num` and the register values of each packet.
fn tshark_modbus(file: &Path, port: &str) -> Vec<String> {
    let out = Command::new(crate::capture::tshark())
        .env("HOME", file.parent().unwrap())
        .env_remove("XDG_CONFIG_HOME")
        .arg("-r")
        .arg(file)
        .args(["-o", &format!("mbtcp.tcp.port:{port}"), "-T", "fields", "-E", "aggregator=,"])
        .args(["-e", "modbus.func_code", "-e", "modbus.reference_num", "-e", "modbus.regval_uint16"])
        .output()
        .expect("tshark runs");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8(out.stdout).unwrap().lines().map(str::to_owned).collect()
}

#[test]
fn a_read_is_captured_with_its_request_and_reply() {
    let modbus = sim(&["modbus", "--transport", "tcp"]);
    ok("modbus-tcp", &modbus.address, &["write", "4x100", "7", "8"]);
    let dir = tempfile::tempdir().unwrap();
    let (file, name) = path_of(&dir);
    let (success, out, err) = plc("modbus-tcp", &modbus.address, &["read", "4x100", "2", "--capture", &name]);
    assert!(success, "{err}");
    assert_eq!(out, "4x100 7\n4x101 8\n");
    assert!(err.contains(&format!("capture: 2 frames written to {name}")), "{err}");

    let capture = read_file(&file).unwrap();
    let Link::Ip { transport: Transport::Tcp, remote, .. } = capture.link else {
        panic!("{:?}", capture.link)
    };
    assert_eq!(remote.to_string(), modbus.address);
    let directions: Vec<Direction> = capture.frames.iter().map(|f| f.direction).collect();
    assert_eq!(directions, [Direction::Sent, Direction::Received]);
    // MBAP header, then function 3 at 100 for 2; the answer: 4 bytes, 7 and 8.
    assert_eq!(capture.frames[0].bytes[7..], [3, 0, 100, 0, 2]);
    assert_eq!(capture.frames[1].bytes[7..], [3, 4, 0, 7, 0, 8]);

    let port = modbus.address.rsplit_once(':').unwrap().1;
    assert_eq!(tshark_modbus(&file, port), ["3\t100\t", "3\t\t7,8"]);
}

#[test]
fn a_failed_read_still_writes_its_capture() {
    // The simulated PLC is station 1: station 5 gets no answer, a try and a retry.
    let mewtocol = sim(&["mewtocol"]);
    let dir = tempfile::tempdir().unwrap();
    let (file, name) = path_of(&dir);
    let args = ["--unit", "5", "--timeout-ms", "100", "--retries", "1", "read", "DT0", "--capture", &name];
    let (success, _, err) = plc("mewtocol-tcp", &mewtocol.address, &args);
    assert!(!success);
    assert!(err.contains(&format!("capture: 2 frames written to {name}")), "{err}");
    let capture = read_file(&file).unwrap();
    assert!(capture.frames.iter().all(|f| f.direction == Direction::Sent && f.bytes.starts_with(b"%05#RD")));
    assert_eq!(capture.frames[1].annotations.retry, 1);

    // No port for MC: refused before a link opens, and no file is left behind (a new
    // name: rackd never writes over a file).
    let (file, name) = (dir.path().join("mc.pcapng"), dir.path().join("mc.pcapng").display().to_string());
    let (success, _, err) = plc("mc3e", "127.0.0.1", &["read", "D0", "--capture", &name]);
    assert!(!success);
    assert!(err.contains(&format!("capture: no link was opened, nothing written to {name}")), "{err}");
    assert!(!file.exists());
}

#[test]
fn ctrl_c_ends_a_poll_and_the_capture_is_written() {
    let modbus = sim(&["modbus", "--transport", "tcp"]);
    let dir = tempfile::tempdir().unwrap();
    let (file, name) = path_of(&dir);
    let mut poller =
        spawn("modbus-tcp", &modbus.address, &["read", "4x0", "--interval", "20", "--capture", &name]);
    // Kept open until the end: a poller writing into a closed pipe would die of it.
    let mut lines = BufReader::new(poller.stdout.take().unwrap()).lines().map_while(Result::ok);
    let polls = lines.by_ref().filter(|l| l.starts_with("-- poll ")).take(3).count();
    assert_eq!(polls, 3);
    let status = Command::new("kill").args(["-INT", &poller.id().to_string()]).status().unwrap();
    assert!(status.success());
    let err = stderr_of(&mut poller);
    assert!(poller.wait().unwrap().success(), "{err}");
    drop(lines);
    let capture = read_file(&file).unwrap();
    let n = capture.frames.len();
    assert!(n >= 6 && n.is_multiple_of(2), "a request and a reply per poll: {n}");
    assert!(err.contains(&format!("capture: {n} frames written to {name}")), "{err}");
}
