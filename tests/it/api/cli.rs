//! The binary's own commands: check-config, hash-key, openapi, plc.

use std::process::Command;

use crate::support::eventually_blocking;

fn rackd(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_rackd")).args(args).output().unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into(),
        String::from_utf8_lossy(&out.stderr).into(),
    )
}

#[test]
fn check_config_accepts_the_example_and_names_the_bad_key_and_line() {
    let example = concat!(env!("CARGO_MANIFEST_DIR"), "/config/rackd.example.toml");
    let (ok, out, _) = rackd(&["check-config", example]);
    assert!(ok && out.contains("ok"));

    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, "[server]\nlisten = \"127.0.0.1:8080\"\n\n[database]\npaht = \"x.db\"\n").unwrap();
    let (ok, _, err) = rackd(&["check-config", bad.to_str().unwrap()]);
    assert!(!ok);
    assert!(err.contains("bad.toml:5:1: database.paht: unknown field `paht`"), "{err}");

    std::fs::write(&bad, "[server]\nlisten = \"nowhere\"\n").unwrap();
    let (ok, _, err) = rackd(&["check-config", bad.to_str().unwrap()]);
    assert!(!ok && err.contains("bad.toml:2:1: server.listen: "), "{err}");

    // Each problem of an entry alone: the layers read its keys in name order, so a bad
    // hash would be reported before the role.
    let key = format!("[[auth.keys]]\nname = \"x\"\nrole = \"root\"\nhash = \"sha256:{}\"\n", "0".repeat(64));
    std::fs::write(&bad, &key).unwrap();
    let (ok, _, err) = rackd(&["check-config", bad.to_str().unwrap()]);
    assert!(!ok && err.contains("bad.toml:3:1: auth.keys[0].role: ") && err.contains("root"), "{err}");
    std::fs::write(&bad, key.replace("root", "admin").replace(&"0".repeat(64), "00")).unwrap();
    let (ok, _, err) = rackd(&["check-config", bad.to_str().unwrap()]);
    assert!(!ok && err.contains("bad.toml:4:1: auth.keys[0].hash: "), "{err}");
}

/// A webhook with an event type rackd does not write, on line 4.
const BAD_WEBHOOK: &str = "[[webhooks]]\nname = \"wms\"\nurl = \"https://wms.plant.local/events\"\n\
                           events = [\"job.created\"]\nsecret = \"whsec_MfKQ9r8GKYqrTwjUPD8ILPZIo2LaLaSw\"\n";

#[test]
fn check_config_names_a_bad_webhooks_key_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, BAD_WEBHOOK).unwrap();
    let (ok, _, err) = rackd(&["check-config", bad.to_str().unwrap()]);
    assert!(!ok && err.contains("bad.toml:4:1: webhooks[0].events: "), "{err}");
    assert!(err.contains("\"job.created\" is not an event type") && err.contains("job.updated"), "{err}");
    assert!(!err.contains("MfKQ9r8GKYqrTwjUPD8ILPZIo2LaLaSw"), "{err}");
    std::fs::write(&bad, BAD_WEBHOOK.replace("job.created", "job.*")).unwrap();
    let (ok, out, err) = rackd(&["check-config", bad.to_str().unwrap()]);
    assert!(ok && out.contains("ok"), "{err}");
}

#[test]
fn serve_refuses_to_start_with_a_bad_webhook() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("bad.toml");
    let db = dir.path().join("rackd.db");
    let server = format!("[server]\nlisten = \"127.0.0.1:0\"\n[database]\npath = {db:?}\n");
    std::fs::write(&file, format!("{BAD_WEBHOOK}{server}")).unwrap();
    let (ok, _, err) = rackd(&["serve", "--config", file.to_str().unwrap()]);
    assert!(!ok && err.contains("bad.toml:4:1: webhooks[0].events: "), "{err}");
    assert!(err.contains("\"job.created\" is not an event type"), "{err}");
    assert!(!db.exists(), "refused before anything started: {err}");
}

#[test]
fn check_config_refuses_a_key_of_another_kind_and_a_quirk_of_another_protocol() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("devices.toml");
    let crane = "[[devices]]\nid = \"crane1\"\nkind = \"crane\"\naddress = \"10.0.0.1:8000\"\n";
    std::fs::write(&file, crane).unwrap();
    let (ok, out, err) = rackd(&["check-config", file.to_str().unwrap()]);
    assert!(ok && out.contains("ok"), "a crane needs no more than its address: {err}");

    std::fs::write(&file, format!("{crane}stride = 1\n")).unwrap();
    let (ok, _, err) = rackd(&["check-config", file.to_str().unwrap()]);
    assert!(!ok && err.contains("`stride` is a key of shelf devices"), "{err}");
    assert!(err.contains("devices.toml:5:1: devices[0].stride: "), "{err}");

    std::fs::write(&file, format!("{crane}quirks = [\"length0\"]\n")).unwrap();
    let (ok, _, err) = rackd(&["check-config", file.to_str().unwrap()]);
    assert!(!ok && err.contains("length0") && err.contains("mc3e"), "{err}");
}

#[test]
fn check_config_names_the_line_of_a_bad_address_and_an_environment_variable() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("site.toml");
    let shelf =
        "[[devices]]\nid = \"shelf1\"\nkind = \"shelf\"\naisles = [1]\naddress = \"192.168.1.300:502\"\n";
    std::fs::write(&file, shelf).unwrap();
    let (ok, _, err) = rackd(&["check-config", file.to_str().unwrap()]);
    assert!(!ok && err.contains("site.toml:5:1: devices[0].address: ") && err.contains("IPv4"), "{err}");

    std::fs::write(&file, shelf.replace(".300", ".30")).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_rackd"))
        .args(["check-config", file.to_str().unwrap()])
        .env("RACKD_INTAKE__QUEUE", "many")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("env RACKD_INTAKE__QUEUE: intake.queue: "), "{err}");
}

#[test]
fn check_config_explain_prints_every_value_with_its_origin() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("site.toml");
    std::fs::write(&file, "[server]\nlisten = \"127.0.0.1:9999\"\n").unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_rackd"))
        .args(["check-config", file.to_str().unwrap(), "--explain"])
        .env("RACKD_INTAKE__QUEUE", "77")
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let line = |start: &str| {
        text.lines().find(|l| l.starts_with(start)).unwrap_or_else(|| panic!("{start}: {text}"))
    };
    assert!(line("listen = \"127.0.0.1:9999\"").ends_with(&format!("# {}:2:1", file.display())), "{text}");
    assert!(line("queue = 77").ends_with("# env RACKD_INTAKE__QUEUE"), "{text}");
    assert!(line("busy_timeout_ms = 5000").ends_with("# default"), "{text}");
    assert!(text.contains("[events]") && text.contains("retention_hours = 168"), "{text}");
}

/// `rackd serve` in the background, killed when dropped.
struct Server(std::process::Child);

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Starts `command`, a `rackd serve` configured to listen on port 0, with its log in
/// `dir`; the server and the port it says it listens on.
fn serve(mut command: Command, dir: &std::path::Path) -> (Server, u16) {
    let log = dir.join("rackd.log");
    command.env("RACKD_LOG", "info").stderr(std::fs::File::create(&log).unwrap());
    let mut server = Server(command.spawn().unwrap());
    let port = crate::support::listening::rackd_blocking(&log, &mut server.0).port();
    (server, port)
}

/// The status of `GET path` at `port`, with `headers`; waits up to 20 s for the server.
fn status(port: u16, path: &str, headers: &str) -> u16 {
    use std::io::{Read, Write};
    eventually_blocking(format!("an answer on port {port}"), std::time::Duration::from_secs(20), || {
        let mut s = std::net::TcpStream::connect(("127.0.0.1", port)).ok()?;
        write!(s, "GET {path} HTTP/1.0\r\nhost: x\r\n{headers}\r\n").unwrap();
        let mut reply = String::new();
        let _ = s.read_to_string(&mut reply);
        reply.split(' ').nth(1).and_then(|c| c.parse().ok())
    })
}

#[test]
fn the_environment_decides_where_serve_listens_over_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("site.toml");
    // The file names a port the test holds without listening: a server that took the
    // file's address would fail to bind it; the environment's port 0 is the server's choice.
    let held = crate::support::held::HeldPort::new();
    let in_file = held.addr();
    let db = dir.path().join("rackd.db");
    std::fs::write(&file, format!("[server]\nlisten = \"{in_file}\"\n[database]\npath = {db:?}\n")).unwrap();
    let mut command = Command::new(env!("CARGO_BIN_EXE_rackd"));
    command.args(["serve", "--config", file.to_str().unwrap()]).env("RACKD_SERVER__LISTEN", "127.0.0.1:0");
    let (_server, in_env) = serve(command, dir.path());
    assert_ne!(in_env, in_file.port());
    assert_eq!(status(in_env, "/healthz", ""), 200);
    assert!(std::net::TcpStream::connect(in_file).is_err(), "the file's port is not used");
}

#[test]
fn the_old_listen_variable_is_refused_not_silently_applied() {
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_rackd"))
        .args(["serve", "--database", dir.path().join("x.db").to_str().unwrap()])
        .env("RACKD_LISTEN", "127.0.0.1:0")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("RACKD_SERVER__LISTEN"), "{err}");
}

#[test]
fn a_keyed_server_takes_its_keys_from_auth_keys_file() {
    let dir = tempfile::tempdir().unwrap();
    let keys = dir.path().join("rackd_keys");
    let hash = "sha256:2bb80d537b1da3e38bd30361aa855686bde0eacd7162fef6a25fe97bf527a25b"; // "secret"
    std::fs::write(&keys, format!("[[keys]]\nname = \"wms\"\nrole = \"operator\"\nhash = \"{hash}\"\n"))
        .unwrap();
    let file = dir.path().join("site.toml");
    let db = dir.path().join("rackd.db");
    std::fs::write(&file, format!("[server]\nlisten = \"127.0.0.1:0\"\n[database]\npath = {db:?}\n"))
        .unwrap();
    let mut command = Command::new(env!("CARGO_BIN_EXE_rackd"));
    command.args(["serve", "--config", file.to_str().unwrap()]).env("RACKD_AUTH__KEYS_FILE", &keys);
    let (_server, port) = serve(command, dir.path());
    assert_eq!(status(port, "/api/v1/jobs", ""), 401);
    assert_eq!(status(port, "/api/v1/jobs", "authorization: Bearer wrong\r\n"), 401);
    assert_eq!(status(port, "/api/v1/jobs", "authorization: Bearer secret\r\n"), 200);
}

#[test]
fn plc_refuses_a_quirk_flag_of_another_protocol_before_connecting() {
    let (ok, _, err) =
        rackd(&["plc", "--protocol", "ppi-tcp", "--address", "127.0.0.1:9", "--no-bcc", "read", "VW0"]);
    assert!(!ok && err.contains("no-bcc") && err.contains("ppi-tcp"), "{err}");
    let (ok, _, err) = rackd(&["plc", "--protocol", "mc9", "--address", "127.0.0.1:9", "read", "D0"]);
    assert!(!ok && err.contains("mc9"), "{err}");
}

/// `rackd ARGS` with `input` on its standard input.
fn rackd_in(args: &[&str], input: &str) -> (bool, String, String) {
    use std::io::Write;
    let mut child = Command::new(env!("CARGO_BIN_EXE_rackd"))
        .args(args)
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    child.stdin.take().unwrap().write_all(input.as_bytes()).unwrap();
    let out = child.wait_with_output().unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into(),
        String::from_utf8_lossy(&out.stderr).into(),
    )
}

#[test]
fn hash_key_reads_the_key_from_standard_input_or_makes_one() {
    let (ok, out, err) = rackd_in(&["hash-key"], "a-key-of-24-characters!!\n");
    assert!(ok, "{err}");
    assert_eq!(out.trim(), rackd::auth::KeyHash::of("a-key-of-24-characters!!").to_string());
    let (ok, out, _) = rackd(&["hash-key", "--generate"]);
    assert!(ok && out.contains("key:  rk_") && out.contains("hash: sha256:"), "{out}");
    // What --generate prints goes into the file as it is, and the key hashes to it.
    let key = out.lines().find_map(|l| l.strip_prefix("key:  ")).unwrap();
    let hash = out.lines().find_map(|l| l.strip_prefix("hash: ")).unwrap();
    assert_eq!(rackd_in(&["hash-key"], key).1.trim(), hash);
}

#[test]
fn hash_key_refuses_a_key_on_the_command_line_and_a_short_key() {
    // An argument is in `ps` and the shell's history for everyone to read.
    let (ok, out, err) = rackd(&["hash-key", "a-key-of-24-characters!!"]);
    assert!(!ok && out.is_empty(), "{out}");
    assert!(err.contains("standard input") && err.contains("| rackd hash-key"), "{err}");
    let (ok, out, err) = rackd_in(&["hash-key"], "x\n");
    assert!(!ok && out.is_empty() && err.contains("at least 16 characters"), "{out}{err}");
    let (ok, _, err) = rackd_in(&["hash-key"], "");
    assert!(!ok && err.contains("no key"), "{err}");
}

#[test]
fn serve_refuses_a_public_address_without_keys() {
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("x.db");
    let (ok, _, err) = rackd(&["serve", "--listen", "0.0.0.0:0", "--database", db.to_str().unwrap()]);
    assert!(!ok && err.contains("--insecure"), "{err}");
}

#[test]
fn a_reader_that_goes_away_ends_the_output_quietly() {
    use std::io::Read;
    let mut child = Command::new(env!("CARGO_BIN_EXE_rackd"))
        .arg("openapi")
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut first = [0u8; 16];
    child.stdout.as_mut().unwrap().read_exact(&mut first).unwrap();
    drop(child.stdout.take()); // as `| head -c 16` does
    let status = child.wait().unwrap();
    let mut err = String::new();
    child.stderr.take().unwrap().read_to_string(&mut err).unwrap();
    assert!(status.success(), "{status}: {err}");
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn a_port_in_use_is_reported_before_anything_starts() {
    let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = taken.local_addr().unwrap().to_string();
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("rackd.db");
    let out = Command::new(env!("CARGO_BIN_EXE_rackd"))
        .args(["serve", "--listen", &addr, "--database", db.to_str().unwrap()])
        .env("RUST_LOG", "info")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(err.contains(&format!("binding {addr}")), "{err}");
    assert!(!db.exists(), "nothing was started, not even the database: {err}");
}

#[test]
fn a_database_directory_rackd_cannot_write_is_named_with_the_fix() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    std::fs::create_dir(&data).unwrap();
    // Readable and enterable by everyone, writable by its owner only.
    std::fs::set_permissions(dir.path(), std::fs::Permissions::from_mode(0o755)).unwrap();
    std::fs::set_permissions(&data, std::fs::Permissions::from_mode(0o555)).unwrap();
    let root = std::fs::metadata("/proc/self").map(|m| std::os::unix::fs::MetadataExt::uid(&m) == 0).unwrap();
    // Root writes anywhere: the check runs as `nobody` then, on a copy of the binary it
    // can reach wherever the checkout is.
    let bin = dir.path().join("rackd");
    std::fs::copy(env!("CARGO_BIN_EXE_rackd"), &bin).unwrap();
    // The database in the folder itself, and in a subfolder rackd would have to create there.
    for db in [data.join("rackd.db"), data.join("site").join("rackd.db")] {
        let args = ["serve", "--listen", "127.0.0.1:0", "--database", db.to_str().unwrap()];
        let out = if root {
            Command::new("runuser").args(["-u", "nobody", "--", bin.to_str().unwrap()]).args(args).output()
        } else {
            Command::new(&bin).args(args).output()
        }
        .expect("runuser (util-linux) runs the check as an unprivileged user when the tests run as root");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{err}");
        assert!(err.contains(&format!("cannot write in {}:", data.display())), "{err}");
        assert!(err.contains("rackd runs as uid") && err.contains("chown"), "{err}");
        let owner = std::os::unix::fs::MetadataExt::uid(&std::fs::metadata(&data).unwrap());
        assert!(err.contains(&format!("it belongs to uid {owner}")), "{err}");
        assert!(err.contains("named volume") && err.contains("uid 10001"), "the container's fix: {err}");
    }
}

#[test]
fn logs_to_a_pipe_carry_no_colour_and_the_format_comes_from_the_environment() {
    // A PLC that accepts the connection and never answers: `plc read` logs its attempts.
    let silent = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = silent.local_addr().unwrap().to_string();
    let read =
        ["plc", "--protocol", "modbus-tcp", "--address", &addr, "--timeout-ms", "50", "--retries", "0"];
    let out = Command::new(env!("CARGO_BIN_EXE_rackd"))
        .args(read)
        .args(["read", "4x0", "1"])
        .env("RACKD_LOG", "debug")
        .env("RACKD_LOG_FORMAT", "json")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    let json_lines: Vec<&str> = err.lines().filter(|l| l.starts_with('{')).collect();
    assert!(!json_lines.is_empty(), "RACKD_LOG_FORMAT=json gives JSON lines: {err}");
    for line in json_lines {
        serde_json::from_str::<serde_json::Value>(line).unwrap_or_else(|e| panic!("{e}: {line}"));
    }
    let out = Command::new(env!("CARGO_BIN_EXE_rackd"))
        .args(read)
        .args(["read", "4x0", "1"])
        .env("RACKD_LOG", "debug")
        .env_remove("NO_COLOR")
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stderr);
    assert!(text.contains("DEBUG") || text.contains("WARN"), "text logs: {text}");
    assert!(!text.contains('\u{1b}'), "no ANSI escapes into a pipe: {text:?}");
}

#[test]
fn db_rollups_rebuilds_only_when_told_to() {
    let dir = tempfile::tempdir().unwrap();
    let db = format!("sqlite:{}", dir.path().join("rackd.db").display());
    let (ok, _, err) = rackd(&["db", "rollups", "--database", &db]);
    assert!(!ok && err.contains("--rebuild"), "{err}");
    let (ok, out, err) = rackd(&["db", "rollups", "--rebuild", "--database", &db]);
    assert!(ok, "{err}");
    assert!(
        out.contains("rebuilt the rollups of") && out.contains("from 0 history entries: 0 rows"),
        "{out}"
    );
}

#[test]
fn the_db_commands_take_a_plain_path_as_serve_does() {
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("rackd.db");
    let path = db.to_str().unwrap();
    let (ok, out, err) = rackd(&["db", "rollups", "--rebuild", "--database", path]);
    assert!(ok, "a plain path: {err}");
    assert!(out.contains(&format!("rebuilt the rollups of {path}")), "{out}");
    let archive = dir.path().join("archive");
    let args =
        ["db", "archive", "--before", "2026-01-01", "--to", archive.to_str().unwrap(), "--database", path];
    let (ok, out, err) = rackd(&args);
    assert!(ok && out.contains("archived 0 jobs"), "{out}{err}");
    let copy = dir.path().join("copy.db");
    let (ok, out, err) = rackd(&["db", "copy", "--from", path, "--to", copy.to_str().unwrap()]);
    assert!(ok && out.contains(&format!("copied {path} to {}", copy.display())), "{out}{err}");
    // The forms of before still work; a URL of another database is still refused.
    let (ok, _, err) = rackd(&["db", "rollups", "--rebuild", "--database", &format!("sqlite:{path}")]);
    assert!(ok, "{err}");
    let (ok, _, err) = rackd(&["db", "rollups", "--rebuild", "--database", "mysql://db.plant/rackd"]);
    assert!(!ok && err.contains("postgres://"), "{err}");
}

#[test]
fn check_config_warns_of_a_webhook_in_clear_to_another_machine() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("site.toml");
    let entry = |url: &str| {
        BAD_WEBHOOK.replace("job.created", "job.*").replace("https://wms.plant.local/events", url)
    };
    std::fs::write(&file, entry("http://wms.plant.local/events")).unwrap();
    let (ok, out, err) = rackd(&["check-config", file.to_str().unwrap()]);
    assert!(ok && out.contains("ok"), "a warning, not an error: {err}");
    assert!(err.contains("site.toml:3:1: webhooks[0].url: warning: ") && err.contains("https://"), "{err}");
    for quiet in [
        "https://wms.plant.local/events",
        "http://127.0.0.1:9000/events",
        "http://localhost/x",
        "http://[::1]:80/",
    ] {
        std::fs::write(&file, entry(quiet)).unwrap();
        let (ok, _, err) = rackd(&["check-config", file.to_str().unwrap()]);
        assert!(ok && !err.contains("warning"), "{quiet}: {err}");
    }
}
