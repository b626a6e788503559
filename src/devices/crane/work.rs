//! Giving the crane work and taking it back: the hand-over of the next job, cancels through
//! the API, and the automatic cancel of a business alarm.

use tracing::Instrument;

use super::{Crane, CraneError, Current};
use crate::devices::cancel::{CancelRefusal, Withdrawal};
use crate::domain::{Failure, FailureKind, Job, Reported};
use crate::wire::alarms::{self, AlarmClass};
use crate::wire::registers::{self, CraneView};
use crate::wire::task_id_for;

impl Crane {
    /// Hands the best eligible queued job to the idle crane.
    pub(super) async fn dispatch(&mut self) -> Result<(), CraneError> {
        let Some(job) = self.port.next_task().await? else { return Ok(()) };
        let span = tracing::info_span!("job", job = job.id);
        self.dispatch_job(job).instrument(span).await
    }

    async fn dispatch_job(&mut self, job: Job) -> Result<(), CraneError> {
        let Some(spec) = job.spec() else { return Ok(()) };
        let task = match registers::task_for(&spec, task_id_for(job.id), &self.stations) {
            Ok(task) => task,
            Err(why) => {
                let failure = Failure { kind: FailureKind::Unsupported, code: None, text: why.into() };
                return self.record(job.id, Reported::Failed(failure), "the crane cannot run this job").await;
            }
        };
        // From the first write on the crane may take the task: follow it whatever happens.
        self.current = Some(Current {
            job: job.id,
            task,
            seen: false,
            latched_at: None,
            cancel_sent: false,
            alarm: None,
            action: 0,
        });
        self.hand_over(job.id, &task).await?;
        if let Some(c) = self.current.as_mut() {
            c.latched_at = Some(tokio::time::Instant::now());
        }
        let cause = format!("handed to the crane as task {} (mode {})", task.number, task.mode as u16);
        self.record(job.id, Reported::Taken, cause).await
    }

    /// Cancels the task the crane holds through mode 3; a job it does not hold is not
    /// held (the dispatcher cancels it while queued).
    pub(super) async fn cancel(&mut self, id: i64) -> Result<Withdrawal, CancelRefusal> {
        let held = self.current.as_ref().filter(|c| c.job == id).cloned();
        let Some(c) = held else { return Ok(Withdrawal::NotHeld) };
        if c.cancel_sent {
            return Ok(Withdrawal::Done);
        }
        if self.view.is_some_and(|v| [20, 30].contains(&v.action)) {
            return Err(CancelRefusal::Ended);
        }
        match self.send_cancel(&c).await {
            Ok(()) => {}
            Err(CraneError::Plc(e)) => return Err(CancelRefusal::Link(e)),
            Err(CraneError::Report(e)) => return Err(CancelRefusal::Report(e)),
            Err(e) => {
                tracing::warn!(error = %e, "the crane did not take the cancel");
                return Err(CancelRefusal::NotTaken);
            }
        }
        let cause = "cancel (mode 3) sent to the crane through the API";
        match self.record(id, Reported::Cancelling, cause).await {
            Ok(()) => Ok(Withdrawal::Done),
            Err(CraneError::Report(e)) => Err(CancelRefusal::Report(e)),
            Err(_) => Err(CancelRefusal::NotTaken),
        }
    }

    /// Reacts to the alarm the crane shows: a business alarm on the held task cancels it
    /// (when `auto_cancel`), so that the job fails with the alarm once 40 comes back.
    pub(super) async fn on_alarm(&mut self, v: &CraneView) -> Result<(), CraneError> {
        if v.alarm == 0 || !self.config.auto_cancel || self.handing.is_some() {
            return Ok(());
        }
        let alarm = alarms::lookup(v.alarm);
        let Some(c) = self.current.clone() else { return Ok(()) };
        if alarm.class != AlarmClass::Business || c.cancel_sent || v.task != c.task.number {
            return Ok(());
        }
        tracing::warn!(code = alarm.code, "business alarm: cancelling the task");
        self.send_cancel(&c).await?;
        let failure =
            Failure { kind: FailureKind::Alarm, code: Some(alarm.code as i64), text: alarm.text.clone() };
        if let Some(c) = self.current.as_mut() {
            c.alarm = Some(failure);
        }
        let cause = format!("alarm {}: {}; cancel (mode 3) sent", alarm.code, alarm.text);
        self.record(c.job, Reported::Cancelling, cause).await
    }

    /// Hands over the cancel (mode 3) of the held task and remembers it was sent.
    async fn send_cancel(&mut self, c: &Current) -> Result<(), CraneError> {
        self.hand_over(c.job, &c.task.cancel()).await?;
        if let Some(held) = self.current.as_mut().filter(|h| h.job == c.job) {
            held.cancel_sent = true;
        }
        Ok(())
    }
}
