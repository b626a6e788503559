//! A large group of submissions on SQLite, written while it is applied.
//!
//! A group is applied in memory on the writer's thread, then written by SQLite's thread
//! (sqlx runs a SQLite connection on a thread of its own). Done one after the other, each
//! thread waits for the other half the time: in a group of batches, applying took about
//! 4 µs a job and the inserts about 6, and `/proc/stat` showed the machine a third idle.
//! So a group of submissions only, with more new jobs than one insert statement takes, is
//! written as it is applied: after each submission, as soon as a full statement's rows are
//! ready (2047 jobs, or 8191 history entries or events) and SQLite's thread is free, they
//! go to it, and the writer applies the next submissions while SQLite inserts them. What
//! is left at the end goes as [`save::intake`] writes any group. Measured with `bench
//! intake`, four ABBA blocks: batches 83,187 → 87,462 jobs a second (+5%, ahead or level
//! in each block) for the same CPU time per job; single POSTs never take this path.
//!
//! Nothing changes for what is written or answered: the same rows in the same transaction,
//! the same ids and event numbers, and a refused statement fails the group as before
//! ([`super::commit`] rolls it back and applies it again). Only groups that do not read
//! their references are streamed (see [`super::load`]): a submission never reads what an
//! earlier one of its group wrote, so writing early changes nothing it sees.

use std::future::Future;
use std::pin::Pin;
use std::task::Poll;

use sqlx::sqlite::SqliteQueryResult;
use sqlx::{QueryBuilder, Sqlite, SqliteConnection};

use super::Command;
use super::apply::{Answer, Group};
use super::save::{self, Written, poll_once};

/// Whether `cmds` are streamed: submissions only, with more new jobs than one statement
/// takes (fewer leave nothing to write before the end).
pub(super) fn fits(cmds: &[&Command]) -> bool {
    let mut jobs = 0;
    for cmd in cmds {
        match cmd {
            // Terms are checked against what is stored: read first.
            Command::Submit { jobs: new, .. } if new.iter().all(|j| j.terms.is_plain()) => jobs += new.len(),
            _ => return false,
        }
    }
    jobs > save::JOBS_PER_STATEMENT
}

/// A statement on SQLite's thread, handing the connection back when done.
type Flight<'c> = Pin<
    Box<dyn Future<Output = (&'c mut SqliteConnection, Result<SqliteQueryResult, sqlx::Error>)> + Send + 'c>,
>;

/// The connection: free for the next statement, or running one.
enum Line<'c> {
    Free(&'c mut SqliteConnection),
    Busy(Flight<'c>),
}

impl<'c> Line<'c> {
    /// Free again if its statement is done (or failed: the error), else still busy.
    async fn check(self) -> Result<Line<'c>, sqlx::Error> {
        match self {
            Line::Busy(mut flight) => match poll_once(&mut flight).await {
                Poll::Ready((c, result)) => result.map(|_| Line::Free(c)),
                Poll::Pending => Ok(Line::Busy(flight)),
            },
            free => Ok(free),
        }
    }

    /// The connection once its statement is done.
    async fn free(self) -> Result<&'c mut SqliteConnection, sqlx::Error> {
        match self {
            Line::Busy(flight) => {
                let (c, result) = flight.await;
                result.map(|_| c)
            }
            Line::Free(c) => Ok(c),
        }
    }
}

/// Sends `statement` to SQLite's thread on `c` (its first poll hands it over).
async fn send(
    c: &mut SqliteConnection,
    mut statement: QueryBuilder<Sqlite>,
) -> Result<Line<'_>, sqlx::Error> {
    let flight: Flight<'_> = Box::pin(async move {
        let result = statement.build().persistent(true).execute(&mut *c).await;
        (c, result)
    });
    Line::Busy(flight).check().await
}

/// Applies `cmds` (which [`fits`]) to `group` and writes its intake rows on `c` meanwhile
/// (see the module doc), counting statements in `count`. Returns the answers and how far
/// the intake rows are written (all of them): the rest of what the group produced is left to
/// [`save::save`].
pub(super) async fn submissions(
    c: &mut SqliteConnection,
    cmds: &[&Command],
    group: &mut Group,
    count: &mut usize,
) -> Result<(Vec<Answer>, Written), sqlx::Error> {
    let mut answers = Vec::with_capacity(cmds.len());
    let mut written = Written::default();
    let mut line = Line::Free(c);
    for cmd in cmds {
        answers.push(group.command(cmd));
        line = match line.check().await? {
            Line::Free(c) => match written.next_full(group) {
                Some(chunk) => {
                    *count += 1;
                    send(c, chunk.statement()).await?
                }
                None => Line::Free(c),
            },
            busy => busy,
        };
    }
    let c = line.free().await?;
    // The group's change to the counts of jobs is written with the rest of the group.
    let written = save::intake(c, group, written, &[], count).await?;
    Ok((answers, written))
}
