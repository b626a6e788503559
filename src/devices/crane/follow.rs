//! Following the crane by polling D200..D239: heartbeat, the held task's progress, its
//! completion and acknowledgement, and recovery after a restart.

use tokio::time::Instant;

use super::ack::Outcome;
use super::{Crane, CraneError, Current};
use crate::domain::{Failure, FailureKind, JobState, Reported};
use crate::protocols::PlcError;
use crate::wire::registers::{self, BLOCK_WORDS, CraneView, wcs};
use crate::wire::task_id_for;

impl Crane {
    /// One poll: read the crane's block, step the heartbeat, follow the task, acknowledge
    /// a recorded completion, react to alarms.
    pub(super) async fn poll(&mut self) -> Result<(), CraneError> {
        let words = self.read(&self.crane.clone(), BLOCK_WORDS).await?;
        let view = CraneView::parse(&words).ok_or(PlcError::Malformed("short crane block"))?;
        let now = Instant::now();
        if self.view.is_none_or(|v| v.heartbeat != view.heartbeat) {
            self.heartbeat_moved = crate::domain::time::now();
        }
        if let Some(word) = self.heartbeat.observe(view.heartbeat, now) {
            self.write(&self.wcs_word(wcs::HEARTBEAT), &[word]).await?;
            self.heartbeat.wrote(word, now);
        }
        self.view = Some(view);
        self.show(&view);
        self.advance_handing(&view).await?;
        self.follow(&view).await?;
        if let Some(word) = self.ack.next_word(view.completion, self.ack_written) {
            // Unknown until answered: a write that times out may still have landed.
            self.ack_written = None;
            self.write(&self.wcs_word(wcs::ACK), &[word]).await?;
            self.ack_written = Some(word);
        }
        self.on_alarm(&view).await
    }

    /// Brings the held job in line with what the crane shows.
    async fn follow(&mut self, v: &CraneView) -> Result<(), CraneError> {
        if self.current.is_none() && v.task != 0 {
            self.adopt(v.task).await?;
        }
        let Some(mut c) = self.current.clone() else { return Ok(()) };
        let Some(job) = self.port.job(c.job) else {
            self.current = None;
            return Ok(());
        };
        if v.task != c.task.number {
            if self.handing.as_ref().is_some_and(|h| h.job == c.job) {
                // Handed over, or possibly latched: followed until the hand-over is over.
                return Ok(());
            }
            let showing = c.latched_at.is_some_and(|at| at.elapsed() < self.handshake_timeout());
            if !c.seen && showing {
                // Latched; the crane shows it once it starts (a step after ACK = 0, say).
                return Ok(());
            }
            self.current = None;
            if (c.seen || c.latched_at.is_some()) && !job.state.is_terminal() {
                let text = format!("the crane no longer holds task {} (it shows {})", c.task.number, v.task);
                let lost = Failure { kind: FailureKind::Lost, code: None, text: text.clone() };
                self.record(job.id, Reported::Failed(lost), text).await?;
            }
            return Ok(());
        }
        c.seen = true;
        if let Some(outcome) = Outcome::of(v.action, v.completion) {
            let (to, cause) = match (outcome, c.alarm.take()) {
                (Outcome::Done, _) => {
                    (Reported::Finished { forced: false }, "the crane completed it (20)".into())
                }
                (Outcome::Forced, _) => {
                    (Reported::Finished { forced: true }, "force-completed on the crane's panel (30)".into())
                }
                (Outcome::Cancelled, Some(f)) => {
                    let cause = format!("cancelled after alarm {}: {}", f.code.unwrap_or(0), f.text);
                    (Reported::Failed(f), cause)
                }
                (Outcome::Cancelled, None) => (Reported::Cancelled, "the crane cancelled it (40)".to_owned()),
            };
            self.record(job.id, to, cause).await?;
            // Done with the job; the acknowledgement follows in the same poll.
            self.current = None;
            return Ok(());
        }
        if (1..=18).contains(&v.action) && v.action != c.action {
            let cause = format!(
                "action {} ({}), travel {} lift {} load {}",
                v.action,
                registers::action_text(v.action),
                v.travel,
                v.lift,
                v.load
            );
            tracing::debug!("{cause}");
            self.record(job.id, Reported::Running, cause).await?;
            c.action = v.action;
        }
        self.current = Some(c);
        Ok(())
    }

    /// Follows the task the crane shows when it belongs to an unfinished job of ours.
    async fn adopt(&mut self, task: u16) -> Result<(), CraneError> {
        let unfinished = self.port.unfinished();
        let Some(job) = unfinished.into_iter().find(|j| task_id_for(j.id) == task) else { return Ok(()) };
        let Some(spec) = job.spec() else { return Ok(()) };
        let Ok(task) = registers::task_for(&spec, task, &self.stations) else { return Ok(()) };
        tracing::info!(job = job.id, task = task.number, "following the crane's task");
        self.record(job.id, Reported::Taken, format!("the crane holds it as task {}", task.number)).await?;
        self.current = Some(Current {
            job: job.id,
            task,
            seen: true,
            latched_at: None,
            cancel_sent: job.state == JobState::Cancelling,
            alarm: None,
            action: 0,
        });
        Ok(())
    }

    /// On start: read both blocks, take rackd's own words as found, follow the crane's
    /// task if it is ours, carry on an interrupted hand-over ([`Crane::reconstruct`]), fail
    /// the rest as `lost`.
    pub(super) async fn recover(&mut self) -> Result<(), CraneError> {
        let mine = self.read(&self.wcs.clone(), BLOCK_WORDS).await?;
        let words = self.read(&self.crane.clone(), BLOCK_WORDS).await?;
        let view = CraneView::parse(&words).ok_or(PlcError::Malformed("short crane block"))?;
        let word = |k: u32| mine.get(k as usize).copied().unwrap_or(0);
        self.heartbeat.found(word(wcs::HEARTBEAT));
        self.ack_written = Some(word(wcs::ACK));
        self.current = None;
        self.handing = None;
        self.blocked = None;
        if view.task != 0 {
            self.adopt(view.task).await?;
        }
        self.reconstruct(&mine, &view).await?;
        let unfinished = self.port.unfinished();
        let held = self.current.as_ref().map(|c| c.job);
        for job in unfinished.iter().filter(|j| j.state != JobState::Queued && Some(j.id) != held) {
            let text = format!(
                "after a restart the crane does not hold task {} (it shows {})",
                task_id_for(job.id),
                view.task
            );
            let lost = Failure { kind: FailureKind::Lost, code: None, text: text.clone() };
            self.record(job.id, Reported::Failed(lost), text).await?;
        }
        tracing::info!(task = view.task, stb = word(wcs::STB), ack = view.ack, "crane recovered");
        self.poll().await
    }
}
