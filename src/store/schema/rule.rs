//! The rule for migrations, read from a migration's own text: the compatibility it claims
//! (its `-- compatible-from: N` line, [`compatible_from`]) and the statements that would
//! break a node of an earlier schema ([`breaking`]), which the test below refuses in every
//! migration after [`BASELINE`] that claims older nodes run on it.
//!
//! The rule (docs/development/migrations.md has it for people):
//! - Within a release line a migration is **additive**: new tables, new columns that are
//!   nullable or have a default, new indexes. It says `-- compatible-from: P`, P being the
//!   newest migration of the previous release: nodes of that release run on it.
//! - A **removal or a rename** comes a release after the code stopped using what it
//!   removes; its migration says so on a `-- removal:` line (what, unused since when) and
//!   claims compatibility with the release that stopped using it. The test cannot read the
//!   code's queries: the line is the author's word, for the reviewer to check.
//! - A migration nothing older can run on says `-- compatible-from:` its own version:
//!   every node must be upgraded before it starts (stop them all, as before this rule).
//!
//! The check is a plain reading of the text, on purpose: comments are dropped, statements
//! split at `;`, and a statement is breaking when it drops or renames anything, alters a
//! column (type, `NOT NULL`, default), adds a constraint to a table, or adds a `NOT NULL`
//! column without a default. A `CREATE UNIQUE INDEX` on an existing table could refuse an
//! old node's writes too; it is left to review (a unique index on a new table is common
//! and harmless).

/// The newest migration written before the rule: the ones up to it carry no
/// `-- compatible-from:` line and are not checked (every node that checks compatibility
/// knows them all).
pub const BASELINE: i64 = 12;

/// The `-- compatible-from: N` line's N, if the migration has one.
pub fn compatible_from(sql: &str) -> Option<i64> {
    sql.lines().find_map(|line| line.trim().strip_prefix("-- compatible-from:")?.trim().parse().ok())
}

/// Whether the migration has a `-- removal:` line (see the module documentation).
pub fn says_removal(sql: &str) -> bool {
    sql.lines().any(|line| line.trim().starts_with("-- removal:"))
}

/// The statements of `sql` that a node of an earlier schema could break on, as written
/// (whitespace folded, lowercase).
pub fn breaking(sql: &str) -> Vec<String> {
    let text: String = sql
        .lines()
        .map(|line| line.split_once("--").map_or(line, |(code, _)| code))
        .collect::<Vec<_>>()
        .join(" ")
        .to_lowercase();
    text.split(';')
        .map(|s| s.split_whitespace().collect::<Vec<_>>().join(" "))
        .filter(|s| !s.is_empty() && is_breaking(s))
        .collect()
}

/// One statement, whitespace folded and lowercase.
fn is_breaking(statement: &str) -> bool {
    let words: Vec<&str> = statement.split(' ').collect();
    let has = |w: &str| words.contains(&w);
    if words.first() == Some(&"drop") || has("rename") {
        return true;
    }
    if !statement.starts_with("alter table") {
        return false;
    }
    let adds_column = has("add") && !has("constraint");
    has("drop")
        || statement.contains(" alter column ")
        || (has("add") && has("constraint"))
        || (adds_column && statement.contains(" not null") && !has("default"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::store::{POSTGRES_MIGRATOR, SQLITE_MIGRATOR};

    #[test]
    fn breaking_statements_are_found() {
        for sql in [
            "DROP TABLE jobs;",
            "drop index jobs_by_state",
            "ALTER TABLE jobs DROP COLUMN note;",
            "ALTER TABLE jobs RENAME COLUMN note TO remark;",
            "ALTER TABLE jobs RENAME TO tasks",
            "ALTER TABLE jobs ALTER COLUMN note TYPE BIGINT",
            "ALTER TABLE jobs\n  ALTER COLUMN note SET NOT NULL;",
            "ALTER TABLE jobs ADD COLUMN note TEXT NOT NULL;",
            "ALTER TABLE jobs ADD note TEXT NOT NULL",
            "ALTER TABLE jobs ADD CONSTRAINT positive CHECK (priority > 0)",
        ] {
            assert_eq!(breaking(sql).len(), 1, "{sql}");
        }
    }

    #[test]
    fn additive_statements_pass() {
        let sql = "-- compatible-from: 12\n-- drop nothing, rename nothing: comments are not read\n\
                   CREATE TABLE notes (id BIGINT PRIMARY KEY, text TEXT NOT NULL, CONSTRAINT c CHECK (id > 0));\n\
                   ALTER TABLE jobs ADD COLUMN note TEXT;\n\
                   ALTER TABLE cluster_nodes ADD COLUMN version TEXT NOT NULL DEFAULT '';\n\
                   CREATE INDEX notes_by_text ON notes (text);\n\
                   CREATE UNIQUE INDEX notes_once ON notes (text);";
        assert_eq!(breaking(sql), Vec::<String>::new());
        assert_eq!(compatible_from(sql), Some(12));
        assert!(!says_removal(sql));
        assert_eq!(compatible_from("CREATE TABLE t (x INTEGER);"), None);
        assert_eq!(compatible_from("-- compatible-from: 0011\n"), Some(11));
    }

    /// The rule, over every migration of both engines (migrations/sqlite and
    /// migrations/postgres, as compiled in).
    #[test]
    fn migrations_after_the_baseline_follow_the_rule() {
        for (engine, migrator) in [("sqlite", &SQLITE_MIGRATOR), ("postgres", &POSTGRES_MIGRATOR)] {
            for m in migrator.iter().filter(|m| m.version > BASELINE) {
                let (sql, name) = (m.sql.as_str(), format!("migrations/{engine}: {:04}", m.version));
                let from = compatible_from(sql).unwrap_or_else(|| {
                    panic!("{name} has no `-- compatible-from: N` line (docs/development/migrations.md)")
                });
                assert!(from <= m.version, "{name} claims compatibility from a later schema, {from}");
                if from < m.version && !says_removal(sql) {
                    let found = breaking(sql);
                    assert!(
                        found.is_empty(),
                        "{name} claims older nodes run on it (compatible-from: {from}) but is not additive: {found:?}"
                    );
                }
            }
        }
    }
}
