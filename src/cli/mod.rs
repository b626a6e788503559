//! The command line: `rackd serve`, `openapi`, `check-config`, `hash-key`, `healthcheck`,
//! `plc`, `sim`. The benchmarks are an example (`examples/bench/`), out of the service binary.

pub mod demo;
pub mod plc;
pub mod sim;

use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use clap::{Parser, Subcommand, ValueEnum};

use crate::app::{Application, shutdown_signal};
use crate::config::Sources;

/// rackd: a warehouse control system.
#[derive(Parser, Debug)]
#[command(version, about)]
pub struct Cli {
    /// Log format.
    #[arg(long, global = true, env = "RACKD_LOG_FORMAT", value_enum, default_value_t = LogFormat::Text)]
    pub log_format: LogFormat,
    /// What to do.
    #[command(subcommand)]
    pub command: Option<Command>,
}

/// Log output format.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum LogFormat {
    /// Human-readable lines.
    Text,
    /// One JSON object per line.
    Json,
}

/// The subcommands.
#[derive(Subcommand, Debug)]
pub enum Command {
    /// Run the service (the default). Without a config, the demo site.
    Serve(ServeArgs),
    /// Print the OpenAPI document.
    Openapi,
    /// Check a configuration file (with the RACKD_SECTION__KEY environment) and report
    /// the first error as FILE:LINE:COL: KEY: MESSAGE (or env VAR: KEY: MESSAGE), and what
    /// it warns of (a webhook in plain http to another machine) as FILE:LINE:COL: KEY:
    /// warning: MESSAGE, on stderr.
    CheckConfig {
        /// The file.
        file: PathBuf,
        /// Print the effective configuration, every key, with where each value came from.
        #[arg(long)]
        explain: bool,
    },
    /// Print the hash of an API key for `[[auth.keys]]`: the key is read from standard
    /// input (`rackd hash-key < FILE`), never taken as an argument, which every user of the
    /// machine can read in `ps` and which stays in the shell's history.
    HashKey {
        /// Refused: a key on the command line is visible to every user (see above).
        #[arg(hide = true)]
        key: Option<String>,
        /// Make a new random key, print it and its hash.
        #[arg(long, conflicts_with = "key")]
        generate: bool,
    },
    /// Exit 0 if the server at URL answers /healthz (for container health checks).
    Healthcheck {
        /// The server's base URL (`/healthz` is added) or the full URL to check.
        #[arg(long, env = "RACKD_HEALTHCHECK_URL", default_value = "http://127.0.0.1:8080")]
        url: String,
        /// For https: a PEM file of the CA (or CAs) that signed the server's certificate,
        /// trusted besides the public roots (a site's own CA).
        #[arg(long, env = "RACKD_HEALTHCHECK_CA_FILE")]
        ca_file: Option<PathBuf>,
        /// For https: the name the certificate is checked against, when the URL reaches
        /// the server by another one (`--url https://127.0.0.1:8080` in its container,
        /// `--server-name rackd.plant.local`).
        #[arg(long, env = "RACKD_HEALTHCHECK_SERVER_NAME")]
        server_name: Option<String>,
    },
    /// Read or write a PLC's memory by hand (commissioning).
    Plc(plc::PlcArgs),
    /// Run a device simulator alone.
    #[command(subcommand)]
    Sim(sim::SimCommand),
    /// The store's database.
    #[command(subcommand)]
    Db(DbCommand),
}

/// `rackd db ...`
#[derive(clap::Subcommand, Debug)]
pub enum DbCommand {
    /// Copy a site's store to an empty database, with every id and event number (stop
    /// rackd first). Example: rackd db copy --from data/rackd.db --to postgres://rackd@db/rackd
    Copy {
        /// The store to copy: a SQLite file's PATH (or sqlite:PATH), or postgres://...
        #[arg(long, value_name = "PATH|URL")]
        from: String,
        /// The empty database to copy it to: PATH (or sqlite:PATH), or postgres://...
        #[arg(long, value_name = "PATH|URL")]
        to: String,
    },
    /// Move the jobs that ended before a date, with their history, to a gzip'd JSON Lines
    /// file per day (rackd may run). Example: rackd db archive --database data/rackd.db
    /// --before 2026-08-01 --to /var/lib/rackd/archive
    Archive {
        /// The store: a SQLite file's PATH (or sqlite:PATH), or postgres://...
        #[arg(long, value_name = "PATH|URL")]
        database: String,
        /// Jobs that ended before this day (YYYY-MM-DD, from midnight UTC) leave the store.
        #[arg(long, value_parser = parse_date)]
        before: time::Date,
        /// The folder the files go to (created if missing).
        #[arg(long)]
        to: PathBuf,
    },
    /// Recompute the KPIs' rollups from the job history, after a restore, an import or
    /// rows written by another tool (rackd may run). Example: rackd db rollups --rebuild
    /// --database data/rackd.db
    Rollups {
        /// The store: a SQLite file's PATH (or sqlite:PATH), or postgres://...
        #[arg(long, value_name = "PATH|URL")]
        database: String,
        /// Rebuild them (the one thing this command does; said so that it is not run by
        /// mistake).
        #[arg(long, required = true)]
        rebuild: bool,
    },
}

/// A store named on the command line, by `flag`. Read here rather than by clap, whose
/// error would quote the text whole, a password in it included.
fn database(flag: &str, text: &str) -> anyhow::Result<crate::store::Database> {
    crate::store::Database::parse(text).with_context(|| flag.to_owned())
}

/// A day written `YYYY-MM-DD`.
fn parse_date(text: &str) -> Result<time::Date, String> {
    let format = time::macros::format_description!("[year]-[month]-[day]");
    time::Date::parse(text, &format).map_err(|_| format!("{text:?} is not a day written YYYY-MM-DD"))
}

/// `rackd serve` options. Settings come from the defaults, the file, the environment
/// (`RACKD_<SECTION>__<KEY>`) and these flags, each overriding the one before.
#[derive(clap::Args, Debug, Default)]
pub struct ServeArgs {
    /// Configuration file; without one rackd runs the demo site.
    #[arg(long, env = "RACKD_CONFIG")]
    pub config: Option<PathBuf>,
    /// Listen address, overriding server.listen of the file and RACKD_SERVER__LISTEN.
    #[arg(long)]
    pub listen: Option<SocketAddr>,
    /// Database file, overriding database.path of the file and RACKD_DATABASE__PATH.
    #[arg(long)]
    pub database: Option<PathBuf>,
    /// Allow serving without API keys on a non-loopback address.
    #[arg(long)]
    pub insecure: bool,
}

impl ServeArgs {
    /// Where these options and the environment say the configuration comes from.
    pub fn sources(&self) -> Sources {
        Sources::of_process(self.config.clone(), self.listen, self.database.clone())
    }
}

/// Runs the command line.
pub async fn run(cli: Cli) -> anyhow::Result<ExitCode> {
    match cli.command.unwrap_or(Command::Serve(ServeArgs::default())) {
        Command::Serve(args) => {
            let sources = args.sources();
            let loaded = sources.load()?;
            for warning in loaded.warnings() {
                tracing::warn!("{warning}");
            }
            let mut config = loaded.config;
            // Bound first: a port in use is reported before any simulator or device starts.
            let listener = crate::app::bind(config.server.listen).await?;
            let sim = match args.config {
                Some(_) => None,
                None => Some(demo::start(&mut config).await?),
            };
            let mut app = Application::build_on(&config, listener, args.insecure).await?;
            match sim {
                Some(sim) => app.keep(sim),
                // The demo site's devices point at its simulators: it is not reloaded.
                None => app.reload_from(sources),
            }
            // Listening before the server answers: a SIGHUP from then on is a reload.
            #[cfg(unix)]
            {
                use tokio::signal::unix::{SignalKind, signal};
                let hangups = signal(SignalKind::hangup()).context("listening for SIGHUP")?;
                app.reload_on(hangups);
            }
            app.run_until(shutdown_signal()).await?;
        }
        Command::Db(DbCommand::Copy { from, to }) => {
            let (from, to) = (database("--from", &from)?, database("--to", &to)?);
            let copied = crate::store::copy::copy(&from, &to)
                .await
                .with_context(|| format!("copying {} to {}", from.display(), to.display()))?;
            for (table, rows) in copied {
                println!("{table}: {rows} rows");
            }
            println!("copied {} to {}", from.display(), to.display());
        }
        Command::Db(DbCommand::Archive { database: text, before, to }) => {
            let database = database("--database", &text)?;
            let pool = crate::store::open(&database, std::time::Duration::from_secs(30))
                .await
                .with_context(|| format!("opening {}", database.display()))?;
            let done =
                crate::store::archive::archive(&pool, before, &to, crate::store::archive::Delete::Direct)
                    .await
                    .with_context(|| format!("archiving {} before {before}", database.display()))?;
            pool.close().await;
            for file in &done.files {
                println!("{}", file.display());
            }
            println!(
                "archived {} jobs to {} files in {}; {} kept (a lock or an unfinished job names them)",
                done.jobs,
                done.files.len(),
                to.display(),
                done.kept
            );
        }
        Command::Db(DbCommand::Rollups { database: text, rebuild: _ }) => {
            let database = database("--database", &text)?;
            let pool = crate::store::open(&database, std::time::Duration::from_secs(30))
                .await
                .with_context(|| format!("opening {}", database.display()))?;
            let started = std::time::Instant::now();
            let done = crate::store::rollups::rebuild::rebuild(&pool, |entries, _| {
                if entries % 1_000_000 < crate::store::rollups::rebuild::PAGE as u64 {
                    eprintln!("{entries} history entries replayed");
                }
            })
            .await
            .with_context(|| format!("rebuilding the rollups of {}", database.display()))?;
            pool.close().await;
            println!(
                "rebuilt the rollups of {} from {} history entries: {} rows, in {:.1} s (the swap {:.2} s)",
                database.display(),
                done.entries,
                done.rows,
                started.elapsed().as_secs_f64(),
                done.swap.as_secs_f64()
            );
        }
        Command::Openapi => {
            say(crate::api::openapi().to_pretty_json().context("encoding OpenAPI")?);
        }
        Command::CheckConfig { file, explain } => {
            match Sources::of_process(Some(file.clone()), None, None).load() {
                Ok(loaded) => {
                    // On stderr: `--explain`'s output stays the configuration alone.
                    for warning in loaded.warnings() {
                        eprintln!("{warning}");
                    }
                    match explain {
                        true => say(loaded.explain()),
                        false => println!("{}: ok", file.display()),
                    }
                }
                Err(e) => {
                    eprintln!("{e}");
                    return Ok(ExitCode::FAILURE);
                }
            }
        }
        Command::HashKey { key, generate } => {
            if key.is_some() {
                eprintln!(
                    "rackd hash-key takes the key on standard input, not as an argument (which every user sees \
                     in ps): rackd hash-key < FILE, or printf %s \"$KEY\" | rackd hash-key; or make a new one \
                     with rackd hash-key --generate"
                );
                return Ok(ExitCode::FAILURE);
            }
            let key = if generate {
                let k = crate::auth::generate_key();
                println!("key:  {k}");
                k
            } else {
                let mut line = String::new();
                std::io::stdin().read_line(&mut line)?;
                line.trim().to_owned()
            };
            if let Err(why) = crate::auth::acceptable_key(&key) {
                eprintln!("rackd hash-key: {why}");
                return Ok(ExitCode::FAILURE);
            }
            println!("{}{}", if generate { "hash: " } else { "" }, crate::auth::KeyHash::of(&key));
        }
        Command::Healthcheck { url, ca_file, server_name } => {
            let url = health_url(&url);
            let (client, target) = health_client(&url, ca_file.as_deref(), server_name.as_deref())?;
            // The URL as printed: a password or a token in it as `***`.
            let shown = crate::redact::url(&url);
            match client.get(target).send().await {
                Ok(r) if r.status().is_success() => println!("{shown}: ok"),
                Ok(r) => {
                    eprintln!("{shown}: {}", r.status());
                    return Ok(ExitCode::FAILURE);
                }
                Err(e) => {
                    eprintln!("{shown}: {}", describe(&e.without_url().into()));
                    return Ok(ExitCode::FAILURE);
                }
            }
        }
        Command::Plc(args) => plc::run(args).await?,
        Command::Sim(s) => sim::run(s).await?,
    }
    Ok(ExitCode::SUCCESS)
}

/// Prints a line to stdout; a reader that went away (`rackd openapi | head`) ends the
/// program quietly, as Unix tools do, instead of a panic.
pub fn say(line: impl std::fmt::Display) {
    use std::io::Write;
    if let Err(e) = writeln!(std::io::stdout().lock(), "{line}") {
        if e.kind() == std::io::ErrorKind::BrokenPipe {
            std::process::exit(0);
        }
        eprintln!("rackd: writing to stdout: {e}");
        std::process::exit(1);
    }
}

/// An error and its causes on one line, each cause once: many errors already name their
/// cause in their own words, and the chain would repeat it.
pub fn describe(e: &anyhow::Error) -> String {
    let mut out = String::new();
    for cause in e.chain() {
        let text = cause.to_string();
        if out.contains(&text) {
            continue;
        }
        if !out.is_empty() {
            out.push_str(": ");
        }
        out.push_str(&text);
    }
    out
}

/// The URL `healthcheck` asks: a base URL gets `/healthz`; one with a path is taken as is.
fn health_url(given: &str) -> String {
    match reqwest::Url::parse(given) {
        Ok(url) if !matches!(url.path(), "" | "/") => url.to_string(),
        _ => format!("{}/healthz", given.trim_end_matches('/')),
    }
}

/// The client `healthcheck` asks with, and the URL it asks: trusting `ca_file` too, and
/// reaching `url`'s address under `server_name` when one is given.
fn health_client(
    url: &str,
    ca_file: Option<&std::path::Path>,
    server_name: Option<&str>,
) -> anyhow::Result<(reqwest::Client, reqwest::Url)> {
    let shown = crate::redact::url(url);
    let mut url = reqwest::Url::parse(url).with_context(|| format!("{shown} is not a URL"))?;
    // Nothing between a health check and its server: no proxy from the environment.
    let mut client = reqwest::Client::builder()
        .timeout(std::time::Duration::from_secs(3))
        .no_proxy()
        .tls_built_in_native_certs(false);
    if let Some(path) = ca_file {
        let pem = std::fs::read(path).with_context(|| format!("reading --ca-file {}", path.display()))?;
        let cas = reqwest::Certificate::from_pem_bundle(&pem)
            .with_context(|| format!("--ca-file {}: not PEM certificates", path.display()))?;
        anyhow::ensure!(!cas.is_empty(), "--ca-file {}: no certificate in it", path.display());
        for ca in cas {
            client = client.add_root_certificate(ca);
        }
    }
    if let Some(name) = server_name {
        let addrs = url.socket_addrs(|| None).with_context(|| format!("resolving {shown}"))?;
        client = client.resolve_to_addrs(name, &addrs);
        url.set_host(Some(name)).with_context(|| format!("--server-name {name:?}"))?;
    }
    Ok((client.build()?, url))
}

#[cfg(test)]
mod tests {
    #[test]
    fn each_cause_is_said_once() {
        #[derive(Debug, thiserror::Error)]
        #[error("the database does not answer: {0}")]
        struct Outer(#[source] std::io::Error);
        let io = std::io::Error::new(std::io::ErrorKind::PermissionDenied, "unable to open database file");
        let e = anyhow::Error::new(Outer(io)).context("opening database data/rackd.db");
        assert_eq!(
            super::describe(&e),
            "opening database data/rackd.db: the database does not answer: unable to open database file"
        );
        assert_eq!(format!("{e:#}").matches("unable to open").count(), 2, "what anyhow alone prints");
    }

    #[test]
    fn healthcheck_takes_a_base_or_a_full_url() {
        assert_eq!(super::health_url("http://h:8080"), "http://h:8080/healthz");
        assert_eq!(super::health_url("http://h:8080/"), "http://h:8080/healthz");
        assert_eq!(super::health_url("http://h:8080/healthz"), "http://h:8080/healthz");
        assert_eq!(super::health_url("http://h:8080/readyz"), "http://h:8080/readyz");
    }
}
