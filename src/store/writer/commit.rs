//! One group, one transaction: read what it needs, apply it in memory, write it set-based.
//!
//! A group's statements are a constant number whatever its size (see [`super::load`] and
//! [`super::save`]). If the database refuses a statement of the group (a constraint, a
//! trigger, a full disk), the group is rolled back and applied again request by request,
//! each in a savepoint of its own, so that one bad request fails alone and the rest of its
//! group commits; only a failing commit fails them all. A broken connection fails the group
//! at once (the writer then takes a fresh one). Ids and event sequence numbers are handed
//! out in memory and given back with whatever rolls back, so they stay gapless.

use super::apply::{Answer, Group, Next, Out};
use super::{Command, Conn, Tell, WriteError, load, save};
use crate::domain::time::now_ms;
use crate::store::engine::Engine;
use crate::store::on;

/// Applies `group` in one transaction. `next` is the writer's numbering, read from the
/// tables when unknown. Returns the answers, and the events and lock changes of the group.
pub(super) async fn commit(
    db: &mut Conn,
    group: &[Command],
    next: &mut Option<Next>,
    tell: Option<&Tell>,
    shared: bool,
) -> Result<(Vec<Answer>, Out), sqlx::Error> {
    begin(db, shared).await?;
    let all: Vec<&Command> = group.iter().collect();
    let start_read = next.is_none();
    let attempt = async {
        let start = match *next {
            Some(n) => n,
            None => load::next(db).await?,
        };
        let applied = apply(db, &all, start, tell).await?;
        Ok::<_, sqlx::Error>(applied)
    }
    .await;
    match attempt {
        Ok((answers, applied)) => {
            if let Err(e) = run(db, "COMMIT").await {
                rollback(db).await;
                return Err(e);
            }
            *next = Some(applied.next);
            let mut out = applied.out;
            out.statements += 2 + usize::from(start_read);
            return Ok((answers, out));
        }
        // One request, or a failure that is not about what the group asked (the connection,
        // the pool): replaying request by request would only fail again.
        Err(e) if group.len() == 1 || !matches!(e, sqlx::Error::Database(_)) => {
            rollback(db).await;
            return Err(e);
        }
        Err(e) => {
            tracing::warn!(error = %e, requests = group.len(), "group refused; committing its requests one by one");
            rollback(db).await;
        }
    }
    let result = one_by_one(db, group, next, tell, shared).await;
    if result.is_err() {
        rollback(db).await;
    }
    result
}

/// The group again, each request in a savepoint of its own.
async fn one_by_one(
    db: &mut Conn,
    group: &[Command],
    next: &mut Option<Next>,
    tell: Option<&Tell>,
    shared: bool,
) -> Result<(Vec<Answer>, Out), sqlx::Error> {
    begin(db, shared).await?;
    let mut numbers = match *next {
        Some(n) => n,
        None => load::next(db).await?,
    };
    let mut answers = Vec::with_capacity(group.len());
    let mut out = Out::default();
    for cmd in group {
        run(db, "SAVEPOINT request").await?;
        match apply(db, &[cmd], numbers, tell).await {
            Ok((mut answer, applied)) => {
                run(db, "RELEASE SAVEPOINT request").await?;
                numbers = applied.next;
                out.events.extend(applied.out.events);
                out.locks.extend(applied.out.locks);
                out.timings.extend(applied.out.timings);
                out.statements += applied.out.statements + 2;
                answers.push(answer.remove(0));
            }
            Err(e) => {
                tracing::error!(error = %e, "request refused by the database");
                run(db, "ROLLBACK TO SAVEPOINT request").await?;
                run(db, "RELEASE SAVEPOINT request").await?;
                out.statements += 3;
                answers.push(Answer::Failed(WriteError::Database(std::sync::Arc::new(e))));
            }
        }
    }
    run(db, "COMMIT").await?;
    *next = Some(numbers);
    Ok((answers, out))
}

/// Reads, applies and writes `cmds` inside the open transaction.
async fn apply(
    db: &mut Conn,
    cmds: &[&Command],
    next: Next,
    tell: Option<&Tell>,
) -> Result<(Vec<Answer>, Group), sqlx::Error> {
    let mut count = 0;
    let loaded = load::load(db, cmds, &mut count).await?;
    let mut group = Group::new(loaded, next, now_ms(), tell.cloned());
    let answers = cmds.iter().map(|cmd| group.command(cmd)).collect();
    save::save(db, &group, &mut count).await?;
    group.out.statements = count;
    Ok((answers, group))
}

/// Opens the group's transaction; on SQLite it takes the write lock at once. A `shared`
/// writer (one of several on the database) takes the writers' lock on PostgreSQL too (an
/// advisory lock, key 7263001, released with the transaction).
async fn begin(db: &mut Conn, shared: bool) -> Result<(), sqlx::Error> {
    let sql = match (db.engine(), shared) {
        (Engine::Sqlite, _) => "BEGIN IMMEDIATE",
        (Engine::Postgres, false) => "BEGIN",
        (Engine::Postgres, true) => "BEGIN; SELECT pg_advisory_xact_lock(7263001)",
    };
    run(db, sql).await
}

/// Rolls back; a failure to is logged (the connection then fails the next group too).
async fn rollback(db: &mut Conn) {
    if let Err(e) = run(db, "ROLLBACK").await {
        tracing::error!(error = %e, "rollback failed");
    }
}

async fn run(db: &mut Conn, sql: &'static str) -> Result<(), sqlx::Error> {
    on!(Conn, db, c => sqlx::raw_sql(sql).execute(&mut *c).await.map(drop))?;
    Ok(())
}
