//! Giving the crane work and taking it back: the hand-over of the next job, cancels through
//! the API, and the automatic cancel of a business alarm.

use super::alarms::{self, AlarmClass};
use super::registers::{self, CraneView};
use super::{Crane, CraneError, Current};
use crate::devices::follow::Reported;
use crate::devices::shelf::slot::task_id_for;
use crate::domain::{Failure, JobState, Transition};
use crate::service::dispatch::next_jobs;
use crate::store::jobs;
use crate::store::writer::Change;

impl Crane {
    /// Hands the best eligible queued job to the idle crane.
    pub(super) async fn dispatch(&mut self) -> Result<(), CraneError> {
        let unfinished = jobs::unfinished(&self.pool, &self.config.id)
            .await
            .map_err(|e| CraneError::Store(e.to_string()))?;
        let Some(job) = next_jobs(&unfinished, 1).into_iter().next().cloned() else { return Ok(()) };
        let Some(spec) = job.spec() else { return Ok(()) };
        let task = match registers::task_for(&spec, task_id_for(job.id), &self.stations) {
            Ok(task) => task,
            Err(why) => {
                let failure = Failure { kind: "unsupported".into(), code: None, text: why.into() };
                return self.record(&job, Reported::Failed(failure), "the crane cannot run this job").await;
            }
        };
        // From the first write on the crane may take the task: follow it whatever happens.
        self.current =
            Some(Current { job: job.id, task, seen: false, cancel_sent: false, alarm: None, action: 0 });
        self.hand_over(&task).await?;
        if let Some(c) = self.current.as_mut() {
            c.seen = true;
        }
        let cause = format!("handed to the crane as task {} (mode {})", task.number, task.mode as u16);
        self.record(&job, Reported::Taken, &cause).await
    }

    /// Cancels a job: at once while queued; the crane's task through mode 3.
    pub(super) async fn cancel(&mut self, id: i64) -> Result<(), String> {
        let job = jobs::get(&self.pool, id).await.map_err(|e| e.to_string())?.ok_or("no such job")?;
        if job.state.is_terminal() {
            return Err(format!("job {id} is already {}", job.state));
        }
        let held = self.current.as_ref().filter(|c| c.job == id).cloned();
        let Some(c) = held else {
            if job.state != JobState::Queued {
                return Err(format!("job {id} is {} but the crane does not hold it", job.state));
            }
            return self.transition(id, Transition::Cancel, "cancelled through the API").await;
        };
        if c.cancel_sent {
            return Ok(());
        }
        if self.view.is_some_and(|v| [20, 30].contains(&v.action)) {
            return Err(format!("job {id} has already ended on the crane; it is recorded at the next poll"));
        }
        self.send_cancel(&c).await.map_err(|e| format!("sending the cancel to the crane: {e}"))?;
        self.transition(id, Transition::RequestCancel, "cancel (mode 3) sent to the crane through the API")
            .await
    }

    /// Reacts to the alarm the crane shows: a business alarm on the held task cancels it
    /// (when `auto_cancel`), so that the job fails with the alarm once 40 comes back.
    pub(super) async fn on_alarm(&mut self, v: &CraneView) -> Result<(), CraneError> {
        if v.alarm == 0 || !self.config.auto_cancel {
            return Ok(());
        }
        let alarm = alarms::lookup(v.alarm);
        let Some(c) = self.current.clone() else { return Ok(()) };
        if alarm.class != AlarmClass::Business || c.cancel_sent || v.task != c.task.number {
            return Ok(());
        }
        tracing::warn!(device = %self.config.id, job = c.job, code = alarm.code, "business alarm: cancelling the task");
        self.send_cancel(&c).await?;
        let failure =
            Failure { kind: "alarm".into(), code: Some(alarm.code as i64), text: alarm.text.clone() };
        if let Some(c) = self.current.as_mut() {
            c.alarm = Some(failure);
        }
        let cause = format!("alarm {}: {}; cancel (mode 3) sent", alarm.code, alarm.text);
        // A job not yet seen running may already be past cancelling: nothing to record then.
        let _ = self.transition(c.job, Transition::RequestCancel, &cause).await;
        Ok(())
    }

    /// Hands over the cancel (mode 3) of the held task and remembers it was sent.
    async fn send_cancel(&mut self, c: &Current) -> Result<(), CraneError> {
        self.hand_over(&c.task.cancel()).await?;
        if let Some(held) = self.current.as_mut().filter(|h| h.job == c.job) {
            held.cancel_sent = true;
        }
        Ok(())
    }

    async fn transition(&self, id: i64, transition: Transition, cause: &str) -> Result<(), String> {
        let change = Change::Transition {
            transition,
            cause: cause.into(),
            expect: None,
            failure: None,
            forced: false,
        };
        self.writer.change(id, change).await.map(|_| ()).map_err(|e| e.to_string())
    }
}
