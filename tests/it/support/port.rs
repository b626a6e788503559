//! The dispatcher's side of a device's port in memory, for the tests that run a device
//! adapter in one process (the crane on paused time, the adapters over the simulated
//! wire): jobs by id, reports walked through the domain's state machine ([`path`]) and
//! recorded in order, pause as a flag.

use std::collections::{BTreeMap, HashSet};
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};

use async_trait::async_trait;
use rackd::devices::port::{Port, ReportError};
use rackd::domain::report::path;
use rackd::domain::{Job, JobSpec, JobState, NewJob, Priority, Report, Reported};
use tokio::sync::Notify;
use tokio::time::Instant;

/// The dispatcher's side of the port, in memory: jobs by id, reports recorded in order.
#[derive(Default)]
pub struct TestPort {
    pub jobs: Mutex<BTreeMap<i64, Job>>,
    pub paused: AtomicBool,
    pub wake: Notify,
    pub reports: Mutex<Vec<(Instant, Report)>>,
}

#[async_trait]
impl Port for TestPort {
    fn unfinished(&self) -> Vec<Job> {
        self.jobs.lock().unwrap().values().filter(|j| !j.state.is_terminal()).cloned().collect()
    }

    fn job(&self, id: i64) -> Option<Job> {
        self.jobs.lock().unwrap().get(&id).filter(|j| !j.state.is_terminal()).cloned()
    }

    fn next(&self, free: usize, holding: &HashSet<i64>) -> Vec<Job> {
        if self.paused.load(Ordering::SeqCst) {
            return Vec::new();
        }
        let jobs = self.jobs.lock().unwrap();
        let queued = jobs.values().filter(|j| j.state == JobState::Queued && !holding.contains(&j.id));
        queued.take(free).cloned().collect()
    }

    async fn work_waiting(&self) {
        self.wake.notified().await
    }

    async fn report(&self, reports: Vec<Report>) -> Result<Vec<Job>, ReportError> {
        let mut jobs = self.jobs.lock().unwrap();
        let mut answers = Vec::new();
        for report in reports {
            let job = jobs.get_mut(&report.job).ok_or(ReportError::NotFound(report.job))?;
            for t in path(job.state, &report.to) {
                job.state = job.state.apply(t).unwrap_or_else(|e| panic!("{report:?}: {e}"));
            }
            if let Some(failure) = report.to.failure() {
                job.failure = Some(failure.clone());
            }
            job.forced |= report.to.forced();
            answers.push(job.clone());
            self.reports.lock().unwrap().push((Instant::now(), report));
        }
        Ok(answers)
    }
}

impl TestPort {
    /// Queues a job (as the writer hands a committed job to the dispatcher); its id.
    pub fn queue(&self, spec: JobSpec) -> i64 {
        let mut jobs = self.jobs.lock().unwrap();
        let id = jobs.keys().last().map_or(1, |k| k + 1);
        let new = NewJob {
            spec,
            reference: None,
            priority: Priority::DEFAULT,
            barcode: None,
            device: None,
            serves: None,
            terms: Default::default(),
        };
        jobs.insert(id, new.accepted(id, rackd::domain::time::now_ms()));
        drop(jobs);
        self.wake.notify_one();
        id
    }

    /// Pauses or resumes the device, as the dispatcher's control state does.
    pub fn set_paused(&self, paused: bool) {
        self.paused.store(paused, Ordering::SeqCst);
        if !paused {
            self.wake.notify_one();
        }
    }

    /// Job `id` as the port holds it, ended or not.
    pub fn job_as_held(&self, id: i64) -> Job {
        self.jobs.lock().unwrap()[&id].clone()
    }

    /// Every job, ended or not.
    pub fn jobs(&self) -> Vec<Job> {
        self.jobs.lock().unwrap().values().cloned().collect()
    }

    /// The reports of job `id`, in order.
    pub fn reports_of(&self, id: i64) -> Vec<Reported> {
        let reports = self.reports.lock().unwrap();
        reports.iter().filter(|(_, r)| r.job == id).map(|(_, r)| r.to.clone()).collect()
    }
}
