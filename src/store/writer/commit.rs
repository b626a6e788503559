//! One group, one transaction: read what it needs, apply it in memory, write it set-based.
//!
//! A group's statements are a constant number whatever its size (see [`super::load`] and
//! [`super::save`]). If the database refuses a statement of the group (a constraint, a
//! trigger, a full disk), the group is rolled back and applied again request by request,
//! each in a savepoint of its own, so that one bad request fails alone and the rest of its
//! group commits; only a failing commit fails them all. A broken connection fails the group
//! at once (the writer then takes a fresh one). Ids and event sequence numbers are handed
//! out in memory and given back with whatever rolls back, so they stay gapless.
//!
//! A group does not read the jobs its submissions' references name unless the writer has
//! lately seen one stored (see [`load`]): if the unique index on `jobs.reference` refuses
//! the group, it is rolled back and applied again, reading them, before anything is
//! answered, so each request gets the answer it would have had (its stored job, or the
//! conflict). Only what was committed is answered: the attempt rolled back leaves nothing.

use super::apply::{Answer, Group, Loaded, Next, Out, Spare};
use super::unsure::{self, Session, Token, Unsure};
use super::{Command, Conn, Sent, Tell, WriteError, load, save, stream};
use crate::domain::time::now_ms;
use crate::store::cluster::{self, LEASE};
use crate::store::engine::Engine;
use crate::store::on;

/// Applies `group` in one transaction. `carry.next` is the writer's numbering, read from
/// the tables when unknown; `carry.references` says whether the group reads the stored jobs
/// its submissions' references name first (see [`load`]): if it does not and the unique index
/// refuses one, the group is rolled back and applied again, reading them. Returns the
/// answers, and the events and lock changes of the group. A command sent fenced whose epoch
/// no longer holds the cluster's lease is answered [`WriteError::Fenced`] and left out; the
/// check locks the lease row until the commit. A failed `COMMIT` on PostgreSQL is
/// [`Failed::Unsure`], to be settled by reading what landed (see [`unsure`]).
pub(super) async fn commit(
    db: &mut Conn,
    group: &[Sent],
    carry: &mut Carry,
    tell: Option<&Tell>,
    shared: bool,
) -> Result<(Vec<Answer>, Out), Failed> {
    if let Conn::Postgres(c) = &mut *db
        && carry.session.is_none()
    {
        carry.session = Some(unsure::session(c).await?);
    }
    let mut read = carry.references.read();
    loop {
        begin(db, shared).await?;
        let held = match fences(db, group).await {
            Ok(held) => held,
            Err(e) => {
                rollback(db).await;
                return Err(e.into());
            }
        };
        let kept: Vec<&Command> = group.iter().zip(&held).filter(|(_, h)| **h).map(|(s, _)| &s.cmd).collect();
        match kept_in_one(db, &kept, carry, read, tell, shared).await? {
            Attempt::Committed(answers, out, stored) => {
                carry.references.committed(stored);
                return Ok((merge(group, &held, answers), out));
            }
            Attempt::Unsure(mut unsure) => {
                unsure.answers = merge(group, &held, std::mem::take(&mut unsure.answers));
                return Err(Failed::Unsure(unsure));
            }
            Attempt::Stored => {
                carry.references.stored();
                read = true;
            }
            Attempt::Refused => {
                let result = one_by_one(db, &kept, carry, tell, shared, group, &held).await;
                if let Err(Failed::Sure(_)) = result {
                    rollback(db).await;
                }
                return match result {
                    Ok((answers, out)) => Ok((merge(group, &held, answers), out)),
                    Err(Failed::Unsure(mut unsure)) => {
                        unsure.answers = merge(group, &held, std::mem::take(&mut unsure.answers));
                        Err(Failed::Unsure(unsure))
                    }
                    Err(e) => Err(e),
                };
            }
        }
    }
}

/// What the writer carries from one group to the next.
#[derive(Default)]
pub(super) struct Carry {
    /// The writer's numbering: `None` until read, and again after a failed group.
    pub(super) next: Option<Next>,
    /// Whether groups read their references first (see [`load::References`]).
    references: load::References,
    /// Memory a group leaves to the next.
    spare: Spare,
    /// The mark each group leaves on PostgreSQL (see [`unsure`]).
    token: Token,
    /// The writer's session on PostgreSQL, read on its first group.
    session: Option<Session>,
}

impl Carry {
    /// The writer's connection broke: its session is another from now on, and after a
    /// failed group its numbering is read again.
    pub(super) fn lost(&mut self, failed: bool) {
        self.session = None;
        if failed {
            self.next = None;
        }
    }

    /// An unsure group landed: carry on from it.
    pub(super) fn landed(&mut self, unsure: &Unsure) {
        self.next = Some(unsure.next);
        if let Some(stored) = unsure.stored {
            self.references.committed(stored);
        }
    }
}

/// How a group failed.
pub(super) enum Failed {
    /// Nothing of it was written.
    Sure(sqlx::Error),
    /// Its `COMMIT` failed on PostgreSQL: it may have landed (see [`unsure`]).
    Unsure(Box<Unsure>),
}

impl From<sqlx::Error> for Failed {
    fn from(e: sqlx::Error) -> Failed {
        Failed::Sure(e)
    }
}

/// How the attempt to commit a group's kept commands in one transaction went (rolled back
/// unless committed).
// One a group, alive until the group is answered: its size does not matter, and boxing what
// the group did would cost an allocation per commit.
#[allow(clippy::large_enum_variant)]
enum Attempt {
    /// Committed: their answers, what the group did, and whether it read a reference stored
    /// already.
    Committed(Vec<Answer>, Out, bool),
    /// Refused by a unique index, its references not read: a reference was stored already.
    Stored,
    /// Refused by the database: to be replayed request by request.
    Refused,
    /// Its `COMMIT` failed on PostgreSQL.
    Unsure(Box<Unsure>),
}

/// Whether each command of `group` may be committed: unfenced, or fenced under the epoch
/// that holds the lease now.
async fn fences(db: &mut Conn, group: &[Sent]) -> Result<Vec<bool>, sqlx::Error> {
    let epochs: std::collections::BTreeSet<i64> = group.iter().filter_map(|s| s.epoch).collect();
    let mut holds = std::collections::BTreeMap::new();
    for epoch in epochs {
        let held = match db {
            Conn::Postgres(c) => cluster::fence(c, LEASE, epoch).await?,
            Conn::Sqlite(_) => false,
        };
        holds.insert(epoch, held);
    }
    Ok(group.iter().map(|s| s.epoch.is_none_or(|e| holds[&e])).collect())
}

/// The answers of the kept commands, with the fenced ones put back in their places.
fn merge(group: &[Sent], held: &[bool], answers: Vec<Answer>) -> Vec<Answer> {
    if held.iter().all(|h| *h) {
        return answers;
    }
    let mut answers = answers.into_iter();
    group
        .iter()
        .zip(held)
        .map(|(s, h)| match h {
            true => answers.next().unwrap_or(Answer::Failed(WriteError::Closed)),
            false => Answer::Failed(WriteError::Fenced(s.epoch)),
        })
        .collect()
}

/// The kept commands in the open transaction, committed (see [`Attempt`]); `read` says
/// whether their submissions' references are read first.
async fn kept_in_one(
    db: &mut Conn,
    all: &[&Command],
    carry: &mut Carry,
    read: bool,
    tell: Option<&Tell>,
    shared: bool,
) -> Result<Attempt, sqlx::Error> {
    let start_read = carry.next.is_none();
    let attempt = async {
        let start = match carry.next {
            Some(n) => n,
            None => load::next(db).await?,
        };
        let applied = apply(db, all, start, &mut carry.spare, read, tell).await?;
        Ok::<_, sqlx::Error>(applied)
    }
    .await;
    match attempt {
        Ok((answers, mut applied)) => {
            let token = carry.token.next();
            let committed = finish(db, shared, &token.1).await;
            applied.recycle(&mut carry.spare);
            let stored = applied.read_stored();
            let mut out = applied.out;
            out.statements += 2 + usize::from(start_read);
            match committed {
                Ok(()) => {
                    carry.next = Some(applied.next);
                    Ok(Attempt::Committed(answers, out, stored))
                }
                Err(error) if db.engine() == Engine::Postgres => Ok(Attempt::Unsure(Box::new(Unsure {
                    answers,
                    out,
                    next: applied.next,
                    stored: Some(stored),
                    token: carry.token,
                    session: carry.session.clone(),
                    error,
                }))),
                Err(e) => {
                    rollback(db).await;
                    Err(e)
                }
            }
        }
        Err(e) if !read && e.as_database_error().is_some_and(|d| d.is_unique_violation()) => {
            tracing::debug!(error = %e, "a reference of the group is stored already; applying it again, reading them");
            rollback(db).await;
            Ok(Attempt::Stored)
        }
        // One request, or a failure that is not about what the group asked (the connection,
        // the pool): replaying request by request would only fail again.
        Err(e) if all.len() <= 1 || !matches!(e, sqlx::Error::Database(_)) => {
            rollback(db).await;
            Err(e)
        }
        Err(e) => {
            tracing::warn!(error = %e, requests = all.len(), "group refused; committing its requests one by one");
            rollback(db).await;
            Ok(Attempt::Refused)
        }
    }
}

/// The group again, each request in a savepoint of its own (the fences checked again in
/// the new transaction: `held` must still hold, or the group fails and is answered as a
/// failed commit).
async fn one_by_one(
    db: &mut Conn,
    kept: &[&Command],
    carry: &mut Carry,
    tell: Option<&Tell>,
    shared: bool,
    group: &[Sent],
    held: &[bool],
) -> Result<(Vec<Answer>, Out), Failed> {
    begin(db, shared).await?;
    if fences(db, group).await? != held {
        return Err(sqlx::Error::Protocol("the cluster lease moved during the group".into()).into());
    }
    let mut numbers = match carry.next {
        Some(n) => n,
        None => load::next(db).await?,
    };
    let mut answers = Vec::with_capacity(kept.len());
    let mut out = Out::default();
    for cmd in kept {
        run(db, "SAVEPOINT request").await?;
        match apply(db, &[cmd], numbers, &mut carry.spare, true, tell).await {
            Ok((mut answer, mut applied)) => {
                run(db, "RELEASE SAVEPOINT request").await?;
                applied.recycle(&mut carry.spare);
                numbers = applied.next;
                out.events.extend(applied.out.events);
                out.locks.extend(applied.out.locks);
                out.timings.extend(applied.out.timings);
                out.counts.add(&applied.out.counts);
                out.sequences.extend(applied.out.sequences);
                out.statements += applied.out.statements + 2;
                out.writes += applied.out.writes;
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
    let token = carry.token.next();
    match finish(db, shared, &token.1).await {
        Ok(()) => {
            carry.next = Some(numbers);
            Ok((answers, out))
        }
        Err(error) if db.engine() == Engine::Postgres => Err(Failed::Unsure(Box::new(Unsure {
            answers,
            out,
            next: numbers,
            stored: None,
            token: carry.token,
            session: carry.session.clone(),
            error,
        }))),
        Err(e) => Err(e.into()),
    }
}

/// Reads (their references if `read`), applies and writes `cmds` inside the open transaction.
async fn apply(
    db: &mut Conn,
    cmds: &[&Command],
    next: Next,
    spare: &mut Spare,
    read: bool,
    tell: Option<&Tell>,
) -> Result<(Vec<Answer>, Group), sqlx::Error> {
    let mut count = 0;
    if !read
        && let Conn::Sqlite(c) = &mut *db
        && stream::fits(cmds)
    {
        // Submissions only, their references not read: nothing to load.
        let mut group = Group::new(Loaded::default(), next, now_ms(), tell.cloned(), cmds, spare);
        let (answers, written) = stream::submissions(c, cmds, &mut group, &mut count).await?;
        group.audit_submissions();
        group.counted();
        save::save(db, &group, written, &mut count).await?;
        (group.out.statements, group.out.writes) = (count, count);
        return Ok((answers, group));
    }
    let loaded = load::load(db, cmds, read, &mut count).await?;
    let reads = count;
    let mut group = Group::new(loaded, next, now_ms(), tell.cloned(), cmds, spare);
    let answers = cmds.iter().map(|cmd| group.command(cmd)).collect();
    group.audit_submissions();
    group.counted();
    save::save(db, &group, save::Written::default(), &mut count).await?;
    (group.out.statements, group.out.writes) = (count, count - reads);
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

/// Commits. On PostgreSQL the group's mark (`mark`, see [`unsure`]) goes in the same
/// message, and a `shared` writer notifies [`NOTIFY_CHANNEL`] there too (sent by the server
/// at the commit, and only if it commits), so the other nodes read the new events.
async fn finish(db: &mut Conn, shared: bool, mark: &str) -> Result<(), sqlx::Error> {
    let sql = match (db.engine(), shared) {
        (Engine::Sqlite, _) => return run(db, "COMMIT").await,
        (Engine::Postgres, true) => format!("{mark}; NOTIFY rackd_commits; COMMIT"),
        (Engine::Postgres, false) => format!("{mark}; COMMIT"),
    };
    on!(Conn, db, c => sqlx::raw_sql(sqlx::AssertSqlSafe(sql)).execute(&mut *c).await.map(drop))
}

/// The channel a shared writer notifies at each commit (see [`finish`]).
pub const NOTIFY_CHANNEL: &str = "rackd_commits";

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
