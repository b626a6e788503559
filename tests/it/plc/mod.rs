//! `rackd plc` against the real simulators (`rackd sim modbus|mc3e|mewtocol|ppi`), both as
//! child processes talking over 127.0.0.1: formats, notations, S7 double words, the poll
//! loop and the hints in its errors.

mod capture;
mod formats;
mod identify;
mod polls;

use std::io::{BufRead, BufReader, Read};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

/// A simulator running as `rackd sim ...` on 127.0.0.1, killed when dropped.
pub struct Sim {
    child: Child,
    /// `127.0.0.1:PORT` it listens on.
    pub address: String,
}

impl Drop for Sim {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Starts `rackd sim ARGS --listen 127.0.0.1:0` and waits for the address it reports.
pub fn sim(args: &[&str]) -> Sim {
    let mut child = Command::new(env!("CARGO_BIN_EXE_rackd"))
        .arg("sim")
        .args(args)
        .args(["--listen", "127.0.0.1:0"])
        .env("RACKD_LOG", "info")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let stderr = child.stderr.take().unwrap();
    let (tx, rx) = mpsc::channel();
    // Reads stderr to the end, so the simulator never writes into a closed pipe.
    std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            if let Some(at) = line.find("127.0.0.1:") {
                let port: String = line[at + 10..].chars().take_while(char::is_ascii_digit).collect();
                let _ = tx.send(format!("127.0.0.1:{port}"));
            }
        }
    });
    let address = rx.recv_timeout(Duration::from_secs(20)).expect("the simulator reports its address");
    Sim { child, address }
}

/// `rackd plc --protocol PROTOCOL --address ADDRESS ARGS`: success, stdout, stderr.
pub fn plc(protocol: &str, address: &str, args: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_rackd"))
        .args(["plc", "--protocol", protocol, "--address", address])
        .args(args)
        .output()
        .unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into(),
        String::from_utf8_lossy(&out.stderr).into(),
    )
}

/// `rackd plc` that must succeed; its stdout.
pub fn ok(protocol: &str, address: &str, args: &[&str]) -> String {
    let (ok, out, err) = plc(protocol, address, args);
    assert!(ok, "rackd plc {args:?} failed: {err}");
    out
}

/// `rackd plc` as a child process, its stdout piped.
pub fn spawn(protocol: &str, address: &str, args: &[&str]) -> Child {
    Command::new(env!("CARGO_BIN_EXE_rackd"))
        .args(["plc", "--protocol", protocol, "--address", address])
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

/// All of a child's stderr.
pub fn stderr_of(child: &mut Child) -> String {
    let mut err = String::new();
    child.stderr.take().unwrap().read_to_string(&mut err).unwrap();
    err
}
