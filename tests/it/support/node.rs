//! A `rackd serve` child process for tests that kill it (SIGKILL, no goodbye) and start it
//! again: the failover of `standby::failover`, the webhooks' deliveries of
//! `webhooks::kills`, the shelf's jobs of `shelf::kills`.
//!
//! A node listens on port 0: it binds whatever port is free each time it starts, and
//! [`Node::start`] reads the address from its own "rackd listening" log line, so no port is
//! picked before the child binds it (another process could take it in between), nor kept
//! for its next start (the same). Its [`Node::url`] changes at each start.

use std::fs::OpenOptions;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Child, Command};

use rackd::config::Config;

/// A `rackd serve` child process with its config file and log; killed when dropped (and
/// its log printed if the test fails).
pub struct Node {
    pub name: String,
    /// Where it listens since its last start (empty before the first).
    pub url: String,
    config: PathBuf,
    log: PathBuf,
    child: Option<Child>,
}

impl Node {
    pub fn new(dir: &Path, name: &str, config: &Config) -> Node {
        let name = name.to_owned();
        let path = dir.join(format!("{name}.toml"));
        std::fs::write(&path, toml::to_string(config).unwrap()).unwrap();
        assert_eq!(config.server.listen.port(), 0, "a node listens on port 0 (see the module doc)");
        Node { log: dir.join(format!("{name}.log")), config: path, url: String::new(), name, child: None }
    }

    pub fn start(&mut self) {
        let mut log = OpenOptions::new().create(true).append(true).open(&self.log).unwrap();
        writeln!(log, "===== test: starting node {} =====", self.name).unwrap();
        let mut command = Command::new(env!("CARGO_BIN_EXE_rackd"));
        // The test's own RACKD_ variables (this test's, the harness's) are not the node's.
        for (key, _) in std::env::vars().filter(|(k, _)| k.starts_with("RACKD_")) {
            command.env_remove(key);
        }
        command.args(["serve", "--config"]).arg(&self.config).env("RACKD_LOG", "info");
        command.current_dir(self.config.parent().unwrap()).stdout(log.try_clone().unwrap()).stderr(log);
        let starts = self.log().matches("===== test: starting node").count();
        self.child = Some(command.spawn().unwrap());
        self.url = format!("http://{}", self.listening(starts));
    }

    /// The address the `start`-th start (counted from 1) says it listens on, read from its
    /// log (at most 30 s).
    fn listening(&mut self, start: usize) -> String {
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(30);
        loop {
            let log = self.log();
            let this = log.split("===== test: starting node").nth(start).unwrap_or("");
            if let Some(at) = this.lines().find_map(super::listening::rackd_line) {
                return at.to_string();
            }
            assert!(self.running(), "node {} stopped before listening:\n{this}", self.name);
            assert!(
                std::time::Instant::now() < deadline,
                "node {} not listening after 30 s:\n{this}",
                self.name
            );
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
    }

    /// SIGKILL: the process ends without a word, its lease left to run out.
    pub fn kill(&mut self) {
        if let Some(mut child) = self.child.take() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }

    /// The configuration file it was started with.
    pub fn config_file(&self) -> &Path {
        &self.config
    }

    /// What it logged so far.
    pub fn log(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    /// Sends it SIGHUP (a reload).
    pub fn hang_up(&self) {
        let pid = self.child.as_ref().expect("the node runs").id();
        let sent = Command::new("kill").args(["-HUP", &pid.to_string()]).status().unwrap();
        assert!(sent.success(), "kill -HUP {pid}");
    }

    pub fn running(&mut self) -> bool {
        self.child.as_mut().is_some_and(|c| matches!(c.try_wait(), Ok(None)))
    }
}

impl Drop for Node {
    fn drop(&mut self) {
        self.kill();
        if std::thread::panicking() {
            let log = std::fs::read_to_string(&self.log).unwrap_or_default();
            let tail: Vec<&str> = log.lines().rev().take(80).collect();
            eprintln!("----- node {} (last lines of {}) -----", self.name, self.log.display());
            tail.iter().rev().for_each(|l| eprintln!("{l}"));
        }
    }
}
