//! When each task reached the crane, started and ended, for a benchmark that needs the
//! instants themselves rather than the sums of [`super::stats`]: `bench site` takes the
//! time a task waited for the WCS (from the crane's last completion to the next hand-over)
//! and when a box reached the station (its completion) from here. Off unless asked for
//! ([`super::CraneSim::record_tasks`]): a crane simulator left running for days keeps no
//! record that grows.
//!
//! The instants are real ones (the clock the WCS runs on); a benchmark turns them into
//! simulated time through the time scale. A completion is dated to the moment its last
//! action state's time ran out, not to the tick that noticed it, so a coarse tick at a
//! high time scale does not move it.

use tokio::time::Instant;

/// One task's instants.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TaskTimes {
    /// The task number (D8 as handed over).
    pub number: u16,
    /// When the crane took the task (hand-over step 2: ACK := 1).
    pub received: Instant,
    /// When it started to run it (step 4).
    pub started: Option<Instant>,
    /// When it ended, and how: 20 (complete) or 40 (cancelled).
    pub ended: Option<(Instant, u16)>,
}

/// Every task the crane took since recording began, in order.
#[derive(Clone, Debug, Default)]
pub struct Timeline {
    tasks: Vec<TaskTimes>,
}

impl Timeline {
    /// The tasks so far.
    pub fn tasks(&self) -> &[TaskTimes] {
        &self.tasks
    }

    /// A task taken at step 2.
    pub(super) fn received(&mut self, number: u16, at: Instant) {
        self.tasks.push(TaskTimes { number, received: at, started: None, ended: None });
    }

    /// The last task taken starts.
    pub(super) fn started(&mut self, number: u16, at: Instant) {
        if let Some(t) = self.last(number) {
            t.started.get_or_insert(at);
        }
    }

    /// The last task taken ends in `state`.
    pub(super) fn ended(&mut self, number: u16, at: Instant, state: u16) {
        if let Some(t) = self.last(number) {
            t.ended.get_or_insert((at, state));
        }
    }

    fn last(&mut self, number: u16) -> Option<&mut TaskTimes> {
        self.tasks.last_mut().filter(|t| t.number == number)
    }
}
