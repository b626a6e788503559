//! What the job writer tells after each commit, and to whom: the dispatcher's queues
//! (committed jobs, lock changes, why a job waits), the event hub, the metrics (and the
//! counts of jobs and alarms behind them).
//!
//! A node of a cluster that does not drive the machines keeps no queues: they take in
//! nothing while [`Queues::drives`] is false, and the active node's waiting watcher tells
//! why a job waits (it retells what it never told). Its hub is fed from the event log,
//! which every node writes (`app::cluster`), not from its own commits: the same commit
//! would come twice. For the same reason its counts of jobs and alarms are read again from
//! the store as it follows the log, not changed by its own commits. Every node tells its own
//! store faults (`store::fault`): each has its own writer.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use crate::api::metrics::Metrics;
use crate::service::dispatch::Queues;
use crate::service::events::Hub;
use crate::store::fault::StoreFault;
use crate::store::writer::{Hooks, Publish, Stored};

/// The writer's hooks; `clustered` when the node is one of a cluster.
pub(super) fn hooks(
    queues: &Queues,
    hub: &Hub,
    metrics: &Arc<Metrics>,
    commits: &Arc<AtomicU64>,
    fault: &StoreFault,
    clustered: bool,
) -> Hooks {
    // The crane planners' cache of the store counts commits: this node's at once, the
    // others' as the log is followed.
    let (hub, commits) = (hub.clone(), commits.clone());
    let publish: Publish = Arc::new(move |events| {
        commits.fetch_add(1, Ordering::Release);
        if !clustered {
            hub.publish(events)
        }
    });
    let stalled = fault.clone();
    let (fault, counted) = (fault.clone(), metrics.clone());
    let stored: Stored = Arc::new(move |outcome| {
        if let Err(cause) = outcome {
            counted.count_store_failure(cause);
        }
        fault.observe(outcome);
    });
    let counted = metrics.clone();
    Hooks {
        stalled: Some(Arc::new(move || stalled.observe(Err(crate::store::fault::Cause::Unreachable)))),
        stored: Some(stored),
        unsure: Some(Arc::new(move |landed| counted.count_unsure_commit(landed))),
        committed: Some(queues.hook()),
        sequenced: Some(queues.sequenced_hook()),
        locked: Some(queues.locked_hook()),
        tell: Some(queues.tell_hook()),
        publish: Some(publish),
        // A node of a cluster reads the counts again as it follows the log (`cluster`).
        observe: Some(metrics.writer_hook(!clustered)),
    }
}
