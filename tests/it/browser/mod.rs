//! The dashboard in a real browser: headless Chromium driven over WebDriver (chromedriver,
//! started here on a port of its choosing) against the real server on 127.0.0.1:0 with a temporary
//! database and the demo site's simulated shelf PLC, crane and light tower, run fast.
//!
//! Needs `chromium` and `chromedriver` (Debian: `apt-get install chromium chromium-driver`),
//! found on the PATH or at `$CHROMIUM` and `$CHROMEDRIVER`; without them the tests fail,
//! unless `RACKD_SKIP_BROWSER=1` is set, which skips them loudly. Screenshots are kept in
//! `target/artefacts/` (`dashboard.png` from the main test, `first-screen-*.png`,
//! `dashboard-tablet.png`, `dashboard-stale.png`, `dashboard-orders.png`, ...).
//!
//! `control.rs` covers what the page shows of issue 14's API (waiting reasons, KPIs,
//! acknowledging alarms, `whoami`): it passes once that API is served.

use rackd::store::Engine;
mod actions;
mod control;
mod keys;
mod layout;
mod orders;
mod reload;
mod store;
mod webhooks;

use std::path::{Path, PathBuf};
use std::process::{Child, Command};
use std::time::Duration;

use fantoccini::{Client, ClientBuilder, Locator};
use rackd::cli::demo::{self, Pace};
use rackd::config::Config;
use rackd::sim::crane::CraneSim;
use rackd::sim::shelf::ShelfSim;
use rackd::sim::tower::TowerSim;
use serde_json::{Value, json};

use crate::support;
use crate::support::held::HeldPort;
use crate::support::{TestApp, eventually, try_eventually_every};

/// The demo site, fast: a shelf task takes 200 ms, a crane transfer 16 x 40 ms.
const FAST: Pace = Pace { task_time: Duration::from_millis(200), crane_step: Duration::from_millis(40) };

/// One browser test at a time: two Chromiums on two shared cores make both slow and flaky.
static ONE_AT_A_TIME: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());

/// The demo site's simulators, and the config that points at them (for a restart).
pub struct Sims {
    /// The stacker crane (tests raise alarms on it).
    pub crane: CraneSim,
    /// The shelf PLC (tests cut its link with faults).
    pub shelf: ShelfSim,
    _tower: TowerSim,
    config: Config,
}

/// The demo site (shelf `shelf1` on aisle 1, crane `crane1` on aisle 2, light tower
/// `tower1`) at [`FAST`] pace, with the config changed by `edit`; keep the simulators as long
/// as the server.
pub async fn demo_app(edit: impl FnOnce(&mut Config)) -> (TestApp, Sims) {
    demo_app_on(None, edit).await
}

/// As [`demo_app`], serving on `port` when given (a port the test holds, to start the
/// server again there: [`start_again`]).
pub async fn demo_app_on(port: Option<&HeldPort>, edit: impl FnOnce(&mut Config)) -> (TestApp, Sims) {
    let mut demo_config = Config::demo();
    let (shelf, crane, tower) =
        demo::start_with(&mut demo_config, FAST).await.expect("demo simulators start");
    let (db, dir) = support::fresh_database(Engine::Sqlite).await;
    let edit = |c: &mut Config| {
        c.site = demo_config.site.clone();
        c.devices = demo_config.devices.clone();
        edit(c);
        demo_config.auth = c.auth.clone();
    };
    let mut app = match port {
        Some(port) => support::spawn_on_port(db, port, edit).await,
        None => support::spawn_on(db, edit).await,
    };
    app.keep(dir);
    (app, Sims { crane, shelf, _tower: tower, config: demo_config })
}

/// A server stopped with its database kept, to start again where it was.
pub struct Stopped {
    db: rackd::store::Database,
    dir: Option<tempfile::TempDir>,
}

/// Stops `app` gracefully, keeping its database.
pub async fn stop_keeping(app: TestApp) -> Stopped {
    let (db, dir) = app.stop().await;
    Stopped { db, dir }
}

/// Starts a stopped server again on its database and on the port it served on (held by
/// the test meanwhile, so a page that was open reconnects to it), with the same
/// simulators. Keep the directory as long as it runs.
pub async fn start_again(
    stopped: Stopped,
    port: &HeldPort,
    sims: &Sims,
) -> (TestApp, Option<tempfile::TempDir>) {
    let app = support::spawn_on_port(stopped.db, port, |c| {
        c.site = sims.config.site.clone();
        c.devices = sims.config.devices.clone();
        c.auth = sims.config.auth.clone();
    })
    .await;
    (app, stopped.dir)
}

/// Where test artefacts (screenshots) go: `target/artefacts`.
pub fn artefacts() -> PathBuf {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("target").join("artefacts");
    std::fs::create_dir_all(&dir).expect("creating target/artefacts");
    dir
}

/// A program: the path in the environment variable `var` when set, else the first of
/// `names` on the PATH (or at one of the usual places).
fn find_program(var: &str, names: &[&str]) -> Option<PathBuf> {
    if let Some(path) = std::env::var_os(var) {
        return Some(PathBuf::from(path)).filter(|p| p.is_file());
    }
    let path = std::env::var_os("PATH").unwrap_or_default();
    let dirs =
        std::env::split_paths(&path).chain([PathBuf::from("/usr/bin"), PathBuf::from("/usr/lib/chromium")]);
    dirs.flat_map(|d| names.iter().map(move |n| d.join(n))).find(|p| p.is_file())
}

/// A headless Chromium under chromedriver, closed (and its processes killed) on drop.
pub struct Browser {
    /// The WebDriver session.
    pub client: Client,
    _driver: Driver,
    _profile: tempfile::TempDir,
    _turn: tokio::sync::MutexGuard<'static, ()>,
}

impl Browser {
    /// Starts chromedriver and a browser session; `None` when skipped by
    /// `RACKD_SKIP_BROWSER=1` and the browser is missing. Panics, with what to install,
    /// when it is missing otherwise.
    pub async fn start() -> Option<Browser> {
        let driver_path = find_program("CHROMEDRIVER", &["chromedriver"]);
        let chromium = find_program("CHROMIUM", &["chromium", "chromium-browser", "google-chrome"]);
        let (Some(driver_path), Some(chromium)) = (driver_path, chromium) else {
            let what = "the browser tests need Chromium and chromedriver: install them with \
                        `apt-get install chromium chromium-driver` (Debian/Ubuntu), or run `cargo xtask test`, which does";
            if std::env::var("RACKD_SKIP_BROWSER").is_ok_and(|v| v == "1") {
                // Straight to stderr: the test harness does not capture that, so it shows.
                let banner =
                    format!("\n!!!!!!!!!!\n!!! SKIPPED: {what}; RACKD_SKIP_BROWSER=1 is set\n!!!!!!!!!!\n");
                let _ = std::io::Write::write_all(&mut std::io::stderr(), banner.as_bytes());
                return None;
            }
            panic!("{what} (or set RACKD_SKIP_BROWSER=1 to skip them)");
        };
        let turn = ONE_AT_A_TIME.lock().await;
        let (driver, port) = start_driver(&driver_path).await;
        let profile = tempfile::tempdir().unwrap();
        let client = connect(port, &chromium, profile.path()).await;
        client.set_window_size(1680, 1400).await.unwrap();
        Some(Browser { client, _driver: driver, _profile: profile, _turn: turn })
    }

    /// Loads `url` and waits for the page's modules to have started.
    pub async fn open(&self, url: &str) {
        self.client.goto(url).await.unwrap();
        self.wait("the dashboard script to start", "return window.rackd !== undefined", 10).await;
    }

    /// Waits (15 s at most) until the page's connection to the event stream is live.
    pub async fn live(&self) {
        self.wait(
            "the connection to be live",
            "return document.getElementById('conn').dataset.state === 'live'",
            15,
        )
        .await;
    }

    /// Opens the page with `key` in its address (`/?token=KEY`, as a link hands a key over)
    /// and accepts it where the page asks whether to use it.
    pub async fn open_with_key(&self, app: &TestApp, key: &str) {
        self.open(&app.url(&format!("/?token={key}"))).await;
        self.wait(
            "the page to ask about the link's key",
            "return document.getElementById('token-dialog').open
                && document.getElementById('token-who').textContent.startsWith('It is the key')",
            10,
        )
        .await;
        self.click("#token-use").await;
    }

    /// Makes the page's viewport `width` x `height` CSS pixels (the window is grown by what
    /// the browser itself takes).
    pub async fn viewport(&self, width: u32, height: u32) {
        self.client.set_window_size(width, height).await.unwrap();
        let inner = self.js("return [window.innerWidth, window.innerHeight]").await;
        let (w, h) = (inner[0].as_u64().unwrap() as u32, inner[1].as_u64().unwrap() as u32);
        if (w, h) != (width, height) {
            self.client.set_window_size(2 * width - w, 2 * height - h).await.unwrap();
        }
        let script = format!("return window.innerWidth === {width} && window.innerHeight === {height}");
        self.wait(&format!("a {width}x{height} viewport"), &script, 5).await;
    }

    /// Asserts that the element matching `css` lies wholly inside the first screen: the
    /// viewport of the page scrolled to its top, from the element's bounding rectangle.
    pub async fn assert_in_first_screen(&self, css: &str, what: &str) {
        let script = "window.scrollTo(0, 0);
            const n = document.querySelector(arguments[0]);
            if (!n) return null;
            const r = n.getBoundingClientRect();
            return {top: r.top, left: r.left, bottom: r.bottom, right: r.right,
                    width: window.innerWidth, height: window.innerHeight};";
        let r = self.client.execute(script, vec![json!(css)]).await.unwrap();
        assert!(!r.is_null(), "{what}: nothing matches {css}");
        let f = |k: &str| r[k].as_f64().unwrap();
        let inside = f("top") >= 0.0
            && f("left") >= 0.0
            && f("bottom") <= f("height")
            && f("right") <= f("width")
            && f("bottom") > f("top");
        if !inside {
            self.screenshot_viewport("failure.png").await;
        }
        assert!(inside, "{what} ({css}) is not inside the first screen: {r}");
    }

    /// Saves what the viewport shows now (no resizing) as `target/artefacts/<name>`.
    pub async fn screenshot_viewport(&self, name: &str) -> PathBuf {
        let png = self.client.screenshot().await.unwrap();
        let path = artefacts().join(name);
        std::fs::write(&path, png).unwrap();
        path
    }

    /// Runs `script` (a function body) in the page and returns its value.
    pub async fn js(&self, script: &str) -> Value {
        self.client.execute(script, vec![]).await.unwrap_or_else(|e| panic!("script {script:?}: {e}"))
    }

    /// Waits until `script` returns something truthy; on timeout saves a screenshot
    /// (`target/artefacts/failure.png`) and fails with `what`.
    pub async fn wait(&self, what: &str, script: &str, secs: u64) -> Value {
        let every = Duration::from_millis(100);
        let waited = try_eventually_every(every, what, Duration::from_secs(secs), async || {
            let value = self.js(script).await;
            let truthy = !matches!(&value, Value::Null | Value::Bool(false))
                && value != json!(0)
                && value != json!("");
            if truthy { Ok(value) } else { Err(format!("the page still says {value}")) }
        })
        .await;
        match waited {
            Ok(value) => value,
            Err(message) => {
                self.screenshot("failure.png").await;
                panic!("{message} (see target/artefacts/failure.png)");
            }
        }
    }

    /// The text of the first element matching a CSS selector, or null.
    pub async fn text(&self, css: &str) -> Value {
        self.client
            .execute(
                "const n = document.querySelector(arguments[0]); return n && n.textContent;",
                vec![json!(css)],
            )
            .await
            .unwrap()
    }

    /// Clicks the element matching a CSS selector, as a user would: scrolled to the middle
    /// of the window first, where the sticky header cannot cover it.
    pub async fn click(&self, css: &str) {
        let element =
            self.client.wait().at_most(Duration::from_secs(10)).for_element(Locator::Css(css)).await;
        let element = element.unwrap_or_else(|e| panic!("no {css} to click: {e}"));
        let arg = serde_json::to_value(&element).unwrap();
        self.client.execute("arguments[0].scrollIntoView({block: 'center'})", vec![arg]).await.unwrap();
        element.click().await.unwrap();
    }

    /// Saves a screenshot of the whole page (the window grown to fit it, up to 3000 pixels
    /// high) as `target/artefacts/<name>`.
    pub async fn screenshot(&self, name: &str) -> PathBuf {
        let height = self.js("window.scrollTo(0, 0); return document.documentElement.scrollHeight").await;
        let viewport = self.js("return window.innerHeight").await;
        let (Some(height), Some(viewport)) = (height.as_u64(), viewport.as_u64()) else {
            panic!("page size")
        };
        if height > viewport {
            let (width, window) = self.client.get_window_size().await.unwrap();
            let grown = (window + height - viewport).min(3000) as u32;
            self.client.set_window_size(width as u32, grown).await.unwrap();
            tokio::time::sleep(Duration::from_millis(200)).await;
        }
        let png = self.client.screenshot().await.unwrap();
        let path = artefacts().join(name);
        std::fs::write(&path, png).unwrap();
        path
    }

    /// Ends the session (Chromium quits) and stops chromedriver.
    pub async fn close(self) {
        let _ = self.client.clone().close().await;
    }
}

/// The chromedriver process, killed with the Chromium it started when dropped (also after
/// a panic).
struct Driver(Child);

impl Drop for Driver {
    fn drop(&mut self) {
        // The whole process group: chromedriver made it its own, and its browser is in it.
        let _ = Command::new("kill").args(["-KILL", "--", &format!("-{}", self.0.id())]).status();
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Starts chromedriver on a free port it chooses and says (see `support::listening`). Port
/// 0 gives it a free IPv6 port, which it then binds on IPv4 too: when another process holds
/// that number on IPv4 it exits ("IPv4 port not available"), and it is started again.
async fn start_driver(driver_path: &std::path::Path) -> (Driver, u16) {
    let log_path = artefacts().join("chromedriver.log");
    for _ in 0..5 {
        let log = std::fs::File::create(&log_path).unwrap();
        let mut command = Command::new(driver_path);
        command.arg("--port=0").stdout(log.try_clone().unwrap()).stderr(log);
        // Its own process group, so that the browser it starts can be killed with it.
        std::os::unix::process::CommandExt::process_group(&mut command, 0);
        let mut driver =
            Driver(command.spawn().unwrap_or_else(|e| panic!("starting {}: {e}", driver_path.display())));
        let said = crate::support::eventually(
            "chromedriver to say where it listens",
            Duration::from_secs(20),
            async || {
                let text = std::fs::read_to_string(&log_path).unwrap_or_default();
                let port = text.lines().find_map(|line| {
                    line.split("started successfully on port ")
                        .nth(1)?
                        .trim_end_matches(['.', ' '])
                        .parse::<u16>()
                        .ok()
                });
                match (port, driver.0.try_wait()) {
                    (Some(port), _) => Ok(Some(port)),
                    (None, Ok(Some(_))) if text.contains("port not available") => Ok(None),
                    (None, Ok(Some(status))) => {
                        panic!("chromedriver ended ({status}) before it listened; its log:\n{text}")
                    }
                    (None, _) => Err(text),
                }
            },
        )
        .await;
        if let Some(port) = said {
            return (driver, port);
        }
    }
    panic!("chromedriver found no free port in 5 starts; see {}", log_path.display())
}

/// Waits for chromedriver to listen, then opens a session with a headless, offline Chromium.
async fn connect(port: u16, chromium: &Path, profile: &Path) -> Client {
    let url = format!("http://127.0.0.1:{port}");
    let status = format!("{url}/status");
    eventually(format!("chromedriver to answer on port {port}"), Duration::from_secs(20), async || {
        reqwest::get(&status).await
    })
    .await;
    let args = [
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-quic",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--disable-dev-shm-usage",
        "--window-size=1680,1400",
        &format!("--user-data-dir={}", profile.display()),
    ];
    let capabilities = json!({
        "browserName": "chrome",
        "goog:chromeOptions": {"binary": chromium, "args": args},
    });
    let serde_json::Value::Object(capabilities) = capabilities else { unreachable!() };
    ClientBuilder::new(hyper_util::client::legacy::connect::HttpConnector::new())
        .capabilities(capabilities)
        .connect(&url)
        .await
        .unwrap_or_else(|e| panic!("opening a Chromium session through chromedriver: {e}"))
}
