//! What differs between the two engines, in one place: how to connect (SQLite's pragmas,
//! PostgreSQL's version check), and the text of the writer's set-based statements.
//!
//! The writer hands a whole group's rows to the database as ONE JSON array parameter
//! (`$1`), so a statement's text stays the same however many rows it carries (one prepared
//! statement, cached) and no engine's limit on bound parameters is ever reached. SQLite
//! reads the array with `json_each` and `->>`, PostgreSQL with `json_populate_recordset`
//! over the table's own row type, which also converts every field to its column's type.
//!
//! TLS to PostgreSQL ([`PgTls`]): rustls on ring. The URL's `sslmode` means what libpq
//! says, with three decisions of rackd's where the URL leaves it open:
//! - **no `sslmode`, a host that is not loopback**: `require`, not libpq's `prefer`
//!   (which falls back to plaintext without a word when the server offers no TLS, and
//!   checks no certificate when it does); a site that means plaintext says
//!   `sslmode=disable`. Loopback and Unix sockets keep `prefer`.
//! - **no `sslmode` and a CA** (`database.ca_file` or `sslrootcert`): `verify-full`: a
//!   site that names its CA wants the server checked against it.
//! - **`require` and a CA**: `verify-ca`, as libpq does.
//!
//! `allow` is refused (the driver never tries TLS with it), and so are `verify-ca` and
//! `verify-full` without a CA (`config::check`). Once connected, rackd logs whether the link
//! is encrypted (`pg_stat_ssl`), as a warning when it is not and the host is not loopback.

use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::time::Duration;

use sqlx::postgres::{PgConnectOptions, PgPoolOptions, PgSslMode};
use sqlx::sqlite::{SqliteConnectOptions, SqliteJournalMode, SqlitePoolOptions, SqliteSynchronous};

use super::Pool;
use super::hosts::{self, Fresh, Hosts, SessionAttrs};

/// The oldest PostgreSQL server rackd runs on (`server_version_num`): 14, the oldest
/// release its community still supported when this was written.
pub const MIN_POSTGRES: i64 = 140000;

/// Where the store is.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Database {
    /// A SQLite file (created, with its folder, if missing).
    Sqlite(PathBuf),
    /// A PostgreSQL server's URL.
    Postgres(String),
}

impl Database {
    /// A SQLite file's path, as `PATH` or `sqlite:PATH`, or a `postgres://` /
    /// `postgresql://` URL: what `rackd db` takes for a store (`rackd serve --database`
    /// takes a path too). Any other URL (`mysql://`, `postgres//` that lost its colon) is
    /// refused, shown without its password.
    pub fn parse(text: &str) -> Result<Database, DatabaseError> {
        if text.starts_with("postgres://") || text.starts_with("postgresql://") {
            PgTls::of(text).check()?;
            super::hosts::Hosts::parse(text)?;
            Ok(Database::Postgres(text.to_owned()))
        } else if let Some(path) = text.strip_prefix("sqlite:") {
            let path = path.strip_prefix("//").unwrap_or(path);
            if path.is_empty() {
                return Err(DatabaseError::NoPath);
            }
            Ok(Database::Sqlite(PathBuf::from(path)))
        } else if has_scheme(text) || text.starts_with("postgres//") || text.starts_with("postgresql//") {
            Err(DatabaseError::Neither(crate::redact::url(text)))
        } else if text.is_empty() {
            Err(DatabaseError::NoPath)
        } else {
            Ok(Database::Sqlite(PathBuf::from(text)))
        }
    }

    /// Which engine it is.
    pub fn engine(&self) -> Engine {
        match self {
            Database::Sqlite(_) => Engine::Sqlite,
            Database::Postgres(_) => Engine::Postgres,
        }
    }

    /// For messages: the file's path, or the URL without its password.
    pub fn display(&self) -> String {
        match self {
            Database::Sqlite(path) => path.display().to_string(),
            Database::Postgres(url) => crate::redact::url(url),
        }
    }
}

/// Whether `text` starts with a URL's scheme (`mysql:`, `postgres:`), which a path does not.
fn has_scheme(text: &str) -> bool {
    match text.split_once(':') {
        Some((scheme, _)) => {
            scheme.starts_with(|c: char| c.is_ascii_alphabetic())
                && scheme.chars().all(|c| c.is_ascii_alphanumeric() || "+-.".contains(c))
        }
        None => false,
    }
}

/// Why a text is not a store [`Database::parse`] takes. No variant holds a password.
#[derive(Debug, thiserror::Error)]
pub enum DatabaseError {
    /// Another URL than PostgreSQL's (shown without its password).
    #[error("{0:?} is neither a SQLite file's path (PATH or sqlite:PATH) nor a postgres:// URL")]
    Neither(String),
    /// `sqlite:` (or nothing) without a path.
    #[error("a SQLite store needs a file's path (data/rackd.db, or sqlite:data/rackd.db)")]
    NoPath,
    /// A `postgres://` URL the driver does not read (in its words), or whose list of
    /// hosts rackd does not take.
    #[error(transparent)]
    Postgres(#[from] super::hosts::HostsError),
    /// A `sslmode` rackd does not take.
    #[error(transparent)]
    SslMode(#[from] SslModeError),
}

/// A `sslmode` rackd does not take.
#[derive(Debug, thiserror::Error)]
pub enum SslModeError {
    /// `allow`, which the driver takes but never uses TLS with.
    #[error(
        "sslmode=allow is not supported: the driver would never use TLS with it; say prefer, require, \
         verify-ca or verify-full (or disable)"
    )]
    Allow,
    /// A mode libpq does not have.
    #[error("sslmode={0} is not one of {modes}", modes = SSL_MODES.join(", "))]
    Unknown(String),
}

/// What a PostgreSQL URL says about TLS, as written (`sslmode`, `sslrootcert`; sqlx's
/// spellings `ssl-mode`, `ssl-root-cert` and `ssl-ca` too).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct PgTls {
    /// `sslmode`, lowercased, if the URL says it.
    pub mode: Option<String>,
    /// `sslrootcert`, if the URL names a CA file.
    pub root_cert: Option<PathBuf>,
    /// Whether the host is loopback or a Unix socket.
    pub loopback: bool,
}

/// The `sslmode`s rackd accepts (libpq's, less `allow`).
pub const SSL_MODES: [&str; 5] = ["disable", "prefer", "require", "verify-ca", "verify-full"];

impl PgTls {
    /// What `url` says.
    pub fn of(url: &str) -> PgTls {
        let mut tls = PgTls::default();
        let rest = url.split_once("://").map_or(url, |(_, r)| r);
        let (before_query, query) = rest.split_once('?').unwrap_or((rest, ""));
        let after_user = before_query.rsplit_once('@').map_or(before_query, |(_, h)| h);
        let mut host = host_of(after_user.split('/').next().unwrap_or_default()).to_owned();
        for (key, value) in form_urlencoded::parse(query.as_bytes()) {
            match &*key {
                "sslmode" | "ssl-mode" => tls.mode = Some(value.to_ascii_lowercase()),
                "sslrootcert" | "ssl-root-cert" | "ssl-ca" => tls.root_cert = Some(PathBuf::from(&*value)),
                "host" | "hostaddr" => host = value.into_owned(),
                _ => {}
            }
        }
        tls.loopback = is_loopback(&host);
        tls
    }

    /// Refuses a `sslmode` rackd does not support, in words for `check-config`.
    pub fn check(&self) -> Result<(), SslModeError> {
        match self.mode.as_deref() {
            Some("allow") => Err(SslModeError::Allow),
            Some(mode) if !SSL_MODES.contains(&mode) => Err(SslModeError::Unknown(mode.to_owned())),
            _ => Ok(()),
        }
    }

    /// The mode rackd connects with, given the CA it has (the URL's or `ca_file`); see the
    /// module documentation. `from_env` is the driver's mode when `PGSSLMODE` sets it.
    pub fn effective(&self, has_ca: bool, from_env: Option<PgSslMode>) -> PgSslMode {
        let said = self.mode.as_deref().and_then(|m| m.parse().ok()).or(from_env);
        match said {
            Some(PgSslMode::Require) if has_ca => PgSslMode::VerifyCa,
            Some(mode) => mode,
            None if has_ca => PgSslMode::VerifyFull,
            None if self.loopback => PgSslMode::Prefer,
            None => PgSslMode::Require,
        }
    }
}

/// The host of `HOST:PORT`, `[V6]:PORT` or `HOST`.
fn host_of(authority: &str) -> &str {
    if let Some(v6) = authority.strip_prefix('[') {
        return v6.split(']').next().unwrap_or_default();
    }
    authority.split(':').next().unwrap_or_default()
}

/// A host that is this machine: `localhost`, a loopback address, a Unix socket's folder
/// (or no host at all, which is the socket too).
fn is_loopback(host: &str) -> bool {
    host.is_empty()
        || host.starts_with('/')
        || host.eq_ignore_ascii_case("localhost")
        || host.parse::<std::net::IpAddr>().is_ok_and(|ip| ip.is_loopback())
}

/// `sslmode` as written in a URL.
pub fn mode_name(mode: PgSslMode) -> &'static str {
    match mode {
        PgSslMode::Disable => "disable",
        PgSslMode::Allow => "allow",
        PgSslMode::Prefer => "prefer",
        PgSslMode::Require => "require",
        PgSslMode::VerifyCa => "verify-ca",
        PgSslMode::VerifyFull => "verify-full",
    }
}

/// What `[database]` sets beside where the store is, each for one engine; the other's is
/// not used.
#[derive(Clone, Copy, Debug, Default)]
pub struct Settings<'a> {
    /// A PostgreSQL server's CA file (`database.ca_file`), for `verify-ca` and
    /// `verify-full`; the URL's own `sslrootcert` is used when it is `None`. How the TLS
    /// mode is chosen is in the module documentation.
    pub ca: Option<&'a Path>,
    /// The SQLite VFS the file is opened through (`database.sqlite_vfs`), by the name it is
    /// registered under in the process; SQLite's default (`unix`) when `None`. rackd
    /// registers none of its own: the test suite registers one that fails writes on command
    /// (tests/it/support/faulty_vfs.rs), and SQLite refuses a name it does not know
    /// (`no such vfs`).
    pub vfs: Option<&'a str>,
}

/// One of the two engines.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Engine {
    /// SQLite.
    Sqlite,
    /// PostgreSQL.
    Postgres,
}

/// Why the store could not be opened.
#[derive(Debug, thiserror::Error)]
pub enum OpenError {
    /// The database (or its folder) cannot be reached or created.
    #[error(transparent)]
    Database(#[from] sqlx::Error),
    /// The folder of the SQLite file cannot be written.
    #[error(transparent)]
    Folder(#[from] std::io::Error),
    /// A migration failed, or the database's schema is not one this rackd runs on.
    #[error("migrating the schema: {0}")]
    Schema(#[from] super::schema::SchemaError),
    /// TLS with the PostgreSQL server failed: it offers none, or its certificate does not
    /// verify.
    #[error("TLS with the PostgreSQL server failed (sslmode={mode}{ca}): {source}; {hint}")]
    Tls {
        /// The mode rackd connected with.
        mode: &'static str,
        /// `, CA FILE` when a CA was given.
        ca: String,
        /// What to look at.
        hint: &'static str,
        /// The driver's error.
        source: sqlx::Error,
    },
    /// No host of a `database.url` that lists several (or asks for `target_session_attrs`)
    /// fits, within the time a connection is waited for.
    #[error("no host of database.url is {attrs} (target_session_attrs): {said}")]
    NoHost {
        /// What was asked of a host.
        attrs: &'static str,
        /// What each host said, the last time they were tried.
        said: String,
    },
    /// The PostgreSQL server is too old.
    #[error(
        "PostgreSQL {found} is not supported: rackd needs PostgreSQL 14 or newer (server_version_num {MIN_POSTGRES} and up)"
    )]
    Version {
        /// What the server says it is.
        found: String,
    },
}

impl Engine {
    /// The migrations of this engine's schema.
    pub fn migrator(self) -> &'static sqlx::migrate::Migrator {
        match self {
            Engine::Sqlite => &super::SQLITE_MIGRATOR,
            Engine::Postgres => &super::POSTGRES_MIGRATOR,
        }
    }

    /// A derived table of the rows of the JSON array bound as `$1`, one column per name in
    /// `columns` (each a column of `table`, whose type it takes).
    pub fn json_rows(self, table: &str, columns: &[&str]) -> String {
        match self {
            Engine::Sqlite => {
                let list: Vec<String> = columns.iter().map(|c| format!("value->>'{c}' AS {c}")).collect();
                format!("SELECT {} FROM json_each($1)", list.join(", "))
            }
            Engine::Postgres => {
                format!("SELECT {} FROM json_populate_recordset(NULL::{table}, $1::json)", columns.join(", "))
            }
        }
    }

    /// `INSERT INTO table (columns) SELECT ...` the rows of the JSON array bound as `$1`
    /// (on SQLite `INSERT OR FAIL`: see [`Engine::or_fail`]).
    pub fn insert_json(self, table: &str, columns: &[&str]) -> String {
        let or_fail = self.or_fail();
        format!("INSERT{or_fail} INTO {table} ({}) {}", columns.join(", "), self.json_rows(table, columns))
    }

    /// What follows `INSERT` or `UPDATE` in the writer's statements: on SQLite ` OR FAIL`.
    /// A statement that fails keeps the rows it wrote before the failing one, so
    /// SQLite need not copy every page the statement changes to a statement journal first
    /// (it does for a multi-row statement under the default `ABORT`). The writer never goes
    /// on after a failed statement: it rolls the group back (or the request's savepoint),
    /// which takes those rows back too. Measured with `bench intake` (three alternating
    /// pairs): single POSTs +3%, batches +4%; the statement journal had taken a fifth of
    /// SQLite's thread (perf). PostgreSQL has no such clause and no such journal.
    pub fn or_fail(self) -> &'static str {
        match self {
            Engine::Sqlite => " OR FAIL",
            Engine::Postgres => "",
        }
    }

    /// `UPDATE table SET` every column of `set` from the rows of the JSON array bound as
    /// `$1`, matching the table's rows on the `key` columns.
    pub fn update_json(self, table: &str, key: &[&str], set: &[&str]) -> String {
        let all: Vec<&str> = key.iter().chain(set).copied().collect();
        let assign: Vec<String> = set.iter().map(|c| format!("{c} = r.{c}")).collect();
        let on: Vec<String> = key.iter().map(|c| format!("{table}.{c} = r.{c}")).collect();
        format!(
            "UPDATE{} {table} SET {} FROM ({}) AS r WHERE {}",
            self.or_fail(),
            assign.join(", "),
            self.json_rows(table, &all),
            on.join(" AND ")
        )
    }

    /// The bare name, for messages and the command line.
    pub fn as_str(self) -> &'static str {
        match self {
            Engine::Sqlite => "sqlite",
            Engine::Postgres => "postgres",
        }
    }
}

/// A pool of at most `max` connections to `database`, with every engine setting made here
/// (and only here); a PostgreSQL server's version is checked.
///
/// On PostgreSQL the server ends a session of rackd's whose transaction has waited on its
/// client for `busy_timeout` (at least a second): `idle_in_transaction_session_timeout`.
/// rackd never waits on anything but the database inside a transaction, so such a session
/// belongs to a node cut off mid-transaction (a partition, a frozen process). Its
/// transaction then rolls back and its locks go; without this, a dispatch write cut off
/// under the lease's fence (`store::cluster::fence` locks the lease row `FOR KEY SHARE`) would
/// hold that row until the server's TCP keepalive gave up, hours on a quiet link, and no
/// standby could take over. The rollback keeps the fence's promise: the write is committed
/// before the new node starts, or not at all.
///
/// `settings` are the engine's own: a PostgreSQL server's CA (see [`Settings::ca`]), a
/// SQLite VFS.
///
/// A URL that lists several hosts (or says `target_session_attrs`) starts on the first host
/// that fits, and a task follows the one that takes writes through a failover (`hosts`).
pub async fn connect(
    database: &Database,
    busy_timeout: Duration,
    max: u32,
    settings: Settings<'_>,
) -> Result<Pool, OpenError> {
    match database {
        Database::Sqlite(path) => {
            prepare_folder(path)?;
            // A new database is rackd's user's alone; SQLite gives its WAL and shared
            // memory files the database file's permissions.
            match crate::files::create(path) {
                Err(e) if e.kind() != std::io::ErrorKind::AlreadyExists => return Err(e.into()),
                _ => {}
            }
            let options = sqlite_options(path, busy_timeout, settings.vfs)?;
            Ok(Pool::Sqlite(SqlitePoolOptions::new().max_connections(max).connect_with(options).await?))
        }
        Database::Postgres(url) => {
            let ca = settings.ca;
            let hosts =
                Hosts::parse(url).map_err(|e| OpenError::Database(sqlx::Error::Configuration(e.into())))?;
            let idle = busy_timeout.max(Duration::from_secs(1));
            let wait = busy_timeout.max(Duration::from_secs(5));
            let each: Vec<PgHost> =
                hosts.urls.iter().map(|u| PgHost::of(u, idle, ca)).collect::<Result<_, sqlx::Error>>()?;
            let options: Vec<PgConnectOptions> = each.iter().map(|h| h.options.clone()).collect();
            let several = each.len() > 1;
            // The host to start on, and the finder's first connection to it: the first
            // that fits (see `hosts`); one host that need not be checked is connected to
            // as it always was.
            let (start, watch) = if several || hosts.attrs != SessionAttrs::Any {
                let (i, conn) = first_fitting(&options, &hosts, wait).await?;
                (i, Some(conn))
            } else {
                (0, None)
            };
            let host = &each[start];
            let fresh = Fresh::new();
            let mut pool = PgPoolOptions::new().max_connections(max).acquire_timeout(wait);
            let attrs = hosts.attrs;
            if attrs != SessionAttrs::Any {
                pool = pool.after_connect(move |conn, _| {
                    Box::pin(async move {
                        match attrs.check(conn).await? {
                            true => Ok(()),
                            false => Err(sqlx::Error::Protocol(format!(
                                "the server is not {} (target_session_attrs)",
                                attrs.as_str()
                            ))),
                        }
                    })
                });
            }
            if several {
                let fresh = fresh.clone();
                pool = pool.before_acquire(move |_, meta| {
                    let keep = fresh.keeps(meta.age);
                    Box::pin(async move { Ok(keep) })
                });
            }
            let pool = pool
                .connect_with(host.options.clone())
                .await
                .map_err(|e| tls_failure(e, host.mode, host.ca_file.as_deref(), host.tls.mode.is_none()))?;
            let version: String = sqlx::query_scalar("SHOW server_version_num").fetch_one(&pool).await?;
            if !supported(&version) {
                let found =
                    sqlx::query_scalar("SHOW server_version").fetch_one(&pool).await.unwrap_or(version);
                return Err(OpenError::Version { found });
            }
            log_link(&pool, host.mode, host.tls.loopback).await;
            if several {
                tracing::info!(
                    host = %hosts.labels[start],
                    hosts = hosts.labels.len(),
                    target_session_attrs = attrs.as_str(),
                    "database.url lists several hosts: connected to the first that fits, following it through failovers"
                );
                tokio::spawn(hosts::find(pool.clone(), options, hosts.labels, attrs, start, watch, fresh));
            }
            Ok(Pool::Postgres(pool))
        }
    }
}

/// One host of a `database.url`: its connect options with every setting of rackd's, and
/// the TLS mode they were given.
struct PgHost {
    options: PgConnectOptions,
    mode: PgSslMode,
    tls: PgTls,
    ca_file: Option<PathBuf>,
}

impl PgHost {
    /// The options of `url` (one host), sessions ending a transaction idle for `idle`, and
    /// the CA `ca` if given.
    fn of(url: &str, idle: Duration, ca: Option<&Path>) -> Result<PgHost, sqlx::Error> {
        let tls = PgTls::of(url);
        let mut options = PgConnectOptions::from_str(url)?
            .application_name("rackd")
            .options([("idle_in_transaction_session_timeout", format!("{}ms", idle.as_millis()))]);
        if let Some(ca) = ca {
            options = options.ssl_root_cert(ca);
        }
        let from_env = std::env::var("PGSSLMODE").ok().map(|_| options.get_ssl_mode());
        let ca_file = ca.map(Path::to_owned).or_else(|| tls.root_cert.clone());
        let mode = tls.effective(ca_file.is_some(), from_env);
        Ok(PgHost { options: options.ssl_mode(mode), mode, tls, ca_file })
    }
}

/// The first host (in the order listed) that fits the URL's `target_session_attrs`, tried
/// in rounds for at most `wait`.
async fn first_fitting(
    options: &[PgConnectOptions],
    hosts: &Hosts,
    wait: Duration,
) -> Result<(usize, sqlx::PgConnection), OpenError> {
    let deadline = tokio::time::Instant::now() + wait;
    let mut backoff = Duration::from_millis(50);
    loop {
        match hosts::first_passing(options, &hosts.labels, hosts.attrs).await {
            Ok(found) => return Ok(found),
            Err(said) if tokio::time::Instant::now() + backoff >= deadline => {
                return Err(OpenError::NoHost { attrs: hosts.attrs.as_str(), said: said.join("; ") });
            }
            Err(_) => {}
        }
        tokio::time::sleep(backoff).await;
        backoff = (backoff * 2).min(hosts::MAX_BACKOFF);
    }
}

/// A TLS failure said in rackd's words, with what to look at; any other error as it is.
fn tls_failure(e: sqlx::Error, mode: PgSslMode, ca: Option<&Path>, defaulted: bool) -> OpenError {
    let sqlx::Error::Tls(cause) = &e else { return OpenError::Database(e) };
    let hint = if cause.to_string().contains("does not support TLS") {
        if defaulted {
            "the server offers no TLS, which rackd requires of a host that is not loopback when the URL says no \
             sslmode: turn on ssl on the server, or say sslmode=disable in database.url to accept plaintext"
        } else {
            "the server offers no TLS: turn on ssl on the server, or change sslmode in database.url"
        }
    } else if ca.is_some() {
        "check that the server's certificate is signed by that CA and, with verify-full, names the URL's host"
    } else {
        "check the server's TLS settings"
    };
    let ca = ca.map(|p| format!(", CA {}", p.display())).unwrap_or_default();
    OpenError::Tls { mode: mode_name(mode), ca, hint, source: e }
}

/// Logs whether the link to the server is encrypted: a warning when it is not and the
/// host is not this machine.
async fn log_link(pool: &sqlx::PgPool, mode: PgSslMode, loopback: bool) {
    let sql = "SELECT ssl, version FROM pg_stat_ssl WHERE pid = pg_backend_pid()";
    let row: Result<(bool, Option<String>), _> = sqlx::query_as(sql).fetch_one(pool).await;
    let mode = mode_name(mode);
    match row {
        Ok((true, version)) => {
            let version = version.unwrap_or_default();
            let verified = match mode {
                "verify-full" => "certificate and host name verified",
                "verify-ca" => "certificate verified, host name not",
                _ => "certificate not verified",
            };
            tracing::info!(sslmode = mode, "database link encrypted with TLS ({version}, {verified})");
        }
        Ok((false, _)) if loopback => {
            tracing::info!(sslmode = mode, "database link not encrypted (a loopback host)")
        }
        Ok((false, _)) => tracing::warn!(
            sslmode = mode,
            "database link NOT encrypted: the store's data crosses the network in clear; say \
             sslmode=verify-full (or require) in database.url"
        ),
        Err(e) => tracing::debug!(error = %e, "the database link's encryption is not known (pg_stat_ssl)"),
    }
}

/// The page size of a new SQLite database, in bytes.
///
/// A commit writes each page it changed to the WAL as a frame of its own (two `pwrite`s a
/// frame), so the intake tables' appends cost half the frames at 8 KiB. The scattered leaf
/// of the reference index a single job dirties costs twice the bytes, and the two balance.
/// Measured with `bench intake`, ten alternating runs each against 4 KiB: batches 65,586 →
/// 69,636 jobs a second (+6%), single POSTs 14,885 → 14,916 (no change). 16 KiB gave
/// batches +12% but single POSTs -6% (six runs each), so 8 KiB it is.
///
/// The setting only applies when the file is created: an existing database keeps the page
/// size it was made with (SQLite can change it only by `VACUUM`, and not in WAL mode), and
/// works as before.
pub const SQLITE_PAGE_SIZE: u32 = 8192;

/// Whether a server saying this `server_version_num` is new enough.
fn supported(version_num: &str) -> bool {
    version_num.trim().parse::<i64>().is_ok_and(|v| v >= MIN_POSTGRES)
}

/// SQLite's settings: WAL, `synchronous=FULL` (a commit is on disk; the writer's own
/// connection lowers it to `NORMAL` and syncs the WAL itself, see `store::writer::durable`),
/// foreign keys, and how long a statement waits for another connection's lock.
///
/// A new database gets pages of [`SQLITE_PAGE_SIZE`] bytes, twice SQLite's default. How
/// SQLite itself is compiled (without memory statistics) is set in `.cargo/config.toml`.
/// `vfs` is [`Settings::vfs`].
fn sqlite_options(
    path: &Path,
    busy_timeout: Duration,
    vfs: Option<&str>,
) -> Result<SqliteConnectOptions, sqlx::Error> {
    let options = SqliteConnectOptions::from_str("sqlite:")?;
    let options = match vfs {
        Some(name) => options.vfs(name.to_owned()),
        None => options,
    };
    Ok(options
        .filename(path)
        .create_if_missing(true)
        .page_size(SQLITE_PAGE_SIZE)
        .journal_mode(SqliteJournalMode::Wal)
        .synchronous(SqliteSynchronous::Full)
        .busy_timeout(busy_timeout)
        .foreign_keys(true)
        .statement_cache_capacity(128))
}

/// Creates the SQLite file's folder, naming the fix when rackd may not write there.
fn prepare_folder(path: &Path) -> std::io::Result<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        if let Err(e) = std::fs::create_dir_all(dir) {
            // A folder to create inside one rackd cannot write (a root-owned volume with
            // the database in a subfolder): name that folder, not just "permission denied".
            if let Some(existing) = dir.ancestors().find(|a| a.is_dir()) {
                writable(existing)?;
            }
            return Err(e);
        }
        writable(dir)?;
    }
    Ok(())
}

/// Checks that rackd may create files in `dir` (SQLite needs the database's directory for
/// its journal), so that a volume owned by another user is named with the fix instead of
/// SQLite's "unable to open database file". The message names the directory, its owner and
/// rackd's own uid, and the fixes a container user has: give the directory to rackd's uid,
/// mount a named volume (which the image prepares for uid 10001), or run as the owner.
fn writable(dir: &Path) -> std::io::Result<()> {
    use std::os::unix::fs::MetadataExt;
    let probe = dir.join(format!(".rackd-write-test-{}", std::process::id()));
    match std::fs::OpenOptions::new().write(true).create_new(true).open(&probe) {
        Ok(_) => std::fs::remove_file(&probe),
        Err(e) if e.kind() == std::io::ErrorKind::PermissionDenied => {
            let meta = std::fs::metadata(dir)?;
            // /proc/self belongs to the process's effective user.
            let me =
                std::fs::metadata("/proc/self").map(|m| m.uid().to_string()).unwrap_or_else(|_| "?".into());
            let (dir, owner) = (dir.display(), meta.uid());
            // Running as root to write a root-owned folder is not a fix worth offering.
            let as_owner = if owner == 0 {
                String::new()
            } else {
                format!(", or run rackd as uid {owner} (--user {owner})")
            };
            Err(std::io::Error::new(
                e.kind(),
                format!(
                    "cannot write in {dir}: it belongs to uid {owner} (mode {:o}) and rackd runs as uid {me}; \
                     give it to uid {me} (chown {me} {dir}, on the host folder of a bind mount), or mount a \
                     named volume there (-v rackd-data:{dir}; the image runs as uid 10001){as_owner}",
                    meta.mode() & 0o7777,
                ),
            ))
        }
        Err(e) => Err(e),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn databases_parse_from_the_command_line() {
        let sqlite = |text: &str| Database::parse(text).unwrap();
        assert_eq!(sqlite("sqlite:data/x.db"), Database::Sqlite("data/x.db".into()));
        assert_eq!(sqlite("sqlite:///tmp/x.db"), Database::Sqlite("/tmp/x.db".into()));
        // A plain path, as `rackd serve --database` takes it.
        assert_eq!(sqlite("data/x.db"), Database::Sqlite("data/x.db".into()));
        assert_eq!(sqlite("/var/lib/rackd/rackd.db"), Database::Sqlite("/var/lib/rackd/rackd.db".into()));
        assert_eq!(sqlite("./a:b.db"), Database::Sqlite("./a:b.db".into()));
        assert!(matches!(Database::parse("postgres://u:p@h/db"), Ok(Database::Postgres(_))));
        for other in ["mysql://u:p@h/db", "postgres//u:p@h/db", "postgres:u:p@h/db", "sqlite:", ""] {
            let e = Database::parse(other).unwrap_err().to_string();
            assert!(!e.contains(":p@"), "{other}: {e}");
        }
    }

    #[test]
    fn servers_older_than_14_are_refused() {
        assert!(supported("140000") && supported("150018") && supported("170002\n"));
        assert!(!supported("130016") && !supported("90624") && !supported("") && !supported("x"));
        let e = OpenError::Version { found: "13.16".into() };
        assert_eq!(
            e.to_string(),
            "PostgreSQL 13.16 is not supported: rackd needs PostgreSQL 14 or newer (server_version_num 140000 and up)"
        );
    }

    #[test]
    fn passwords_stay_out_of_messages() {
        let db = Database::Postgres("postgres://rackd:s3cret@db.plant:5432/rackd?sslmode=require".into());
        assert_eq!(db.display(), "postgres://rackd:***@db.plant:5432/rackd?sslmode=require");
    }

    #[test]
    fn without_sslmode_a_remote_host_requires_tls_and_a_ca_means_verify_full() {
        let mode = |url: &str, ca: bool| mode_name(PgTls::of(url).effective(ca, None));
        assert_eq!(mode("postgres://u:p@db.plant:5432/rackd", false), "require");
        assert_eq!(mode("postgres://u@10.0.0.5/rackd", false), "require");
        for local in [
            "postgres://u@127.0.0.1:5432/rackd",
            "postgres://u@localhost/rackd",
            "postgres://u@[::1]:5432/rackd",
            "postgres:///rackd?host=/run/postgresql",
        ] {
            assert_eq!(mode(local, false), "prefer", "{local}");
        }
        assert_eq!(mode("postgres://u@db.plant/rackd", true), "verify-full");
        assert_eq!(mode("postgres://u@db.plant/rackd?sslmode=require", true), "verify-ca", "libpq's rule");
        assert_eq!(mode("postgres://u@db.plant/rackd?sslmode=disable", false), "disable");
        assert_eq!(mode("postgres://u@db.plant/rackd?sslmode=prefer", false), "prefer");
        assert_eq!(mode("postgres://u@127.0.0.1/rackd?ssl-mode=VERIFY-FULL", true), "verify-full");
        let tls = PgTls::of("postgres://u@h/db?sslmode=verify-ca&sslrootcert=%2Fetc%2Fca.pem");
        assert_eq!(tls.root_cert.as_deref(), Some(Path::new("/etc/ca.pem")));
        assert!(matches!(PgTls::of("postgres://u@h/db?sslmode=allow").check(), Err(SslModeError::Allow)));
        assert!(PgTls::of("postgres://u@h/db?sslmode=verify-full").check().is_ok());
    }

    #[test]
    fn set_statements_take_one_json_parameter() {
        let sql = Engine::Sqlite.insert_json("audit", &["id", "by"]);
        assert_eq!(
            sql,
            "INSERT OR FAIL INTO audit (id, by) SELECT value->>'id' AS id, value->>'by' AS by FROM json_each($1)"
        );
        let sql = Engine::Sqlite.update_json("jobs", &["id"], &["state"]);
        assert!(sql.starts_with("UPDATE OR FAIL jobs SET state = r.state FROM (SELECT "), "{sql}");
        let sql = Engine::Postgres.insert_json("audit", &["id"]);
        assert!(sql.starts_with("INSERT INTO audit (id) SELECT id FROM json_populate_recordset"), "{sql}");
        let sql = Engine::Postgres.update_json("jobs", &["id"], &["state"]);
        assert_eq!(
            sql,
            "UPDATE jobs SET state = r.state FROM (SELECT id, state FROM json_populate_recordset(NULL::jobs, $1::json)) \
             AS r WHERE jobs.id = r.id"
        );
    }
}
