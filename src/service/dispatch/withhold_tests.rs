//! Overlapping cancels of one job, in explicit order: a store, a writer and the dispatcher
//! of their own, and a device task played by the test, which answers each request when the
//! test says (see [`super::withhold`]).
//!
//! A single cancel is held between its device's "not held" and its commit while a bulk
//! cancel of the same job ends (refused, failed, or dropped with its request): the job
//! must stay withheld, its device unwoken, until the single cancel has committed
//! `cancelled`. And a cancel dropped on its own lets its job go again.

use std::collections::{BTreeMap, HashSet};
use std::pin::pin;
use std::sync::Arc;
use std::time::Duration;

use futures::FutureExt;
use rstest::rstest;
use tokio::sync::{mpsc, watch};

use super::{Actor, BulkError, Dispatcher, Queues, Setup};
use crate::config::devices::DeviceKind;
use crate::devices::port::Port;
use crate::devices::{DeviceHandle, DeviceRequest, DeviceStatus, Devices, Withdrawal};
use crate::domain::{JobSpec, JobState, Location, NewJob, Priority, Who};
use crate::store::writer::{Hooks, Outcome, Writer};
use crate::store::{Database, open};

/// The dispatcher of one shelf, `shelf1`, with a queued job; the device's requests, and its
/// port.
struct Site {
    dispatcher: Dispatcher,
    devices: Devices,
    requests: mpsc::Receiver<DeviceRequest>,
    port: Arc<dyn Port>,
    job: i64,
    _dir: tempfile::TempDir,
}

async fn site() -> Site {
    let dir = tempfile::tempdir().unwrap();
    let pool = open(&Database::Sqlite(dir.path().join("rackd.db")), Duration::from_secs(5)).await.unwrap();
    let setup = Setup { id: "shelf1".into(), window: 100, aisles: vec![1], planner: None };
    let queues = Queues::new([setup]);
    let hooks = Hooks { committed: Some(queues.hook()), ..Hooks::default() };
    let (writer, _task) = Writer::start(&pool, 100, 100, hooks).await.unwrap();
    let dispatcher = Dispatcher::new(queues.clone(), writer.clone(), pool);
    let (tx, requests) = mpsc::channel(8);
    let handle = DeviceHandle {
        status: watch::channel(DeviceStatus::new("shelf1", DeviceKind::Shelf, "test", "-", 4)).1,
        requests: tx,
        tags: None,
        recorder: None,
    };
    let devices: Devices = Arc::new(BTreeMap::from([("shelf1".to_owned(), handle)]));
    let to = Location { aisle: 1, row: 1, bay: 2, level: 3, position: 1 };
    let new = NewJob {
        spec: JobSpec::Store { to },
        reference: None,
        priority: Priority::default(),
        barcode: None,
        device: Some("shelf1".into()),
        serves: None,
        terms: Default::default(),
    };
    let Outcome::Created { job, .. } = writer.submit(vec![new]).await.unwrap().remove(0) else {
        panic!("a new job")
    };
    let port = queues.port("shelf1", writer);
    Site { dispatcher, devices, requests, port, job: job.id, _dir: dir }
}

impl Site {
    /// What the device would be offered now.
    fn offered(&self) -> Vec<i64> {
        self.port.next(4, &HashSet::new()).iter().map(|j| j.id).collect()
    }

    /// Whether the device was woken since it last looked (and takes the wake-up).
    fn woken(&self) -> bool {
        self.port.work_waiting().now_or_never().is_some()
    }
}

fn who() -> Who {
    Who { name: "wms".into(), client: None }
}

fn actor() -> Actor {
    Actor { by: "operator".into(), client: None, reason: None }
}

/// How the first of two overlapping cancels ends.
#[derive(Clone, Copy, Debug)]
enum End {
    /// Refused: it lists a job the writer refuses.
    Refused,
    /// Failed: the device task stopped before it answered.
    Failed,
    /// Dropped with its request, after its device answered (a client's timeout).
    Dropped,
}

#[rstest]
#[case::refused(End::Refused)]
#[case::failed(End::Failed)]
#[case::dropped(End::Dropped)]
#[tokio::test]
async fn a_bulk_cancel_that_ends_first_does_not_let_go_of_a_job_another_cancel_holds(#[case] end: End) {
    let mut s = site().await;
    let id = s.job;
    assert_eq!(s.offered(), vec![id], "the job is offered before any cancel");
    s.woken();

    // The single cancel asks the device, which does not hold the job...
    let who = who();
    let mut single = pin!(s.dispatcher.cancel(id, &s.devices, &who));
    assert!(futures::poll!(single.as_mut()).is_pending());
    let Some(DeviceRequest::Cancel { job, reply }) = s.requests.recv().await else { panic!("a cancel") };
    assert_eq!(job, id);
    reply.send(Ok(Withdrawal::NotHeld)).unwrap();
    // ... and is not polled again until the end: between its answer and its commit.

    // A bulk cancel of the same job begins and ends meanwhile.
    let actor = actor();
    let listed = match end {
        End::Refused => vec![id, 999_999],
        End::Failed | End::Dropped => vec![id],
    };
    let mut bulk = Box::pin(s.dispatcher.bulk_cancel(listed, &s.devices, false, &actor));
    assert!(futures::poll!(bulk.as_mut()).is_pending());
    let Some(DeviceRequest::Holding { jobs, reply }) = s.requests.recv().await else { panic!("holding") };
    assert_eq!(jobs, vec![id]);
    match end {
        End::Refused => {
            reply.send(Vec::new()).unwrap();
            let refused = bulk.await;
            assert!(matches!(refused, Err(BulkError::Refused(_))), "{refused:?}");
        }
        End::Failed => {
            drop(reply);
            let failed = bulk.await;
            assert!(matches!(failed, Err(BulkError::Unavailable { .. })), "{failed:?}");
        }
        End::Dropped => {
            reply.send(Vec::new()).unwrap();
            drop(bulk);
        }
    }
    assert_eq!(s.offered(), Vec::<i64>::new(), "the single cancel still holds the job: offered to nobody");
    assert!(!s.woken(), "the device is not woken for a job still withheld");

    let done = single.await.expect("the single cancel commits");
    assert_eq!(done.state, JobState::Cancelled);
    assert_eq!(s.offered(), Vec::<i64>::new(), "a cancelled job is offered to nobody");
}

#[rstest]
#[case::single(false)]
#[case::bulk(true)]
#[tokio::test]
async fn a_cancel_dropped_with_its_request_lets_its_job_go(#[case] bulk: bool) {
    let mut s = site().await;
    let id = s.job;
    s.woken();
    let (who, actor) = (who(), actor());
    {
        let mut cancel = match bulk {
            false => s.dispatcher.cancel(id, &s.devices, &who).map(|_| ()).boxed(),
            true => s.dispatcher.bulk_cancel(vec![id], &s.devices, false, &actor).map(|_| ()).boxed(),
        };
        assert!(futures::poll!(cancel.as_mut()).is_pending());
        let request = s.requests.recv().await.expect("a request");
        assert!(matches!(request, DeviceRequest::Cancel { .. } | DeviceRequest::Holding { .. }));
        assert_eq!(s.offered(), Vec::<i64>::new(), "withheld while the cancel decides");
        drop(request);
    }
    assert!(s.woken(), "the device is woken: the job is its to take again");
    assert_eq!(s.offered(), vec![id], "a dropped cancel leaves no hold behind");
}
