//! The task that keeps the dispatcher's book of sequences and dependencies
//! ([`super::gate`]) read, releases what it holds when its time comes, and tells jobs late.

use super::queues::Queues;

/// Keeps the book read, wakes the devices when a member is released and tells jobs late:
/// reads what the book has not seen (after a commit names it; again every second while the
/// store cannot be read), asks the writer for a `job.late` event of each unfinished job
/// whose deadline just passed, and sleeps until the next release or deadline, or the next
/// change. Runs until the process ends.
pub async fn watch(queues: Queues, pool: crate::store::Pool, writer: crate::store::writer::Writer) {
    loop {
        let late = queues.book().newly_late(crate::domain::time::now_ms());
        if !late.is_empty() {
            match writer.record(crate::store::writer::Record::Late { jobs: late }).await {
                Ok(()) | Err(crate::store::writer::WriteError::Closed) => {}
                Err(e) => tracing::warn!(error = %e, "telling jobs late"),
            }
        }
        let unknown = queues.book().unknown();
        let mut retry = false;
        if !unknown.is_empty() {
            match super::gate::resolve(&pool, &unknown).await {
                Ok(read) => {
                    queues.book().read(read.sequences, read.refs);
                    queues.wake_all();
                }
                Err(e) => {
                    tracing::warn!(error = %e, "reading the sequences and dependencies jobs wait for");
                    retry = true;
                }
            }
        }
        let now = crate::domain::time::now_ms();
        let release = {
            let book = queues.book();
            [book.next_release(now), book.next_deadline(now)].into_iter().flatten().min()
        };
        let still = !queues.book().unknown().is_empty();
        let wait = match (release, retry || still) {
            (_, true) => std::time::Duration::from_secs(1),
            (Some(at), false) => std::time::Duration::from_millis(u64::try_from(at - now).unwrap_or(0)),
            (None, false) => std::time::Duration::from_secs(3600),
        };
        let changed = queues.0.book_changed.notified();
        tokio::select! {
            () = changed => {}
            () = tokio::time::sleep(wait) => queues.wake_all(),
        }
    }
}
