//! The store: jobs, job history, locations, alarms, controls and the event log, on one of
//! two engines through sqlx: SQLite (embedded, the default: `database.path`) or PostgreSQL
//! (`database.url`, for sites that outgrow one machine).
//!
//! Decisions:
//! - **One enum over the two pools** ([`Pool`]) rather than a trait with a crate per engine:
//!   every query is written once, with `$1` placeholders both engines accept, and the
//!   [`on!`] macro compiles it for each engine (sqlx checks the types per engine, and the
//!   row types derive `FromRow` for both). The few statements whose text must differ (the
//!   writer's set-based statements, which read their rows from one JSON parameter) are
//!   built in one place, [`engine`].
//! - **Both schemas use the same types**: every integer column is 64-bit (`INTEGER` in
//!   SQLite, `BIGINT` in PostgreSQL) and every flag a boolean (0/1 in SQLite), so one row
//!   type per table reads both. Migrations are per engine, in `migrations/sqlite` and
//!   `migrations/postgres`.
//! - **No `query!` macros**: they check a query against one engine's schema at build time,
//!   and every query here runs on two; the tests run every query on both engines instead
//!   (tests/store and the API suite on each), which also needs no database at build time.
//! - Durability: SQLite runs in WAL mode; the writer's connection commits with
//!   `synchronous=NORMAL` and the writer syncs the WAL itself before it answers anyone
//!   (`writer::durable`), every other connection keeps `synchronous=FULL`. PostgreSQL runs
//!   with its defaults (`synchronous_commit=on`). Either way nothing is answered before it
//!   is on disk, so a 201 means the job survives a power cut. Every change goes through
//!   one writer ([`writer::Writer`]) that commits many requests per transaction.
//! - Migrations run through [`schema`], not sqlx's migrator: a node runs on a schema newer
//!   than it knows when each newer migration is recorded compatible with it (each
//!   migration's `-- compatible-from: N` line, kept in `_rackd_migrations`), which is what
//!   lets a hot-standby site upgrade one node at a time and roll back. The rule migrations
//!   follow is [`schema::rule`].

pub mod alarms;
pub mod archive;
pub mod cluster;
mod columns;
pub mod controls;
pub mod copy;
pub mod counts;
pub mod engine;
pub mod events;
pub mod fault;
pub mod hosts;
pub mod import;
pub mod jobs;
pub mod locations;
pub mod paging;
pub mod rollups;
pub mod schema;
pub mod sequences;
pub mod stats;
pub mod webhooks;
pub mod writer;

use std::time::Duration;

use sqlx::{PgPool, SqlitePool};

pub use engine::{
    Database, DatabaseError, Engine, OpenError, PgTls, SQLITE_PAGE_SIZE, Settings, SslModeError,
};
pub use jobs::{Job, JobEvent, JobFilter};

/// The migrations of each engine, embedded in the binary.
pub static SQLITE_MIGRATOR: sqlx::migrate::Migrator = sqlx::migrate!("./migrations/sqlite");
/// See [`SQLITE_MIGRATOR`].
pub static POSTGRES_MIGRATOR: sqlx::migrate::Migrator = sqlx::migrate!("./migrations/postgres");

/// A connection pool to the store, on either engine.
#[derive(Clone, Debug)]
pub enum Pool {
    /// An embedded SQLite file.
    Sqlite(SqlitePool),
    /// A PostgreSQL server.
    Postgres(PgPool),
}

/// Runs `$body` with `$p` bound to the engine's own value of `$value` (a [`Pool`] or any
/// enum with the same two variants), compiling it once per engine.
macro_rules! on {
    ($ty:ident, $value:expr, $p:ident => $body:expr) => {
        match $value {
            $ty::Sqlite($p) => $body,
            $ty::Postgres($p) => $body,
        }
    };
}
pub(crate) use on;

/// A write transaction outside the writer ([`Pool::write_tx`]).
pub(crate) enum Tx {
    Sqlite(sqlx::Transaction<'static, sqlx::Sqlite>),
    Postgres(sqlx::Transaction<'static, sqlx::Postgres>),
}

/// Where a read runs: on the pool, or inside a read transaction ([`Pool::read_tx`]).
pub enum Reader<'a> {
    /// A SQLite pool.
    Sqlite(&'a SqlitePool),
    /// A PostgreSQL pool.
    Postgres(&'a PgPool),
    /// A SQLite read transaction.
    SqliteTx(&'a mut sqlx::SqliteConnection),
    /// A PostgreSQL read transaction.
    PostgresTx(&'a mut sqlx::PgConnection),
}

/// Runs `$body` with `$p` bound to the executor of `$reader` (a [`Reader`]), compiling it
/// once per engine and kind of executor.
macro_rules! read {
    ($reader:expr, $p:ident => $body:expr) => {
        match $reader {
            $crate::store::Reader::Sqlite($p) => $body,
            $crate::store::Reader::Postgres($p) => $body,
            $crate::store::Reader::SqliteTx($p) => $body,
            $crate::store::Reader::PostgresTx($p) => $body,
        }
    };
}
pub(crate) use read;

impl<'a> From<&'a Pool> for Reader<'a> {
    fn from(pool: &'a Pool) -> Reader<'a> {
        match pool {
            Pool::Sqlite(p) => Reader::Sqlite(p),
            Pool::Postgres(p) => Reader::Postgres(p),
        }
    }
}

/// A read transaction: every read in it sees the store as of one moment.
pub enum ReadTx {
    /// On SQLite (a deferred transaction holds one WAL snapshot from its first read).
    Sqlite(sqlx::Transaction<'static, sqlx::Sqlite>),
    /// On PostgreSQL (`REPEATABLE READ, READ ONLY`).
    Postgres(sqlx::Transaction<'static, sqlx::Postgres>),
}

impl ReadTx {
    /// Reads inside the transaction.
    pub fn reader(&mut self) -> Reader<'_> {
        match self {
            ReadTx::Sqlite(tx) => Reader::SqliteTx(&mut *tx),
            ReadTx::Postgres(tx) => Reader::PostgresTx(&mut *tx),
        }
    }

    /// Ends the transaction.
    pub async fn finish(self) -> Result<(), sqlx::Error> {
        on!(ReadTx, self, tx => tx.commit().await)
    }
}

impl Pool {
    /// Which engine this is.
    pub fn engine(&self) -> Engine {
        match self {
            Pool::Sqlite(_) => Engine::Sqlite,
            Pool::Postgres(_) => Engine::Postgres,
        }
    }

    /// The migrations this engine's schema is made of.
    pub fn migrator(&self) -> &'static sqlx::migrate::Migrator {
        self.engine().migrator()
    }

    /// Starts a read transaction (see [`ReadTx`]).
    pub async fn read_tx(&self) -> Result<ReadTx, sqlx::Error> {
        Ok(match self {
            Pool::Sqlite(p) => ReadTx::Sqlite(p.begin().await?),
            Pool::Postgres(p) => {
                let mut tx = p.begin().await?;
                sqlx::raw_sql("SET TRANSACTION ISOLATION LEVEL REPEATABLE READ, READ ONLY")
                    .execute(&mut *tx)
                    .await?;
                ReadTx::Postgres(tx)
            }
        })
    }

    /// Starts a write transaction outside the writer (`db copy`, [`import`]): on SQLite
    /// `BEGIN IMMEDIATE`, which takes the write lock at once (waiting up to the busy
    /// timeout) rather than failing at the first write when rackd's writer committed since.
    pub(crate) async fn write_tx(&self) -> Result<Tx, sqlx::Error> {
        Ok(match self {
            Pool::Sqlite(p) => Tx::Sqlite(p.begin_with("BEGIN IMMEDIATE").await?),
            Pool::Postgres(p) => Tx::Postgres(p.begin().await?),
        })
    }

    /// Closes every connection (waits for the ones in use).
    pub async fn close(&self) {
        on!(Pool, self, p => p.close().await)
    }
}

/// Opens (creating a SQLite file if needed) the store and applies pending migrations; a
/// PostgreSQL server older than [`engine::MIN_POSTGRES`] is refused, and so is a schema
/// newer than this rackd that is not compatible with it ([`schema`]).
pub async fn open(database: &Database, busy_timeout: Duration) -> Result<Pool, OpenError> {
    open_with(database, busy_timeout, Settings::default()).await
}

/// As [`open`], with the engine's own settings (a PostgreSQL server's CA file, a SQLite VFS).
pub async fn open_with(
    database: &Database,
    busy_timeout: Duration,
    settings: Settings<'_>,
) -> Result<Pool, OpenError> {
    let known = schema::Known::new(database.engine().migrator());
    Ok(open_known(database, busy_timeout, settings, &known).await?.0)
}

/// As [`open_with`], for a node that knows the migrations `known` (its engine's, or
/// another release's in tests); also says what the migration found.
pub async fn open_known(
    database: &Database,
    busy_timeout: Duration,
    settings: Settings<'_>,
    known: &schema::Known,
) -> Result<(Pool, schema::Found), OpenError> {
    let pool = engine::connect(database, busy_timeout, 8, settings).await?;
    let found = schema::migrate(&pool, known).await?;
    rollups::rebuild::fill_once(&pool).await?;
    Ok((pool, found))
}

/// Why the store is not ready.
#[derive(Debug, thiserror::Error)]
pub enum NotReady {
    /// The database does not answer.
    #[error("the database does not answer: {0}")]
    Unreachable(#[from] sqlx::Error),
    /// A migration this version needs is not applied.
    #[error("migration {version} ({description}) is not applied")]
    Migration {
        /// The migration's version.
        version: i64,
        /// What it does.
        description: String,
    },
}

/// Whether the database answers and every embedded migration is applied.
pub async fn ready(pool: &Pool) -> Result<(), NotReady> {
    let sql = "SELECT version FROM _sqlx_migrations WHERE success = TRUE";
    let applied: Vec<i64> = on!(Pool, pool, p => sqlx::query_scalar(sql).fetch_all(p).await)?;
    match pool.migrator().iter().find(|m| !applied.contains(&m.version)) {
        Some(m) => Err(NotReady::Migration { version: m.version, description: m.description.to_string() }),
        None => Ok(()),
    }
}
