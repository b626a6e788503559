//! The STB/ACK 4-step hand-over (D21 written by rackd, D225 by the crane), each wait
//! bounded by the configured timeout. A hand-over that stops half-way is not undone here:
//! it stays [`Handing`] and [`super::interrupted`] carries it on at each poll.

use std::time::Duration;

use tokio::time::Instant;

use super::interrupted::Handing;
use super::{Crane, CraneError};
use crate::protocols::PlcError;
use crate::wire::registers::{Task, wcs};

/// Why a hand-over did not complete.
#[derive(Debug, thiserror::Error)]
pub enum HandshakeError {
    /// The crane's ACK was still 1 before rackd raised the strobe (a hand-over of someone
    /// else's, or a crane that did not finish the last one).
    #[error("the crane's ACK (D225) is already 1; not handing over")]
    AckStuck,
    /// An earlier hand-over has not run to its end: no second one meanwhile.
    #[error("the hand-over of task {task} has not run to its end; not handing over another")]
    Pending {
        /// The task number of the earlier hand-over.
        task: u16,
    },
    /// The crane did not reach the expected ACK in time at `step` (2: ACK = 1, 4: ACK = 0).
    #[error("hand-over step {step}: ACK did not become {want} within {waited:?}")]
    Timeout {
        /// The step of the spec's table.
        step: u8,
        /// The ACK value waited for.
        want: u16,
        /// How long rackd waited.
        waited: Duration,
    },
}

impl Crane {
    /// Hands `task` of `job` over: task words, STB := 1, ACK = 1, STB := 0, ACK = 0.
    /// Should a step fail, the hand-over stays pending (the strobe is NOT lowered here:
    /// lowering it tells a crane that latched the task to start it) and each poll carries
    /// it on ([`Crane::advance_handing`]).
    /// The frames are marked in the link's flight recorder as serving `job` and the task.
    pub(super) async fn hand_over(&mut self, job: i64, task: &Task) -> Result<(), CraneError> {
        self.plc.serving(Some((job, task.number)));
        let result = self.handshake(job, task).await;
        self.plc.serving(None);
        result
    }

    /// The steps of [`Crane::hand_over`].
    async fn handshake(&mut self, job: i64, task: &Task) -> Result<(), CraneError> {
        if let Some(h) = &self.handing {
            return Err(HandshakeError::Pending { task: h.task.number }.into());
        }
        let ack_at = self.crane_word(25);
        if self.read(&ack_at, 1).await?.first().copied().unwrap_or(0) != 0 {
            return Err(HandshakeError::AckStuck.into());
        }
        let task_at = self.wcs_word(wcs::TASK);
        // The crane takes nothing before the strobe: a failed write of the words is harmless.
        self.write(&task_at, &task.words()).await?;
        // From here the strobe may be up (a write whose reply was lost still happened).
        self.handing = Some(Handing::new(job, *task, Instant::now()));
        self.strobe().await?;
        self.handing = None;
        Ok(())
    }

    /// Steps 1 to 4 once the task words are written.
    async fn strobe(&mut self) -> Result<(), CraneError> {
        let stb = self.wcs_word(wcs::STB);
        self.write(&stb, &[1]).await?;
        self.wait_ack(1, 2).await?;
        if let Some(h) = self.handing.as_mut() {
            h.latched = true;
        }
        self.write(&stb, &[0]).await?;
        self.wait_ack(0, 4).await
    }

    /// Polls D225 until it equals `want`, within the handshake timeout.
    async fn wait_ack(&mut self, want: u16, step: u8) -> Result<(), CraneError> {
        let timeout = self.handshake_timeout();
        let pause = self.config.poll().min(Duration::from_millis(10));
        let start = Instant::now();
        let ack_at = self.crane_word(25);
        loop {
            match self.read(&ack_at, 1).await {
                Ok(w) if w.first() == Some(&want) => return Ok(()),
                Ok(_) | Err(PlcError::Timeout { .. }) => {}
                Err(e) => return Err(e.into()),
            }
            if start.elapsed() >= timeout {
                return Err(HandshakeError::Timeout { step, want, waited: start.elapsed() }.into());
            }
            tokio::time::sleep(pause).await;
        }
    }

    /// How long the crane has for each reaction of the hand-over.
    pub(super) fn handshake_timeout(&self) -> Duration {
        Duration::from_millis(self.config.handshake_timeout_ms)
    }
}
