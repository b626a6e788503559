//! `rackd plc --capture FILE`: the file holds the command's frames after a read, after a
//! failed read, and after Ctrl-C ends a poll (none is left when no link opened); tshark
//! decodes the read's request and reply. Every protocol family records its read, the serial
//! ones on a pty as on a real line (issue 51: Modbus RTU recorded nothing).

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::Command;

use rackd::capture::{Direction, Link, SerialProtocol, Transport, read_file};

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
    // A request and its reply for each of the three polls seen at least. Not exactly pairs:
    // Ctrl-C may land while a request waits for its reply, and on a busy machine a reply
    // later than Modbus TCP's 2 ms timeout floor is retried (a second request, a stale reply).
    let sent = capture.frames.iter().filter(|f| f.direction == Direction::Sent).count();
    assert!(n >= 6 && sent >= 3 && n - sent >= 3, "requests and replies of three polls: {n}, {sent} sent");
    assert_eq!(capture.frames[0].direction, Direction::Sent);
    assert!(err.contains(&format!("capture: {n} frames written to {name}")), "{err}");
}

/// A simulated PLC on the master end of a pty pair; `rackd plc` opens the other end by its
/// path. Kept alive (both ends) until dropped.
struct PtySim {
    path: String,
    _slave: tokio_serial::SerialStream,
    _server: Box<dyn std::any::Any + Send>,
}

/// The serial protocol's simulator on a fresh pty pair.
fn pty_sim(protocol: &str) -> PtySim {
    use rackd::protocols::{mewtocol, ppi};
    use tokio_serial::SerialPort;
    let (master, slave) = tokio_serial::SerialStream::pair().expect("pty pair");
    let path = slave.name().expect("the slave end has a path");
    let server: Box<dyn std::any::Any + Send> = match protocol {
        "modbus-rtu" => {
            use rackd::protocols::modbus::server::{Bank, ModbusServer, ServerOptions};
            let server = ModbusServer::new(std::sync::Arc::new(Bank::new()), ServerOptions::default());
            Box::new(server.serve_rtu_stream(master, 9600))
        }
        "mewtocol" => {
            let state = mewtocol::server::ServerState::new(mewtocol::Bank::default().shared());
            Box::new(mewtocol::server::serve_stream(master, state))
        }
        "ppi" => {
            let state = ppi::server::ServerState::new(ppi::Bank::default().shared());
            Box::new(ppi::server::serve_stream(master, state))
        }
        other => panic!("not a serial protocol: {other}"),
    };
    PtySim { path, _slave: slave, _server: server }
}

/// `rackd plc --capture` records a read on every protocol family, the serial ones on a pty
/// as on a real line: each file holds the read's request and reply (PPI's acknowledgement
/// and poll too), on the link it went over, as many frames as the command says.
#[rstest::rstest]
#[case::modbus_udp("modbus-udp", "4x100")]
#[case::modbus_tcp("modbus-tcp", "4x100")]
#[case::modbus_rtu("modbus-rtu", "4x100")]
#[case::modbus_rtu_tcp("modbus-rtu-tcp", "4x100")]
#[case::mc3e("mc3e", "D100")]
#[case::mewtocol("mewtocol", "DT100")]
#[case::ppi("ppi", "VW100")]
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_protocol_family_is_captured(#[case] protocol: &str, #[case] item: &str) {
    let network = match protocol {
        "modbus-udp" => Some(sim(&["modbus", "--transport", "udp"])),
        "modbus-tcp" => Some(sim(&["modbus", "--transport", "tcp"])),
        "modbus-rtu-tcp" => Some(sim(&["modbus", "--transport", "rtu-over-tcp"])),
        "mc3e" => Some(sim(&["mc3e"])),
        _ => None,
    };
    let serial = network.is_none().then(|| pty_sim(protocol));
    let address = match (&network, &serial) {
        (Some(sim), _) => sim.address.clone(),
        (_, Some(pty)) => pty.path.clone(),
        _ => unreachable!(),
    };
    let dir = tempfile::tempdir().unwrap();
    let (file, name) = path_of(&dir);
    let args = ["read", item, "2", "--capture", &name].map(str::to_owned);
    let run = {
        let (protocol, address) = (protocol.to_owned(), address.clone());
        tokio::task::spawn_blocking(move || plc(&protocol, &address, &args.each_ref().map(String::as_str)))
    };
    let (success, out, err) = run.await.unwrap();
    assert!(success, "{protocol}: {err}");
    assert_eq!(out.lines().count(), 2, "{protocol}: {out}");

    let said = err.split("capture: ").nth(1).and_then(|rest| rest.split(' ').next()?.parse::<usize>().ok());
    let n = said.unwrap_or_else(|| panic!("{protocol}: no capture line in {err:?}"));
    assert!(n >= 2, "{protocol}: a request and its reply at least, {n} frames written");
    assert!(err.contains(&format!("capture: {n} frames written to {name}")), "{protocol}: {err}");
    let capture = read_file(&file).unwrap();
    assert_eq!(capture.frames.len(), n, "{protocol}: the file holds what the command says");
    let sent = capture.frames.iter().filter(|f| f.direction == Direction::Sent).count();
    assert!(sent >= 1 && sent < n, "{protocol}: requests and replies, {sent} of {n} sent");
    assert_eq!(capture.frames[0].direction, Direction::Sent, "{protocol}: the request first");
    let link = match (&capture.link, protocol) {
        (Link::Ip { transport: Transport::Udp, remote, .. }, "modbus-udp")
        | (Link::Ip { transport: Transport::Tcp, remote, .. }, "modbus-tcp" | "mc3e") => remote.to_string(),
        (Link::Serial { protocol: SerialProtocol::ModbusRtu, port }, "modbus-rtu" | "modbus-rtu-tcp")
        | (Link::Serial { protocol: SerialProtocol::Mewtocol, port }, "mewtocol")
        | (Link::Serial { protocol: SerialProtocol::Ppi, port }, "ppi") => port.clone(),
        (other, _) => panic!("{protocol}: captured as {other:?}"),
    };
    // RTU over TCP is a serial line a gateway carries: its port reads `tcp HOST:PORT`.
    let expected = if protocol == "modbus-rtu-tcp" { format!("tcp {address}") } else { address };
    assert_eq!(link, expected, "{protocol}");
}
