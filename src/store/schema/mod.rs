//! Migrating the schema, and running on a schema newer than this rackd knows: what lets a
//! hot-standby site upgrade one node at a time and roll back (docs/operations/standby.md,
//! "Upgrades"; the rule migrations follow is [`rule`]).
//!
//! sqlx's migrator refuses to start on a database that holds a migration it does not know
//! (`VersionMissing`), so once a new node migrated, the old one could neither stay as the
//! standby nor be rolled back to. rackd runs the migrations itself ([`migrate`]), with
//! sqlx's own statements (its lock, its `_sqlx_migrations` table, its `apply`), and
//! replaces that refusal by a compatibility check.
//!
//! Decisions:
//! - **A node's schema** is the newest migration it knows ([`Known::latest`]); the
//!   binary's version is told beside it (`GET /api/v1/cluster`).
//! - **Each migration says which nodes may run on it**: a `-- compatible-from: N` line in
//!   its file means that a node whose schema is N or newer runs on a database where it is
//!   applied; a migration without the line is compatible from its own version only (every
//!   migration up to [`rule::BASELINE`] predates the line). The line is part of the
//!   migration's text, so its checksum covers it.
//! - **The database records it**, since a node cannot read a file it does not have: every
//!   node writes, for each migration it knows, `(version, compatible_from)` into
//!   `_rackd_migrations`, beside sqlx's table and created the same way (`CREATE TABLE IF
//!   NOT EXISTS`, not a migration: it must exist before migrations are compared, and its
//!   shape does not change). A row is written once and never changed.
//! - **The check** ([`plan`]): every applied migration the node does not know must be
//!   newer than the node's schema (an older unknown one comes from another line of
//!   releases) and recorded compatible from the node's schema or an older one. A migration
//!   with no record is incompatible: unknown means no. The node then runs, and says so.
//! - **A node never touches what it does not know**: it applies only its own pending
//!   migrations, and none at all while the database holds one it does not know (a node
//!   missing a migration of its own under a newer one is of another line: refused).
//! - A migration it knows whose checksum differs is an error, as with sqlx; so is a failed
//!   (dirty) migration.
//! - All of it runs under sqlx's migration lock (an advisory lock on PostgreSQL), so two
//!   nodes starting at once do not both migrate, and a node's check cannot pass while
//!   another's migration is half done.
//!
//! The window opens with this rule: nodes of a release before it have sqlx's refusal.

pub mod rule;

use std::collections::HashMap;

use sqlx::Connection;
use sqlx::migrate::{Migrate, Migration, Migrator};

// Not `Engine`: `engine::OpenError` holds this module's error (no cycle).
use super::{Pool, on};

/// The migrations a node knows: its engine's embedded ones, or (for tests standing in for
/// another release) fewer or more.
#[derive(Clone, Debug)]
pub struct Known {
    migrations: Vec<Migration>,
}

impl Known {
    /// The migrations of `migrator`: an engine's compiled into this rackd
    /// (`Engine::migrator`).
    pub fn new(migrator: &Migrator) -> Known {
        Known { migrations: migrator.iter().cloned().collect() }
    }

    /// Only the migrations up to `version`: a node of an earlier release, for tests
    /// (`database.known_schema`).
    pub fn up_to(mut self, version: i64) -> Known {
        self.migrations.retain(|m| m.version <= version);
        self
    }

    /// With one more migration: a node of a later release, for tests.
    pub fn with(mut self, migration: Migration) -> Known {
        self.migrations.push(migration);
        self.migrations.sort();
        self
    }

    /// The node's schema: the newest migration it knows (0 for none).
    pub fn latest(&self) -> i64 {
        self.migrations.iter().map(|m| m.version).max().unwrap_or(0)
    }

    fn get(&self, version: i64) -> Option<&Migration> {
        self.migrations.iter().find(|m| m.version == version)
    }
}

/// What [`migrate`] found and did.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Found {
    /// The node's schema ([`Known::latest`]).
    pub known: i64,
    /// The newest migration applied in the database, after migrating.
    pub database: i64,
    /// The applied migrations this node does not know (each compatible with it).
    pub newer: Vec<i64>,
    /// The migrations this node applied.
    pub applied: Vec<i64>,
}

/// Why a node does not run on the database's schema.
#[derive(Debug, thiserror::Error)]
pub enum SchemaError {
    /// The database does not answer, or a statement failed.
    #[error(transparent)]
    Database(#[from] sqlx::Error),
    /// sqlx's lock or a migration failed.
    #[error(transparent)]
    Migrate(#[from] sqlx::migrate::MigrateError),
    /// A migration failed part-way before (`success` is false in `_sqlx_migrations`).
    #[error("migration {0} failed part-way earlier; repair the database before rackd starts on it")]
    Dirty(i64),
    /// A known migration was applied with other content.
    #[error("migration {0} was applied with other content than this rackd's (its checksum differs)")]
    Modified(i64),
    /// A newer migration this node cannot run with.
    #[error(
        "the database holds migration {version} ({description}), newer than this rackd knows (schema {known}), \
         and {why}: upgrade this node to a release that knows migration {version}"
    )]
    Incompatible {
        /// The migration's version.
        version: i64,
        /// Its description, as recorded.
        description: String,
        /// The node's schema.
        known: i64,
        /// Which nodes it says may run on it.
        why: String,
    },
    /// An unknown migration older than the node's schema, or a pending one of its own
    /// under a newer one: two lines of releases.
    #[error(
        "the database holds migration {version} ({description}) that this rackd (schema {known}) does not know, \
         {why}: it comes from another line of releases"
    )]
    Foreign {
        /// The migration's version.
        version: i64,
        /// Its description, as recorded.
        description: String,
        /// The node's schema.
        known: i64,
        /// How it shows.
        why: String,
    },
}

/// A migration as `_sqlx_migrations` holds it.
#[derive(Clone, Debug, sqlx::FromRow)]
pub struct Applied {
    /// Its version.
    pub version: i64,
    /// Its description.
    pub description: String,
    /// Whether it completed.
    pub success: bool,
    /// Its checksum (SHA-384 of its text).
    pub checksum: Vec<u8>,
}

/// What to do: the node's pending migrations (to apply) and the newer ones it runs with.
#[derive(Debug, PartialEq, Eq)]
pub struct Plan {
    /// Known migrations not applied yet, oldest first.
    pub pending: Vec<i64>,
    /// Applied migrations newer than the node, each recorded compatible with it.
    pub newer: Vec<i64>,
}

/// Decides whether a node knowing `known` runs on a database holding `applied`, whose
/// compatibility records are `marks` (version → compatible from). See the module
/// documentation for the rules.
pub fn plan(known: &Known, applied: &[Applied], marks: &HashMap<i64, i64>) -> Result<Plan, SchemaError> {
    if let Some(dirty) = applied.iter().find(|a| !a.success) {
        return Err(SchemaError::Dirty(dirty.version));
    }
    let latest = known.latest();
    let mut newer = Vec::new();
    for a in applied {
        match known.get(a.version) {
            Some(m) if *m.checksum != *a.checksum => return Err(SchemaError::Modified(a.version)),
            Some(_) => {}
            None if a.version < latest => {
                let why = format!("older than its newest, {latest}");
                return Err(foreign(a, latest, why));
            }
            None => match marks.get(&a.version) {
                Some(&from) if from <= latest => newer.push(a.version),
                recorded => {
                    let why = match recorded {
                        Some(from) => format!("it says nodes run on it from schema {from} on"),
                        None => "no record says which nodes may run on it".to_owned(),
                    };
                    let description = a.description.clone();
                    return Err(SchemaError::Incompatible {
                        version: a.version,
                        description,
                        known: latest,
                        why,
                    });
                }
            },
        }
    }
    let pending: Vec<i64> = known
        .migrations
        .iter()
        .map(|m| m.version)
        .filter(|v| !applied.iter().any(|a| a.version == *v))
        .collect();
    if let (Some(&first), Some(&version)) = (pending.first(), newer.first()) {
        let a = applied.iter().find(|a| a.version == version).expect("a newer migration is applied");
        return Err(foreign(a, latest, format!("while this rackd's own migration {first} is not applied")));
    }
    Ok(Plan { pending, newer })
}

fn foreign(a: &Applied, known: i64, why: String) -> SchemaError {
    SchemaError::Foreign { version: a.version, description: a.description.clone(), known, why }
}

const MARKS_TABLE: &str = "CREATE TABLE IF NOT EXISTS _rackd_migrations (\
     version BIGINT PRIMARY KEY, compatible_from BIGINT NOT NULL)";
const MARK: &str = "INSERT INTO _rackd_migrations (version, compatible_from) VALUES ($1, $2) ON CONFLICT (version) DO NOTHING";
const APPLIED: &str = "SELECT version, description, success, checksum FROM _sqlx_migrations ORDER BY version";

/// Brings the database to the migrations `known` holds, or runs on a newer schema it is
/// compatible with (the module documentation has the rules), under sqlx's migration lock.
pub async fn migrate(pool: &Pool, known: &Known) -> Result<Found, SchemaError> {
    let found = on!(Pool, pool, p => {
        let mut conn = p.acquire().await?;
        conn.lock().await?;
        let result = async {
            conn.ensure_migrations_table("_sqlx_migrations").await?;
            sqlx::query(MARKS_TABLE).execute(&mut *conn).await?;
            let applied: Vec<Applied> = sqlx::query_as(APPLIED).fetch_all(&mut *conn).await?;
            let marks: Vec<(i64, i64)> = sqlx::query_as("SELECT version, compatible_from FROM _rackd_migrations")
                .fetch_all(&mut *conn)
                .await?;
            let plan = plan(known, &applied, &marks.into_iter().collect())?;
            for version in &plan.pending {
                let m = known.get(*version).expect("a pending migration is known");
                conn.apply("_sqlx_migrations", m).await?;
            }
            let mut tx = Connection::begin(&mut *conn).await?;
            for m in &known.migrations {
                let from = rule::compatible_from(m.sql.as_str()).unwrap_or(m.version);
                sqlx::query(MARK).bind(m.version).bind(from).execute(&mut *tx).await?;
            }
            tx.commit().await?;
            let database = applied.iter().map(|a| a.version).chain(plan.pending.iter().copied()).max();
            Ok::<_, SchemaError>(Found {
                known: known.latest(),
                database: database.unwrap_or(0),
                newer: plan.newer,
                applied: plan.pending,
            })
        }
        .await;
        // The lock is the session's: a connection back in the pool must not keep it.
        let unlocked = conn.unlock().await;
        let found = result?;
        unlocked?;
        found
    });
    if !found.newer.is_empty() {
        tracing::info!(
            known = found.known,
            database = found.database,
            newer = ?found.newer,
            "the database's schema is newer than this rackd knows, and compatible with it: running on it"
        );
    }
    Ok(found)
}

/// The newest migration applied in the database (0 for none), read now.
pub async fn database_schema(pool: &Pool) -> Result<i64, sqlx::Error> {
    let sql = "SELECT COALESCE(MAX(version), 0) FROM _sqlx_migrations WHERE success = TRUE";
    on!(Pool, pool, p => sqlx::query_scalar(sql).fetch_one(p).await)
}

#[cfg(test)]
mod tests {
    use std::borrow::Cow;

    use sqlx::migrate::MigrationType;

    use super::*;

    fn migration(version: i64, sql: &'static str) -> Migration {
        Migration::new(
            version,
            Cow::Borrowed("m"),
            MigrationType::Simple,
            sqlx::SqlSafeStr::into_sql_str(sqlx::AssertSqlSafe(sql)),
            false,
        )
    }

    fn known(versions: &[i64]) -> Known {
        Known { migrations: versions.iter().map(|v| migration(*v, "SELECT 1")).collect() }
    }

    fn applied(versions: &[i64]) -> Vec<Applied> {
        let sum = migration(0, "SELECT 1").checksum.to_vec();
        let one = |v: &i64| Applied {
            version: *v,
            description: format!("m{v}"),
            success: true,
            checksum: sum.clone(),
        };
        versions.iter().map(one).collect()
    }

    #[test]
    fn a_node_applies_what_it_lacks() {
        let plan = plan(&known(&[1, 2, 3]), &applied(&[1]), &HashMap::new()).unwrap();
        assert_eq!(plan, Plan { pending: vec![2, 3], newer: vec![] });
    }

    #[test]
    fn a_node_runs_on_newer_migrations_marked_compatible_with_it() {
        let marks = HashMap::from([(4, 3), (5, 2)]);
        let plan = plan(&known(&[1, 2, 3]), &applied(&[1, 2, 3, 4, 5]), &marks).unwrap();
        assert_eq!(plan, Plan { pending: vec![], newer: vec![4, 5] });
    }

    #[test]
    fn a_newer_migration_not_marked_compatible_is_refused() {
        let e = plan(&known(&[1, 2, 3]), &applied(&[1, 2, 3, 4]), &HashMap::from([(4, 4)])).unwrap_err();
        assert_eq!(
            e.to_string(),
            "the database holds migration 4 (m4), newer than this rackd knows (schema 3), and it says nodes run on \
             it from schema 4 on: upgrade this node to a release that knows migration 4"
        );
        let e = plan(&known(&[1, 2, 3]), &applied(&[1, 2, 3, 4]), &HashMap::new()).unwrap_err();
        assert!(e.to_string().contains("no record says which nodes may run on it"), "{e}");
    }

    #[test]
    fn another_line_of_releases_is_refused() {
        let e = plan(&known(&[1, 3]), &applied(&[1, 2, 3]), &HashMap::from([(2, 1)])).unwrap_err();
        assert!(matches!(e, SchemaError::Foreign { version: 2, .. }), "{e}");
        let e = plan(&known(&[1, 2, 3]), &applied(&[1, 2, 4]), &HashMap::from([(4, 2)])).unwrap_err();
        assert!(e.to_string().contains("while this rackd's own migration 3 is not applied"), "{e}");
    }

    #[test]
    fn a_changed_or_failed_migration_is_an_error() {
        let mut changed = applied(&[1, 2]);
        changed[1].checksum = vec![0; 48];
        assert!(matches!(plan(&known(&[1, 2]), &changed, &HashMap::new()), Err(SchemaError::Modified(2))));
        let mut failed = applied(&[1, 2]);
        failed[1].success = false;
        assert!(matches!(plan(&known(&[1, 2]), &failed, &HashMap::new()), Err(SchemaError::Dirty(2))));
    }

    #[test]
    fn a_limited_node_knows_fewer() {
        let all = Known::new(&crate::store::POSTGRES_MIGRATOR);
        let fewer = all.clone().up_to(all.latest() - 1);
        assert!(fewer.latest() < all.latest());
        assert_eq!(fewer.clone().with(migration(99, "SELECT 1")).latest(), 99);
    }
}
