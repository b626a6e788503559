//! Every device's unfinished jobs, in memory, kept by the job writer's commits.
//!
//! The writer hands each commit's jobs to [`Queues::committed`] before it answers anyone,
//! so when a device's report returns, the queues already show it, and a job answered 201
//! is in its device's queue before the client hears of it. Devices ask for work through a
//! [`DevicePort`]: nothing reads the database to find work.
//!
//! Per device, jobs on the machine (`active`) are kept apart from `queued` ones, so a
//! dispatch round weighs every active job and only the oldest `dispatch_window` queued
//! ones: a backlog of a hundred thousand jobs costs each round no more than a thousand.
//!
//! What operators set is kept here too, as the store has it (restored at start): a paused
//! device is offered nothing; a job touching a paused aisle or a locked location waits
//! (it is not handed out, keeps later jobs off its locations, and [`Queues::waiting`] says
//! why, see [`super::waiting`]). The writer hands over every lock change of a commit
//! ([`Queues::locked_hook`]).

use std::collections::{BTreeMap, BTreeSet, HashMap, HashSet};
use std::sync::{Arc, Mutex, MutexGuard, RwLock, RwLockReadGuard};

use async_trait::async_trait;
use tokio::sync::{Notify, watch};

use std::sync::atomic::AtomicU64;

use super::gate::Book;
use super::order::next_jobs;
use super::report_error;
use crate::config::devices::DeviceConfig;
use crate::devices::DeviceStatus;
use crate::devices::port::{Port, ReportError};
use crate::domain::{Job, JobState, Location, LocationLock, Pause, Report, Waiting, WaitingReason};
use crate::service::planner::CranePlanner;
use crate::service::planner::refusal::picks_from;
use crate::store::Pool;
use crate::store::writer::{Committed, Locked, Writer};

/// What operators set for a device, apart from what the device reports.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Control {
    /// The device's own pause: it gets no new work; what it runs goes on and is followed.
    pub pause: Option<Pause>,
    /// The aisles it serves that are paused: jobs there wait.
    pub paused_aisles: Vec<u16>,
}

/// One device's unfinished jobs.
#[derive(Default)]
pub(super) struct Queue {
    /// Jobs handed to the device and not yet ended, by id.
    pub(super) active: BTreeMap<i64, Job>,
    /// Jobs waiting for the device, by id (= acceptance order).
    pub(super) queued: BTreeMap<i64, Job>,
    /// The unfinished jobs touching each location, by id: which job is ahead of which.
    pub(super) on: HashMap<Location, BTreeSet<i64>>,
}

/// A device's way to be told of work, and its control state. A reload that changes the
/// device replaces its lane, keeping its wake-up and control state (a pause holds across).
struct Lane {
    wake: Arc<Notify>,
    control: Arc<watch::Sender<Control>>,
    window: usize,
    aisles: Vec<u16>,
    planner: Option<Arc<CranePlanner>>,
}

/// What holds jobs back whichever device serves them.
#[derive(Default)]
pub(super) struct Holds {
    aisles: BTreeMap<u16, Pause>,
    locks: HashMap<Location, LocationLock>,
}

impl Holds {
    /// Why `job` may not start now, if something here holds it: a locked location first,
    /// then a paused aisle.
    pub(super) fn why(&self, job: &Job) -> Option<Waiting> {
        let locations = job.spec().map(|s| s.locations()).unwrap_or_default();
        for l in &locations {
            if let Some(lock) = self.locks.get(l) {
                let text = format!("location {} is locked: {}", slashed(l), lock.reason);
                let mut w = Waiting::new(WaitingReason::LocationLocked, text);
                w.job = lock.job;
                w.by = lock.job.is_none().then(|| lock.by.clone());
                return Some(w);
            }
        }
        locations.iter().find_map(|l| {
            let pause = self.aisles.get(&l.aisle)?;
            let text = format!("aisle {} is paused{}", l.aisle, because(pause));
            let mut w = Waiting::new(WaitingReason::AislePaused, text);
            w.by = Some(pause.by.clone());
            Some(w)
        })
    }
}

/// A location as people write it: `A/R/B/L/P`.
pub(super) fn slashed(l: &Location) -> String {
    format!("{}/{}/{}/{}/{}", l.aisle, l.row, l.bay, l.level, l.position)
}

/// ": REASON (by WHO)", or " (by WHO)" without a reason.
pub(super) fn because(pause: &Pause) -> String {
    match &pause.reason {
        Some(r) => format!(": {r} (by {})", pause.by),
        None => format!(" (by {})", pause.by),
    }
}

/// The unfinished jobs of every configured device.
#[derive(Clone)]
pub struct Queues(pub(super) Arc<Inner>);

pub(super) struct Inner {
    queues: Mutex<HashMap<String, Queue>>,
    lanes: RwLock<HashMap<String, Arc<Lane>>>,
    holds: Mutex<Holds>,
    /// What each running device reports ([`Queues::watch_device`]).
    pub(super) statuses: Mutex<HashMap<String, Watched>>,
    /// What the waiting reasons of queued jobs were last told as (see [`super::waiting`]).
    pub(super) told: Mutex<HashMap<i64, Option<Waiting>>>,
    /// Wakes the waiting watcher: something a waiting reason depends on changed.
    pub(super) changed: Notify,
    /// How many cancels withhold each job ([`super::withhold`]).
    pub(super) withheld: Mutex<HashMap<i64, usize>>,
    /// Whether this node drives the machines (always, but on a standby of a cluster).
    drives: std::sync::atomic::AtomicBool,
    /// The sequences and dependencies of unfinished jobs ([`super::gate`]).
    pub(super) book: Mutex<Book>,
    /// Wakes the gate's task: something it must read, or a new release time.
    pub(super) book_changed: Notify,
}

/// A device as the dispatcher sees it: its id, its dispatch window, the aisles it serves
/// and, for a crane, its planner.
pub struct Setup {
    /// The device's id.
    pub id: String,
    /// How many of the oldest queued jobs a dispatch round weighs.
    pub window: usize,
    /// The aisles whose locations it serves.
    pub aisles: Vec<u16>,
    /// A crane's planner: it chooses the crane's next task ([`Port::next_task`]).
    pub planner: Option<Arc<CranePlanner>>,
}

impl Setup {
    /// The device `d` as the dispatcher sees it; a crane's planner weighs the double-deep
    /// aisles `deep`, reads the store through `pool` and counts the writer's `commits`.
    pub fn of(d: &DeviceConfig, deep: &BTreeSet<u16>, pool: &Pool, commits: &Arc<AtomicU64>) -> Setup {
        Setup {
            id: d.id().to_owned(),
            window: d.dispatch_window(),
            aisles: d.aisles().to_vec(),
            planner: match d {
                DeviceConfig::Crane(c) => {
                    Some(Arc::new(CranePlanner::new(c, deep, pool.clone(), commits.clone())))
                }
                _ => None,
            },
        }
    }
}

impl Queues {
    /// Empty queues for these devices.
    pub fn new(devices: impl IntoIterator<Item = Setup>) -> Queues {
        let mut queues = HashMap::new();
        let mut lanes = HashMap::new();
        for Setup { id, window, aisles, planner } in devices {
            queues.insert(id.clone(), Queue::default());
            let control = Arc::new(watch::Sender::default());
            let lane = Lane { wake: Arc::new(Notify::new()), control, window, aisles, planner };
            lanes.insert(id, Arc::new(lane));
        }
        Queues(Arc::new(Inner {
            queues: Mutex::new(queues),
            lanes: RwLock::new(lanes),
            holds: Mutex::default(),
            statuses: Mutex::default(),
            told: Mutex::default(),
            changed: Notify::new(),
            withheld: Mutex::default(),
            drives: std::sync::atomic::AtomicBool::new(true),
            book: Mutex::default(),
            book_changed: Notify::new(),
        }))
    }

    /// Whether this node drives the machines: a standby of a cluster keeps no queues (it
    /// takes in no commit and no lock) and knows no reason why a job waits.
    pub fn drives(&self) -> bool {
        self.0.drives.load(std::sync::atomic::Ordering::Acquire)
    }

    /// Says whether this node drives the machines (false from start on a cluster node, true
    /// once it becomes the active one).
    pub fn set_drives(&self, drives: bool) {
        self.0.drives.store(drives, std::sync::atomic::Ordering::Release);
    }

    pub(super) fn book(&self) -> MutexGuard<'_, Book> {
        self.0.book.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// The writer hook for sequences: their rows as committed.
    pub fn sequenced_hook(&self) -> crate::store::writer::Sequenced {
        let queues = self.clone();
        Arc::new(move |rows: &[crate::store::sequences::Row]| {
            if queues.drives() {
                queues.book().sequenced(rows);
                queues.0.book_changed.notify_one();
            }
        })
    }

    /// Deadlines and sequences for `/metrics`; None on a node that does not drive.
    pub fn orders(&self) -> Option<super::gate::Orders> {
        if !self.drives() {
            return None;
        }
        let book = self.book();
        let (late, slack) = book.lateness(crate::domain::time::now_ms());
        Some(super::gate::Orders {
            late,
            ended_late: book.ended_late,
            slack,
            inversions: book.inversions.clone(),
        })
    }

    /// Sets the stations sequences are released by (at start, and on a reload).
    pub fn set_stations(&self, stations: &[crate::config::StationConfig]) {
        self.book().set_stations(stations);
        self.0.book_changed.notify_one();
    }

    pub(super) fn holds(&self) -> MutexGuard<'_, Holds> {
        self.0.holds.lock().unwrap_or_else(|p| p.into_inner())
    }

    pub(super) fn lock(&self) -> MutexGuard<'_, HashMap<String, Queue>> {
        self.0.queues.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// The writer hook: every committed job, as committed.
    pub fn hook(&self) -> Committed {
        let queues = self.clone();
        Arc::new(move |jobs: &[&Job]| queues.committed(jobs))
    }

    /// Takes in committed jobs: new and changed ones go to their device's queue, ended ones
    /// leave it; the device is woken. A node that does not drive takes in nothing. A job
    /// ended that others may wait for (a sequence's member, a dependency) wakes every device.
    pub fn committed(&self, jobs: &[&Job]) {
        if !self.drives() {
            return;
        }
        let terms = jobs.iter().any(|j| {
            !j.after.is_empty() || j.sequence.is_some() || j.reference.is_some() || j.deadline.is_some()
        });
        if terms && self.book().committed(jobs) {
            for lane in self.lanes().values() {
                lane.wake.notify_one();
            }
            self.0.book_changed.notify_one();
        }
        let mut woken: Vec<&str> = Vec::new();
        {
            let mut queues = self.lock();
            for job in jobs {
                let Some(device) = job.device.as_deref() else { continue };
                let Some(queue) = queues.get_mut(device) else { continue };
                queue.put(job);
                if !woken.contains(&device) {
                    woken.push(device);
                }
            }
        }
        for device in woken {
            self.wake(device);
        }
    }

    /// Loads what the store holds (at start, before any device runs); jobs the writer
    /// already handed over are newer and kept.
    pub fn load(&self, device: &str, jobs: Vec<Job>) {
        let fresh: Vec<Job> = {
            let mut queues = self.lock();
            let Some(queue) = queues.get_mut(device) else { return };
            let fresh: Vec<Job> = jobs
                .into_iter()
                .filter(|job| !queue.active.contains_key(&job.id) && !queue.queued.contains_key(&job.id))
                .collect();
            for job in &fresh {
                queue.put(job);
            }
            fresh
        };
        let termed: Vec<&Job> = fresh
            .iter()
            .filter(|j| j.sequence.is_some() || !j.after.is_empty() || j.deadline.is_some())
            .collect();
        if !termed.is_empty() && self.book().committed(&termed) {
            self.0.book_changed.notify_one();
        }
    }

    /// Wakes every device's task, and the waiting watcher.
    pub(super) fn wake_all(&self) {
        for lane in self.lanes().values() {
            lane.wake.notify_one();
        }
        self.0.changed.notify_one();
    }

    /// Wakes `device`'s task, and the waiting watcher.
    pub(super) fn wake(&self, device: &str) {
        if let Some(lane) = self.lane(device) {
            lane.wake.notify_one();
        }
        self.0.changed.notify_one();
    }

    fn lanes(&self) -> RwLockReadGuard<'_, HashMap<String, Arc<Lane>>> {
        self.0.lanes.read().unwrap_or_else(|p| p.into_inner())
    }

    fn lane(&self, device: &str) -> Option<Arc<Lane>> {
        self.lanes().get(device).cloned()
    }

    /// Adds a device (a reload added it: its unfinished jobs are then
    /// [loaded](super::Dispatcher::load)), or sets a configured device's window, aisles
    /// and planner anew (a reload changed it), keeping its queue and control state.
    pub fn set_device(&self, setup: Setup) {
        let Setup { id, window, aisles, planner } = setup;
        self.lock().entry(id.clone()).or_default();
        let mut lanes = self.0.lanes.write().unwrap_or_else(|p| p.into_inner());
        let (wake, control) = match lanes.get(&id) {
            Some(old) => (old.wake.clone(), old.control.clone()),
            None => (Arc::new(Notify::new()), Arc::new(watch::Sender::default())),
        };
        let paused: Vec<u16> = self.holds().aisles.keys().copied().filter(|a| aisles.contains(a)).collect();
        control.send_if_modified(|c| std::mem::replace(&mut c.paused_aisles, paused.clone()) != paused);
        wake.notify_one();
        lanes.insert(id, Arc::new(Lane { wake, control, window, aisles, planner }));
        drop(lanes);
        self.0.changed.notify_one();
    }

    /// Removes a device (a reload removed it): its queued jobs stay in the store and wait
    /// as `no_device` (returned, to be told so); nothing of it is handed out any more.
    pub fn remove_device(&self, device: &str) -> Vec<i64> {
        self.0.lanes.write().unwrap_or_else(|p| p.into_inner()).remove(device);
        let queue = self.lock().remove(device).unwrap_or_default();
        self.0.told.lock().unwrap_or_else(|p| p.into_inner()).retain(|id, _| !queue.queued.contains_key(id));
        self.0.changed.notify_one();
        queue.queued.keys().copied().collect()
    }

    /// The configured devices' ids.
    pub fn devices(&self) -> Vec<String> {
        self.lanes().keys().cloned().collect()
    }

    /// The jobs handed to `device` that have not ended, by id.
    pub fn active_on(&self, device: &str) -> Vec<i64> {
        self.lock().get(device).map(|q| q.active.keys().copied().collect()).unwrap_or_default()
    }

    /// Each device's dispatch window.
    pub(super) fn windows(&self) -> HashMap<String, usize> {
        self.lanes().iter().map(|(id, lane)| (id.clone(), lane.window)).collect()
    }

    /// A crane's planner.
    pub(super) fn planner(&self, device: &str) -> Option<Arc<CranePlanner>> {
        self.lanes().get(device)?.planner.clone()
    }

    /// The device's pause, if it is paused.
    pub(super) fn pause_of(&self, device: &str) -> Option<Pause> {
        self.lanes().get(device).and_then(|l| l.control.borrow().pause.clone())
    }

    /// The unfinished jobs touching a location that `exists` says no longer exists (a
    /// reload that removes or shrinks an aisle), as (job, location), by job.
    pub fn touching_outside(&self, exists: impl Fn(&Location) -> bool) -> Vec<(i64, Location)> {
        let queues = self.lock();
        let mut found: Vec<(i64, Location)> = queues
            .values()
            .flat_map(|q| q.on.iter())
            .filter(|(l, _)| !exists(l))
            .flat_map(|(l, jobs)| jobs.iter().map(|&j| (j, *l)))
            .collect();
        found.sort();
        found.dedup_by_key(|(j, _)| *j);
        found
    }

    /// The job, if it is unfinished and its device is configured.
    pub fn find(&self, id: i64) -> Option<Job> {
        let queues = self.lock();
        queues.values().find_map(|q| q.get(id).cloned())
    }

    /// The device's control state, to watch.
    pub fn control(&self, device: &str) -> Option<watch::Receiver<Control>> {
        self.lanes().get(device).map(|lane| lane.control.subscribe())
    }

    /// Whether `device` is configured.
    pub fn has(&self, device: &str) -> bool {
        self.lanes().contains_key(device)
    }

    /// Pauses (`Some`) or resumes a device; false if it is not configured.
    pub fn set_paused(&self, device: &str, pause: Option<Pause>) -> bool {
        let Some(lane) = self.lane(device) else { return false };
        lane.control.send_if_modified(|c| {
            let changed = c.pause.is_some() != pause.is_some();
            c.pause = pause;
            changed
        });
        lane.wake.notify_one();
        self.0.changed.notify_one();
        true
    }

    /// Pauses (`Some`) or resumes an aisle: jobs touching it wait, whichever device serves
    /// it; the devices that serve it show it.
    pub fn set_aisle_paused(&self, aisle: u16, pause: Option<Pause>) {
        {
            let mut holds = self.holds();
            match pause {
                Some(p) => holds.aisles.insert(aisle, p),
                None => holds.aisles.remove(&aisle),
            };
        }
        let paused: Vec<u16> = self.holds().aisles.keys().copied().collect();
        for lane in self.lanes().values().filter(|l| l.aisles.contains(&aisle)) {
            let mine: Vec<u16> = lane.aisles.iter().copied().filter(|a| paused.contains(a)).collect();
            lane.control.send_if_modified(|c| std::mem::replace(&mut c.paused_aisles, mine.clone()) != mine);
            lane.wake.notify_one();
        }
        self.0.changed.notify_one();
    }

    /// The paused aisles, with who paused them.
    pub fn paused_aisles(&self) -> BTreeMap<u16, Pause> {
        self.holds().aisles.clone()
    }

    /// The writer hook for lock changes: a lock holds jobs back at once; an unlock wakes
    /// every device, since any may have work waiting on the location.
    pub fn locked_hook(&self) -> Locked {
        let queues = self.clone();
        Arc::new(move |changes: &[(Location, Option<LocationLock>)]| queues.locked(changes))
    }

    /// Takes in locks (`Some`) and unlocks (at start: every lock the store holds); a node
    /// that does not drive takes in nothing.
    pub fn locked(&self, changes: &[(Location, Option<LocationLock>)]) {
        if !self.drives() {
            return;
        }
        let unlocked = {
            let mut holds = self.holds();
            let mut unlocked = false;
            for (l, lock) in changes {
                match lock {
                    Some(lock) => drop(holds.locks.insert(*l, lock.clone())),
                    None => unlocked |= holds.locks.remove(l).is_some(),
                }
            }
            unlocked
        };
        if unlocked {
            for lane in self.lanes().values() {
                lane.wake.notify_one();
            }
        }
        self.0.changed.notify_one();
    }

    /// The unfinished job that takes the box at `l` away (a retrieve or move from it), if
    /// any.
    pub fn taking_from(&self, l: Location) -> Option<i64> {
        let queues = self.lock();
        queues.values().find_map(|q| {
            let ids = q.on.get(&l)?;
            ids.iter().copied().find(|id| {
                let job = q.active.get(id).or_else(|| q.queued.get(id));
                job.and_then(|j| j.spec()).is_some_and(|s| picks_from(&s, l))
            })
        })
    }

    /// The port through which `device` gets its work and reports it.
    pub fn port(&self, device: &str, writer: Writer) -> Arc<dyn Port> {
        Arc::new(DevicePort { queues: self.clone(), device: device.to_owned(), writer })
    }
}

impl Queue {
    fn put(&mut self, job: &Job) {
        let locations = job.spec().map(|s| s.locations()).unwrap_or_default();
        if job.state.is_terminal() {
            self.active.remove(&job.id);
            self.queued.remove(&job.id);
            for l in locations {
                if let Some(ids) = self.on.get_mut(&l) {
                    ids.remove(&job.id);
                    if ids.is_empty() {
                        self.on.remove(&l);
                    }
                }
            }
            return;
        }
        for l in locations {
            self.on.entry(l).or_default().insert(job.id);
        }
        if job.state == JobState::Queued {
            self.active.remove(&job.id);
            self.queued.insert(job.id, job.clone());
        } else {
            self.queued.remove(&job.id);
            self.active.insert(job.id, job.clone());
        }
    }

    fn get(&self, id: i64) -> Option<&Job> {
        self.active.get(&id).or_else(|| self.queued.get(&id))
    }

    /// Every active job and the oldest `window` queued ones, in id order.
    fn window(&self, window: usize) -> Vec<&Job> {
        let mut jobs: Vec<&Job> = self.active.values().chain(self.queued.values().take(window)).collect();
        jobs.sort_unstable_by_key(|j| j.id);
        jobs
    }
}

/// One device's [`Port`].
pub(super) struct DevicePort {
    pub(super) queues: Queues,
    pub(super) device: String,
    pub(super) writer: Writer,
}

#[async_trait]
impl Port for DevicePort {
    fn unfinished(&self) -> Vec<Job> {
        let queues = self.queues.lock();
        let Some(queue) = queues.get(&self.device) else { return Vec::new() };
        queue.window(usize::MAX).into_iter().cloned().collect()
    }

    fn job(&self, id: i64) -> Option<Job> {
        self.queues.lock().get(&self.device).and_then(|q| q.get(id)).cloned()
    }

    fn next(&self, free: usize, holding: &HashSet<i64>) -> Vec<Job> {
        self.eligible(free, holding)
    }

    async fn next_task(&self) -> Result<Option<Job>, ReportError> {
        let planner = self.queues.planner(&self.device);
        match planner {
            Some(planner) => super::plan::next_task(self, &self.device, &self.writer, &planner).await,
            None => Ok(self.eligible(1, &HashSet::new()).into_iter().next()),
        }
    }

    async fn work_waiting(&self) {
        match self.queues.lane(&self.device) {
            Some(lane) => lane.wake.notified().await,
            None => std::future::pending().await,
        }
    }

    async fn report(&self, reports: Vec<Report>) -> Result<Vec<Job>, ReportError> {
        if reports.is_empty() {
            return Ok(Vec::new());
        }
        let answers = self.writer.report(reports).await.map_err(report_error)?;
        answers.into_iter().map(|a| a.map_err(report_error)).collect()
    }
}

impl DevicePort {
    /// The queued jobs the order rules let start now, best first, at most `free`; none
    /// while the device is paused.
    pub(super) fn eligible(&self, free: usize, holding: &HashSet<i64>) -> Vec<Job> {
        let Some(lane) = self.queues.lane(&self.device) else { return Vec::new() };
        if free == 0 || lane.control.borrow().pause.is_some() {
            return Vec::new();
        }
        let queues = self.queues.lock();
        let Some(queue) = queues.get(&self.device) else { return Vec::new() };
        let window = queue.window(lane.window);
        let mut held: HashSet<i64> = holding.clone();
        held.extend(self.queues.withheld().keys());
        {
            let holds = self.queues.holds();
            if !holds.locks.is_empty() || !holds.aisles.is_empty() {
                let waiting = window.iter().filter(|j| j.state == JobState::Queued && holds.why(j).is_some());
                held.extend(waiting.map(|j| j.id));
            }
        }
        let mut termed = window
            .iter()
            .filter(|j| j.state == JobState::Queued && (j.sequence.is_some() || !j.after.is_empty()))
            .peekable();
        if termed.peek().is_some() {
            let book = self.queues.book();
            let now = crate::domain::time::now_ms();
            held.extend(termed.filter(|j| book.why(j, now).is_some()).map(|j| j.id));
        }
        next_jobs(window, &held, free).into_iter().cloned().collect()
    }
}

/// A running device's status, and the task that wakes the watcher on its changes (stopped
/// with it).
pub(super) struct Watched {
    pub(super) status: watch::Receiver<DeviceStatus>,
    pub(super) forwarder: tokio::task::JoinHandle<()>,
}

impl Drop for Watched {
    fn drop(&mut self) {
        self.forwarder.abort();
    }
}
