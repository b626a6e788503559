//! `cargo xtask`: rackd's project commands, in plain Rust (the xtask convention), run
//! through the alias in `.cargo/config.toml`.
//!
//! - `cargo xtask test [ARGS]`: installs what the tests drive and is missing, then runs
//!   `cargo test --locked --no-fail-fast ARGS` (e.g. `cargo xtask test --test it crane::`).
//!   This is the README's test command, and `.ci/run`'s.
//! - `cargo xtask setup`: the installs alone.
//! - `cargo xtask eslint`: the dashboard's JavaScript through eslint, at the version
//!   `package-lock.json` pins.
//!
//! What the tests drive, and where it comes from:
//! - Chromium and chromedriver (the dashboard's tests, `tests/it/browser`): Debian's
//!   `chromium`, `chromium-driver` and `fonts-dejavu-core`, unless `$CHROMIUM` and
//!   `$CHROMEDRIVER` name others.
//! - PostgreSQL's binaries (the second engine, the hot standby): Debian's `postgresql`,
//!   unless `$RACKD_PG_BIN` names others. The tests start a throwaway cluster of their own.
//! - schemathesis, prometheus_client and standardwebhooks (the OpenAPI contract, the
//!   metrics' parsers, a webhook receiver built on the specification's own library): a
//!   virtualenv of the project's own, `.ci/venv`, from `.ci/requirements.txt` (pinned),
//!   made again when that file changes; Debian's `python3-venv` where Python lacks it.
//! - tshark (the capture tests, `tests/it/capture`, decode rackd's pcapng files with
//!   Wireshark's dissectors and the project's own in `contrib/wireshark`): Debian's
//!   `tshark`, unless `$TSHARK` names another. Its package asks whether non-root users may
//!   capture; the answer is preseeded (no: the tests only read files), so the install never
//!   waits on a question.
//! - Node.js and npm, for `eslint` alone: Debian's `nodejs` and `npm`.
//!
//! Debian packages are installed with `apt-get` as root, or through `sudo` when it needs no
//! password; otherwise the command stops and prints the `apt-get` line to run. Nothing is
//! skipped: a test whose tool is missing fails and says how to install it.

use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode};

const USAGE: &str = "usage: cargo xtask test [CARGO TEST ARGS] | setup | eslint";

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let root = root();
    let outcome = match args.first().map(String::as_str) {
        Some("test") => setup(&root, &TEST_NEEDS).and_then(|()| test(&root, &args[1..])),
        Some("setup") => setup(&root, &TEST_NEEDS),
        Some("eslint") => setup(&root, &[Need::Node]).and_then(|()| eslint(&root)),
        _ => Err(USAGE.to_owned()),
    };
    match outcome {
        Ok(()) => ExitCode::SUCCESS,
        Err(message) => {
            eprintln!("xtask: {message}");
            ExitCode::FAILURE
        }
    }
}

/// The repository's root: the folder above this package.
fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("xtask/ has a parent").to_owned()
}

/// Something the tests or the lints drive, found or installed.
#[derive(Clone, Copy, Debug)]
enum Need {
    Chromium,
    Postgres,
    PythonVenv,
    Tshark,
    Node,
}

const TEST_NEEDS: [Need; 4] = [Need::Chromium, Need::Postgres, Need::PythonVenv, Need::Tshark];

impl Need {
    /// Whether this machine already has it.
    fn present(self) -> bool {
        match self {
            Need::Chromium => {
                (std::env::var_os("CHROMIUM").is_some() || on_path("chromium"))
                    && (std::env::var_os("CHROMEDRIVER").is_some() || on_path("chromedriver"))
            }
            Need::Postgres => std::env::var_os("RACKD_PG_BIN").is_some() || postgres_installed(),
            Need::PythonVenv => succeeds(Command::new("python3").args(["-c", "import ensurepip, venv"])),
            Need::Tshark => std::env::var_os("TSHARK").is_some() || on_path("tshark"),
            Need::Node => on_path("npm"),
        }
    }

    /// The Debian packages that provide it.
    fn packages(self) -> &'static [&'static str] {
        match self {
            Need::Chromium => &["chromium", "chromium-driver", "fonts-dejavu-core"],
            Need::Postgres => &["postgresql"],
            Need::PythonVenv => &["python3-venv"],
            Need::Tshark => &["tshark"],
            Need::Node => &["nodejs", "npm"],
        }
    }
}

/// PostgreSQL's binaries where the tests look (`/usr/lib/postgresql/*/bin`) and, as root,
/// the `postgres` user they run the server as.
fn postgres_installed() -> bool {
    let binaries = std::fs::read_dir("/usr/lib/postgresql")
        .map(|versions| versions.flatten().any(|v| v.path().join("bin/initdb").exists()))
        .unwrap_or(false);
    binaries && (!is_root() || succeeds(Command::new("id").arg("postgres")))
}

/// Installs what `needs` lack, then the virtualenv when the tests are among them.
fn setup(root: &Path, needs: &[Need]) -> Result<(), String> {
    let packages: Vec<&str> =
        needs.iter().filter(|n| !n.present()).flat_map(|n| n.packages().iter().copied()).collect();
    if !packages.is_empty() {
        apt_install(&packages)?;
    }
    if needs.iter().any(|n| matches!(n, Need::PythonVenv)) {
        python_tools(root)?;
    }
    Ok(())
}

/// `apt-get install` of `packages`, as root or through a sudo that asks no password.
fn apt_install(packages: &[&str]) -> Result<(), String> {
    let line = format!("apt-get update && apt-get install -y {}", packages.join(" "));
    let sudo = if is_root() {
        None
    } else if succeeds(Command::new("sudo").args(["-n", "true"])) {
        Some("sudo")
    } else {
        return Err(format!("the tests need Debian packages this user cannot install; as root: {line}"));
    };
    eprintln!("xtask: installing {} with apt-get", packages.join(" "));
    let apt = |args: &[&str]| {
        let mut command = Command::new(sudo.unwrap_or("apt-get"));
        if sudo.is_some() {
            command.arg("apt-get");
        }
        command.args(args).env("DEBIAN_FRONTEND", "noninteractive");
        run(&mut command)
    };
    if packages.contains(&"tshark") {
        preseed(sudo, WIRESHARK_NO_SETUID)?;
    }
    apt(&["update", "-q"])?;
    let mut install = vec!["install", "-y", "-q"];
    install.extend_from_slice(packages);
    apt(&install).map_err(|e| format!("{e}; the command was: {line}"))
}

/// The answer to `wireshark-common`'s question (may non-root users capture?): no, so the
/// install asks nothing; the tests only read capture files.
const WIRESHARK_NO_SETUID: &str = "wireshark-common wireshark-common/install-setuid boolean false\n";

/// Gives debconf an answer before the package that asks it is installed.
fn preseed(sudo: Option<&str>, answer: &str) -> Result<(), String> {
    use std::io::Write;
    let mut command = match sudo {
        Some(sudo) => {
            let mut c = Command::new(sudo);
            c.arg("debconf-set-selections");
            c
        }
        None => Command::new("debconf-set-selections"),
    };
    let mut child = command
        .stdin(std::process::Stdio::piped())
        .spawn()
        .map_err(|e| format!("debconf-set-selections could not start: {e}"))?;
    let written = child.stdin.take().expect("piped stdin").write_all(answer.as_bytes());
    let status = child.wait().map_err(|e| format!("debconf-set-selections: {e}"))?;
    written.map_err(|e| format!("debconf-set-selections: {e}"))?;
    if status.success() { Ok(()) } else { Err(format!("debconf-set-selections failed ({status})")) }
}

/// `.ci/venv` with exactly `.ci/requirements.txt`, made again when that file changes (a
/// copy beside the virtualenv tells what it was made from).
fn python_tools(root: &Path) -> Result<(), String> {
    let venv = root.join(".ci/venv");
    let wanted =
        std::fs::read(root.join(".ci/requirements.txt")).map_err(|e| format!(".ci/requirements.txt: {e}"))?;
    let made_from = std::fs::read(venv.join("requirements.txt")).ok();
    if venv.join("bin/python").exists() && made_from.as_deref() == Some(wanted.as_slice()) {
        return Ok(());
    }
    eprintln!("xtask: making .ci/venv from .ci/requirements.txt");
    run(Command::new("python3").args(["-m", "venv", "--clear"]).arg(&venv))?;
    run(Command::new(venv.join("bin/pip"))
        .args(["install", "-q", "--disable-pip-version-check", "-r"])
        .arg(root.join(".ci/requirements.txt")))?;
    std::fs::write(venv.join("requirements.txt"), wanted).map_err(|e| format!(".ci/venv: {e}"))
}

/// The whole suite: unit tests, the integration binary, the benchmarks' own tests.
fn test(root: &Path, args: &[String]) -> Result<(), String> {
    run(Command::new(cargo()).current_dir(root).args(["test", "--locked", "--no-fail-fast"]).args(args))
}

/// The dashboard's JavaScript through the eslint `package-lock.json` pins.
fn eslint(root: &Path) -> Result<(), String> {
    run(Command::new("npm").current_dir(root).args(["ci", "--no-audit", "--no-fund", "--loglevel=error"]))?;
    run(Command::new("npx").current_dir(root).args(["--no-install", "eslint", "src/api/dashboard"]))
}

/// The cargo that runs this command (`$CARGO`), so that the toolchain stays the same.
fn cargo() -> PathBuf {
    std::env::var_os("CARGO").map(PathBuf::from).unwrap_or_else(|| "cargo".into())
}

fn run(command: &mut Command) -> Result<(), String> {
    let shown = format!("{command:?}");
    match command.status() {
        Ok(status) if status.success() => Ok(()),
        Ok(status) => Err(format!("{shown} failed ({status})")),
        Err(e) => Err(format!("{shown} could not start: {e}")),
    }
}

fn succeeds(command: &mut Command) -> bool {
    command
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

fn is_root() -> bool {
    Command::new("id").arg("-u").output().is_ok_and(|o| o.stdout.trim_ascii() == b"0")
}

fn on_path(program: &str) -> bool {
    std::env::var_os("PATH")
        .is_some_and(|paths| std::env::split_paths(&paths).any(|dir| dir.join(program).is_file()))
}
