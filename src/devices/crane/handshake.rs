//! The STB/ACK 4-step hand-over (D21 written by rackd, D225 by the crane), each wait
//! bounded by the configured timeout.

use std::time::Duration;

use tokio::time::Instant;

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
    /// Hands `task` over: task words, STB := 1, ACK = 1, STB := 0, ACK = 0. Whatever fails,
    /// the strobe is left at 0 when the link allows.
    pub(super) async fn hand_over(&mut self, task: &Task) -> Result<(), CraneError> {
        let ack_at = self.crane_word(25);
        if self.read(&ack_at, 1).await?.first().copied().unwrap_or(0) != 0 {
            return Err(HandshakeError::AckStuck.into());
        }
        let task_at = self.wcs_word(wcs::TASK);
        self.write(&task_at, &task.words()).await?;
        // From here the strobe may be up (a write whose reply was lost still happened).
        self.strobe_up = true;
        let result = self.strobe().await;
        if result.is_err() {
            self.withdraw_strobe().await;
        }
        result
    }

    /// Steps 1 to 4 once the task words are written.
    async fn strobe(&mut self) -> Result<(), CraneError> {
        let stb = self.wcs_word(wcs::STB);
        self.write(&stb, &[1]).await?;
        self.wait_ack(1, 2).await?;
        self.write(&stb, &[0]).await?;
        self.strobe_up = false;
        self.wait_ack(0, 4).await
    }

    /// Lowers a strobe a failed hand-over may have left up; if the link fails, the next
    /// poll tries again before anything else. Should the crane have taken the data, it
    /// starts the task now, and its D208 echo leads rackd to follow it.
    pub(super) async fn withdraw_strobe(&mut self) {
        if self.write(&self.wcs_word(wcs::STB), &[0]).await.is_ok() {
            self.strobe_up = false;
        }
    }

    /// Polls D225 until it equals `want`, within the handshake timeout.
    async fn wait_ack(&mut self, want: u16, step: u8) -> Result<(), CraneError> {
        let timeout = Duration::from_millis(self.config.handshake_timeout_ms);
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
}
