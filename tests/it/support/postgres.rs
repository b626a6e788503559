//! A throwaway PostgreSQL cluster for the tests, started by the test process itself: one
//! cluster per run of the test binary (started on first use), one fresh database per test.
//!
//! The cluster comes from Debian's `postgresql` package (`/usr/lib/postgresql/*/bin`, the
//! newest version there, or `$RACKD_PG_BIN`). PostgreSQL refuses to run as root, so as root
//! the server runs as the package's `postgres` user (through `setpriv`). It is started by a
//! thread that lives as long as the test process with a parent-death signal, so it dies with
//! the tests however they end; its data folder (in the temp folder, `rackd-pg-PID`) is
//! removed by the next run. Durability settings are off (`fsync=off`) for the tests, which
//! check behaviour; the benchmarks set [`DURABLE`] and measure with PostgreSQL's defaults.
//! Its port is below the kernel's range of ephemeral ports, where no other socket of the
//! tests can take it first (PostgreSQL cannot be given port 0; see [`launch`]).
//!
//! A missing PostgreSQL fails the test with the command that installs it; nothing is
//! skipped.
//!
//! A second cluster, [`tls_database`], only speaks TLS (`ssl=on`, a server certificate
//! signed by a CA of the tests' own, `pg_hba.conf` with `hostssl` lines alone, so a
//! plaintext connection is refused); it is started on first use too, by the tests that
//! need it (the security area), so no other test waits for it. Its databases are made
//! over its Unix socket, so making one needs no TLS.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::OnceLock;
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

use sqlx::Connection;

/// How to install what these tests need.
pub(super) const INSTALL: &str =
    "apt-get update && apt-get install -y postgresql (or run `cargo xtask test`, which installs it)";

/// The running cluster: the URL of its maintenance database, without the database name.
struct Cluster {
    base: String,
}

static CLUSTER: OnceLock<Result<Cluster, String>> = OnceLock::new();

/// The TLS-only cluster.
pub struct TlsCluster {
    /// Its port on 127.0.0.1.
    pub port: u16,
    /// The CA that signed its certificate, PEM.
    pub ca: PathBuf,
    /// Another CA, which did not.
    pub wrong_ca: PathBuf,
    /// Its Unix socket's folder.
    socket_dir: PathBuf,
}

static TLS_CLUSTER: OnceLock<Result<TlsCluster, String>> = OnceLock::new();

/// Set before first use to keep PostgreSQL's durable defaults (the benchmarks do).
pub static DURABLE: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);
static NEXT: AtomicU32 = AtomicU32::new(1);

/// The URL of a fresh, empty database on the test cluster (started on first use).
pub async fn database() -> String {
    let cluster = match CLUSTER.get_or_init(start) {
        Ok(c) => c,
        Err(e) => panic!("the PostgreSQL tests cannot start a server: {e}"),
    };
    let name = format!("t{}_{}", std::process::id(), NEXT.fetch_add(1, Ordering::Relaxed));
    let mut admin =
        sqlx::PgConnection::connect(&format!("{}/postgres", cluster.base)).await.expect("admin connection");
    sqlx::raw_sql(sqlx::AssertSqlSafe(format!("CREATE DATABASE {name}")))
        .execute(&mut admin)
        .await
        .expect("create database");
    format!("{}/{name}", cluster.base)
}

/// A fresh, empty database on the TLS-only cluster (started on first use), as a URL
/// without `sslmode` (`postgres://postgres@127.0.0.1:PORT/NAME`), and the cluster.
pub async fn tls_database() -> (String, &'static TlsCluster) {
    let cluster = match TLS_CLUSTER.get_or_init(start_tls) {
        Ok(c) => c,
        Err(e) => panic!("the PostgreSQL TLS tests cannot start a server: {e}"),
    };
    let name = format!("tls{}_{}", std::process::id(), NEXT.fetch_add(1, Ordering::Relaxed));
    let admin = format!(
        "postgres:///postgres?user=postgres&host={}&port={}",
        cluster.socket_dir.display(),
        cluster.port
    );
    let mut admin = sqlx::PgConnection::connect(&admin).await.expect("admin connection over the socket");
    sqlx::raw_sql(sqlx::AssertSqlSafe(format!("CREATE DATABASE {name}")))
        .execute(&mut admin)
        .await
        .expect("create database");
    (format!("postgres://postgres@127.0.0.1:{}/{name}", cluster.port), cluster)
}

/// The newest PostgreSQL's binaries.
pub(super) fn binaries() -> Result<PathBuf, String> {
    if let Ok(dir) = std::env::var("RACKD_PG_BIN") {
        return Ok(PathBuf::from(dir));
    }
    let mut found: Vec<(u32, PathBuf)> = std::fs::read_dir("/usr/lib/postgresql")
        .map_err(|_| format!("PostgreSQL is not installed (no /usr/lib/postgresql): {INSTALL}"))?
        .filter_map(|e| {
            let e = e.ok()?;
            let version = e.file_name().to_str()?.parse().ok()?;
            let bin = e.path().join("bin");
            bin.join("initdb").exists().then_some((version, bin))
        })
        .collect();
    found.sort();
    found
        .pop()
        .map(|(_, bin)| bin)
        .ok_or_else(|| format!("no initdb under /usr/lib/postgresql/*/bin: {INSTALL}"))
}

/// Runs `program` as the user PostgreSQL may run as (`postgres` when we are root).
pub(super) fn command(program: &Path, as_root: bool) -> Command {
    if as_root {
        let mut c = Command::new("setpriv");
        c.args(["--reuid=postgres", "--regid=postgres", "--init-groups", "--pdeathsig=KILL", "--"])
            .arg(program);
        c
    } else {
        Command::new(program)
    }
}

fn start() -> Result<Cluster, String> {
    let (_, port) = launch("rackd-pg", None)?;
    Ok(Cluster { base: format!("postgres://postgres@127.0.0.1:{port}") })
}

/// Starts the TLS-only cluster: a CA and a server certificate (for 127.0.0.1 and
/// `localhost`), `ssl=on`, and `hostssl` lines alone in `pg_hba.conf`.
fn start_tls() -> Result<TlsCluster, String> {
    let ca = super::tls::Ca::new("rackd test database CA");
    let cert = ca.server();
    let tls = Tls { cert };
    let (dir, port) = launch("rackd-pgtls", Some(&tls))?;
    let keep = dir.join("client");
    std::fs::create_dir_all(&keep).map_err(|e| e.to_string())?;
    let ca_file = ca.write(&keep, "ca.pem");
    let wrong = super::tls::Ca::new("another CA").write(&keep, "wrong-ca.pem");
    Ok(TlsCluster { port, ca: ca_file, wrong_ca: wrong, socket_dir: dir })
}

/// What a TLS-only cluster is given.
pub(super) struct Tls {
    cert: super::tls::ServerCert,
}

/// Makes and starts a cluster in the temp folder's `PREFIX-PID`; answers its folder (the
/// Unix socket's too) and its port.
fn launch(prefix: &str, tls: Option<&Tls>) -> Result<(PathBuf, u16), String> {
    let (bin, as_root) = (binaries()?, as_root()?);
    remove_stale(prefix);
    let dir = folder(&std::env::temp_dir().join(format!("{prefix}-{}", std::process::id())), as_root)?;
    let data = dir.join("data");
    initdb(&bin, as_root, &data)?;
    if let Some(tls) = tls {
        // The server's certificate and key, readable by the server alone, and only TLS
        // connections over TCP (the Unix socket stays open for making databases).
        let (cert, key) = (data.join("server.crt"), data.join("server.key"));
        std::fs::write(&cert, &tls.cert.cert_pem).map_err(|e| e.to_string())?;
        std::fs::write(&key, &tls.cert.key_pem).map_err(|e| e.to_string())?;
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&key, std::fs::Permissions::from_mode(0o600)).map_err(|e| e.to_string())?;
        let hba = "local all all trust\nhostssl all all 127.0.0.1/32 trust\n";
        std::fs::write(data.join("pg_hba.conf"), hba).map_err(|e| e.to_string())?;
        if as_root {
            let status = Command::new("chown").args(["postgres:postgres"]).arg(&cert).arg(&key).status();
            if !status.is_ok_and(|s| s.success()) {
                return Err("cannot give the server's key to the postgres user".into());
            }
        }
    }
    // PostgreSQL cannot be given port 0 (its `port` runs from 1) to say which port it got,
    // so the port is picked here, below the kernel's range of ephemeral ports: every other
    // socket of the tests takes its port from that range (a bind of port 0, an outgoing
    // connection), so none of them can take the port between the pick and the server's
    // bind. Something else on the machine can (another run of the tests): the server then
    // exits saying so, and another port is tried.
    let mut tried = Vec::new();
    while tried.len() < PORT_TRIES {
        let port = outside_ephemeral_range()?;
        tried.push(port);
        match serve(&bin, as_root, &dir, &data, tls, port, &[])? {
            Served::Ready(_) => return Ok((dir, port)),
            Served::PortTaken => continue,
        }
    }
    Err(format!("every port tried was taken before the server bound it: {tried:?}"))
}

/// Whether the tests run as root (the server then runs as `postgres`, which must exist).
pub(super) fn as_root() -> Result<bool, String> {
    let as_root = rustix::process::geteuid().is_root();
    if as_root
        && !Command::new("id").arg("postgres").stdout(Stdio::null()).status().is_ok_and(|s| s.success())
    {
        return Err(format!(
            "running as root needs the `postgres` user, which the package creates: {INSTALL}"
        ));
    }
    Ok(as_root)
}

/// A new, empty folder `dir`, the server's user's.
pub(super) fn folder(dir: &Path, as_root: bool) -> Result<PathBuf, String> {
    let _ = std::fs::remove_dir_all(dir);
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    if as_root {
        let status = Command::new("chown").args(["postgres:postgres"]).arg(dir).status();
        if !status.is_ok_and(|s| s.success()) {
            return Err(format!("cannot give {} to the postgres user", dir.display()));
        }
    }
    Ok(dir.to_owned())
}

/// A new cluster's data folder at `data` (its parent the server's user's).
pub(super) fn initdb(bin: &Path, as_root: bool, data: &Path) -> Result<(), String> {
    let out = command(&bin.join("initdb"), as_root)
        .args(["-A", "trust", "-U", "postgres", "-N", "-E", "UTF8", "--locale=C", "-D"])
        .arg(data)
        .output()
        .map_err(|e| format!("initdb: {e}"))?;
    if !out.status.success() {
        return Err(format!("initdb failed: {}", String::from_utf8_lossy(&out.stderr)));
    }
    Ok(())
}

/// Ports tried for a cluster before giving up.
const PORT_TRIES: usize = 5;

/// How a start of the server went.
pub(super) enum Served {
    /// It answers.
    Ready(Running),
    /// It exited: something else had bound its port.
    PortTaken,
}

/// A port below the kernel's range of ephemeral ports (`ip_local_port_range`) that nothing
/// has bound now.
pub(super) fn outside_ephemeral_range() -> Result<u16, String> {
    let range = std::fs::read_to_string("/proc/sys/net/ipv4/ip_local_port_range").unwrap_or_default();
    let first: u16 = range.split_whitespace().next().and_then(|p| p.parse().ok()).unwrap_or(32768);
    let low = 10000.min(first / 2);
    for _ in 0..100 {
        let port = rand::random_range(low..first);
        if std::net::TcpListener::bind(("127.0.0.1", port)).is_ok() {
            return Ok(port);
        }
    }
    Err(format!("no free port found in {low}..{first}"))
}

/// A server started by [`serve`]: its postmaster's pid, and word of its exit.
pub(super) struct Running {
    /// The postmaster (`setpriv` runs it in its own process).
    pub(super) pid: u32,
    /// Sent once when the server has exited.
    pub(super) exited: std::sync::mpsc::Receiver<Result<std::process::ExitStatus, String>>,
}

/// Starts the server of `data` on `port` with the settings `extra` (`name=value`, after the
/// tests' own, so they win) and waits until it answers, or until it exits because the port
/// was taken.
pub(super) fn serve(
    bin: &Path,
    as_root: bool,
    dir: &Path,
    data: &Path,
    tls: Option<&Tls>,
    port: u16,
    extra: &[&str],
) -> Result<Served, String> {
    let log_path = dir.join("server.log");
    let log = std::fs::File::create(&log_path).map_err(|e| e.to_string())?;
    let mut server = command(&bin.join("postgres"), as_root);
    server.arg("-D").arg(data).args(["-p", &port.to_string(), "-k"]).arg(dir).args([
        "-c",
        "listen_addresses=127.0.0.1",
        "-c",
        "max_connections=400",
    ]);
    if tls.is_some() {
        server.args(["-c", "ssl=on", "-c", "ssl_cert_file=server.crt", "-c", "ssl_key_file=server.key"]);
    }
    if !DURABLE.load(Ordering::Relaxed) {
        server.args(["-c", "fsync=off", "-c", "synchronous_commit=off", "-c", "full_page_writes=off"]);
    }
    for setting in extra {
        server.args(["-c", setting]);
    }
    server.stdout(Stdio::null()).stderr(log);
    // The thread that starts the server waits for it: it ends only if the server does, so
    // the parent-death signal fires only when the whole test process ends.
    let (started, spawned) = std::sync::mpsc::channel();
    let (ended, exited) = std::sync::mpsc::channel();
    std::thread::spawn(move || match server.spawn() {
        Ok(mut child) => {
            let _ = started.send(Ok(child.id()));
            let _ = ended.send(child.wait().map_err(|e| e.to_string()));
        }
        Err(e) => {
            let _ = started.send(Err(e.to_string()));
        }
    });
    let pid = spawned.recv().map_err(|e| e.to_string())?.map_err(|e| format!("postgres: {e}"))?;
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        // Asked over its Unix socket in `dir`, which the server makes only once it has
        // bound its TCP port: the server that answers is this one, not another on the port.
        let ok = std::net::TcpStream::connect(("127.0.0.1", port)).is_ok()
            && Command::new(bin.join("pg_isready"))
                .arg("-h")
                .arg(dir)
                .args(["-p", &port.to_string()])
                .output()
                .is_ok_and(|o| o.status.success());
        if ok {
            return Ok(Served::Ready(Running { pid, exited }));
        }
        if let Ok(status) = exited.try_recv() {
            let log = std::fs::read_to_string(&log_path).unwrap_or_default();
            if log.contains("could not bind") || log.contains("Address already in use") {
                return Ok(Served::PortTaken);
            }
            return Err(format!("the server exited ({status:?}):\n{log}"));
        }
        if Instant::now() > deadline {
            let log = std::fs::read_to_string(&log_path).unwrap_or_default();
            return Err(format!("the server did not start in 60 s:\n{log}"));
        }
        // Often: the tests that restart a server of their own time it from here.
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Removes the data folders (`PREFIX-PID`) of earlier runs whose process is gone.
pub(super) fn remove_stale(prefix: &str) {
    let Ok(entries) = std::fs::read_dir(std::env::temp_dir()) else { return };
    for e in entries.flatten() {
        let name = e.file_name();
        let Some(pid) = name.to_str().and_then(|n| n.strip_prefix(prefix)?.strip_prefix('-')) else {
            continue;
        };
        if !Path::new("/proc").join(pid).exists() {
            let _ = std::fs::remove_dir_all(e.path());
        }
    }
}
