//! A hand-over whose scheme has not run to its end, whether cut while rackd runs (link
//! loss, timeout) or by a restart, and how rackd finishes it from the registers alone.
//!
//! The scheme's rule that matters: once the crane has answered ACK = 1 it has latched the
//! task words, and STB := 0 then tells it to start. So rackd lowers its strobe only where
//! that cannot start a task rackd does not follow:
//!
//! | STB (D21) | ACK (D225) | the crane | rackd |
//! |---|---|---|---|
//! | 0 | 0 | took nothing (or has long started: D208 shows it) | nothing under way; words never strobed are harmless |
//! | 1 | 0 | has not latched yet | waits for ACK = 1 until the handshake timeout, then withdraws the strobe; the task stays *possibly latched* |
//! | 1 | 1 | latched D8's task | step 3: STB := 0, then waits for ACK = 0 |
//! | 0 | 1 | starts D8's task (step 4) | waits for ACK = 0 |
//!
//! Throughout, the task is followed as the job whose number (`task_id_for`) it carries,
//! never written again, and no other task is handed over. When STB and ACK are both 0
//! again the hand-over is over: a latched task (ACK = 1 seen, or its number in D208) moves
//! the job to `dispatched` (mode 3: `cancelling`); a possibly latched one is let go only
//! once the crane shows strictly idle ([`CraneView::is_idle`]: ACK, D208, D203, D223 and
//! D205 at 0) at least a handshake timeout after the strobe was seen down, the time the
//! crane has by contract to react to it; the job is then still `queued` and may be handed
//! over again.
//!
//! At start ([`Crane::reconstruct`]) the same state is rebuilt from rackd's D8..D17, D21
//! and the crane's D225 and D208: with the strobe or ACK up, D8 must be the task number of
//! an unfinished job (for mode 1/2, one the crane holds no other task than). Otherwise, with
//! the strobe up, rackd leaves the strobe as found, dispatches nothing and says so in the
//! device's `last_error` until a person has cleared D21 at the crane and the crane is idle:
//! lowering it could start a task nobody follows, leaving it only keeps the crane waiting.
//! A mode 3 (cancel) hand-over is always finished: a cancel starts no task.

use tokio::time::Instant;

use super::{Crane, CraneError, Current};
use crate::domain::{JobState, Reported};
use crate::wire::registers::{CraneView, Mode, TASK_WORDS, Task, wcs};
use crate::wire::task_id_for;

/// A hand-over not known to be over.
#[derive(Clone, Debug, PartialEq)]
pub(super) struct Handing {
    /// The job the task belongs to (0: none of rackd's, a cancel being finished).
    pub(super) job: i64,
    /// The words as written (or found) in D8..D17.
    pub(super) task: Task,
    /// When the strobe went up (or was found up): ACK = 1 is due a handshake timeout later.
    pub(super) since: Instant,
    /// The crane answered ACK = 1 (or showed the task in D208): it holds the task.
    pub(super) latched: bool,
    /// When the strobe was seen down without the crane having latched.
    pub(super) withdrawn: Option<Instant>,
}

impl Handing {
    /// A hand-over of `task` for `job` whose strobe goes up at `since`.
    pub(super) fn new(job: i64, task: Task, since: Instant) -> Handing {
        Handing { job, task, since, latched: false, withdrawn: None }
    }
}

impl Crane {
    /// Reads rackd's own strobe (D21).
    async fn read_stb(&mut self) -> Result<u16, CraneError> {
        let at = self.wcs_word(wcs::STB);
        Ok(self.read(&at, 1).await?.first().copied().unwrap_or(0))
    }

    /// One poll's step of a pending hand-over (see the module doc), given the crane's
    /// block just read; and the check whether a person has cleared a blocking strobe.
    pub(super) async fn advance_handing(&mut self, v: &CraneView) -> Result<(), CraneError> {
        self.check_blocked(v).await?;
        let Some(mut h) = self.handing.clone() else { return Ok(()) };
        let stb = self.read_stb().await?;
        let now = Instant::now();
        let timeout = self.handshake_timeout();
        if v.ack == 1 || (h.task.mode != Mode::Cancel && v.task == h.task.number) {
            h.latched = true;
        }
        match (stb, v.ack) {
            (0, 0) if h.latched => return self.handed(h).await,
            (0, 0) => {
                let down = *h.withdrawn.get_or_insert(now);
                let settled = now.duration_since(down) >= timeout;
                if settled && (h.task.mode == Mode::Cancel || v.is_idle()) {
                    self.not_taken(h);
                    return Ok(());
                }
                self.handing = Some(h);
            }
            (0, _) => self.handing = Some(h),
            _ if h.latched => {
                self.handing = Some(h);
                tracing::info!("the crane latched the task: STB := 0 (step 3)");
                self.write(&self.wcs_word(wcs::STB), &[0]).await?;
            }
            _ if now.duration_since(h.since) >= timeout => {
                self.handing = Some(h);
                tracing::warn!(
                    task = self.handing.as_ref().map_or(0, |h| h.task.number),
                    "no ACK within the handshake timeout: withdrawing the strobe; the task stays possibly latched"
                );
                self.write(&self.wcs_word(wcs::STB), &[0]).await?;
                if let Some(h) = self.handing.as_mut() {
                    h.withdrawn = Some(Instant::now());
                }
            }
            _ => self.handing = Some(h),
        }
        Ok(())
    }

    /// The crane took the task (or the cancel): the job follows.
    async fn handed(&mut self, h: Handing) -> Result<(), CraneError> {
        self.handing = None;
        let held = self.current.as_mut().filter(|c| c.job == h.job && h.job != 0);
        let Some(c) = held else { return Ok(()) };
        if h.task.mode == Mode::Cancel {
            c.cancel_sent = true;
            let cause = format!(
                "the crane took the cancel (mode 3) of task {} after an interrupted hand-over",
                h.task.number
            );
            return self.record(h.job, Reported::Cancelling, cause).await;
        }
        c.latched_at = Some(Instant::now());
        let cause = format!(
            "the crane latched task {} (mode {}); hand-over finished after an interruption",
            h.task.number, h.task.mode as u16
        );
        self.record(h.job, Reported::Taken, cause).await
    }

    /// The crane did not take the task: the job is free to be handed over again.
    fn not_taken(&mut self, h: Handing) {
        self.handing = None;
        tracing::info!(job = h.job, task = h.task.number, "the crane did not take the task");
        if h.task.mode != Mode::Cancel && self.current.as_ref().is_some_and(|c| c.job == h.job && !c.seen) {
            self.current = None;
        }
    }

    /// While a strobe rackd cannot account for is up: keep saying so; once a person has
    /// lowered it and the crane is idle, carry on.
    async fn check_blocked(&mut self, v: &CraneView) -> Result<(), CraneError> {
        let Some(why) = self.blocked.clone() else { return Ok(()) };
        if self.read_stb().await? == 0 && v.is_idle() {
            tracing::info!("the strobe was cleared and the crane is idle: work resumes");
            self.blocked = None;
            self.status.update(|s| s.last_error = None);
        } else {
            self.status.update(|s| s.last_error = Some(why));
        }
        Ok(())
    }

    /// On start, after the crane's own task (D208) is adopted: rebuilds the hand-over a
    /// stop cut, from rackd's block `mine` (D0..D39) and the crane's view (module doc).
    pub(super) async fn reconstruct(&mut self, mine: &[u16], v: &CraneView) -> Result<(), CraneError> {
        let word = |k: u32| mine.get(k as usize).copied().unwrap_or(0);
        let stb = word(wcs::STB);
        if stb == 0 && v.ack == 0 {
            return Ok(());
        }
        let at = wcs::TASK as usize;
        let task = mine.get(at..at + TASK_WORDS).and_then(Task::from_words);
        let unfinished = self.port.unfinished();
        let job = task.and_then(|t| unfinished.into_iter().find(|j| task_id_for(j.id) == t.number));
        let held = self.current.as_ref().map(|c| c.job);
        match (task, job) {
            (Some(task), job) if task.mode == Mode::Cancel => {
                let job = job.map_or(0, |j| j.id);
                tracing::warn!(
                    stb,
                    ack = v.ack,
                    job,
                    task = task.number,
                    "a cancel hand-over was interrupted: finishing it"
                );
                self.handing =
                    Some(Handing { latched: v.ack == 1, ..Handing::new(job, task, Instant::now()) });
            }
            (Some(task), Some(job)) if held.is_none_or(|h| h == job.id) => {
                tracing::warn!(
                    stb,
                    ack = v.ack,
                    job = job.id,
                    task = task.number,
                    "a hand-over was interrupted: carrying it on as that job"
                );
                if held.is_none() {
                    self.current = Some(Current {
                        job: job.id,
                        task,
                        seen: false,
                        latched_at: None,
                        cancel_sent: job.state == JobState::Cancelling,
                        alarm: None,
                        action: 0,
                    });
                }
                self.handing =
                    Some(Handing { latched: v.ack == 1, ..Handing::new(job.id, task, Instant::now()) });
            }
            _ if stb != 0 => {
                let why = format!(
                    "rackd's strobe (D21) was found up with task words {:?} (ACK {}) that are no unfinished job of rackd's (or clash with the crane's task {}); left as found, no work is handed over until a person clears D21 at the crane",
                    mine.get(at..at + TASK_WORDS).unwrap_or(&[]),
                    v.ack,
                    v.task
                );
                tracing::error!("{why}");
                self.status.update(|s| s.last_error = Some(why.clone()));
                self.blocked = Some(why);
            }
            _ => {
                let why = format!(
                    "the crane is starting task words {:?} that are no unfinished job of rackd's; no work until it is idle",
                    mine.get(at..at + TASK_WORDS).unwrap_or(&[])
                );
                tracing::warn!("{why}");
                self.status.update(|s| s.last_error = Some(why));
            }
        }
        Ok(())
    }
}
