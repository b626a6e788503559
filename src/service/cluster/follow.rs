//! The event log as every node of a cluster follows it: each commit of a shared writer
//! notifies [`NOTIFY_CHANNEL`] (the server sends it at the commit, and only if it
//! commits), and this loop reads the events after the last one it handed on, in `seq`
//! order, whichever node committed them. It also reads every `poll` without a
//! notification, since notifications sent while its listening connection was down are
//! lost; nothing else is.
//!
//! Why the order holds: the writers of a cluster number events under one lock held until
//! their commit (`Writer::start_shared`), so commits become visible in `seq` order and a
//! read after `last` never skips an event that commits later with a smaller number.

use std::sync::Arc;
use std::time::Duration;

use sqlx::postgres::PgListener;
use tokio::time::{sleep, timeout};

use crate::store::events::{self, StoredEvent};
use crate::store::writer::NOTIFY_CHANNEL;
use crate::store::{Pool, Reader};

/// What the follower hands each batch of new events to.
pub type Seen = Arc<dyn Fn(Vec<StoredEvent>) + Send + Sync>;

/// Most events read at once.
const PAGE: u32 = 1000;

/// Follows the log from after `from` for ever, handing new events to `seen` in order.
pub async fn run(pool: sqlx::PgPool, from: i64, poll: Duration, seen: Seen) {
    let reader = Pool::Postgres(pool.clone());
    let mut last = from;
    let mut listener: Option<PgListener> = None;
    loop {
        if listener.is_none() {
            listener = listen(&pool).await;
        }
        loop {
            match events::after(Reader::from(&reader), last, PAGE).await {
                Ok(batch) => {
                    let full = batch.len() == PAGE as usize;
                    if let Some(e) = batch.last() {
                        last = e.seq;
                        seen(batch);
                    }
                    if !full {
                        break;
                    }
                }
                Err(e) => {
                    tracing::warn!(error = %e, "cluster: the event log cannot be read");
                    break;
                }
            }
        }
        match listener.as_mut() {
            Some(l) => match timeout(poll, l.recv()).await {
                Ok(Ok(_)) | Err(_) => {}
                Ok(Err(e)) => {
                    tracing::warn!(error = %e, "cluster: listening for commits failed");
                    listener = None;
                }
            },
            None => sleep(poll).await,
        }
    }
}

async fn listen(pool: &sqlx::PgPool) -> Option<PgListener> {
    let attempt = async {
        let mut l = PgListener::connect_with(pool).await?;
        l.listen(NOTIFY_CHANNEL).await?;
        Ok::<_, sqlx::Error>(l)
    };
    attempt.await.inspect_err(|e| tracing::warn!(error = %e, "cluster: cannot listen for commits")).ok()
}

/// The jobs whose `job.updated` events in `batch` show them unfinished, by id.
pub fn unfinished_jobs(batch: &[StoredEvent]) -> Vec<i64> {
    #[derive(serde::Deserialize)]
    struct Told {
        id: i64,
        state: crate::domain::JobState,
    }
    let mut ids: Vec<i64> = batch
        .iter()
        .filter(|e| e.kind == "job.updated")
        .filter_map(|e| serde_json::from_str::<Told>(&e.data).ok())
        .filter(|t| !t.state.is_terminal())
        .map(|t| t.id)
        .collect();
    ids.sort_unstable();
    ids.dedup();
    ids
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_unfinished_jobs_are_taken_from_a_batch() {
        let e =
            |seq, kind: &str, data: &str| StoredEvent { seq, at: 0, kind: kind.into(), data: data.into() };
        let batch = [
            e(1, "job.updated", r#"{"id":7,"state":"queued","kind":"travel"}"#),
            e(2, "job.updated", r#"{"id":8,"state":"completed"}"#),
            e(3, "device.updated", r#"{"id":9,"state":"queued"}"#),
            e(4, "job.updated", r#"{"id":7,"state":"dispatched"}"#),
        ];
        assert_eq!(unfinished_jobs(&batch), vec![7]);
    }
}
